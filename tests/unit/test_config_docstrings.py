"""Config docstrings hold one line per field: what it means, its unit and when it is off.

Every field a config class declares is named at the start of exactly one docstring line
(``name: ...`` or ``name : ...``; related fields may share it, ``a, b: ...``), and no line
continues onto the next (a deeper-indented line). Longer reasons go into comments beside the
field or into the module docstring.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re

import pytest

CONFIGS = {
    "vnav_graph.config": ("ImuSpec", "GnssSpec", "BaroSpec", "ScenarioConfig"),
    "vnav_graph.sensors.gnss_model": ("GnssErrorSettings",),
    "vnav_graph.estimators.shared_settings": ("SharedSettings",),
    "vnav_graph.sensors.magnetometer": ("MagSpec",),
    "vnav_graph.estimators.ekf.settings": ("EkfConfig",),
    "vnav_graph.estimators.graph.settings": ("GraphConfig",),
    "vnav_graph.estimators.vertical.adaptive": ("AdaptiveConfig",),
    "vnav_graph.estimators.vertical.inputs": ("AhrsConfig",),
    "vnav_graph.estimators.vertical.loops": ("Loop2Config", "Loop3Config"),
    "vnav_graph.estimators.vertical.observer1d": ("ObserverConfig",),
    "vnav_graph.estimators.vertical.vekf7": ("VEKF7Config",),
    "vnav_graph.estimators.vertical.vkf4": ("VKF4Config",),
}
FIELD_LINE = re.compile(r"^(\w+(?:, \w+)*) ?: ")


def docstring_faults(cls: type) -> list[str]:
    lines = inspect.cleandoc(cls.__doc__ or "").splitlines()[1:]
    faults = [f"continued line: {ln.strip()[:50]!r}" for ln in lines if ln.startswith(" ")
              and ln.strip()]
    named: dict[str, int] = {}
    for ln in lines:
        m = FIELD_LINE.match(ln)
        for name in m.group(1).split(", ") if m else ():
            named[name] = named.get(name, 0) + 1
    inherited = {f.name for base in cls.__mro__[1:] if dataclasses.is_dataclass(base)
                 for f in dataclasses.fields(base)}
    for f in dataclasses.fields(cls):
        if f.name in inherited:
            continue
        if named.get(f.name, 0) != 1:
            faults.append(f"{f.name} named on {named.get(f.name, 0)} lines")
    return faults


@pytest.mark.parametrize("module,name", [(m, n) for m, ns in CONFIGS.items() for n in ns])
def test_one_docstring_line_per_field(module: str, name: str) -> None:
    cls = getattr(importlib.import_module(module), name)
    assert dataclasses.is_dataclass(cls)
    assert not docstring_faults(cls), f"{name}: {docstring_faults(cls)}"


def test_the_check_sees_a_missing_and_a_continued_field() -> None:
    @dataclasses.dataclass(frozen=True)
    class Cfg:
        """Settings.

        a: first [m].
        b : second, whose reason
            goes on.
        """

        a: float = 1.0
        b: float = 2.0
        c: float = 3.0

    assert docstring_faults(Cfg) == ["continued line: 'goes on.'", "c named on 0 lines"]
