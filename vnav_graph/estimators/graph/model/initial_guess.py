"""Initial keyframe states of the graph smoothers from GNSS and the IMU: GNSS
positions/velocities, TRIAD attitude (or the compass's heading, or on a hovering vehicle
without one the forward ekf's attitude), IMU propagation and baro-bridged gaps."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ....geo.frames import ned_to_lla, quat_to_mat, skew
from ....nav.arrays import nearest_index
from ....nav.course import SIDESLIP_SD, course_heading, gyro_yaw
from ....nav.rotations import so3_exp
from ....types import ERROR_STATE
from ....types.streams import FloatArray
from . import interval_factors as gf
from .cpp_factors import PRIOR_ATT_SD, level
from .problem import Problem

# TRIAD (specific force + course) needs a clear course: its σ as a heading by the rule of
# ``nav.course`` (the ekf's) at most this [rad]
TRIAD_SD_MAX = np.radians(10.0)
# baseline half-width of the position differences of a position-only receiver [s]
POS_ONLY_BASE_S = 1.0


def initial_states(P: Problem) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Initial R_tb, p_t, v_t at keyframes from GNSS and the IMU (no filter involved).

    Position/velocity: GNSS at keyframes (lever arm removed), else propagated with the
    preintegrated increments. Attitude: TRIAD of (specific force, velocity direction) —
    f_t = a_t − g_t (a_t from differenced GNSS velocity) against the mean measured f_b, and the
    body x axis along the GNSS velocity where the course is a heading to ``TRIAD_SD_MAX``
    by the ekf's rule (``nav.course``; a walker at 1.2 m/s qualifies); otherwise propagated
    with the gyro increments (backwards before the first valid alignment). A position-only
    receiver gets its velocity and acceleration from central differences of the positions
    over ±1 s: without that TRIAD the heading started at 0 (yaw of the levelled first sample)
    and Gauss-Newton crept (½χ² 54 000 → 36 000 in 90 iterations, 28° heading RMSE,
    118 m horizontal error in the 60 s outage of hill-drive seed 0); with it, 5 iterations,
    0.28° and 0.65 m. With the magnetometer in use the heading is then the compass's
    (``compass_heading``: the course is not a multirotor's heading)."""
    imu = P.drive.imu
    nk = P.n_kf
    dr_t, dv_t, dp_t = P.dense.end()
    gt, vel, has, pos_kf, vel_kf, acc_kf, acc_ok = _gnss_at_keyframes(P)
    in_gap, v_bridge = _baro_bridge(P, gt, has, pos_kf, vel_kf)
    g_kf = gf.gravity_t(pos_kf, P.origin)
    f_b = _mean_specific_force(imu.t, imu.accel_b, P.t_kf)
    f_t = acc_kf - g_kf + 2 * np.cross(P.omega_t, vel_kf)
    triad_ok = has & acc_ok & (_course_sd(P, gt, vel, vel_kf) <= TRIAD_SD_MAX)
    rot_triad = np.zeros((nk, 3, 3))
    ok = np.flatnonzero(triad_ok)
    rot_triad[ok] = _triad(f_b[ok], np.array([1.0, 0.0, 0.0]), f_t[ok], vel_kf[ok])
    k0 = int(ok[0]) if ok.size else -1
    # where TRIAD has no course, the tilt still comes from the specific force against the
    # GNSS acceleration at every keyframe that has both (``retilt``); only the heading is
    # carried by the gyro
    tilt_ok = has & acc_ok & ~triad_ok
    if k0 < 0:
        r = level(f_b[0])
    else:
        r = rot_triad[k0]
        for k in range(k0 - 1, -1, -1):
            r = _gyro_back(P, r, k, dr_t)
            if tilt_ok[k]:
                r = retilt(r, f_b[k], f_t[k])
    rot = np.zeros((nk, 3, 3))
    p_out = np.zeros((nk, 3))
    v_out = np.zeros((nk, 3))
    rot[0] = r
    p_out[0] = pos_kf[0] - r @ P.lever if has[0] else pos_kf[0]
    v_out[0] = vel_kf[0]
    omega_x = skew(P.omega_t)  # Ω× as a matrix (np.cross costs ~30 µs per call)
    for k in range(nk - 1):
        T = P.t_kf[k + 1] - P.t_kf[k]
        a = g_kf[k] - 2 * (omega_x @ v_out[k])
        rr = rot[k]
        p1 = p_out[k] + v_out[k] * T + 0.5 * a * T * T + rr @ dp_t[k]
        v1 = v_out[k] + a * T + rr @ dv_t[k]
        r1 = _gyro_forward(P, rr, k, dr_t)
        if triad_ok[k + 1]:
            r1 = rot_triad[k + 1]
        elif tilt_ok[k + 1]:
            r1 = retilt(r1, f_b[k + 1], f_t[k + 1])
        if has[k + 1]:
            p1 = pos_kf[k + 1] - r1 @ P.lever
            v1 = vel_kf[k + 1]
        elif in_gap[k + 1]:
            # long gap between kept fixes (outage or rejected fixes): IMU propagation from
            # unknown biases drifts far outside Gauss-Newton's basin; bridge it instead
            p1, v1 = pos_kf[k + 1], vel_kf[k + 1]
        elif v_bridge[k + 1]:
            p1[2], v1[2] = pos_kf[k + 1, 2], vel_kf[k + 1, 2]
        rot[k + 1], p_out[k + 1], v_out[k + 1] = r1, p1, v1
    # keyframe 0's attitude from the data around keyframe 0 alone: graph-isam2's causal start
    r_c = level(f_b[0])
    if tilt_ok[0]:
        r_c = retilt(r_c, f_b[0], f_t[0])
    # the keyframe from which the heading is known: the first TRIAD keyframe's once the data
    # of its window has arrived (with none, the last keyframe: the heading is never known)
    anchor = nk - 1
    if k0 >= 0:
        look = 2 * POS_ONLY_BASE_S if vel is None else 0.5
        anchor = int(np.searchsorted(P.t_kf, P.t_kf[k0] + look - 1e-9)) if k0 > 0 else 0
    if compass_heading(P, rot):
        P.init_attitude = "compass"
        # the compass's heading at keyframe 0 from keyframe 0's own levelled tilt and the
        # compass sample nearest it (not ``rot[0]``: its tilt is carried back from the first
        # TRIAD keyframe and its correction is a median over ±COMPASS_WINDOW_S)
        r_k0 = compass_turned(P, r_c[None], P.t_kf[:1])
        if r_k0 is not None:
            r_c, anchor = r_k0[0], 0
    elif filter_attitude(P, rot):
        P.init_attitude = "ekf"  # the ekf is causal: its heading from the keyframe it is good
        anchor = P.ekf_heading_kf
    if anchor == 0 and P.init_attitude != "compass":
        r_c = rot[0]  # keyframe 0's own heading (TRIAD's or the ekf's there)
    if P.init_attitude != "triad" and np.any(P.lever):
        p_out[has] = pos_kf[has] - np.einsum("nij,j->ni", rot[has], P.lever)
    p_c = pos_kf[0] - r_c @ P.lever if has[0] else pos_kf[0]
    P.start0 = CausalStart(r_c, p_c, v_out[0].copy(),
                           PRIOR_ATT_SD[2] if anchor == 0 else UNKNOWN_YAW_SD,
                           None if anchor == 0 else min(anchor, nk - 1))
    return rot, p_out, v_out


