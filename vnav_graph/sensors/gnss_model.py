"""The GNSS measurement model of both estimator families, and its Gauss-Markov error state.

One model, two consumers: the filter's rows (``estimators.ekf.updates.gnss_rows``) and the
graph's GNSS factor (``estimators.graph.model.interval_factors.gnss_rows``) both take the
predicted antenna position/velocity and their Jacobians from here.

Measurement (n: local-level NED; IMU position r, velocity v, attitude C = C_nb, lever arm l
in b, body rate ω = ω_nb^b, GNSS error state e in n, first-order Gauss-Markov per axis):

    z_p = r + C l + S e          S: the axes of e that are carried (``GM_AXES``)
    z_v = v + C (ω × l)

Jacobians with respect to the error state (estimated minus true; tilt ψ in n with
C̃ = (I + [ψ×]) C, ``types.ERROR_STATE``):

    ∂z_p/∂δr = I     ∂z_p/∂ψ = −[(C l)×]       ∂z_p/∂δe = S
    ∂z_v/∂δv = I     ∂z_v/∂ψ = −[(C(ω×l))×]    ∂z_v/∂δb_g = C [l×]   (ω = ω̃ − b_g)

The graph perturbs the attitude on the right, C ← C Exp(θ) with θ in b, so ψ = C θ and
∂/∂θ = ∂/∂ψ · C. The Earth and transport rates' path through C in C(ω × l) is left out
(|Ω_ie| |l| ≈ 7e-5 m/s per rad of attitude error).

GNSS error state (``GnssGM``): code-phase errors that are not white (ionosphere, troposphere,
orbit residuals, diffuse multipath) decorrelate over tens of seconds to minutes (Groves,
*Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed.,
ch. 9). Each carried axis is ė = −e/τ + w with steady-state σ (``sd_h`` north and east,
``sd_v`` down). The receiver's σ is taken to cover its whole error, so the fixes keep only
its white rest (``GnssGM.split``). Both families discretise it exactly (``sensors.noise``:
φ = e^{−Δt/τ}, var w = σ²(1 − φ²)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..nav.arrays import put
from ..nav.rotations import cross3, skew3
from ..types.streams import FloatArray

# With a Gauss-Markov GNSS error state, the white part of a fix's σ keeps at least this
# fraction of the receiver's σ (a σ_gm at or above the receiver's would otherwise leave white
# noise 0 and let one fix pin the position)
GM_WHITE_MIN_FRACTION = 0.1
# the per-fix σ floor of every estimator [m, m/s] (``sensors.model``)
GNSS_SD_FLOOR = 0.01
# ``gnss_gm_auto``: the residual autocorrelation at 5 s above which the state is carried
# (white-error drives −0.12 … 0.13, correlated ones 0.24 … 0.72: ``docs/design.md``), and at
# least this many σ of a white series' autocorrelation (1/√pairs: 0.21 for 6 min at 1 Hz)
GM_AUTO_THRESHOLD = 0.15
GM_AUTO_SIGMAS = 4.0
# the NED axes of the error state by its dimension: height only, horizontal only, all three
GM_AXES = {1: (2,), 2: (0, 1), 3: (0, 1, 2)}


@njit(cache=True)
def antenna_position(c_nb, lever_b):
    """Lever-arm offset d = C l (3,) [m, n] and ∂z_p/∂ψ = −[d×] (3, 3)."""
    d = c_nb @ lever_b
    return d, -skew3(d)


@njit(cache=True)
def antenna_velocity(c_nb, lever_b, w_nb_b):
    """Lever-arm velocity u = C (ω × l) (3,) [m/s, n], ∂z_v/∂ψ = −[u×] and
    ∂z_v/∂δb_g = C [l×] (3, 3)."""
    u = c_nb @ cross3(w_nb_b, lever_b)
    return u, -skew3(u), c_nb @ skew3(lever_b)


@njit(cache=True)
def _map_antenna(c_nb, lever_b, w_nb_b, d, h_d, u, h_u):  # pragma: no cover - numba
    for i in range(c_nb.shape[0]):
        di, hi = antenna_position(c_nb[i], lever_b)
        put(d[i], di)
        put(h_d[i], hi)
        if w_nb_b.shape[0]:
            ui, hui, _ = antenna_velocity(c_nb[i], lever_b, w_nb_b[i])
            put(u[i], ui)
            put(h_u[i], hui)


def antenna_arrays(c_nb: FloatArray, lever_b: FloatArray, w_nb_b: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``antenna_position`` at each of M attitudes ``c_nb`` (M, 3, 3) and, when ``w_nb_b``
    has M rows (else 0), ``antenna_velocity`` at each, in one compiled pass:
    d (M, 3), −[d×], u (M, 3) and −[u×]."""
    c = np.ascontiguousarray(c_nb, dtype=float)
    w = np.ascontiguousarray(w_nb_b, dtype=float)
    m = c.shape[0]
    d, h_d = np.empty((m, 3)), np.empty((m, 3, 3))
    u, h_u = np.empty((w.shape[0], 3)), np.empty((w.shape[0], 3, 3))
    _map_antenna(c, np.ascontiguousarray(lever_b, dtype=float), w, d, h_d, u, h_u)
    return d, h_d, u, h_u


