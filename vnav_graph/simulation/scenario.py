"""Scenarios (TOML) and ``simulate(scenario, seed) -> Drive``.

Scenario files live in ``vnav_graph/scenarios/*.toml`` (``benchmarks/scenarios`` links there).
A scenario picks a trajectory kind, a duration, sensor rates and the error models; every
random draw comes from ``np.random.default_rng(seed)`` (the trajectory from
``default_rng([seed, 1])``, the urban GNSS errors from ``default_rng([seed, 2])``, the
optional magnetometer's noise from ``default_rng([seed, 3])``) so a (scenario, seed) pair
always gives the same drive, and switching the magnetometer on changes no other stream.
"""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from ..config import (
    IMU_PRESETS,
    BaroSpec,
    GnssSpec,
    ImuSpec,
    ScenarioConfig,
    replace_fields,
)
from ..types import Drive, Trajectory
from . import SCENARIO_DIR, list_scenarios
from .gnss import simulate_gnss
from .measurements import apply_imu_errors, simulate_baro
from .trajectories import (
    hill_drive_profiles,
    kinematics,
    mount_imu,
    sortie_profiles,
    vertical_kinematics,
)


def scenario_from_dict(d: dict[str, Any]) -> ScenarioConfig:
    """Build a ScenarioConfig from a TOML-like dict (unknown keys are errors)."""
    d = dict(d)
    imu_d = dict(d.pop("imu", {}))
    preset = imu_d.pop("preset", "consumer")
    if preset not in IMU_PRESETS:
        raise ValueError(f"scenario imu.preset: unknown {preset!r} (known: {sorted(IMU_PRESETS)})")
    imu: ImuSpec = replace_fields(IMU_PRESETS[preset], **imu_d)
    gnss_d = dict(d.pop("gnss", {}))
    if "outages" in gnss_d:
        gnss_d["outages"] = tuple(tuple(float(x) for x in w) for w in gnss_d["outages"])
    if "imu_mount_rph_deg" in d:
        d["imu_mount_rph_deg"] = tuple(float(x) for x in d["imu_mount_rph_deg"])
    for key in ("lever_arm_b", "burst_len_s", "burst_err_m", "random_outage_len_s"):
        if key in gnss_d:
            gnss_d[key] = tuple(float(x) for x in gnss_d[key])
    gnss: GnssSpec = replace_fields(GnssSpec(), **gnss_d)
    baro_d = dict(d.pop("baro", {}))
    if "latency_range_s" in baro_d:
        baro_d["latency_range_s"] = tuple(float(x) for x in baro_d["latency_range_s"])
    baro: BaroSpec = replace_fields(BaroSpec(), **baro_d)
    mag = None
    if "magnetometer" in d:
        from ..sensors.magnetometer import MagSpec

        mag_d = dict(d.pop("magnetometer"))
        if "hard_iron_ut" in mag_d:
            mag_d["hard_iron_ut"] = tuple(float(x) for x in mag_d["hard_iron_ut"])
        mag = replace_fields(MagSpec(), **mag_d)
    params = dict(d.pop("params", {}))
    try:
        return ScenarioConfig(imu=imu, gnss=gnss, baro=baro, params=params, magnetometer=mag,
                              **d)
    except TypeError as exc:
        raise ValueError(f"scenario: {exc}") from None


def load_scenario(name_or_path: str | Path, **overrides: Any) -> ScenarioConfig:
    """Load a scenario by name (``hill-drive``) or TOML path; ``overrides`` replace top-level
    fields (e.g. ``duration_s=120``)."""
    p = Path(name_or_path)
    if p.suffix != ".toml":
        p = SCENARIO_DIR / f"{name_or_path}.toml"
        if not p.exists():
            from ..util.suggest import did_you_mean

            known = list_scenarios()
            raise ValueError(f"unknown scenario {str(name_or_path)!r}"
                             f"{did_you_mean(str(name_or_path), known)} (known: "
                             f"{', '.join(known)})")
    elif not p.exists():
        raise ValueError(f"scenario file not found: {p}")
    try:
        d = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"scenario {p.name}: invalid TOML ({exc})") from None
    cfg = scenario_from_dict(d)
    return replace(cfg, **overrides) if overrides else cfg