def _gnss_at_keyframes(P: Problem) -> tuple[FloatArray, FloatArray | None, FloatArray,
                                             FloatArray, FloatArray, FloatArray, FloatArray]:
    """The kept fixes' times, their velocities (None for a position-only receiver), and at
    every keyframe: whether a fix is near, the interpolated position and velocity, the
    GNSS acceleration and whether it is usable (``initial_states``)."""
    u = P.g_pos_use
    gt, pos = P.g_t[u], P.g_pos[u]
    vel = None if P.g_vel is None else P.g_vel[u]
    near = nearest_gap(gt, P.t_kf)
    rate = 1.0 / max(float(np.median(np.diff(gt))), 1e-3) if gt.size > 1 else 1.0
    has = near <= max(0.6 / rate, 0.02)
    pos_kf = np.column_stack([np.interp(P.t_kf, gt, pos[:, i]) for i in range(3)])
    if vel is None:
        # position-only receiver: velocity and acceleration from central differences of the
        # positions over a ±POS_ONLY_BASE_S baseline (σ_v ≈ σ_p/(√2·base): 0.7 m/s at 1 m
        # noise), enough for the course of a vehicle above TRIAD_SPEED
        def cdiff(x: FloatArray, tq: FloatArray, w: float) -> FloatArray:
            return (np.column_stack([np.interp(tq + w, gt, x[:, i]) for i in range(3)])
                    - np.column_stack([np.interp(tq - w, gt, x[:, i]) for i in range(3)])
                    ) / (2 * w)

        w = POS_ONLY_BASE_S
        vel_kf = cdiff(pos, P.t_kf, w)
        acc_kf = (cdiff(pos, P.t_kf + w, w) - cdiff(pos, P.t_kf - w, w)) / (2 * w)
        acc_ok = has & (P.t_kf - 2 * w >= gt[0]) & (P.t_kf + 2 * w <= gt[-1])
    else:
        vel_kf = np.column_stack([np.interp(P.t_kf, gt, vel[:, i]) for i in range(3)])
        w = 0.5
        vp = np.column_stack([np.interp(P.t_kf + w, gt, vel[:, i]) for i in range(3)])
        vm = np.column_stack([np.interp(P.t_kf - w, gt, vel[:, i]) for i in range(3)])
        acc_kf = (vp - vm) / (2 * w)
        acc_ok = has & (np.abs(P.t_kf + w - P.t_kf.clip(gt[0], gt[-1])) >= 0)
    return gt, vel, has, pos_kf, vel_kf, acc_kf, acc_ok


