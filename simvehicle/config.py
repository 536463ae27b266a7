"""Vehicle, autopilot, IMU and GNSS-degradation parameters: the ONE place their values live.

Each section is a frozen dataclass built from the mission's override section of the same
name (``vehicle``, ``autopilot``, ``imu``, ``gnss``) with ``companion.mission.schema.build``.
Defaults are the paper's values (Section V.A) where it gives them; the rest are
our documented choices, marked "(ours)".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from companion.domain.physics import STANDARD_GRAVITY_M_S2
from companion.mission.schema import build


def _positive(obj: Any, *names: str) -> None:
    for name in names:
        if not getattr(obj, name) > 0:
            raise ValueError(f"{name}: must be > 0, got {getattr(obj, name)!r}")


def _non_negative(obj: Any, *names: str) -> None:
    for name in names:
        if getattr(obj, name) < 0:
            raise ValueError(f"{name}: must be >= 0, got {getattr(obj, name)!r}")


@dataclass(frozen=True)
class VehicleConfig:
    """Rigid-body quadrotor (eq. 6-8) and its integration rates."""

    mass_kg: float = 5.0  # paper
    inertia_kg_m2: tuple[float, float, float] = (0.02, 0.02, 0.04)  # paper, diagonal (FRD axes)
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2  # (the estimator uses the same)
    drag_n_s_m: float = 0.25  # (ours) linear air drag, force = -drag * v
    max_thrust_n: float = 98.1  # (ours) thrust-to-weight 2
    max_torque_nm: float = 2.0  # (ours) per axis
    radius_m: float = 0.3  # (ours) collision radius around the centre, horizontal
    physics_rate_hz: int = 200  # paper: IMU and integration rate
    control_rate_hz: int = 20  # paper: control and GNSS rate

    def validate(self) -> None:
        _positive(self, "mass_kg", "gravity_m_s2", "max_thrust_n", "max_torque_nm", "radius_m")
        _positive(self, "physics_rate_hz", "control_rate_hz")
        _non_negative(self, "drag_n_s_m")
        if min(self.inertia_kg_m2) <= 0:
            raise ValueError(f"inertia_kg_m2: every entry must be > 0, got {list(self.inertia_kg_m2)}")
        if self.physics_rate_hz % self.control_rate_hz or 1_000_000 % self.physics_rate_hz:
            raise ValueError("physics_rate_hz must be a multiple of control_rate_hz and divide 1e6 µs")
        if self.max_thrust_n <= self.mass_kg * self.gravity_m_s2:
            raise ValueError("max_thrust_n: must exceed the weight mass_kg * gravity_m_s2")

    @property
    def physics_dt_us(self) -> int:
        return 1_000_000 // self.physics_rate_hz

    @property
    def steps_per_control(self) -> int:
        return self.physics_rate_hz // self.control_rate_hz


@dataclass(frozen=True)
class AutopilotConfig:
    """Cascaded controller (eq. 9-11). All gains (ours): outer loop ~1.5 rad/s, inner ~15 rad/s."""

    kp_xy_1_s2: float = 2.25  # outer P, horizontal
    kd_xy_1_s: float = 2.7  # outer D, horizontal
    ki_xy_1_s3: float = 0.3  # outer I, horizontal
    kp_z_1_s2: float = 4.0  # outer P, vertical
    kd_z_1_s: float = 4.0  # outer D, vertical
    ki_z_1_s3: float = 0.5  # outer I, vertical
    eps_int_m: float = 1.0  # integral active only while ||p_ref - p_hat|| < eps_int (anti-windup)
    max_integral_m_s2: float = 1.5  # |K_i * integral| clamp per axis
    max_accel_m_s2: float = 6.0  # commanded acceleration clamp per axis
    max_tilt_deg: float = 25.0  # roll and pitch command limit
    k_att_nm_rad: float = 4.5  # inner P on roll/pitch: I_xx * (15 rad/s)^2
    d_att_nm_s_rad: float = 0.48  # inner rate damping on roll/pitch: 2 * 0.8 * 15 * I_xx
    k_yaw_nm_rad: float = 1.0  # yaw hold P: I_zz * (5 rad/s)^2
    d_yaw_nm_s_rad: float = 0.32  # yaw rate damping
    stale_estimate_s: float = 0.5  # older estimates are ignored: the autopilot holds on its own
    hold_brake_speed_m_s: float = 0.5  # holding: brake to below this speed, then hold the point reached

    def validate(self) -> None:
        _positive(self, "eps_int_m", "max_accel_m_s2", "stale_estimate_s", "k_att_nm_rad", "k_yaw_nm_rad",
                  "hold_brake_speed_m_s")
        _non_negative(self, "kp_xy_1_s2", "kd_xy_1_s", "ki_xy_1_s3", "kp_z_1_s2", "kd_z_1_s", "ki_z_1_s3")
        _non_negative(self, "max_integral_m_s2", "d_att_nm_s_rad", "d_yaw_nm_s_rad")
        if not 0 < self.max_tilt_deg < 80:
            raise ValueError(f"max_tilt_deg: must be in (0, 80), got {self.max_tilt_deg!r}")

    @property
    def max_tilt_rad(self) -> float:
        return math.radians(self.max_tilt_deg)


@dataclass(frozen=True)
class ImuConfig:
    """Accelerometer and gyro errors, sampled at the physics rate (per axis, body FRD).

    ``measured = (1 + scale) * true + bias + white``: white noise of std
    ``sqrt(sigma² + density² * rate / 2)`` per sample (``sigma_*``: vibration and other white
    noise; ``*_noise_density_*``: the sensor's own noise density over the Nyquist band), a bias
    drawn once at turn-on and then a random walk, and a per-axis scale-factor error drawn once.
    Defaults (white noise only) are the paper's IMU; ``companion.mission.scenarios`` holds a named MEMS part.
    """

    sigma_acc_m_s2: float = 0.08  # paper
    sigma_gyro_rad_s: float = 0.003  # (ours)
    acc_noise_density_m_s2_rt_hz: float = 0.0  # sensor noise density (datasheet)
    gyro_noise_density_rad_s_rt_hz: float = 0.0
    acc_bias_turn_on_m_s2: float = 0.0  # 1-σ of the turn-on bias per axis
    gyro_bias_turn_on_rad_s: float = 0.0
    acc_bias_walk_m_s2_rt_s: float = 0.0  # bias random walk: std grows as this × √t
    gyro_bias_walk_rad_s_rt_s: float = 0.0
    acc_scale_factor: float = 0.0  # 1-σ of the per-axis scale-factor error (fraction)
    gyro_scale_factor: float = 0.0
    # the barometer sent with each IMU sample (simvehicle.baro; HIGHRES_IMU's pressure fields): a MEMS sensor
    # (MS5611, BMP388: 0.1-0.2 m white at its rate), a thermal drift (its rate drawn once per flight; ≲ a few
    # cm/s), a random walk (weather, airflow) and the day's datum against the standard atmosphere (drawn once)
    baro: bool = True
    baro_sigma_m: float = 0.15
    baro_drift_m_s: float = 0.01
    baro_walk_m_rt_s: float = 0.02
    baro_datum_sigma_m: float = 30.0

    def validate(self) -> None:
        _non_negative(self, "sigma_acc_m_s2", "sigma_gyro_rad_s", "acc_noise_density_m_s2_rt_hz",
                      "gyro_noise_density_rad_s_rt_hz", "acc_bias_turn_on_m_s2", "gyro_bias_turn_on_rad_s",
                      "acc_bias_walk_m_s2_rt_s", "gyro_bias_walk_rad_s_rt_s", "baro_sigma_m",
                      "baro_drift_m_s", "baro_walk_m_rt_s", "baro_datum_sigma_m")
        for name in ("acc_scale_factor", "gyro_scale_factor"):
            if not 0.0 <= getattr(self, name) < 0.1:
                raise ValueError(f"{name}: must be in [0, 0.1), got {getattr(self, name)!r}")

    @property
    def ideal(self) -> bool:
        """White noise only (the paper's IMU): no extra random draws, the paper's stream."""
        return not any((self.acc_noise_density_m_s2_rt_hz, self.gyro_noise_density_rad_s_rt_hz,
                        self.acc_bias_turn_on_m_s2, self.gyro_bias_turn_on_rad_s,
                        self.acc_bias_walk_m_s2_rt_s, self.gyro_bias_walk_rad_s_rt_s,
                        self.acc_scale_factor, self.gyro_scale_factor))


@dataclass(frozen=True)
class AhrsConfig:
    """The attitude the vehicle sends: the truth (``enabled: false``, the paper) or the estimate of
    an onboard complementary filter (Mahony) on the simulated IMU plus a heading reference
    (``simvehicle.ahrs``). All values (ours) unless marked: roll/pitch time constant ``1 / kp_rp`` = 10 s,
    the autopilot-style trade between gyro drift and accelerations leaking into the gravity reference;
    ``gnss_velocity_reference`` takes the accelerations out with the receiver's velocity, as real
    autopilots do (ArduPilot's DCM; its EKFs and PX4's fuse the GNSS velocity)."""

    enabled: bool = False
    kp_rp_1_s: float = 0.1  # roll/pitch correction gain toward the accelerometer's gravity direction
    ki_rp_1_s2: float = 0.002  # gyro-bias integral gain (roll/pitch axes)
    kp_yaw_1_s: float = 0.2  # yaw correction gain toward the heading reference
    ki_yaw_1_s2: float = 0.004  # gyro-bias integral gain from the heading reference
    heading_noise_rad: float = 0.035  # heading reference (magnetometer) white noise, 2° per sample
    heading_bias_rad: float = 0.035  # heading reference bias, 1-σ, drawn once (declination/soft iron)
    heading_rate_hz: float = 50.0  # heading reference rate
    initial_tilt_error_rad: float = 0.02  # 1-σ per axis of the attitude error at boot
    # GNSS-aided gravity reference (ArduPilot DCM's drift correction): between two usable fixes the
    # accelerometer's specific force, rotated to NED and integrated, is compared with the one the
    # fixes' velocity change implies (Δv/Δt − g), not with gravity alone; without a usable fix for
    # ``gnss_timeout_s`` the accelerometer alone, as above
    gnss_velocity_reference: bool = False  # false: the plain complementary filter (accelerations leak in)
    kp_rp_gnss_1_s: float = 0.2  # roll/pitch gain while GNSS-aided (ArduPilot AHRS_RP_P default)
    gnss_min_satellites: int = 6  # a fix below this is not used (ArduPilot AHRS_GPS_MINSATS default)
    gnss_delay_s: float = 0.1  # receiver lag the autopilot assumes: a fix is taken as valid at arrival − this
    gnss_timeout_s: float = 1.0  # (ours) no usable fix for this long: back to the accelerometer alone

    def validate(self) -> None:
        _positive(self, "kp_rp_1_s", "kp_yaw_1_s", "heading_rate_hz", "kp_rp_gnss_1_s", "gnss_timeout_s")
        _non_negative(self, "ki_rp_1_s2", "ki_yaw_1_s2", "heading_noise_rad", "heading_bias_rad",
                      "initial_tilt_error_rad", "gnss_min_satellites", "gnss_delay_s")


@dataclass(frozen=True)
class GnssConfig:
    """GNSS degradation (eq. 22-27), one fix per control period.

    Proximity weight (ours): ``w(d) = clip((d_near - d) / ramp, 0, 1)`` with ``d`` the exact
    distance to the nearest building; the paper's piecewise forms (eq. 25-26 and L̄) are the
    limit ``ramp -> 0``. Each canyon/open pair below is blended with ``w``: bias correlation
    time Γ(d) (eq. 24-25), stationary bias std σ_ss(d) (eq. 23 excitation
    ``σ_ss sqrt(1 - κ²)``, eq. 26), noise variance factor ``m = 1 + (r_urban - 1) w`` and
    mean latency L̄(d) (eq. 27).
    """

    sigma_noise_m: float = 0.08  # paper, nominal white noise per axis
    r_urban: float = 1.5625  # paper-derived: variance factor, 0.08 m -> 0.10 m under multipath
    d_near_m: float = 15.0  # (ours) clearance below which degradation starts
    proximity_ramp_m: float = 10.0  # (ours) full degradation at d <= d_near - ramp
    gamma_open_s: float = 0.3  # (ours) bias correlation time in open sky
    gamma_canyon_s: float = 3.0  # paper: multipath time constant
    sigma_bias_open_m: float = 0.05  # (ours) stationary bias std in open sky
    sigma_bias_max_m: float = 1.2  # paper: maximum bias std
    latency_open_s: float = 0.1  # (ours) mean latency in open sky
    latency_canyon_s: float = 0.6  # (ours) mean latency in a canyon
    latency_tau_s: float = 2.5  # paper: latency correlation time, ζ = exp(-Δt/τ)
    latency_noise_s: float = 0.03  # paper: latency process noise std per fix
    latency_cap_s: float = 1.2  # paper: latency is clipped to [0, cap]
    satellites_open: int = 16  # (ours) satellites_visible in open sky
    satellites_canyon: int = 7  # (ours) satellites_visible in a canyon
    report_accuracy: bool = True  # (ours) h_acc/v_acc carry the white-noise std (not the bias)
    # --- the receiver's Doppler velocity
    # Off in the paper's scenario (its receiver gives positions only). A reflection corrupts the carrier's
    # Doppler far less than the code's range: its error is the rate of change of the extra path, a fraction of
    # the receiver's own speed (zero at rest), not a metre-size offset. Per axis: white noise sqrt(σ_v² + (w κ
    # |v|)²) with the proximity weight w, σ_v = sigma_velocity_m_s (u-blox M8/M9 speed accuracy in open sky)
    # and κ = velocity_reflection_factor (ours: a canyon's reflections shift the Doppler velocity by ~10 % of
    # the speed). The reported speed accuracy is that std (with report_accuracy). Drawn from its own stream,
    # so the positions are those of the receiver without velocity.
    velocity: bool = False
    sigma_velocity_m_s: float = 0.05
    velocity_reflection_factor: float = 0.1
    # --- effects the estimator does not model (simvehicle.nlos; all off = the paper's GNSS)
    # A fixed constellation; a satellite whose line of sight a building blocks is tracked by its
    # reflection (NLOS, a pseudorange delay drawn when it goes behind the building, so the fix
    # steps) with probability nlos_reflect_prob, else lost. Noise then scales with the satellites
    # used: σ · sqrt(satellites_open / n) (fewer satellites, worse geometry).
    nlos: bool = False
    constellation_size: int = 16  # (ours) satellites above the mask in open sky
    elevation_min_deg: float = 15.0  # (ours) elevation mask
    nlos_reflect_prob: float = 0.5  # (ours) a blocked satellite is tracked by reflection with this prob.
    nlos_delay_mean_m: float = 1.0  # (ours) mean extra path of a reflection (exponential), metres
    satellite_noise: bool = False  # noise std × sqrt(constellation_size / satellites used)
    heavy_tail_dof: float = 0.0  # > 0: white noise is Student-t with this many dof (same std); 0 = Gaussian

    def validate(self) -> None:
        _positive(self, "sigma_noise_m", "d_near_m", "proximity_ramp_m", "gamma_open_s", "gamma_canyon_s")
        _positive(self, "latency_tau_s", "latency_cap_s")
        _non_negative(self, "sigma_bias_open_m", "sigma_bias_max_m", "latency_open_s", "latency_canyon_s")
        _non_negative(self, "latency_noise_s", "satellites_open", "satellites_canyon")
        if self.r_urban < 1:
            raise ValueError(f"r_urban: must be >= 1, got {self.r_urban!r}")
        if max(self.latency_open_s, self.latency_canyon_s) > self.latency_cap_s:
            raise ValueError("latency_open_s/latency_canyon_s: must not exceed latency_cap_s")
        if not 4 <= self.constellation_size <= 64:
            raise ValueError(f"constellation_size: must be in [4, 64], got {self.constellation_size!r}")
        if not 0.0 <= self.elevation_min_deg < 80.0:
            raise ValueError(f"elevation_min_deg: must be in [0, 80), got {self.elevation_min_deg!r}")
        if not 0.0 <= self.nlos_reflect_prob <= 1.0:
            raise ValueError(f"nlos_reflect_prob: must be in [0, 1], got {self.nlos_reflect_prob!r}")
        _non_negative(self, "nlos_delay_mean_m", "sigma_velocity_m_s", "velocity_reflection_factor")
        if self.heavy_tail_dof != 0.0 and not self.heavy_tail_dof > 2.0:
            raise ValueError(f"heavy_tail_dof: must be 0 (Gaussian) or > 2 (finite variance), "
                             f"got {self.heavy_tail_dof!r}")

    @property
    def unmodelled(self) -> bool:
        """Any effect beyond eq. 22-27 switched on (needs the extra random stream)."""
        return self.nlos or self.satellite_noise or self.heavy_tail_dof > 0.0


RECEIVER_SYSTEMS = ("GPS", "GLONASS", "GALILEO", "BEIDOU")


@dataclass(frozen=True)
class ReceiverConfig:
    """A raw GNSS receiver flown through the 3-D city (``simvehicle.receiver``): per-satellite line of
    sight, diffraction and facade reflections, tracking, clock; its single-point fix replaces the
    eq. 22-27 fixes when ``enabled``. Physics and receiver values from the literature, "(cal)" the
    few adjusted on the tuning mission against the smartLoc Berlin drive (docs/simcal.md).
    """

    enabled: bool = False
    systems: tuple[str, ...] = ("GPS", "GLONASS")  # of RECEIVER_SYSTEMS (smartLoc's receiver: GPS + GLONASS)
    rate_hz: float = 5.0  # measurement epochs (u-blox M8T raw data: up to 10 Hz)
    start_utc: str = "2024-03-20T08:00:00"  # GPS time of boot = this UTC date ...
    start_spread_s: float = 86400.0  # ... plus a time drawn from the seed in [0, spread): each seed its sky
    latency_s: float = 0.08  # measurement epoch -> output (u-blox NAV-PVT ~ 50-100 ms)
    elevation_mask_deg: float = 0.0  # satellites tracked above this (the fix applies its own 5° mask)
    # C/N0 of an unobstructed signal: zenith value less the antenna's gain roll-off (1 − sin el)² × rolloff
    cn0_zenith_dbhz: float = 50.0  # GPS L1 C/A (Galileo, BeiDou alike); patch antenna, u-blox class receiver
    cn0_glonass_offset_db: float = -4.0  # (cal) GLONASS G1 arrives weaker on such antennas
    antenna_rolloff_db: float = 14.0  # gain at the horizon below the zenith's
    cn0_noise_db: float = 1.0  # white noise of the C/N0 estimate per epoch
    cn0_threshold_dbhz: float = 12.0  # a tracked signal is lost below this (u-blox M8: ~10 dB-Hz) ...
    cn0_acquire_dbhz: float = 26.0  # (cal) ... and (re)acquired only above this (18 with the C/N0 realism)
    # reflections off facades (simvehicle.receiver.reflection_amplitude): Fresnel coefficients of a dielectric
    # (or a conductor) at the incidence angle, split into the co- (RHCP) and cross-polarised (LHCP) parts the
    # antenna receives, the LHCP part rejected by the antenna's cross-polar discrimination (XPD, ∝ sin el),
    # less an absorption/roughness loss; per facade, drawn once per flight: conductor or dielectric, loss
    facade_permittivity: float = 5.0  # relative permittivity of a dielectric facade (concrete ~5, glass ~6)
    metal_facade_fraction: float = 0.5  # (cal) facades reflecting as conductors (metallised glass, cladding)
    facade_absorption_db: float = 2.0  # roughness/absorption loss of a facade, mean ...
    facade_absorption_sd_db: float = 1.0  # ... and spread between facades
    antenna_xpd_db: float = 10.0  # (cal) the antenna's LHCP rejection at the zenith (patch antennas 10-20 dB)
    diffraction: bool = True  # roof-edge (knife-edge) diffraction of blocked and grazing signals
    # a blocked satellite without a mapped reflection: tracked, with this probability per blocked episode,
    # through reflectors the map lacks (detail, other buildings, vehicles): an extra path drawn once per
    # episode (exponential) and a loss
    unmapped_prob: float = 0.9  # (cal)
    unmapped_delay_mean_m: float = 40.0  # (cal)
    unmapped_loss_db: float = 6.0  # besides the antenna's XPD (a reflection, of whatever kind)
    # an unmapped reflection's further loss 20 log10(δ / ref) dB for an extra path δ beyond ref: the spreading
    # of a diffuse scatterer's power (∝ 1/distance², the distance ∝ the extra path); 0: off
    unmapped_spreading_ref_m: float = 0.0  # (cal) 40 m with the C/N0 realism (docs/simcal.md)
    # diffuse multipath (Rician fading) on every tracked signal: a complex Gaussian component of mean power
    # 1/K of the signal's, Gauss-Markov in time, arriving late; in C/N0 and the DLL like the second path
    diffuse_fading: bool = False  # off: the calibration of docs/simcal.md's first table
    diffuse_k_los_db: float = 10.0  # Rice factor K of a direct signal (land-mobile-satellite, unshadowed)
    diffuse_k_nlos_db: float = 3.0  # K of a reflection (itself scattered: nearer Rayleigh, K = 0)
    diffuse_delay_mean_m: float = 15.0  # its delay, exponential, per satellite and flight (nearby scatterers)
    diffuse_time_s: float = 1.0  # its correlation time, as the receiver's ~1 s C/N0 and code loops see it
    # code tracking: early-minus-late DLL (Betz and Kolodziej 2009 noise; triangle correlation multipath)
    correlator_spacing_chips: float = 0.2
    dll_bandwidth_hz: float = 0.5  # carrier-aided (u-blox class)
    integration_s: float = 0.02
    doppler_sigma_m_s: float = 0.05  # pseudorange-rate noise at 45 dB-Hz, ∝ 10^((45 − C/N0)/20)
    # errors every receiver shares: broadcast orbit/clock (SISRE), the ionosphere Klobuchar leaves
    sisre_m: float = 0.6  # GPS, Galileo, BeiDou (per satellite and flight)
    sisre_glonass_m: float = 1.5
    iono_error_fraction: float = 0.3  # true delay = Klobuchar × (1 + f · N(0, 1)), per satellite and flight
    glonass_ifb_sd_m: float = 1.0  # GLONASS inter-frequency bias per channel
    # receiver clock (TCXO): initial drift, Allan-variance coefficients; the offset kept within ±0.5 ms by
    # 1 ms resets (u-blox's unsteered clock)
    clock_drift0_s_s: float = 1e-7
    clock_h0: float = 2e-19
    clock_h_2: float = 2e-20
    # the receiver's own fix (companion.gnss.solve_position)
    weighting: str = "cn0-elevation"
    raim: bool = False

    def validate(self) -> None:
        _positive(self, "rate_hz", "cn0_zenith_dbhz", "correlator_spacing_chips", "dll_bandwidth_hz",
                  "integration_s", "unmapped_delay_mean_m", "diffuse_delay_mean_m", "diffuse_time_s")
        _non_negative(self, "start_spread_s", "latency_s", "antenna_rolloff_db", "cn0_noise_db",
                      "facade_absorption_db", "facade_absorption_sd_db", "antenna_xpd_db", "unmapped_loss_db",
                      "unmapped_spreading_ref_m",
                      "doppler_sigma_m_s", "sisre_m", "sisre_glonass_m", "iono_error_fraction",
                      "glonass_ifb_sd_m", "clock_drift0_s_s", "clock_h0", "clock_h_2")
        bad = [s for s in self.systems if s not in RECEIVER_SYSTEMS]
        if bad or not self.systems:
            raise ValueError(f"systems: each one of {', '.join(RECEIVER_SYSTEMS)}, got {list(self.systems)}")
        for name in ("unmapped_prob", "metal_facade_fraction"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name}: must be in [0, 1], got {getattr(self, name)!r}")
        if not self.facade_permittivity > 1.0:
            raise ValueError(f"facade_permittivity: must be > 1, got {self.facade_permittivity!r}")
        if not 0.0 < self.correlator_spacing_chips <= 1.0:
            raise ValueError(f"correlator_spacing_chips: must be in (0, 1], "
                             f"got {self.correlator_spacing_chips!r}")
        if not 0.0 <= self.elevation_mask_deg < 90.0:
            raise ValueError(f"elevation_mask_deg: must be in [0, 90), got {self.elevation_mask_deg!r}")
        from companion.gnss.spp import SppConfig  # the solver's own check of the weighting

        SppConfig(weighting=self.weighting)
        parse_utc(self.start_utc)


def parse_utc(text: str) -> tuple[int, int, int, int, int, float]:
    """``YYYY-MM-DDTHH:MM:SS`` -> calendar fields (a ValueError naming the format otherwise)."""
    try:
        date, _, clock = text.partition("T")
        y, mo, d = (int(v) for v in date.split("-"))
        hh, mi, ss = clock.split(":")
        fields = (y, mo, d, int(hh), int(mi), float(ss))
    except ValueError:
        raise ValueError(f"start_utc {text!r}: expected YYYY-MM-DDTHH:MM:SS") from None
    if not (1980 <= y <= 2200 and 1 <= mo <= 12 and 1 <= d <= 31 and 0 <= fields[3] < 24
            and 0 <= fields[4] < 60 and 0 <= fields[5] < 60):
        raise ValueError(f"start_utc {text!r}: out of range")
    return fields


@dataclass(frozen=True)
class SimConfig:
    """Everything the simulated vehicle needs, one section per part."""

    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    autopilot: AutopilotConfig = field(default_factory=AutopilotConfig)
    imu: ImuConfig = field(default_factory=ImuConfig)
    gnss: GnssConfig = field(default_factory=GnssConfig)
    ahrs: AhrsConfig = field(default_factory=AhrsConfig)
    receiver: ReceiverConfig = field(default_factory=ReceiverConfig)


SECTIONS = ("vehicle", "autopilot", "imu", "gnss", "ahrs", "receiver")
_SECTION_TYPES: dict[str, type] = {
    "vehicle": VehicleConfig, "autopilot": AutopilotConfig, "imu": ImuConfig, "gnss": GnssConfig,
    "ahrs": AhrsConfig, "receiver": ReceiverConfig,
}


def sim_config_for(mission: Any) -> SimConfig:
    """The SimConfig of a mission: each part built from ``mission.settings(name)`` (its sensor
    scenario's fields, ``companion.mission.scenarios``, under the mission's own section)."""
    where = str(getattr(mission, "source", None) or getattr(mission, "name", "mission"))
    return SimConfig(**{name: build(_SECTION_TYPES[name], mission.settings(name), f"{where}: {name}")
                        for name in SECTIONS})
