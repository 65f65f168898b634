"""Public extension point of the graph smoothers: user factors and user variables.

An *extension* is any callable ``f(view) -> Terms``. It receives a read-only ``GraphView`` of
the problem (keyframe times, the drive, the tangent frame, the initial estimate as
``gtsam.Values``) and returns ``Terms``: GTSAM factors (any C++ built-in or
``gtsam.CustomFactor``) and new ``Variable``s with their initial values and Gaussian priors.
Both smoothers take a list of them::

    GraphBatch(config, extensions=[f, g])
    GraphISAM2(config, extensions=[f, g])

- ``graph-batch`` adds every factor, variable and prior to the batch graph before the solve.
  The solver's column layout follows the graph's keys: few added variables stay on the banded
  fast path, a factor linking keyframes ≥ 2 apart switches to GTSAM elimination
  (``GraphConfig.solver``, ``layout``).
- ``graph-isam2`` adds each factor at the update that creates the last keyframe it touches
  (its "ready" keyframe), and each new variable, with its prior, at the first update that
  uses it (keyframe 0 if no factor uses it). Its final smoothing pass is the batch graph with
  the same terms.

The extension is called **once per run**, before any solve, with the initial estimate; its
factors must depend on measurements, not on that estimate (GTSAM relinearises them). The
value, σ of every tangent component and covariance of each new variable are reported in
``Estimate.info["extra_variables"]`` (``"est"``, ``"sd"``, ``"cov"``) under GTSAM's key name
(``gtsam.DefaultKeyFormatter``: ``M(0)`` → ``"m0"``), and in ``summary.json``.

Keys: the keyframe variables are ``X(k)`` (Pose3, body → tangent frame, the Pose3 tangent
ordered (rotation, translation)), ``V(k)`` (velocity in the tangent frame [m/s]) and ``B(k)``
(``imuBias.ConstantBias``, (accel, gyro); the bias of interval k → k+1 — with the
accelerometer scale factors ``A(0)`` (``GraphConfig.accel_scale``) its accelerometer part is
the effective bias b_a + diag(ā_k)·k_a), plus ``C(k)`` (baro Gauss-Markov bias [m]) when the
drive has a barometer, for k = 0 … ``view.n_keyframes`` − 1 (``gtsam.symbol_shorthand``).
The letters ``RESERVED`` (x, v, b, c, k, g, a) belong to the smoother (g: the optional GNSS
Gauss-Markov error ``G(k)``, ``GraphConfig.gnss_gm_sd_h`` / ``gnss_gm_sd_v``; a: ``A(0)``): new
variables take another letter, and factors may not touch ``K`` (the baro calibration, one
variable in the batch but one per segment in iSAM2).

Cost: a ``CustomFactor`` is linearised from Python by ``graph-batch`` (``graph.linearize``,
≈ 0.1 ms per factor) and by ``graph-isam2`` (``isam2.py_factors``: with a ``Values`` of the
factor's own keys, rebuilt when a key moves past iSAM2's threshold, ≈ 20–100 µs per rebuild;
iSAM2's own C++ relinearisation would copy its whole ``Values`` at every callback); C++
built-ins cost nothing special.

Bad input — an extension that is not callable or returns something else than ``Terms``, a
factor that is not a ``gtsam.NonlinearFactor``, a key that is neither a keyframe variable nor
a declared new variable, a keyframe index out of range, a reserved letter, a duplicate
variable, a prior of the wrong size, a factor whose error or Jacobians have the wrong shape at
the initial values (each factor is evaluated once in Python before GTSAM linearises it: a wrong
Jacobian shape would crash GTSAM's C++) — is a one-line ``failures.ExtensionError`` (a
``ValueError``) naming the extension; ``run`` and ``holdout`` stop on it with exit 2, a bench
row is ``failed`` with it.

Worked examples: ``examples/ex_graph_factor_zupt.py`` (zero-velocity factor at standstills),
``ex_graph_factor_mag.py`` (magnetometer with a hard-iron bias variable),
``ex_graph_factor_odometry.py`` (relative-position factor over 10 keyframes); the guide is
``docs/extending.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, C, V, X

from ....geo.frames import lla_to_ned
from ....types import Drive
from ....types.streams import FloatArray
from ....util.failures import ExtensionError
from .interval_factors import rot_t_n
from .jacobians import factor_shapes
from .problem import Problem

__all__ = ["RESERVED", "GraphExtension", "GraphView", "Terms", "Variable", "B", "C", "V", "X"]

RESERVED = "xvbckga"  # key letters of the smoother's own variables


@dataclass(frozen=True)
class GraphView:
    """Read-only view of a graph problem handed to an extension.

    drive: the drive being smoothed (never read ``drive.truth`` in a real extension; the
    examples that simulate a missing sensor say so). t_kf: keyframe times [s], shape (K,),
    on the drive's clock (read-only). origin_lla: origin of the tangent frame (lat, lon [rad],
    ellipsoidal height [m]). has_baro: whether ``C(k)`` exists. values: a copy of the initial
    estimate (keyframe variables only). frame: "t" = the Earth-fixed tangent-plane NED frame
    at ``origin_lla`` in which positions and velocities of the graph are resolved.
    """

    drive: Drive
    t_kf: FloatArray
    origin_lla: FloatArray
    has_baro: bool
    values: Any
    frame: str = "tangent-plane NED at origin_lla"

    @property
    def n_keyframes(self) -> int:
        return int(self.t_kf.size)

    def keyframe_at(self, t: Any) -> Any:
        """Index of the keyframe nearest to each time ``t`` [s] (int, or an int array)."""
        tq = np.asarray(t, float)
        i = np.clip(np.searchsorted(self.t_kf, tq), 1, self.n_keyframes - 1)
        left = self.t_kf[i - 1]
        i = np.where(np.abs(tq - left) <= np.abs(self.t_kf[i] - tq), i - 1, i)
        return int(i) if np.ndim(i) == 0 else i

    def to_tangent(self, lla: FloatArray) -> FloatArray:
        """Positions (lat, lon [rad], h [m]), shape (N, 3), in the tangent frame [m]."""
        return lla_to_ned(np.atleast_2d(np.asarray(lla, float)), self.origin_lla)

    def rot_t_n(self, lla: FloatArray) -> FloatArray:
        """C_tn (N, 3, 3): local-level NED at each ``lla`` → the tangent frame (to bring a
        NED-resolved vector or attitude C_nb into the graph's frame: C_tn C_nb)."""
        return rot_t_n(np.atleast_2d(np.asarray(lla, float)), self.origin_lla)

    def rotation(self, k: int) -> FloatArray:
        """Initial attitude of keyframe k: rotation matrix body → tangent frame (3, 3)."""
        return self.values.atPose3(X(k)).rotation().matrix()

    def position(self, k: int) -> FloatArray:
        """Initial position of keyframe k in the tangent frame [m] (3,)."""
        return np.asarray(self.values.atPose3(X(k)).translation(), float)

    def velocity(self, k: int) -> FloatArray:
        """Initial velocity of keyframe k in the tangent frame [m/s] (3,)."""
        return np.asarray(self.values.atVector(V(k)), float)


@dataclass(frozen=True)
class Variable:
    """A new variable: ``key`` (a ``gtsam.symbol_shorthand`` key whose letter is not in
    ``RESERVED``), initial ``value`` (a vector — a float is a 1-vector —, ``gtsam.Pose3`` or
    ``gtsam.Rot3``), Gaussian prior with σ ``prior_sd`` per tangent component around
    ``prior_mean`` (default: ``value``), and, for graph-isam2 with typed thresholds, the
    relinearisation threshold of every component (default ``GraphConfig.relinearize_threshold``).
    """

    key: int
    value: Any
    prior_sd: Any
    prior_mean: Any = None
    relinearize_threshold: float | None = None


@dataclass(frozen=True)
class Terms:
    """What an extension adds: ``factors`` (``gtsam.NonlinearFactor``s) and ``variables``."""

    factors: Sequence[Any] = ()
    variables: Sequence[Variable] = ()


class GraphExtension(Protocol):
    """An extension: called once per run with the problem's view, returns its terms."""

    def __call__(self, view: GraphView) -> Terms: ...


# ----------------------------------------------------------------------------------------
# Used by the smoothers (not needed by an extension)


@dataclass
class Collected:
    """Validated terms of all extensions of one run.

    factors / ready: every user factor and the keyframe at which all its keys exist;
    variables: key → (Variable, normalised value); prior: key → its prior factor;
    first: key → keyframe at which graph-isam2 inserts the variable."""

    factors: list[Any] = field(default_factory=list)
    ready: list[int] = field(default_factory=list)
    variables: dict[int, tuple[Variable, Any]] = field(default_factory=dict)
    prior: dict[int, Any] = field(default_factory=dict)
    first: dict[int, int] = field(default_factory=dict)
    # extension name → {"factors": n, "variables": m} it added (``info["extensions"]``)
    counts: dict[str, dict[str, int]] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.factors or self.variables)

    def add_to_batch(self, graph: Any, vals: Any, values_from: Any = None) -> None:
        """Add every factor, prior and variable to a batch graph. New variables start at their
        initial value, or at their value in ``values_from`` (e.g. the iSAM2 estimate)."""
        for f in self.factors:
            graph.add(f)
        for key, (var, value) in self.variables.items():
            graph.add(self.prior[key])
            vals.insert(key, value if values_from is None else read_value(values_from, var))

    def at_keyframe(self, k: int) -> tuple[list[Any], Any]:
        """Factors (with the priors of the variables they bring in) and values of the new
        variables that graph-isam2 adds at the update creating keyframe ``k``."""
        fs = [f for f, r in zip(self.factors, self.ready, strict=True) if r == k]
        vals = gtsam.Values()
        for key, (_, value) in self.variables.items():
            if self.first[key] == k:
                vals.insert(key, value)
                fs.append(self.prior[key])
        return fs, vals

    def threshold_entries(self, default: float) -> dict[str, FloatArray]:
        """iSAM2 relinearisation threshold per key letter of the new variables."""
        out: dict[str, FloatArray] = {}
        for key, (var, value) in self.variables.items():
            ch = chr(gtsam.Symbol(key).chr())
            thr = default if var.relinearize_threshold is None else var.relinearize_threshold
            vec = np.full(tangent_dim(value), float(thr))
            if ch in out and out[ch].size != vec.size:
                raise ExtensionError(
                    f"graph extension: variables with the letter {ch!r} have different "
                    f"dimensions ({out[ch].size} and {vec.size}); graph-isam2's typed "
                    "relinearisation thresholds need one dimension per letter — use "
                    "another letter")
            out[ch] = vec if ch not in out else np.minimum(out[ch], vec)
        return out