def _course_sd(P: Problem, gt: FloatArray, vel: FloatArray | None, vel_kf: FloatArray
               ) -> FloatArray:
    """σ of the course at every keyframe as a heading [rad]: ``nav.course.course_heading``
    over the kept fixes (the ekf's rule, with the sway against the gyro-carried heading),
    read at the fix nearest each keyframe. A position-only receiver's velocity is the
    keyframes' central differences, σ_p/(√2·base) of noise, and the sway is measured over
    the keyframes."""
    u = P.g_pos_use
    imu = P.drive.imu
    if vel is not None and P.g_vel_sd is not None:
        if gt.size == 0:
            return np.full(P.n_kf, np.pi)
        vsd = np.hypot(P.g_vel_sd[u, 0], P.g_vel_sd[u, 1]) / np.sqrt(2.0)
        sd = course_heading(gt, vel[:, :2], vsd, SIDESLIP_SD,
                            gyro_yaw(imu.t, imu.gyro_b[:, 2], gt)).yaw_sd
        return sd[nearest_index(gt, P.t_kf)]
    vsd_fix = np.hypot(P.g_pos_sd[u, 0], P.g_pos_sd[u, 1]) / (2.0 * POS_ONLY_BASE_S)
    vsd = np.interp(P.t_kf, gt, vsd_fix) if gt.size else np.full(P.n_kf, np.inf)
    return course_heading(P.t_kf, vel_kf[:, :2], vsd, SIDESLIP_SD,
                          gyro_yaw(imu.t, imu.gyro_b[:, 2], P.t_kf)).yaw_sd


