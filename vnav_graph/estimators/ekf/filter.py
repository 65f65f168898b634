"""Reference INS/GNSS/baro error-state EKF (``ekf``) and its RTS smoother (``ekf-rts``).

The filter equations, the covariance grid, the measurement timing and the heading handling
are specified in docs/ekf.md (the numba kernels are ``ekf.model``). This module turns
a ``Drive`` into the kernel inputs (noise from the drive's specs, alignment, and the grids,
process noise and event list of ``ekf.inputs``, the measurement records of ``ekf.updates``)
and the kernel outputs into an ``Estimate``.

Outputs
-------
- trajectory: at every ``D``-th IMU epoch (``D = round(imu_rate / traj_rate_hz)``, 50 Hz by
  default) plus every covariance-grid epoch and the last epoch; the value at a grid epoch is
  the state after that epoch's measurement update.
- covariance: the 18-state ``ERROR_STATE`` block at ``cov_output_hz`` (5 Hz by default) —
  a subset of the ``cov_rate_hz`` (10 Hz) propagation grid. Rows of the baro states are NaN
  when the drive has no barometer.
- ``baro``: scale and latency are random constants: the final filtered (``ekf``) / smoothed
  (``ekf-rts``) value with its one-sigma. ``bias_m`` is the time average of b(t) over the
  output epochs; its ``sd`` for ``ekf-rts`` is the smoothed σ of that average, with the
  epochs' cross-covariances (``rts`` docstring), for ``ekf`` the time average of σ_b(t), an
  upper bound (σ(mean e) ≤ mean σ(e) for any correlation between epochs); its prior σ is
  that of a stationary Gauss-Markov bias's time average over the drive, as in graph-batch.
- innovations (``updates.report``): normalised (z − h(x̃))/√S_ii of every accepted
  measurement component: ``gnss_pos`` (N, 3), ``gnss_vel`` (N, 3), ``baro`` (N,), ``mag``
  (N,), ``zupt`` (N, 3).
- info: per measurement kind (``updates.report``) ``gnss_rejected`` (fixes whose horizontal
  pair or height was refused: χ² gate, σ_v limit or probation, docs/ekf.md),
  ``gnss_alt_rejected`` (height refused), ``gnss_vel_rejected``, ``baro_rejected``,
  ``mag_used`` / ``mag_rejected``, ``zupt_intervals`` ([t_start, t_end] [s] of the
  standstills given zero-velocity updates, ``EkfConfig.zupt``; ``nav.standstill``),
  ``zupt_used`` / ``zupt_rejected`` (updates applied / refused by their χ²₃ gate) and
  ``zupt`` (the detector's threshold and noise); and ``imu_gaps`` ([start, length] of
  bridged IMU gaps [s]), ``heading_time_s`` (time the heading last became known),
  ``heading_source`` (given / magnetometer / accel-matching / gnss-course, the course
  confirmed by the matching / gnss-track), ``gnss_forced``, rates used.

Noise
-----
The shared sensor model of the drive (``sensors.model``, the same for ekf, ekf-rts,
vekf7 and both graphs): the drive's specs when present; on a real log the IMU noise inferred
from the log (``infer_imu_spec``: the ``REAL_LOG_IMU`` prior raised to the measured white
scatter — a phone on a skier shows 0.036 m/s²/√Hz and 0.31 °/s/√Hz, 100× the MPU-9250
datasheet — plus a vibration bias walk), ``REAL_LOG_BARO`` for the baro (10 m bias σ);
GNSS: per-fix sigmas of the stream floored at ``GNSS_SD_FLOOR`` (``sensors.model``), in
the updates and in the initial position/velocity variances. On a real log the baro bias
prior mean is taken from the first baro sample minus the initial GNSS height (a relative baro
altitude would otherwise be hundreds of metres off). Discrete variances come from
``vnav_graph.sensors.noise`` only. Small floors keep P positive definite with ideal sensors.

References: Groves, *Principles of GNSS, Inertial and Multisensor Integrated Navigation
Systems*, 2nd ed., ch. 14; seed 004 (17/19-state INS/GNSS EKF, in-flight alignment §5.4);
seed 001 (baro error model); Rauch, Tung & Striebel, AIAA J. 3(8), 1965.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.stats import chi2

from ...config import REAL_LOG_BARO, ImuSpec
from ...geo.earth import OMEGA_IE
from ...sensors.magnetometer import field_and_info
from ...sensors.model import (
    SensorModel,
    accel_scale_sd,
    baro_prior,
    sensor_model,
)
from ...sensors.noise import gm_mean_prior_sd
from ...types import BaroEstimate, Drive, Estimate, ParamEstimate, Trajectory
from ...types.streams import FloatArray
from ...util.pages import small_pages
from ..base import with_online
from ..checks import checked
from ..gnss_auto import with_gm_auto
from ..zupt import drive_standstill
from . import backward, carry, inputs, kernel, regate, rts, updates
from . import model as km
from .alignment import Alignment, initial_state
from .settings import EkfConfig

NDArrayInt = Any
PROVIDES = frozenset({"alt", "vel_d", "pos_h", "vel_h", "att", "baro", "cov"})


@dataclass(frozen=True)
class _Run:
    """Everything one forward pass produces (internal)."""

    t_out: FloatArray
    lla: FloatArray
    vel: FloatArray
    q: FloatArray
    par: FloatArray
    t_grid: FloatArray
    grid_idx: NDArrayInt
    out_idx: NDArrayInt
    cov_grid: NDArrayInt  # grid numbers of the covariance-output epochs
    cov_packed: FloatArray
    rts: tuple[Any, ...] | None
    innovations: dict[str, FloatArray]
    info: dict[str, Any]
    prior_sd: dict[str, float]
    latency_mean: float  # the baro latency's prior mean [s]
    tau: tuple[float, float, float, float]
    has_baro: bool
    model: SensorModel  # the shared sensor model of the drive (post-smoothing gate)
    g_latency: float  # GNSS latency subtracted from the fix stamps [s]


def run_forward(drive: Drive, cfg: EkfConfig, store_rts: bool) -> _Run:
    """One forward EKF pass over ``drive`` (see module docstring)."""
    imu = drive.imu
    t = imu.t
    if t.size < 3:
        raise ValueError("ekf: the IMU stream needs at least 3 samples")
    if cfg.heading_source not in ("auto", "track", "accel"):
        raise ValueError("EkfConfig.heading_source: 'auto', 'track' or 'accel'")
    # the noise model every estimator shares (sensors.model)
    model = sensor_model(drive, cfg.gnss_gm)
    ispec: ImuSpec = model.imu
    ka_sd = accel_scale_sd(model, cfg.accel_scale)  # the shared rule (sensors.model)
    est_scale = ka_sd > 0
    bp = model.baro if model.baro is not None else baro_prior(REAL_LOG_BARO)
    if cfg.baro_scale_sd is not None:
        bp = replace(bp, scale_sd=float(cfg.baro_scale_sd))
    gaps = model.gaps
    gr = inputs.grids(t, gaps, imu.rate_hz, cfg)
    qd = inputs.process_noise(t, gr.grid_idx, gaps, ispec, bp, cfg)
    fm, mag_info = field_and_info(drive, cfg.use_mag)  # WMM on the drive's date, or None
    ini = initial_state(drive, cfg, model, bp, ka_sd, fm)
    # standstill (nav.standstill) with the shared model: zero-velocity updates inside it
    still = drive_standstill(drive, model) if cfg.zupt else None
    ctx = updates.Context(drive, model, cfg, ini, bp, fm, still)
    meas, stamps = updates.measurements(ctx)
    ev = inputs.events(t, gr.grid_idx, stamps)
    inn = updates.new_innovations(stamps)
    baro = drive.baro
    gate2 = float(chi2.ppf(cfg.gate_prob, 2))
    gate1 = float(chi2.ppf(cfg.gate_prob, 1))
    tilt_rate_sd = np.sqrt(2.0) * OMEGA_IE * np.cos(ini.lla0[0])
    gm = cfg.gnss_gm
    tau = (ispec.gyro_bias_tau, ispec.accel_bias_tau, bp.bias_tau,
           np.inf if gm is None else gm.tau_s)
    heading_accel = meas.gnss.has_vel and cfg.heading_source in ("auto", "accel")

    hk = cfg.huber_k()
    # scalars coerced to one numba type each (float64, int64, bool): one compiled kernel
    res = kernel.FilterOutput(*kernel.run_filter(
        kernel.Grids(t, imu.gyro_b, imu.accel_b, gr.grid_of, gr.out_of, int(gr.grid_idx.size),
                     int(gr.out_idx.size), gr.cov_out_of, int(gr.cov_grid.size), gr.gap_step,
                     inputs.gap_relevel(imu, gaps, cfg)),
        kernel.Initial(ini.lla0, ini.v0, ini.q0, ini.par0, ini.p0, bool(ini.heading_known)),
        kernel.Noise(qd, *(float(x) for x in tau), float(ini.yaw_unknown_var),
                     float(tilt_rate_sd), float(bp.bias_sd**2)),
        kernel.Events(ev.ev_t, ev.ev_type, ev.ev_idx, int(ev.max_pending)),
        meas,
        kernel.Settings(
            gate_pos=gate2, gate_vel=gate2, gate_v=gate1,
            max_consec=max_rejects(cfg, drive),
            max_sd_v=float(cfg.max_gnss_sd_v), probation_s=float(cfg.gnss_probation_s),
            heading_v_min=float(cfg.heading_speed_min), heading_accel=bool(heading_accel),
            heading_course=bool(heading_accel and cfg.heading_source == "auto"),
            course_confirm_sd=float(cfg.course_confirm_sd),
            align_chunk_s=float(cfg.align_chunk_s), align_forget_s=float(cfg.align_forget_s),
            align_sd_max=float(cfg.align_sd_max),
            align_acc_sd=float(np.sqrt(2.0) * ispec.accel_bias_sd),
            gap_forget_s=float(cfg.gap_heading_forget_s), store_rts=bool(store_rts),
            huber_pos=hk[0], huber_vel=hk[1], tilt_consider=bool(cfg.tilt_consider)),
        inn,
    ))
    innov, info = updates.report(ctx, meas, inn, res.par, res.cov[-1])
    info.update(_report(drive, res, gr, gaps, ini, cfg, heading_accel, est_scale,
                        inn.forced_pos))
    info.update(mag_info)
    vel_note = model.gnss_vel_note()
    if vel_note:  # the velocity σ raised to what the positions support
        info["gnss_vel_note"] = vel_note
    if gm is not None:
        info.update(gm.info())
    if baro is not None:  # for the post-solve scale check (sensors.baro)
        info["baro_scale_max_abs"] = float(np.max(np.abs(res.par[:, km.PSC])))
    # the bias's is the prior σ of its time average over the drive, as graph-batch's
    prior = {"scale": bp.scale_sd, "latency": bp.latency_sd,
             "bias": gm_mean_prior_sd(bp.bias_sd, bp.bias_tau, float(t[-1] - t[0]))}
    rts = (res.rts_p, res.rts_ing, res.rts_q, res.corr, res.reset_at) if store_rts else None
    return _Run(t[gr.out_idx], res.lla, res.v, res.q, res.par, t[gr.grid_idx], gr.grid_idx,
                gr.out_idx, gr.cov_grid, res.cov, rts, innov, info, prior, bp.latency_mean, tau,
                baro is not None, model, float(ini.g_latency))


def _report(drive: Drive, res: kernel.FilterOutput, gr: inputs.Grids, gaps: NDArrayInt,
            ini: Alignment, cfg: EkfConfig, heading_accel: bool, est_scale: bool,
            forced: NDArrayInt) -> dict[str, Any]:
    """``Estimate.info`` besides the measurements' (``updates.report``; module docstring);
    ``forced``: the GNSS fixes whose horizontal pair was forced in."""
    o_par, t_heading = res.par, res.t_heading
    t = drive.imu.t
    gnss = drive.gnss
    info = {
        "imu_gaps": [[float(t[i]), float(t[i + 1] - t[i])] for i in gaps],
        "heading_time_s": None if np.isnan(t_heading) else float(t_heading),
        "cov_rate_hz": float(drive.imu.rate_hz / gr.m_grid),
        "cov_output_every": int(gr.e_cov),
        "traj_decimation": int(gr.d_out),
        "accel_scale_estimated": bool(est_scale),
        "accel_scale": o_par[-1, km.PKA:km.PKA + 3].copy(),
        "static_align_s": float(t[ini.i_static - 1] - t[0]),
        # the time from which the output is causal: the alignment read data up to here
        "online_from_s": float(ini.t_ready),
        "heading_source": ("magnetometer" if ini.heading_from_mag else
                           "given" if ini.heading_known else
                           "gnss-course" if res.by_course else
                           "accel-matching" if heading_accel else "gnss-track"),
    }
    # horizontal pairs forced in after max_rejects refusals in a row: each inflated P by its
    # own innovation, so the filter then follows the fixes whatever they are
    info["gnss_forced"] = int(forced.sum())
    if forced.any() and gnss is not None:
        info["warnings"] = [
            f"ekf: {int(forced.sum())} GNSS fix(es) forced in after "
            f"{max_rejects(cfg, drive)} refusals in a row (the covariance inflated by each "
            f"one's innovation; first at {float(gnss.t[forced][0] - t[0]):.1f} s)"]
    return info


def _estimate(name: str, run: _Run, traj: Trajectory, par: FloatArray, cov: FloatArray,
              t0: float, online: Trajectory | None, cfg: EkfConfig,
              bias_mean_sd: float | None = None) -> Estimate:
    """``bias_mean_sd``: the smoothed σ of the mean baro bias (``rts``); without it (the
    forward filter) the average of the pointwise σ, an upper bound (module docstring)."""
    baro = None
    if run.has_baro:
        last = cov[-1]
        if bias_mean_sd is None:
            bias_mean_sd = float(np.mean(np.sqrt(np.clip(cov[:, km.IBB, km.IBB], 0, None))))
        baro = BaroEstimate(
            scale=ParamEstimate(float(par[-1, km.PSC]), float(np.sqrt(last[km.ISC, km.ISC])),
                                run.prior_sd["scale"], 0.0),
            latency_s=ParamEstimate(float(par[-1, km.PTD]), float(np.sqrt(last[km.ITD, km.ITD])),
                                    run.prior_sd["latency"], run.latency_mean),
            bias_m=ParamEstimate(float(np.mean(par[:, km.PBB])), bias_mean_sd,
                                 run.prior_sd["bias"]),
        )
    return Estimate(
        estimator=name, trajectory=traj, provides=PROVIDES, cov=cov,
        t_cov=run.t_grid[run.cov_grid], baro=baro, runtime_s=time.perf_counter() - t0,
        online=online, innovations=run.innovations, info=run.info, config=cfg,
    )


def _trajectory(run: _Run, lla: FloatArray, vel: FloatArray, q: FloatArray,
                par: FloatArray) -> Trajectory:
    # arrays made here are handed over read-only: ``Trajectory`` shares them, not copies
    fresh = [np.where(q[:, :1] < 0, -q, q), par[:, km.PBG:km.PBG + 3].copy(),
             par[:, km.PBA:km.PBA + 3].copy(), par[:, km.PBB].copy()]
    for a in fresh:
        a.setflags(write=False)
    return Trajectory(run.t_out, lla, vel, *fresh)


class EKF:
    """Full INS/GNSS/baro error-state EKF (forward filter). ``run(drive) -> Estimate``."""

    name = "ekf"

    def __init__(self, config: EkfConfig | None = None) -> None:
        self.config = config or EkfConfig()

    def run(self, drive: Drive) -> Estimate:
        if self.config.gnss_gm_auto:  # without, then perhaps with the GNSS error state
            return with_gm_auto(drive, self.config, self.name,
                                lambda cfg: type(self)(cfg).run(drive))
        with small_pages():  # large numpy arrays without huge-page faults (util.pages)
            return checked(self._run(drive), self.config,
                           lambda cfg: type(self)(cfg).run(drive),
                           mag_rerun=lambda cfg: type(self)(cfg)._run(drive))

    def _run(self, drive: Drive) -> Estimate:
        t0 = time.perf_counter()
        run = run_forward(drive, self.config, store_rts=False)
        traj = _trajectory(run, run.lla, run.vel, run.q, run.par)
        cov = km.unpack_cov(run.cov_packed, run.has_baro)
        # the forward filter's real-time answer, set here so that a pass run again after a
        # whole-drive check keeps this one's (``Estimate.with_real_time_of``)
        return with_online(self.name, _estimate(self.name, run, traj, run.par, cov, t0, None,
                                                self.config))


class EKFRTS(EKF):
    """``ekf`` followed by a Rauch-Tung-Striebel smoother on the covariance grid (``run``
    and its post-solve checks are ``EKF``'s), and with ``EkfConfig.post_gate`` the
    post-smoothing GNSS gate (``ekf.regate``)."""

    name = "ekf-rts"

    def _run(self, drive: Drive) -> Estimate:
        t0 = time.perf_counter()
        est = self._gated(drive, t0)
        if not self.config.fb_separation:
            return est
        try:
            sep = backward.fb_separation(drive, est, self.config,
                                         lambda d, c: EKF(c).run(d))
            note = None
        except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
            sep, note = None, f"{self.name}: the backward pass failed ({exc}); no fb_separation"
        info = {**est.info, "fb_separation": sep}
        if note is not None:
            info["warnings"] = [*(info.get("warnings") or []), note]
        return est.replace(info=info, runtime_s=time.perf_counter() - t0)

    def _gated(self, drive: Drive, t0: float) -> Estimate:
        """The smoothed estimate, with ``post_gate`` after the post-smoothing gate rounds."""
        run, est = self._smooth(drive, t0)
        if not self.config.post_gate or drive.gnss is None:
            return est
        def again(d: Drive) -> tuple[SensorModel, Estimate]:
            r, e = self._smooth(d, t0)
            return r.model, e

        return regate.regated(drive, est, run.model, run.g_latency, self.config, self.name,
                              again, t0, self._weighted(t0))

    def _weighted(self, t0: float) -> Callable[[Drive], Estimate] | None:
        """The passes of ``ekf.regate.huber_rounds``: forward (its GNSS Huber loss off: the
        weights are in the fixes' σ) and RTS, None when no round applies."""
        cfg = self.config
        if cfg.post_huber_rounds <= 0 or not any(cfg.huber_k()[:2]):
            return None
        off = replace(cfg, loss_gnss_pos="none", loss_gnss_vel="none")

        def weighted(d: Drive) -> Estimate:
            return type(self)(off)._smooth(d, t0)[1].replace(config=cfg)

        return weighted

    def _smooth(self, drive: Drive, t0: float) -> tuple[_Run, Estimate]:
        """The forward pass and the RTS smoother over it (``t0``: start of the run's clock);
        with ``carry_heading_back`` run again from t0 with the acquired heading given
        (``ekf.carry``)."""
        cfg = self.config
        run, est = self._pass(drive, cfg, t0)
        if not cfg.carry_heading_back:
            return run, est
        assert run.rts is not None
        redo = carry.rerun_config(cfg, run.info, run.t_grid, run.rts[4], run.t_out, run.q,
                                  run.par[:, km.PBG:km.PBG + 3], est)
        if redo is None:
            return run, est
        run2, est2 = self._pass(drive, redo[0], t0)
        info = {**est2.info, **redo[1]}
        # the causal (online) estimate stays the first pass's: the re-run knows the future
        return replace(run2, info=info), est2.replace(info=info, config=cfg, online=est.online)

    def _pass(self, drive: Drive, cfg: EkfConfig, t0: float) -> tuple[_Run, Estimate]:
        """One forward pass with ``cfg`` and the RTS smoother over it."""
        run = run_forward(drive, cfg, store_rts=True)
        assert run.rts is not None
        rts_p, rts_ing, rts_q, corr, reset_at = run.rts
        cov_out_of = np.full(run.t_grid.size, -1, dtype=np.int64)
        cov_out_of[run.cov_grid] = np.arange(run.cov_grid.size)
        w_mean = rts.mean_weights(run.t_grid, run.t_out, reset_at)
        es, cov_s, var_b = rts.rts_smooth(rts_p, rts_ing, rts_q, corr, reset_at, *run.tau,
                                          cov_out_of, run.cov_grid.size, w_mean)
        e_out = rts.smooth_corrections(run.t_grid, run.t_out, run.rts[3], run.rts[4], es)
        lla, vel, q, par = rts.apply_error(run.lla, run.vel, run.q, run.par, e_out)
        online = _trajectory(run, run.lla, run.vel, run.q, run.par)
        traj = _trajectory(run, lla, vel, q, par)
        cov = km.unpack_cov(cov_s, run.has_baro)
        est = _estimate(self.name, run, traj, par, cov, t0, online, cfg,
                        float(np.sqrt(max(var_b, 0.0))))
        if cfg.gnss_gm is not None and drive.gnss is not None:
            # the smoothed GNSS error state at every fix (the post-smoothing gate's residual)
            tg = drive.gnss.t - run.g_latency
            ge = np.column_stack([np.interp(tg, run.t_out, par[:, km.PGE + a])
                                  for a in range(3)])
            est = est.replace(info={**est.info, "gnss_gm_at_fixes": ge})
        return run, est


def max_rejects(cfg: EkfConfig, drive: Drive) -> int:
    """Refusals in a row after which the next GNSS pair is forced in:
    ``EkfConfig.max_consecutive_rejects``, or ``max_rejected_s`` over the median fix interval."""
    g = drive.gnss
    if cfg.max_rejected_s is None or g is None or g.t.size < 2:
        return int(cfg.max_consecutive_rejects)
    return max(1, int(round(float(cfg.max_rejected_s) / float(np.median(np.diff(g.t))))))
