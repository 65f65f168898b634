"""Python factors in ``graph-isam2``: each ``gtsam.CustomFactor`` of an extension (the compass
heading factors of ``model.builtin_sensors``, a user's factors) enters iSAM2 as a
``LinearContainerFactor`` linearised here, and is relinearised by :class:`PyFactorBook`.

Why: iSAM2 relinearises a ``CustomFactor`` from C++, and pybind11 hands the Python callback
a copy of iSAM2's whole ``Values`` each time (a ``const Values&`` that no Python object
owns is copied): ≈ 200 µs per call for 2 000 variables, O(variables) per call, for every
heading factor of the window at every relinearisation (docs/real_logs.md, "Magnetometer
noise, field strength and spread"). Linearised here, the callback gets a ``Values`` of the
factor's own keys (≈ 20–40 µs per factor, independent of the drive's length).

The book does what iSAM2 does for its own factors, per factor: it keeps each factor's
linearisation point, and after each update (every ``relinearize_skip``-th) checks every
factor still in iSAM2 against the current estimate — a keyframe pose X(k) by its rotation
angle and body-frame translation (as ``relin.TermBook``), any other key component-wise —
with iSAM2's thresholds (``setup.threshold_map``; an extension variable's
``Variable.relinearize_threshold``). A factor beyond them is linearised again at the current
estimate of its keys and swapped in at the next update (``removeFactorIndices``); a robust
noise model gets its IRLS weight there, as iSAM2 would give it. A vector variable that only
such factors (and its prior) touch holds only linear factors in iSAM2, so iSAM2 itself never
relinearises it (threshold ``LINEAR_ONLY``, as the baro calibration K): the book does.
Factors whose keyframes left iSAM2's window (``window``) are in its marginal and are no longer
rebuilt (``freeze``). graph-batch adds the same ``CustomFactor``s to its graph unchanged.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from ..model.extend import Collected, read_value
from ..settings import GraphConfig
from .relin import split_keys

LINEAR_ONLY = 1e9  # iSAM2 threshold of a variable whose factors are all linear here
_POSE, _VEC = 0, 1  # kinds of a (factor, key) pair's value


class PyFactorBook:
    """Linearisation points and iSAM2 indices of the extensions' ``CustomFactor``s (module
    docstring). ``now``: the current value of each extension variable."""

    def __init__(self, ext: Collected, cfg: GraphConfig) -> None:
        self.ext = ext
        self.factors = [f for f in ext.factors if isinstance(f, gtsam.CustomFactor)]
        self.slot = {id(f): i for i, f in enumerate(self.factors)}
        n = len(self.factors)
        self.idx = np.full(n, -1, dtype=np.int64)  # iSAM2 factor index (-1: not in iSAM2)
        self.live = np.zeros(n, dtype=bool)  # in iSAM2 and still rebuilt
        keys = [np.asarray([int(k) for k in f.keys()], dtype=np.uint64) for f in self.factors]
        self.keys = keys
        sizes = np.array([k.size for k in keys], dtype=int)
        pf = np.repeat(np.arange(n), sizes)
        self.pair_start = np.r_[0, np.cumsum(sizes)]  # pairs of factor i: start[i]:start[i+1]
        pk = np.concatenate(keys) if keys else np.zeros(0, dtype=np.uint64)
        self.pair_f, self.pair_key = pf, pk
        self.pair_ch, self.pair_k = split_keys(pk)
        self.ext_vars = {key: var for key, (var, _) in ext.variables.items()}
        self.now: dict[int, Any] = {key: value for key, (_, value) in ext.variables.items()}
        dims = [6] + [np.asarray(v).size for v in self.now.values()
                      if not isinstance(v, (gtsam.Pose3, gtsam.Rot3))]
        d = max(dims)
        self.dim = d
        self.kind = np.array([_POSE if _is_pose(int(k), self.now) else _VEC for k in pk],
                             dtype=int)
        m = pk.size
        self.lin_r = np.tile(np.eye(3), (m, 1, 1))
        self.lin_v = np.zeros((m, d))
        self.thr_r, self.thr_v = _thresholds(cfg, d, pk, self.kind, self.ext_vars, self.now)
        self.skip = max(int(cfg.relinearize_skip), 1)
        self.checks = 0
        self.pending = np.zeros(0, dtype=int)
        self.rebuilt = 0  # factors linearised again and swapped in
        # the factors the next update adds: slots and positions in its graph (``note``)
        self.new: tuple[list[int], list[int]] = ([], [])

    # -- keys and values -----------------------------------------------------------------

    def linear_only(self) -> set[str]:
        """Letters of the extension vectors that only these factors and their priors touch:
        iSAM2 need not relinearise them (``LINEAR_ONLY``)."""
        held = {int(k) for f in self.ext.factors if not isinstance(f, gtsam.CustomFactor)
                for k in f.keys()}
        return {chr(gtsam.Symbol(key).chr()) for key in self.ext_vars
                if key not in held and not isinstance(self.now[key], (gtsam.Pose3, gtsam.Rot3))}

    def read_ext(self, est: Any) -> None:
        """The extension variables' values in ``est`` (those it holds)."""
        for key, var in self.ext_vars.items():
            if est.exists(key):
                self.now[key] = read_value(est, var)

    def ext_keys(self, k_new: int) -> Any:
        """The extension variables iSAM2 holds once keyframe ``k_new`` exists."""
        return gtsam.KeyVector([key for key in self.ext_vars if self.ext.first[key] <= k_new])

    def _value(self, key: int, arrays: tuple[Any, ...]) -> Any:
        rot, pos, vel, bias, cb, _ = arrays
        if key in self.now:
            return self.now[key]
        ch, k = chr(gtsam.Symbol(key).chr()), int(gtsam.Symbol(key).index())
        if ch == "x":
            return gtsam.Pose3(gtsam.Rot3(rot[k]), pos[k])
        if ch == "v":
            return np.array(vel[k], float)
        if ch == "b":
            return gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6])
        return np.array([cb[k]], float)

    # -- building ------------------------------------------------------------------------

    def build(self, f: Any, arrays: tuple[Any, ...]) -> Any:
        """Factor ``f`` (one of ``factors``) linearised at the current values of its keys, as
        a ``LinearContainerFactor``; its linearisation point is noted."""
        i = self.slot[id(f)]
        vals = gtsam.Values()
        for p in range(int(self.pair_start[i]), int(self.pair_start[i + 1])):
            key = int(self.pair_key[p])
            v = self._value(key, arrays)
            vals.insert(key, v)
            self.lin_r[p], self.lin_v[p] = _flat(v, self.dim)
        return gtsam.LinearContainerFactor(f.linearize(vals), vals)

    def add(self, fs: list[Any], nf: Any, arrays: tuple[Any, ...]) -> None:
        """An extension's factors into ``nf``: one of ``factors`` linearised here (its slot
        and position noted for ``record_new``), any other as it is."""
        for f in fs:
            if id(f) in self.slot:
                self.new[0].append(self.slot[id(f)])
                self.new[1].append(nf.size())
                nf.add(self.build(f, arrays))
            else:
                nf.add(f)

    def rebuild_into(self, nf: Any, base: int, arrays: tuple[Any, ...]) -> list[int]:
        """The pending factors rebuilt into ``nf``, which follows ``base`` factors of the
        update (noted for ``record_new``); the iSAM2 indices they replace."""
        if not self.pending.size:
            return []
        slots, at, removed = self.rebuild(nf, arrays)
        self.new[0].extend(slots)
        self.new[1].extend(base + a for a in at)
        return removed

    def record_new(self, new_idx: Any, offset: int) -> None:
        """iSAM2 indices of the factors the last update added (``add``, ``rebuild_into``; at
        positions after its first ``offset`` factors)."""
        if self.new[0]:
            self.record(self.new[0], new_idx, [offset + a for a in self.new[1]])
        self.new = ([], [])

    def check(self, isam: Any, k_new: int, arrays: tuple[Any, ...]) -> None:
        """After an update: the extension variables' estimates, and the factors now due."""
        if not self.factors:
            return
        keys = self.ext_keys(k_new)
        if len(keys):
            self.read_ext(isam.calculateEstimate(keys))
        self.pending = self.due(arrays)

    def record(self, slots: list[int], new_idx: Any, positions: list[int]) -> None:
        """iSAM2 indices of the factors ``slots`` just added at ``positions`` of the update."""
        for i, at in zip(slots, positions, strict=True):
            self.idx[i] = int(new_idx[at])
            self.live[i] = True

    def freeze(self, deleted: list[int]) -> None:
        """Factors ``deleted`` left iSAM2 (into the window's marginal): never rebuilt."""
        gone = np.isin(self.idx, np.asarray(deleted, dtype=np.int64))
        self.live &= ~gone
        self.idx[gone] = -1

    # -- policy --------------------------------------------------------------------------

    def due(self, arrays: tuple[Any, ...], force: bool = False) -> np.ndarray:
        """The live factors whose keys moved beyond the thresholds since they were built
        (checked every ``relinearize_skip``-th call, each call with ``force``)."""
        self.checks += 1
        if not force and (self.checks - 1) % self.skip:
            return np.zeros(0, dtype=int)
        sel = np.flatnonzero(self.live[self.pair_f])
        if not sel.size:
            return np.zeros(0, dtype=int)
        rot, pos = arrays[0], arrays[1]
        r_now = np.tile(np.eye(3), (sel.size, 1, 1))
        v_now = np.zeros((sel.size, self.dim))
        ch, kf = self.pair_ch[sel], self.pair_k[sel]
        xs = ch == ord("x")
        r_now[xs], v_now[xs, 0:3] = rot[kf[xs]], pos[kf[xs]]
        others = self.pair_key[sel[~xs]]
        for key in np.unique(others):  # one value per key (H(0): one for all its factors)
            j = np.flatnonzero(~xs)[others == key]
            r, v = _flat(self._value(int(key), arrays), self.dim)
            r_now[j], v_now[j] = r, v
        lin_r, lin_v = self.lin_r[sel], self.lin_v[sel]
        pose = self.kind[sel] == _POSE
        d_r = np.einsum("nji,njl->nil", lin_r, r_now)
        ang = np.arccos(np.clip((np.einsum("nii->n", d_r) - 1.0) / 2.0, -1.0, 1.0))
        d_v = v_now - lin_v
        d_v[pose, 0:3] = np.einsum("nji,nj->ni", lin_r[pose], d_v[pose, 0:3])
        bad = (pose & (ang > self.thr_r[sel])) | (np.abs(d_v) > self.thr_v[sel]).any(1)
        return np.unique(self.pair_f[sel[bad]])

    def rebuild(self, nf: Any, arrays: tuple[Any, ...]) -> tuple[list[int], list[int], list[int]]:
        """The pending factors built again into ``nf``: their slots, their positions in
        ``nf`` and the iSAM2 indices of the factors they replace."""
        ids = [int(i) for i in self.pending if self.live[i]]
        self.pending = np.zeros(0, dtype=int)
        at, removed = [], []
        for i in ids:
            removed.append(int(self.idx[i]))
            at.append(nf.size())
            nf.add(self.build(self.factors[i], arrays))
            self.live[i] = False
        self.rebuilt += len(ids)
        return ids, at, removed