def _baro_bridge(P: Problem, gt: FloatArray, has: FloatArray, pos_kf: FloatArray,
                 vel_kf: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Keyframes inside long gaps between kept fixes (``in_gap``), and those whose height and
    vertical speed come from the baro (``v_bridge``; ``pos_kf``, ``vel_kf`` set in place)."""
    nk = P.n_kf
    pos = P.g_pos[P.g_pos_use]
    # inside gaps > 5 s between kept fixes: linear bridge horizontally, baro height
    # (plus the median GNSS − baro offset) vertically when a barometer is present
    gap_len = np.zeros(nk)
    if gt.size > 1:
        j = np.clip(np.searchsorted(gt, P.t_kf), 1, gt.size - 1)
        gap_len = gt[j] - gt[j - 1]
    in_gap = ~has & (gap_len > 5.0) & (P.t_kf > gt[0]) & (P.t_kf < gt[-1])
    # after the last kept fix (a drive that ends in an outage): IMU propagation horizontally,
    # the baro vertically (as in a gap: a stepped accelerometer carries the propagated height
    # hundreds of metres away, docs/real_logs.md "Initial heading and tilt of a hovering
    # multirotor", and the bilinear baro term (1 + s)·h, linearised there, then pulls s
    # towards −1; docs/graph.md "Baro scale limit"). Not before the first fix:
    # keyframe 0 starts graph-isam2's causal pass, and the baro's offset is the whole drive's
    outside = ~has & (P.t_kf > gt[-1])
    baro = P.drive.baro
    v_bridge = np.zeros(nk, dtype=bool)
    if baro is not None and np.any(in_gap | outside) and baro.t.size > 1:
        hg = ned_to_lla(pos, P.origin)[:, 2]
        off = float(np.median(hg - np.interp(gt, baro.t, baro.altitude)))
        v_bridge = in_gap | outside
        hb = np.interp(P.t_kf[v_bridge], baro.t, baro.altitude) + off
        pos_kf[v_bridge, 2] = -(hb - P.h0)
        vz = -np.gradient(np.interp(P.t_kf, baro.t, baro.altitude), P.t_kf)
        vel_kf[v_bridge, 2] = vz[v_bridge]
    return in_gap, v_bridge


def _mean_specific_force(t: FloatArray, accel_b: FloatArray, t_kf: FloatArray) -> FloatArray:
    """Mean measured specific force over ±0.25 s around every keyframe."""
    cs = np.vstack([np.zeros((1, 3)), np.cumsum(accel_b, axis=0)])
    lo = np.searchsorted(t, t_kf - 0.25)
    hi = np.searchsorted(t, t_kf + 0.25, side="right")
    return (cs[hi] - cs[lo]) / np.maximum(hi - lo, 1)[:, None]


# yaw σ of graph-isam2's causal start before the heading is known [rad] (a prior that only
# keeps the yaw regular: the heading is unknown on a standstill without a compass)
UNKNOWN_YAW_SD = np.pi


@dataclass(frozen=True)
class CausalStart:
    """Keyframe 0 of graph-isam2's online pass from the data around keyframe 0 alone.

    rot, pos, vel: R_tb, p_t, v_t (tilt from the specific force against the GNSS
    acceleration, heading from TRIAD, the compass or the forward ekf there; yaw 0 of the
    levelled specific force when none of them has it); yaw_sd: the σ of keyframe 0's yaw prior
    (``UNKNOWN_YAW_SD`` without a heading); anchor: the keyframe from which the heading is
    known (the data of the first TRIAD keyframe's window has arrived, or the ekf's heading σ
    is below ``FILTER_YAW_SD_MAX``; the last keyframe when neither ever happens), after which
    the online pass starts again from ``initial_states``' keyframe 0 (the heading carried
    back to it by the gyro, or yaw 0); None when keyframe 0's own heading is that one."""

    rot: FloatArray
    pos: FloatArray
    vel: FloatArray
    yaw_sd: float
    anchor: int | None


# vehicles whose GNSS course is not their heading (they hover and fly sideways)
HOVERING = ("multirotor", "helicopter", "vtol")


def filter_attitude(P: Problem, rot: FloatArray) -> bool:
    """``GraphConfig.init_attitude``: replace the keyframe attitudes ``rot`` (in place) by the
    forward ekf's (no compass, the graph's GNSS, its own alignment: a causal filter that finds
    the heading from the IMU and GNSS accelerations) when asked to ("ekf"), or by default
    ("auto") on a hovering vehicle when the graph uses no compass. Where the ekf's heading σ
    exceeds ``FILTER_YAW_SD_MAX`` (before it acquires the heading, after a long gap) the
    attitude is carried by the gyro increments from the nearest keyframe where it does not
    (forwards, or backwards before the first): the ekf's placeholder heading there left
    graph-batch 11.7 in ½χ² above its optimum on a simulated drive. TRIAD takes the heading
    from the course, which a multirotor does not fly along; propagated from there through a
    vibrating gyro, a wrong heading turns into a wrong tilt, and Gauss-Newton ends in a far
    minimum. Where the ekf never acquires its heading, its attitudes are used as they are:
    their tilt, levelled on the specific force, is right (docs/real_logs.md, "Initial heading
    and tilt of a hovering multirotor"). Returns whether the attitudes were replaced."""
    mode = P.cfg.init_attitude
    if mode == "triad":
        return False
    if mode == "auto":
        from ....sensors.magnetometer import usable

        compass = P.cfg.use_mag and usable(P.drive.mag)[0]
        if compass or P.drive.meta.get("vehicle") not in HOVERING:
            return False
    from ...ekf.filter import EKF, EkfConfig

    try:
        est = EKF(EkfConfig(use_mag=False)).run(P.drive)
    except (ValueError, RuntimeError, FloatingPointError, np.linalg.LinAlgError) as exc:
        # an initial guess is not worth failing the smoother for: TRIAD's, and say why
        P.init_note = f"initial attitude from TRIAD: the forward ekf failed ({exc})"
        return False
    tr = est.trajectory
    if tr.q_nb is None or est.cov is None or est.t_cov is None:
        return False
    yaw = ERROR_STATE["att_n"].start + 2
    yaw_sd = np.sqrt(np.interp(P.t_kf, est.t_cov, est.cov[:, yaw, yaw]))
    good = yaw_sd <= FILTER_YAW_SD_MAX
    j = nearest_index(tr.t, P.t_kf)
    out = gf.rot_t_n(tr.lla[j], P.origin) @ quat_to_mat(tr.q_nb[j])
    if good.any():
        # elsewhere the gyro carries the attitude: forwards from the previous keyframe,
        # backwards before the first good one. (Where the heading was never acquired, the
        # ekf's tilt — levelled by its accelerometer and GNSS updates — with its best heading.)
        dr_t = P.dense.end()[0]
        first = int(np.argmax(good))
        P.ekf_heading_kf = first
        for k in range(first + 1, P.n_kf):
            if not good[k]:
                out[k] = _gyro_forward(P, out[k - 1], k - 1, dr_t)
        for k in range(first - 1, -1, -1):
            out[k] = _gyro_back(P, out[k + 1], k, dr_t)
    rot[:] = out
    return True