def simulate(scenario: ScenarioConfig | str, seed: int = 0, **overrides: Any) -> Drive:
    """Simulate one drive. Deterministic given ``(scenario, seed)``.

    The truth (``Drive.truth``) is sampled at the IMU epochs; its attitude is the IMU's (with
    ``imu_mount_rph_deg`` not the vehicle's: ``meta["imu_mount_rph_deg"]``), and it carries
    the realised IMU biases and the baro Gauss-Markov bias (interpolated to IMU epochs). A
    ``side_slip_gain`` or ``imu_mount_rph_deg`` is recorded in ``meta``. A scenario with a
    ``[magnetometer]`` section also gives ``Drive.mag`` and ``meta["mag_truth"]``: the
    hard-iron bias ``hard_iron_ut`` (3,) in b [µT] and the World Magnetic Model field at the
    origin (``field_ned_ut`` (3,) µT north-east-down, ``declination_rad``,
    ``inclination_rad``, ``model``, ``year``).
    """
    cfg = load_scenario(scenario, **overrides) if isinstance(scenario, str) else (
        replace(scenario, **overrides) if overrides else scenario
    )
    rng = np.random.default_rng(seed)
    origin = np.array([np.radians(cfg.origin_lat_deg), np.radians(cfg.origin_lon_deg),
                       cfg.origin_alt_m])
    dt = 1.0 / cfg.imu_rate_hz
    t = np.arange(0.0, cfg.duration_s + 0.5 * dt, dt)
    traj_rng = np.random.default_rng([seed, 1])  # trajectory draws independent of sensor draws
    p = cfg.params
    if cfg.kind == "vertical":
        kin = vertical_kinematics(t, origin, traj_rng, **p)
    else:
        if cfg.kind == "hill-drive":
            prof = hill_drive_profiles(cfg.duration_s, traj_rng, **p)
            turns = False
        else:
            prof = sortie_profiles(cfg.duration_s, traj_rng, **p)
            turns = True
        kin = kinematics(t, *prof, origin, coordinated_turns=turns,
                         slip_gain=float(cfg.side_slip_gain))
        if any(cfg.imu_mount_rph_deg):
            kin = mount_imu(kin, np.radians(cfg.imu_mount_rph_deg))
    imu, imu_err = apply_imu_errors(t, kin.gyro_b, kin.accel_b, cfg.imu, rng)
    # only the truth and ω_nb are needed from here on: the ideal IMU readings are dropped
    # (each per-sample array is 17 MB on a 1-hour 200 Hz drive)
    kin_truth, omega_nb_b = kin.truth, kin.omega_nb_b
    del kin

    def omega_nb(tq: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(tq, t, omega_nb_b[:, j]) for j in range(3)])

    # the urban GNSS errors draw from their own generator: switching them on leaves every
    # other draw of the drive unchanged
    gnss, gnss_log = simulate_gnss(kin_truth, omega_nb, cfg.gnss, rng,
                                   urban_rng=np.random.default_rng([seed, 2]))
    omega_nb_b = None  # ``omega_nb`` is not called again
    t_baro = np.arange(0.0, cfg.duration_s + 1e-9, 1.0 / cfg.baro.rate_hz)
    baro, baro_truth, bias_b = simulate_baro(
        t_baro, t, kin_truth.alt, float(origin[2]), cfg.baro, rng
    )
    # the truth's read-only arrays are shared with kin_truth, not copied (streams.as_array)
    truth = Trajectory(
        t, kin_truth.lla, kin_truth.vel_n, kin_truth.q_nb, imu_err.bias_gyro,
        imu_err.bias_accel, np.interp(t, t_baro, bias_b),
    )
    mag, mag_truth = None, None
    if cfg.magnetometer is not None:
        mag, mag_truth = _simulate_mag(kin_truth, origin, cfg.magnetometer,
                                       np.random.default_rng([seed, 3]))
    meta = {
        "name": f"{cfg.name}-seed{seed}",
        "scenario": cfg.name,
        "seed": seed,
        "source": "simulated",
        "kind": cfg.kind,
        "imu_grade": cfg.imu.name,
        # every window without fixes: the configured ones, then the random ones
        "gnss_outages": [list(w) for w in cfg.gnss.outages + gnss_log.random_outages],
        "gnss_random_outages": [list(w) for w in gnss_log.random_outages],
        "gnss_burst_windows": [list(w) for w in gnss_log.burst_windows],
        "gnss_burst_fixes": int(gnss_log.in_burst.sum()),
        "gnss_outliers": int(gnss_log.outlier.sum()),
        "accel_scale_true": imu_err.accel_scale.tolist(),
    }
    if cfg.side_slip_gain or any(cfg.imu_mount_rph_deg):
        meta["side_slip_gain"] = float(cfg.side_slip_gain)
        meta["imu_mount_rph_deg"] = list(cfg.imu_mount_rph_deg)
    if mag_truth is not None:
        meta["mag_truth"] = mag_truth
        meta["decimal_year"] = mag_truth["year"]  # the drive's date, as a log reader gives it
    return Drive(imu, gnss, baro, origin, truth, baro_truth, MappingProxyType(meta), mag=mag)


def _simulate_mag(truth: Trajectory, origin: np.ndarray, spec: Any,
                  rng: np.random.Generator) -> tuple[Any, dict[str, Any]]:
    """The magnetometer stream and its truth record (``meta["mag_truth"]``, JSON-ready).
    The field is the WMM's at the drive origin (lat, lon [rad], height [m]) in ``spec.year``.
    """
    from ..geo.magfield import earth_field
    from .measurements import simulate_mag

    f = earth_field(float(origin[0]), float(origin[1]), float(origin[2]), spec.year)
    stream = simulate_mag(truth, spec, f.ned_ut, rng)
    record = {
        "hard_iron_ut": list(spec.hard_iron_ut),
        "field_ned_ut": f.ned_ut.tolist(),
        "declination_rad": f.declination_rad,
        "inclination_rad": f.inclination_rad,
        "model": f.model,
        "year": float(spec.year),
    }
    if f.note:
        record["note"] = f.note
    return stream, record