def body_tilt(h_psi: FloatArray, c_nb: FloatArray) -> FloatArray:
    """A Jacobian w.r.t. the n-frame tilt ψ turned into one w.r.t. the body rotation θ of
    C ← C Exp(θ) (ψ = C θ): ``h_psi @ c_nb`` for stacks (M, r, 3) · (M, 3, 3)."""
    return h_psi @ c_nb


@dataclass(frozen=True)
class GnssGM:
    """First-order Gauss-Markov GNSS error state: steady-state σ ``sd_h`` (north and east) and
    ``sd_v`` (down) [m], correlation time ``tau_s`` [s]. An axis of σ 0 is not carried."""

    sd_h: float
    sd_v: float
    tau_s: float

    def __post_init__(self) -> None:
        for name in ("sd_h", "sd_v"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"GNSS Gauss-Markov σ must be ≥ 0 m, not {v}")
        if not (self.sd_h > 0 or self.sd_v > 0):
            raise ValueError("GNSS Gauss-Markov σ: at least one of sd_h, sd_v must be > 0")
        if not (np.isfinite(self.tau_s) and self.tau_s > 0):
            raise ValueError(f"GNSS Gauss-Markov τ must be > 0 s, not {self.tau_s}")

    @property
    def axes(self) -> tuple[int, ...]:
        """The carried NED axes (``GM_AXES``)."""
        return tuple(a for a, s in enumerate((self.sd_h, self.sd_h, self.sd_v)) if s > 0)

    @property
    def dim(self) -> int:
        return len(self.axes)

    @property
    def sd(self) -> FloatArray:
        """σ of each carried axis, (dim,) [m]."""
        return np.array([(self.sd_h, self.sd_h, self.sd_v)[a] for a in self.axes])

    @property
    def sd_m(self) -> float:
        """σ of the height axis [m] (the height-only state's one σ)."""
        return float(self.sd_v)

    def info(self) -> dict[str, dict[str, float]]:
        """What both families put in ``Estimate.info``: ``gnss_gm`` (σ north/east, σ down,
        τ) and, when the height axis is carried, ``gnss_height_gm`` (its σ and τ)."""
        out = {"gnss_gm": {"sd_h_m": float(self.sd_h), "sd_v_m": float(self.sd_v),
                           "tau_s": float(self.tau_s)}}
        if self.sd_v > 0:
            out["gnss_height_gm"] = {"sd_m": float(self.sd_v), "tau_s": float(self.tau_s)}
        return out

    def split(self, pos_sd: FloatArray) -> FloatArray:
        """The white part of the fixes' σ (N, 3) [m] on the carried axes:
        √(σ² − σ_gm²), at least ``GM_WHITE_MIN_FRACTION``·σ and ``GNSS_SD_FLOOR``."""
        out = np.array(pos_sd, dtype=float, copy=True)
        for a, s in zip(self.axes, self.sd, strict=True):
            out[:, a] = white_rest(out[:, a], float(s))
        return out


def white_rest(sd: FloatArray, sd_gm: float) -> FloatArray:
    """√(σ² − σ_gm²), at least ``GM_WHITE_MIN_FRACTION``·σ and ``GNSS_SD_FLOOR`` [m]."""
    sd = np.asarray(sd, dtype=float)
    white2 = np.maximum(sd**2 - sd_gm**2, (GM_WHITE_MIN_FRACTION * sd) ** 2)
    return np.maximum(np.sqrt(white2), GNSS_SD_FLOOR)


def gnss_gm(sd_h: float, sd_v: float, tau_s: float, who: str) -> GnssGM | None:
    """An estimator config's (σ_h, σ_v, τ) as a :class:`GnssGM`, None when both σ are 0
    (off); ``ValueError`` naming ``who`` (the config class) on a bad value."""
    if sd_h == 0 and sd_v == 0:
        return None
    try:
        return GnssGM(float(sd_h), float(sd_v), float(tau_s))
    except ValueError as e:
        raise ValueError(f"{who}.gnss_gm_sd_v, gnss_gm_sd_h, gnss_gm_tau_s: {e}") from None


@dataclass(frozen=True)
class GnssErrorSettings:
    """The GNSS error-state fields ``EkfConfig`` and ``GraphConfig`` share (flat config keys).

    gnss_gm_sd_h: σ of the Gauss-Markov GNSS error state, north and east [m] (0: not carried).
    gnss_gm_sd_v: σ of that state, down [m] (0: not carried).
    gnss_gm_tau_s: correlation time of that state [s].
    gnss_gm_auto: carry that state only when a first pass's GNSS residuals are correlated.
    """

    gnss_gm_sd_h: float = 0.0
    gnss_gm_sd_v: float = 0.0
    gnss_gm_tau_s: float = 300.0
    # a first pass without the state, then, when the autocorrelation of the fixes' residuals
    # at 5 s exceeds ``GM_AUTO_THRESHOLD`` on either axis (``sensors.gnss_residuals``), the
    # pass again with it (``estimators.gnss_auto``; ``info["gnss_gm_auto"]``)
    gnss_gm_auto: bool = False

    @property
    def gnss_gm(self) -> GnssGM | None:
        gm = gnss_gm(self.gnss_gm_sd_h, self.gnss_gm_sd_v, self.gnss_gm_tau_s,
                     type(self).__name__)
        if self.gnss_gm_auto and gm is None:
            raise ValueError(f"{type(self).__name__}.gnss_gm_auto needs the state's σ "
                             "(gnss_gm_sd_h or gnss_gm_sd_v > 0)")
        return gm
