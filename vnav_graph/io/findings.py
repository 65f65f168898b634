"""What the input checks of :mod:`vnav_graph.io.sanity` found: repairs, warnings, statistics.

One :class:`Findings` record is filled by every check of a ``check_drive`` run (the stream
checks in ``sanity`` and the IMU checks in ``imu_checks``) and becomes ``meta["warnings"]``,
``meta["repaired"]`` and ``meta["sanity"]``; :func:`reject` builds the one-line ``ValueError``
of a refused drive.
"""

from __future__ import annotations

from typing import Any


class Findings:
    """Repairs (``repair``), warnings (``warn``) and statistics (``diag``) of one run."""

    def __init__(self, meta: dict[str, Any]) -> None:
        self.meta = meta
        self.diag: dict[str, Any] = {}  # measured statistics → meta["sanity"]
        self.warnings: list[str] = [str(w) for w in (meta.get("warnings") or [])]
        rep = meta.get("repaired")
        self.repaired: dict[str, dict[str, int]] = (
            {k: dict(v) for k, v in rep.items() if isinstance(v, dict)}
            if isinstance(rep, dict) else {})

    def repair(self, stream: str, reason: str, count: int, warning: str) -> None:
        d = self.repaired.setdefault(stream, {})
        d[reason] = d.get(reason, 0) + int(count)
        self.warnings.append(warning)

    def warn(self, warning: str) -> None:
        self.warnings.append(warning)


def reject(stream: str, why: str) -> ValueError:
    """The one-line error that refuses a drive: ``"<stream>: <why>"``."""
    return ValueError(f"{stream}: {why}")