def tangent_dim(value: Any) -> int:
    if isinstance(value, (gtsam.Pose3, gtsam.imuBias.ConstantBias)):
        return 6
    if isinstance(value, gtsam.Rot3):
        return 3
    return int(np.asarray(value).size)


def prior_factor(key: int, mean: Any, model: Any) -> Any:
    """GTSAM's prior factor on ``key`` for a value of ``mean``'s type (Pose3, Rot3,
    imuBias.ConstantBias or a vector)."""
    if isinstance(mean, gtsam.Pose3):
        return gtsam.PriorFactorPose3(key, mean, model)
    if isinstance(mean, gtsam.Rot3):
        return gtsam.PriorFactorRot3(key, mean, model)
    if isinstance(mean, gtsam.imuBias.ConstantBias):
        return gtsam.PriorFactorConstantBias(key, mean, model)
    return gtsam.PriorFactorVector(key, mean, model)


def read_value(vals: Any, var: Variable) -> Any:
    """The current value of a new variable in ``vals``, of its declared type."""
    if isinstance(var.value, gtsam.Pose3):
        return vals.atPose3(var.key)
    if isinstance(var.value, gtsam.Rot3):
        return vals.atRot3(var.key)
    return np.asarray(vals.atVector(var.key), float)


def key_name(key: int) -> str:
    return str(gtsam.DefaultKeyFormatter(key))