def _flat(v: Any, d: int) -> tuple[np.ndarray, np.ndarray]:
    """A value as (rotation matrix, d-vector): a pose's rotation and translation, a
    rotation's matrix, a bias's 6 components, a vector's components (zero-padded)."""
    r, out = np.eye(3), np.zeros(d)
    if isinstance(v, gtsam.Pose3):
        r, out[0:3] = v.rotation().matrix(), v.translation()
    elif isinstance(v, gtsam.Rot3):
        r = v.matrix()
    elif isinstance(v, gtsam.imuBias.ConstantBias):
        out[0:6] = v.vector()
    else:
        a = np.atleast_1d(np.asarray(v, float))
        out[0:a.size] = a
    return r, out


def _is_pose(key: int, now: dict[int, Any]) -> bool:
    """Whether ``key`` is a keyframe pose X(k) or an extension variable whose value (in
    ``now``) is a pose or rotation."""
    if chr(gtsam.Symbol(key).chr()) == "x":
        return True
    return isinstance(now.get(key), (gtsam.Pose3, gtsam.Rot3))


def _thresholds(cfg: GraphConfig, d: int, pair_key: np.ndarray, kind: np.ndarray,
                ext_vars: dict[int, Any], now: dict[int, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Per (factor, key) pair (``pair_key``, ``kind``): the rotation threshold [rad] and the
    component thresholds (translation [m] of a pose, or each vector component), inf where
    never relinearised."""
    m = pair_key.size
    thr_r, thr_v = np.full(m, np.inf), np.full((m, d), np.inf)
    if cfg.relinearize_threshold <= 0:
        return thr_r, thr_v
    typed = cfg.relinearize_typed
    scalar = cfg.relinearize_threshold
    rot, trans, vel, ba, bg = typed if typed is not None else (scalar,) * 5
    by_ch = {"x": None, "v": np.full(3, vel), "b": np.r_[[ba] * 3, [bg] * 3],
             "c": np.full(1, LINEAR_ONLY)}
    for i, key in enumerate(pair_key):
        key = int(key)
        ch = chr(gtsam.Symbol(key).chr())
        if ch == "x":
            thr_r[i], thr_v[i, 0:3] = rot, trans
        elif key in ext_vars:
            var = ext_vars[key]
            t = scalar if var.relinearize_threshold is None else var.relinearize_threshold
            if kind[i] == _POSE:
                thr_r[i], thr_v[i, 0:3] = t, t
            else:
                thr_v[i, 0:np.asarray(now[key]).size] = t
        else:
            thr_v[i, 0:by_ch[ch].size] = by_ch[ch]
    return thr_r, thr_v