# the ekf's heading σ above which its attitude is not used as the initial guess [rad]
FILTER_YAW_SD_MAX = np.radians(10.0)


def compass_heading(P: Problem, rot: FloatArray) -> bool:
    """With a magnetometer the graph uses (``GraphConfig.use_mag`` and a usable compass,
    ``graph.model.builtin_sensors``), turn the keyframe attitudes ``rot`` (in place) about the down
    axis so that their heading is the compass's: the azimuth of R_k·z (z the measured field,
    hard iron zero, as the hard-iron prior's mean) equals the field reference's, as in the
    heading factor. The correction δ_k is the circular median of the keyframes' within
    ±``COMPASS_WINDOW_S`` (noise, motor interference), carried to keyframes without a sample
    from the nearest one. TRIAD's heading is the course, which is the vehicle's heading only
    for a car: a multirotor flies in any direction, its start heading is tens of degrees off
    and Gauss-Newton then creeps along the weakly held heading (docs/real_logs.md, "Initial
    heading and tilt of a hovering multirotor"). The ekf aligns its
    heading on the compass too (``ekf.magnetometer.initial_heading``). Returns whether the
    attitudes were turned."""
    from ....sensors.magnetometer import usable

    if not P.cfg.use_mag or not usable(P.drive.mag)[0]:  # usable: a stream of ≥ 2 samples
        return False
    corr = _compass_corrections(P, rot, P.t_kf)
    if corr is None:
        return False
    ok, d_ok = corr
    t_ok = P.t_kf[ok]
    lo = np.searchsorted(t_ok, t_ok - COMPASS_WINDOW_S)
    hi = np.searchsorted(t_ok, t_ok + COMPASS_WINDOW_S, side="right")
    smooth = np.array([_circular_median(d_ok[a:b]) for a, b in zip(lo, hi, strict=True)])
    delta = smooth[nearest_index(t_ok, P.t_kf)]
    c, s = np.cos(delta), np.sin(delta)
    rz = np.zeros((delta.size, 3, 3))
    rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = c, -s, s, c, 1.0
    rot[:] = rz @ rot
    return True


def _compass_corrections(P: Problem, rot: FloatArray, t_q: FloatArray
                         ) -> tuple[np.ndarray, FloatArray] | None:
    """Where the attitudes ``rot`` at times ``t_q`` have a compass sample within half a
    sample spacing and a horizontal field of at least ``MIN_HORIZONTAL_UT``: the mask and the
    yaw corrections [rad] that turn them onto the compass's heading (the azimuth of R·z, z the
    measured field with zero hard iron, equals the field reference's). None without any."""
    from ....sensors.magnetometer import MIN_HORIZONTAL_UT, drive_field, wrap_pi

    mag = P.drive.mag
    ref = drive_field(P.drive)[0].ned_ut
    j = nearest_index(mag.t, t_q)
    spacing = float(np.median(np.diff(mag.t)))
    m_t = np.einsum("nij,nj->ni", rot, mag.field_b[j])
    ok = (np.abs(mag.t[j] - t_q) <= 0.5 * spacing) & (np.hypot(m_t[:, 0], m_t[:, 1])
                                                      >= MIN_HORIZONTAL_UT)
    if not ok.any():
        return None
    return ok, wrap_pi(np.arctan2(ref[1], ref[0]) - np.arctan2(m_t[ok, 1], m_t[ok, 0]))