def _normalise(var: Any, who: str) -> tuple[Any, Any]:
    """(value, prior factor) of a declared variable, or a one-line ValueError."""
    if not isinstance(var, Variable):
        raise ExtensionError(f"{who}: variables must be graph.extend.Variable, not "
                         f"{type(var).__name__}")
    key = int(var.key)
    ch = chr(gtsam.Symbol(key).chr())
    if ch in RESERVED:
        raise ExtensionError(f"{who}: variable {key_name(key)} uses the letter {ch!r}, reserved "
                             f"for the smoother's own variables ({', '.join(RESERVED)}); pick "
                             "another")
    value = var.value
    if not isinstance(value, (gtsam.Pose3, gtsam.Rot3)):
        try:
            value = np.atleast_1d(np.asarray(value, dtype=float))
        except (TypeError, ValueError):
            value = np.array([np.nan])
        if value.ndim != 1 or not np.all(np.isfinite(value)):
            raise ExtensionError(f"{who}: variable {key_name(key)}: value must be a finite vector, "
                             f"a float, gtsam.Pose3 or gtsam.Rot3")
    mean = value if var.prior_mean is None else var.prior_mean
    if not isinstance(value, (gtsam.Pose3, gtsam.Rot3)):
        try:
            mean = np.atleast_1d(np.asarray(mean, dtype=float))
        except (TypeError, ValueError):
            mean = np.array([np.nan])
        if mean.shape != value.shape or not np.all(np.isfinite(mean)):
            raise ExtensionError(f"{who}: variable {key_name(key)}: prior_mean must be a finite "
                             f"vector of the value's shape {value.shape}")
    elif type(mean) is not type(value):
        raise ExtensionError(f"{who}: variable {key_name(key)}: prior_mean must be a "
                         f"{type(value).__name__} like its value")
    n = tangent_dim(value)
    try:
        sd = np.atleast_1d(np.asarray(var.prior_sd, dtype=float))
    except (TypeError, ValueError):
        sd = np.array([np.nan])
    if sd.size == 1:
        sd = np.full(n, float(sd[0]))
    if sd.shape != (n,) or not np.all(np.isfinite(sd) & (sd > 0)):
        raise ExtensionError(f"{who}: variable {key_name(key)}: prior_sd must be {n} positive "
                         f"finite σ (one per tangent component), not {var.prior_sd!r}")
    return value, prior_factor(key, mean, gtsam.noiseModel.Diagonal.Sigmas(sd))


