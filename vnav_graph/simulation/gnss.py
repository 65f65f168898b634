"""GNSS receiver error model: white position/velocity noise, rate, latency, lever arm,
outage windows and occasional gross outliers, plus an optional urban model.

Urban model (``GnssSpec`` fields ``gm_*``, ``burst_*``, ``random_outage*``), on the fix grid
before any outage is removed, so every process runs on through outages:

- time-correlated error e_gm: first-order Gauss-Markov per NED axis, σ (gm_sd_h, gm_sd_h,
  gm_sd_v), correlation time gm_tau_s. Code-phase GNSS errors that are not white (ionosphere,
  troposphere and orbit residuals, diffuse multipath) decorrelate over tens of seconds to
  minutes (Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
  Systems*, 2nd ed., ch. 9, range error sources);
- multipath bursts: windows of length U(burst_len_s) separated by exponential gaps of mean
  L̄·(1 − f)/f (L̄ the mean length, f = burst_fraction), so a fraction f of the time, hence of
  the fixes, lies inside bursts. A reflected (or only non-line-of-sight) signal travels a
  longer path, so its range error is a bias of one sign that persists while the reflecting
  geometry lasts (Groves ch. 9: tens of metres in urban canyons). In the position domain
  each burst therefore gets one offset m·u with m ~ U(burst_err_m) and u a random direction
  (azimuth uniform, elevation uniform in ±``BURST_MAX_ELEVATION``: mostly horizontal), plus a
  Gauss-Markov jitter of σ ``BURST_JITTER_FRACTION``·m and τ ``BURST_JITTER_TAU_S`` as the
  geometry changes. Doppler is hit less (the reflector moves little relative to the
  antenna): white velocity error of σ burst_vel_sd. Onset and end are abrupt, as when a
  building starts and stops blocking the direct signal;
- random outages: a Poisson number (mean random_outages_per_hour · span/3600) of windows,
  starts uniform over the drive, lengths U(random_outage_len_s).

The reported ``pos_sd`` is sqrt(pos_sd² + gm_sd²) everywhere, bursts included (receivers do
not see multipath in their accuracy estimate): it understates the error inside bursts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import GnssSpec
from ..geo.earth import radii
from ..geo.frames import quat_to_mat
from ..types import Trajectory
from ..types.streams import BoolArray, FloatArray, GnssStream
from .noise import gauss_markov

BURST_MAX_ELEVATION = np.radians(30.0)  # elevation bound of a burst's offset direction [rad]
BURST_JITTER_FRACTION = 0.2  # jitter σ inside a burst, fraction of the burst's offset [-]
BURST_JITTER_TAU_S = 3.0  # correlation time of that jitter [s]


@dataclass(frozen=True)
class GnssErrorLog:
    """What ``simulate_gnss`` did to the fixes (for the drive's meta and for tests).

    outlier : (N,) bool, fix made a gross outlier
    in_burst : (N,) bool, fix inside a multipath burst
    burst_windows : ((t0, t1), ...) burst windows [s] (clipped to the drive span)
    random_outages : ((t0, t1), ...) random outage windows [s] (clipped to the drive span)
    """

    outlier: BoolArray
    in_burst: BoolArray
    burst_windows: tuple[tuple[float, float], ...] = ()
    random_outages: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class _UrbanErrors:
    pos_err_n: FloatArray | None  # (M, 3) [m] GM + burst error on the fix grid, None if off
    vel_err_n: FloatArray | None  # (M, 3) [m/s] burst velocity error, None if off
    in_burst: BoolArray  # (M,)
    burst_windows: tuple[tuple[float, float], ...]
    random_outages: tuple[tuple[float, float], ...]


def _windows(t0: float, t1: float, spec: GnssSpec, rng: np.random.Generator
             ) -> tuple[tuple[tuple[float, float], ...], tuple[tuple[float, float], ...]]:
    """Random outage windows, then burst windows, over [t0, t1] [s]."""
    outages: list[tuple[float, float]] = []
    if spec.random_outages_per_hour > 0:
        n = int(rng.poisson(spec.random_outages_per_hour * (t1 - t0) / 3600.0))
        starts = np.sort(rng.uniform(t0, t1, n))
        lens = rng.uniform(*spec.random_outage_len_s, n)
        outages = [(float(a), float(min(a + d, t1))) for a, d in zip(starts, lens, strict=True)]
    bursts: list[tuple[float, float]] = []
    if spec.burst_fraction > 0:
        f = spec.burst_fraction
        gap_mean = 0.5 * (spec.burst_len_s[0] + spec.burst_len_s[1]) * (1.0 - f) / f
        a = t0 + float(rng.exponential(gap_mean))
        while a < t1:
            b = a + float(rng.uniform(*spec.burst_len_s))
            bursts.append((a, min(b, t1)))
            a = b + float(rng.exponential(gap_mean))
    return tuple(outages), tuple(bursts)


def _urban_errors(t: FloatArray, t0: float, t1: float, spec: GnssSpec,
                  rng: np.random.Generator) -> _UrbanErrors:
    """Urban error processes on the full fix grid ``t`` (M,) [s] of the drive span [t0, t1]
    (module docstring)."""
    outages, bursts = _windows(t0, t1, spec, rng)
    m = t.size
    pos = None
    if spec.gm_sd_h > 0 or spec.gm_sd_v > 0:
        sd = np.array([spec.gm_sd_h, spec.gm_sd_h, spec.gm_sd_v])
        pos = gauss_markov(t, spec.gm_tau_s, 1.0, rng, 3) * sd
    in_burst = np.zeros(m, dtype=bool)
    vel = None
    if bursts:
        pos = np.zeros((m, 3)) if pos is None else pos
        for a, b in bursts:
            k = (t >= a) & (t < b)
            mag = float(rng.uniform(*spec.burst_err_m))
            az = float(rng.uniform(-np.pi, np.pi))
            el = float(rng.uniform(-BURST_MAX_ELEVATION, BURST_MAX_ELEVATION))
            # NED offset: el > 0 points up, i.e. negative down
            u = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
            if not np.any(k):
                continue
            jitter = gauss_markov(t[k], BURST_JITTER_TAU_S, BURST_JITTER_FRACTION * mag, rng, 3)
            pos[k] += mag * u + jitter
            in_burst |= k
        if spec.burst_vel_sd > 0:
            vel = np.zeros((m, 3))
            vel[in_burst] = rng.normal(size=(int(in_burst.sum()), 3)) * spec.burst_vel_sd
    return _UrbanErrors(pos, vel, in_burst, bursts, outages)


def urban_model_on(spec: GnssSpec) -> bool:
    """True when any part of the urban error model of ``spec`` is enabled."""
    return (spec.gm_sd_h > 0 or spec.gm_sd_v > 0 or spec.burst_fraction > 0
            or spec.random_outages_per_hour > 0)


def antenna_position_velocity(
    truth: Trajectory, t: FloatArray, gyro_nb_b: FloatArray | None, lever_arm_b: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """True antenna lla (N, 3) and NED velocity (N, 3) at times ``t``.

    p_ant = p_imu + C_nb·l (converted to lat/lon/h with the radii of curvature);
    v_ant = v_imu + C_nb·(ω_nb^b × l). ``gyro_nb_b`` (N, 3) is ω_nb^b at ``t`` or None for
    a static lever-arm contribution only.
    """
    tr = truth.at(t)
    lla = tr.lla.copy()
    vel = tr.vel_n.copy()
    if np.any(lever_arm_b != 0):
        if tr.q_nb is None:
            raise ValueError("gnss: a lever arm needs the truth attitude")
        c = quat_to_mat(tr.q_nb)
        d_n = c @ lever_arm_b
        rn, re = radii(lla[:, 0])
        lla[:, 0] += d_n[:, 0] / (rn + lla[:, 2])
        lla[:, 1] += d_n[:, 1] / ((re + lla[:, 2]) * np.cos(lla[:, 0]))
        lla[:, 2] -= d_n[:, 2]
        if gyro_nb_b is not None:
            vel += np.einsum("nij,nj->ni", c, np.cross(gyro_nb_b, lever_arm_b))
    return lla, vel


def simulate_gnss(
    truth: Trajectory, gyro_nb_b_fn, spec: GnssSpec, rng: np.random.Generator,
    t_start: float | None = None, urban_rng: np.random.Generator | None = None,
) -> tuple[GnssStream, GnssErrorLog]:
    """Sample fixes at ``spec.rate_hz`` over the truth span, minus outage windows.

    Returns the stream and a ``GnssErrorLog`` (outliers, bursts, random outages).
    ``gyro_nb_b_fn(t)`` gives ω_nb^b (N, 3) for the lever-arm velocity term (or None).
    The urban model draws from ``urban_rng`` (default ``rng``), and only when it is enabled,
    so the draws of the base model do not move when it is switched on or off.
    """
    t0 = truth.t[0] if t_start is None else t_start
    dt = 1.0 / spec.rate_hz
    t_all = np.arange(t0 + dt, truth.t[-1] + 1e-9, dt)
    # time of validity is latency_s before the stamp; a fix valid before the truth starts is
    # not made (clamping its validity to the start gave duplicated times)
    t_valid_all = t_all - spec.latency_s
    urban = None
    if urban_model_on(spec) and t_all.size:
        urban = _urban_errors(t_all, float(t0), float(truth.t[-1]), spec, urban_rng or rng)
    keep = t_valid_all > truth.t[0]
    for a, b in spec.outages + (urban.random_outages if urban is not None else ()):
        keep &= ~((t_all >= a) & (t_all < b))
    t, t_valid = t_all[keep], t_valid_all[keep]
    lever = np.asarray(spec.lever_arm_b, dtype=float)
    w = None if gyro_nb_b_fn is None else gyro_nb_b_fn(t_valid)
    lla, vel = antenna_position_velocity(truth, t_valid, w, lever)
    n = t.size
    sd = np.tile([spec.pos_sd_h, spec.pos_sd_h, spec.pos_sd_v], (n, 1))
    err_n = rng.normal(size=(n, 3)) * sd
    outlier = rng.random(n) < spec.outlier_prob
    err_n[outlier] += rng.normal(size=(int(outlier.sum()), 3)) * spec.outlier_sd
    if urban is not None and urban.pos_err_n is not None:
        err_n += urban.pos_err_n[keep]
    if spec.gm_sd_h > 0 or spec.gm_sd_v > 0:
        # the receiver's accuracy estimate covers white and time-correlated errors, not bursts
        sd = np.sqrt(sd**2 + np.array([spec.gm_sd_h, spec.gm_sd_h, spec.gm_sd_v]) ** 2)
    rn, re = radii(lla[:, 0])
    lla = lla + np.column_stack(
        [err_n[:, 0] / (rn + lla[:, 2]), err_n[:, 1] / ((re + lla[:, 2]) * np.cos(lla[:, 0])),
         -err_n[:, 2]]
    )
    vel_n = vel_sd = None
    if spec.vel_sd > 0:
        vel_n = vel + rng.normal(size=(n, 3)) * spec.vel_sd
        if urban is not None and urban.vel_err_n is not None:
            vel_n += urban.vel_err_n[keep]
        vel_sd = np.full((n, 3), spec.vel_sd)
    stream = GnssStream(t, lla, sd, vel_n, vel_sd, lever, spec)
    if urban is None:
        return stream, GnssErrorLog(outlier, np.zeros(n, dtype=bool))
    return stream, GnssErrorLog(outlier, urban.in_burst[keep], urban.burst_windows,
                                urban.random_outages)