def compass_turned(P: Problem, rot: FloatArray, t_q: FloatArray) -> FloatArray | None:
    """``rot`` (n, 3, 3) at ``t_q`` turned about the down axis onto the compass's heading
    sample by sample (``_compass_corrections``), or None where any lacks a sample."""
    corr = _compass_corrections(P, rot, t_q)
    if corr is None or not corr[0].all():
        return None
    c, s = np.cos(corr[1]), np.sin(corr[1])
    rz = np.zeros((c.size, 3, 3))
    rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = c, -s, s, c, 1.0
    return rz @ rot


# half-width of the window over which the compass corrections of the initial heading are
# combined (compass_heading) [s]
COMPASS_WINDOW_S = 2.0


def _circular_median(a: FloatArray) -> float:
    """The angle of ``a`` [rad] nearest to all others in the L1 sense on the circle,
    approximated by the median of the angles unwrapped around their circular mean."""
    mean = np.arctan2(np.mean(np.sin(a)), np.mean(np.cos(a)))
    return float(mean + np.median((a - mean + np.pi) % (2 * np.pi) - np.pi))


def nearest_gap(t_ref: FloatArray, t_q: FloatArray) -> FloatArray:
    """|t_q − nearest t_ref| for every t_q, in O((n + m) log n) memory-light steps (the
    (m, n) difference matrix it replaces took 520 MB transient on a 30-min drive)."""
    if t_ref.size == 0:
        return np.full(t_q.shape, np.inf)
    ts = np.sort(t_ref)
    j = np.searchsorted(ts, t_q)
    lo = ts[np.clip(j - 1, 0, ts.size - 1)]
    hi = ts[np.clip(j, 0, ts.size - 1)]
    return np.minimum(np.abs(t_q - lo), np.abs(hi - t_q))


def _gyro_forward(P: Problem, r: FloatArray, k: int, dr_t: FloatArray) -> FloatArray:
    """R_tb at keyframe k+1 from ``r`` at k: the preintegrated gyro increment ``dr_t[k]`` and
    the Earth rate of the (Earth-fixed) tangent frame."""
    return so3_exp(-P.omega_t * (P.t_kf[k + 1] - P.t_kf[k])) @ r @ dr_t[k]


def _gyro_back(P: Problem, r: FloatArray, k: int, dr_t: FloatArray) -> FloatArray:
    """R_tb at keyframe k from ``r`` at k+1 (``_gyro_forward`` inverted)."""
    return so3_exp(P.omega_t * (P.t_kf[k + 1] - P.t_kf[k])) @ r @ dr_t[k].T


def retilt(r: FloatArray, f_b: FloatArray, f_t: FloatArray) -> FloatArray:
    """``r`` turned by the smallest rotation that takes r·f_b onto f_t: the tilt of the
    specific force, the heading (nearly) kept, as TRIAD's first vector does. A tilt propagated
    through a vibrating gyro for tens of seconds before the first TRIAD keyframe is tens of
    degrees off, while the specific force's tilt is right to a few degrees
    (docs/real_logs.md, "Initial heading and tilt of a hovering multirotor")."""
    u, v = _unit(r @ f_b), _unit(f_t)
    axis = np.cross(u, v)
    sin = float(np.linalg.norm(axis))
    if sin < 1e-12:
        return r
    return so3_exp(axis / sin * np.arctan2(sin, float(u @ v))) @ r


def _unit(x: FloatArray) -> FloatArray:
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _triad(f_b: FloatArray, x_b: FloatArray, f_t: FloatArray, v_t: FloatArray) -> FloatArray:
    """R_tb of TRIAD: (f_b, body x axis ``x_b``) against (f_t, v_t); f_b, f_t, v_t (n, 3) or
    (3,), x_b (3,); (n, 3, 3) or (3, 3)."""
    b1, n1 = _unit(f_b), _unit(f_t)
    b2, n2 = _unit(np.cross(f_b, x_b)), _unit(np.cross(f_t, v_t))
    mb = np.stack([b1, b2, np.cross(b1, b2)], axis=-1)
    mn = np.stack([n1, n2, np.cross(n1, n2)], axis=-1)
    return mn @ np.swapaxes(mb, -1, -2)