def _name(ext: Any, i: int) -> str:
    n = getattr(ext, "name", None) or getattr(ext, "__name__", None) or type(ext).__name__
    return f"graph extension {i} ({n})"


def check_extensions(extensions: Any) -> tuple[Callable[[GraphView], Terms], ...]:
    """The extensions as a tuple of callables, or a one-line ValueError."""
    if extensions is None:
        return ()
    if callable(extensions) or isinstance(extensions, (str, bytes)):
        raise ExtensionError("extensions must be a list of callables view -> Terms, not a single "
                         f"{type(extensions).__name__}; wrap it: extensions=[f]")
    out = tuple(extensions)
    for i, e in enumerate(out):
        if not callable(e):
            raise ExtensionError(f"graph extension {i}: {type(e).__name__} is not callable "
                             "(expected a function view -> Terms)")
    return out


def collect(extensions: Sequence[Callable[[GraphView], Terms]], view: GraphView) -> Collected:
    """Call every extension with ``view`` and validate what they return (``Collected``)."""
    col = Collected()
    nk = view.n_keyframes
    template = {"x": nk, "v": nk, "b": nk}
    if view.has_baro:
        template["c"] = nk
    pending: list[tuple[Any, list[int], str]] = []
    for i, ext in enumerate(extensions):
        who = _name(ext, i)
        terms = ext(view)
        if not isinstance(terms, Terms):
            raise ExtensionError(f"{who}: returned {type(terms).__name__}, expected "
                             "graph.extend.Terms(factors=[...], variables=[...])")
        name = who[who.index("(") + 1:-1] if who.endswith(")") else who
        col.counts[name if name not in col.counts else f"{name} {i}"] = {
            "factors": len(terms.factors), "variables": len(terms.variables)}
        for var in terms.variables:
            value, prior = _normalise(var, who)
            key = int(var.key)
            if key in col.variables:
                raise ExtensionError(f"{who}: variable {key_name(key)} is declared twice")
            col.variables[key] = (var, value)
            col.prior[key] = prior
        for f in terms.factors:
            if not isinstance(f, gtsam.NonlinearFactor):
                raise ExtensionError(f"{who}: factors must be gtsam.NonlinearFactor (a C++ factor "
                                 f"or gtsam.CustomFactor), not {type(f).__name__}")
            pending.append((f, [int(k) for k in f.keys()], who))
    for f, keys, who in pending:
        ready = 0
        for key in keys:
            if key in col.variables:
                continue
            sym = gtsam.Symbol(key)
            ch, idx = chr(sym.chr()), int(sym.index())
            if ch == "k":
                raise ExtensionError(f"{who}: a factor on {key_name(key)}: the baro calibration K "
                                 "cannot take user factors")
            if ch not in template:
                raise ExtensionError(f"{who}: a factor on {key_name(key)}, which is neither a "
                                 "keyframe variable (X, V, B" + (", C" if view.has_baro else "")
                                 + ") nor a declared Variable")
            if not 0 <= idx < template[ch]:
                raise ExtensionError(f"{who}: a factor on {key_name(key)}: keyframe index out of "
                                 f"range 0..{nk - 1}")
            ready = max(ready, idx)
        col.factors.append(f)
        col.ready.append(ready)
        for key in keys:
            if key in col.variables:
                col.first[key] = min(col.first.get(key, ready), ready)
    for key in col.variables:
        col.first.setdefault(key, 0)
    _check_shapes(col, [(f, who) for f, _, who in pending], view)
    return col


def _check_shapes(col: Collected, factors: list[tuple[Any, str]], view: GraphView) -> None:
    """Each factor evaluated once at the initial values with its Jacobians' shapes checked
    (``jacobians.factor_shapes``): a wrong shape would crash GTSAM's C++ in ``linearize``."""
    vals = gtsam.Values(view.values)
    for key, (_, value) in col.variables.items():
        if not vals.exists(key):
            vals.insert(key, value)
    for f, who in factors:
        if not all(vals.exists(k) for k in f.keys()):
            continue  # a key the view does not hold (cannot be evaluated here)
        try:
            factor_shapes(f, vals)
        except ValueError as exc:
            keys = ", ".join(key_name(k) for k in f.keys())
            raise ExtensionError(f"{who}: its factor on {keys}: {exc}") from None


def make_view(P: Problem, vals: Any) -> GraphView:
    """The view of a problem (``problem.Problem``) at the initial values ``vals``."""
    t_kf = np.array(P.t_kf, dtype=float)
    t_kf.setflags(write=False)
    origin = np.array(P.origin, dtype=float)
    origin.setflags(write=False)
    return GraphView(P.drive, t_kf, origin, P.drive.baro is not None, gtsam.Values(vals))

