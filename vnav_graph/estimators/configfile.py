"""Estimator configs from a TOML file: ``vnav-graph run|bench|holdout --config FILE.toml``.

One table per estimator, named as in the registry (docs/design.md); its keys are fields of
that estimator's config dataclass (``GraphConfig``, ``EkfConfig``, ``Loop3Config`` …), and
every key not given keeps the estimator's own default::

    [graph-batch]
    max_iterations = 300

    [ekf]
    gate_prob = 0.999

    [loop3]
    ahrs = { tilt_omega = 0.04 }                  # a nested config: a (sub-)table
    gains = [0.15, 0.0075, 0.000125]              # a tuple field: an array

Values are checked against the field types before any work: ``int`` (a TOML integer),
``float`` (integer or float), ``bool``, ``str``, fixed-length or ``...`` tuples of those, and
nested config dataclasses. TOML has no null, so a field that defaults to ``None`` can only be
given a value. An unknown section (estimator) or key, or a value of the wrong type, is a
``ValueError`` with one line naming the file, the section and the key (exit 2 in the CLI).

The section names the estimator, not its config class: ``[graph-batch]`` and
``[graph-isam2]`` are set independently although both take a ``GraphConfig``. A section for
an extension estimator (``--plugin``) works the same when that estimator has a dataclass
``config`` attribute. Note that ``graph-isam2`` applies its low-IMU-rate settings only to its
default config (``graph.isam2.LOW_RATE_SETTINGS``); any ``[graph-isam2]`` section turns that off.
"""

from __future__ import annotations

import dataclasses
import tomllib
import types
import typing
from pathlib import Path
from typing import Any

from ..util.failures import failure_message
from ..util.suggest import did_you_mean
from .base import available, create


def load_configs(path: str | Path) -> dict[str, Any]:
    """Read ``path`` and return ``{estimator name: config object}`` for its sections.

    Each config is the estimator's default config (``create(name).config``) with the file's
    keys replaced. Raises ValueError (one line) on a missing or malformed file, an unknown
    estimator or key, or a value of the wrong type.
    """
    p = Path(path)
    try:
        doc = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise ValueError(f"--config: no such file: {p}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--config: cannot read {p}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{p}: not valid TOML: {exc}") from None
    names = available()
    configs: dict[str, Any] = {}
    for section, table in doc.items():
        if not isinstance(table, dict):
            raise ValueError(f"{p}: top-level key {section!r} is not an [estimator] table")
        if section not in names:
            raise ValueError(f"{p}: unknown estimator [{section}]{_hint(section, names)} "
                             f"(available: {', '.join(names)})")
        base = getattr(create(section), "config", None)
        if not dataclasses.is_dataclass(base) or isinstance(base, type):
            raise ValueError(f"{p}: [{section}] has no config dataclass to set")
        configs[section] = override(base, table, f"{p}: [{section}]")
    return configs


def override(config: Any, table: dict[str, Any], where: str = "config", prefix: str = "") -> Any:
    """``config`` (a dataclass instance) with the fields in ``table`` replaced, each value
    checked against the field's type. Error messages start with ``where`` and name the key
    as ``prefix + key`` (``prefix`` is the dotted path of a nested config)."""
    fields = {f.name: f for f in dataclasses.fields(config)}
    try:
        hints = typing.get_type_hints(type(config))
    except Exception:  # an annotation that does not resolve at run time: use the value's type
        hints = {n: type(getattr(config, n)) for n in fields}
    changes: dict[str, Any] = {}
    renamed = getattr(type(config), "RENAMED", {})
    for key, value in table.items():
        if key in renamed:
            raise ValueError(f"{where} key {prefix + key!r} is now {prefix + renamed[key]!r}")
        if key not in fields:
            hint = (_hint(key, list(fields))
                    or f" (keys of {type(config).__name__}: {', '.join(fields)})")
            raise ValueError(f"{where} unknown key {prefix + key!r}{hint}")
        changes[key] = _coerce(value, hints[key], getattr(config, key), where, prefix + key)
    try:
        return dataclasses.replace(config, **changes)
    except (ValueError, TypeError) as exc:  # the config's own validation
        msg = failure_message(exc)
        loc = f"{where} {prefix.rstrip('.')}" if prefix else where
        raise ValueError(f"{loc}: {msg}") from None


def _hint(word: str, choices: list[str]) -> str:
    return did_you_mean(word, choices)


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def _coerce(value: Any, tp: Any, current: Any, where: str, key: str) -> Any:
    """``value`` converted to the field type ``tp`` (ValueError if it is not one); ``key``
    names the field in messages."""
    at = f"{where} {key}"
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is types.UnionType:
        arms = [a for a in typing.get_args(tp) if a is not type(None)]
        errors = []
        for arm in arms:
            try:
                return _coerce(value, arm, current, where, key)
            except ValueError as exc:
                errors.append(exc)
        if len(arms) == 1:
            raise errors[0]
        raise ValueError(f"{at}: expected {' or '.join(map(_type_name, arms))}, "
                         f"got {type(value).__name__} {value!r}")
    if tp is bool:
        if isinstance(value, bool):
            return value
    elif tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif tp is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
    elif tp is str:
        if isinstance(value, str):
            return value
    elif origin is tuple:
        args = typing.get_args(tp)
        if isinstance(value, list):
            variadic = len(args) == 2 and args[1] is Ellipsis
            item_types = [args[0]] * len(value) if variadic else list(args)
            if len(item_types) != len(value):
                raise ValueError(f"{at}: expected {len(args)} values, got {len(value)}")
            return tuple(_coerce(v, it, None, where, f"{key}[{i}]")
                         for i, (v, it) in enumerate(zip(value, item_types, strict=True)))
    elif isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if isinstance(value, dict):
            base = current if isinstance(current, tp) else tp()
            return override(base, value, where, f"{key}.")
    else:
        raise ValueError(f"{at}: a field of type {_type_name(tp)} cannot be set from a "
                         "config file")
    raise ValueError(f"{at}: expected {_type_name(tp)}, got {type(value).__name__} "
                     f"{value!r}")
