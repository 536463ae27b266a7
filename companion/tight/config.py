"""Parameters of the tightly coupled filter: one frozen dataclass, every field with its unit.

Two motion models share every other parameter (``motion``):

* ``"imu"``: an IMU (specific force + the autopilot's attitude) drives position and velocity, with
  the loose filter's accelerometer bias (body axes) and NED acceleration error states; the white
  acceleration density is the IMU's input error (the loose filter's value);
* ``"constant-velocity"``: no inertial data (smartLoc, a receiver alone): a white-acceleration
  model whose density is the vehicle's own manoeuvring (a car in town: ~1 m/s² over a few seconds
  horizontally, almost none vertically); the IMU error states stay at zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from companion.estimator.consistency import check_accuracy_window

MOTIONS = ("imu", "constant-velocity")
SHADOW_MAX_CANDIDATES = 10_000  # shadow matching's grid an epoch (default 625), one line-of-sight call


@dataclass(frozen=True)
class TightConfig:
    motion: Literal["imu", "constant-velocity"] = "imu"  # what drives the prediction (module doc)
    # --- process model
    # White acceleration density (m/s² per √Hz: Q_vv = σ² T). "imu": the loose filter's 0.3 (attitude
    # error × g and vibration). "constant-velocity": the vehicle's manoeuvres (see
    # ``for_ground_vehicle``).
    sigma_acc_m_s2: float = 0.3
    sigma_acc_vertical_m_s2: float = 0.3
    sigma_acc_bias0_m_s2: float = 0.2  # body accelerometer bias prior (EKF2-like), "imu" only
    sigma_acc_bias_rw_m_s2_sqrt_s: float = 3e-3
    sigma_acc_ned0_m_s2: float = 0.2  # NED acceleration error (attitude error × g) prior, "imu" only
    sigma_acc_ned_rw_m_s2_sqrt_s: float = 0.01
    # Receiver clock: a common phase random walk (white frequency noise, m²/s) shared by every
    # system's clock, each system's offset a slow random walk of its own (inter-system bias, m²/s),
    # and a common drift random walk (m²/s³). A TCXO: h0 ≈ 2e-19 s → c² h0 / 2 ≈ 0.01 m²/s; drift
    # noise c² 2π² h₋₂ ≈ 0.04 m²/s³; we keep an order of magnitude more for thermal steps.
    q_clock_m2_s: float = 0.1
    q_isb_m2_s: float = 1e-3
    q_drift_m2_s3: float = 0.5
    sigma_clock0_m: float = 100.0  # a system's clock when first seen: from its own residuals ± this
    sigma_drift0_m_s: float = 100.0  # drift at start (a receiver's clock can drift 300 m/s = 1 ppm)
    sigma_velocity0_m_s: float = 5.0  # velocity at start (from the Doppler solution when there is one)
    # Its vertical part on its own: a quadrotor climbs at metres a second, a car on a town's roads
    # (grades of a few per cent) at tenths of one (``for_ground_vehicle``: 0.2). Without Doppler a
    # 5 m/s vertical prior is what the first epochs' noise moves, and the height drifts after a restart.
    sigma_velocity0_vertical_m_s: float = 5.0
    # --- measurements
    # A-priori σ model of a pseudorange (the single-point solution's: ``companion.gnss.spp``):
    # "cn0-elevation" σ² = a² + b² 10^((45 − C/N0)/10) / sin² el, GLONASS × 1.5; "uniform"; "given".
    sigma_uniform_m: float = 5.0
    sigma_floor_m: float = 0.5
    sigma_zenith_m: float = 3.0
    cn0_ref_dbhz: float = 45.0
    glonass_sigma_factor: float = 1.5
    # The receiver's C/N0 calibration (companion.tight.cn0cal): every C/N0 is read relative to the receiver's
    # own running distribution, minus (its cn0_calibration_quantile − cn0_calibration_ref_dbhz) · n / (n +
    # cn0_calibration_prior_obs) after n signals, so that the absolute constants here (cn0_ref_dbhz,
    # prior_cn0_mid_dbhz) hold for a receiver that reports C/N0 several dB higher or lower. Quantile and
    # reference from the simulator's tuning flights (mission default-tuning, profiles 0-3 × seeds 1000-1001):
    # of the quantiles 0.9 / 0.95 / 0.98 / 0.99 the per-flight level varies by sd 1.5 / 0.95 / 0.46 / 0.40 dB
    # (the environment's share); 0.98 (2 % of signals, less at the mercy of a few outliers than 1 %), its
    # pooled level there 50.2 dB-Hz. NaN: off (absolute C/N0). The prior's weight in signals (the offset
    # shrunk by n / (n + this) while few are seen), on the same flights with every C/N0 offset by -10 / -6 /
    # 0 / +6 dB,
    # mean per-flight median / p95 of tight-second-order (m): off 15.2/56.8, 12.3/46.6, 9.3/35.1, 9.0/28.4;
    # 0: 9.1/34.4 at every offset; 50: 9.1-9.2/34.4-34.6; 200: 9.1-9.3/34.4-34.9; 1000: 8.9-9.8/33.5-37.1
    cn0_calibration_quantile: float = 0.98
    cn0_calibration_ref_dbhz: float = 50.2
    cn0_calibration_prior_obs: float = 0.0
    # σ of a line-of-sight pseudorange at cn0_ref (grows as 1/√(C/N0)): the belief rows' nominal R when
    # belief_sigma_model is "los"
    sigma_los_cn0_m: float = 3.0
    sigma_range_rate_m_s: float = 0.5  # Doppler σ of an ideal observation (same shape as the pseudorange σ)
    elevation_mask_deg: float = 5.0
    # Innovation gate (standard deviations) per satellite: 5 is EKF2/EKF3's GNSS gate.
    gate_sigma: float = 5.0
    # No satellite passed for this long: re-start from a single-point solution (EKF2_NOAID_TOUT).
    reset_timeout_s: float = 5.0
    # A system whose satellites all disagree with its predicted clock by more than this (m) has
    # stepped (a receiver clock jump of milliseconds): its clock is re-initialised, not the position.
    clock_jump_m: float = 1000.0
    # --- barometer (TightNavigator: an ImuSample's pressure_alt_m; docs/tight.md "Barometer")
    # The height −p_D + b_baro, b_baro the pressure altitude's unknown datum (the standard atmosphere's AMSL
    # for PX4, the height over the ground calibration for ArduPilot): a state started at the first sample
    # from the filter's own height and vertical variance (a relative height), a random walk.
    # one sample: a MEMS baro (MS5611, BMP388) 0.1-0.2 m at rest, + the airframe's (propwash, airspeed)
    sigma_baro_m: float = 0.5
    # the datum's random walk: the sensor's thermal drift (≲ a few cm/s) and the weather (~1 hPa in 3 h) need
    # ~0.1 m/√s, but the filter averages the canyon's vertical GNSS errors as if white, over-confident
    # in its height; 0.5 (5 m in 100 s) keeps the reported vertical accuracy near what it was without a
    # barometer. Chosen on the canyon's tuning flights (default-tuning, profiles 0-3 × seeds 1000-1001,
    # second-order, against none: 0.1: horizontal median / p95 −0.61 / −0.28 m, vertical −5.3 / −27.3 m,
    # reported vertical 1 σ / 2 σ 35 / 75 % (60 / 97 % without); 0.5: −0.46 / −0.74, −4.3 / −16.1, 52 / 93 %)
    sigma_baro_drift_m_sqrt_s: float = 0.5
    # one sample fused per period (the first of each): at the IMU's rate the re-fusion after a late epoch
    # would cost more than it adds
    baro_period_s: float = 0.2
    baro_gate_sigma: float = 5.0  # the barometer's innovation gate (σ)
    # gated this long without a fused sample, the datum stepped: b_baro re-starts relative (counted
    # baro_datum_restarts). ArduPilot SITL's HIGHRES_IMU pressure_alt is 0 for its first ~35 s, then its
    # altitude (a 97 m step, measured): without this the barometer stayed gated for the flight.
    baro_restart_s: float = 5.0
    # The datum when it is known (m; NaN: unknown, the relative start above): the pressure altitude of the
    # frame's origin, so that b_baro starts there with σ baro_datum_sigma_m, uncorrelated, and the first
    # sample is fused.
    # ArduPilot zeroes its barometer on the ground at arming: with the frame at that home (a mission's) the
    # datum is 0 to the drift since (a few m at most); a pressure altitude on the standard atmosphere (PX4)
    # is home's AMSL altitude only to the day's weather (1 hPa ≈ 8 m): leave it NaN there.
    baro_datum_m: float = math.nan
    baro_datum_sigma_m: float = 2.0
    # --- odometry (ground vehicles): forward speed as a measurement of |v_horizontal|
    sigma_speed_m_s: float = 0.1  # wheel speed σ along the track (plus speed_sigma_fraction × speed)
    speed_sigma_fraction: float = 0.02  # + this × speed (wheel radius, slip)
    # heading from the odometry's yaw rate: the offset ψ₀ starts from the filter's velocity direction
    # after odometry_heading_start_s, once the filter moves at the odometry's speed (to 30 %) with a
    # velocity σ below 30 % of it, with σ odometry_heading0_rad (or more); it walks with the yaw rate's white
    # noise (rad/√s) and integrates minus the yaw rate's bias b_ω, a state: a car's yaw-rate sensor is
    # zeroed by the vehicle at standstill, leaving ≲ 0.1°/s (σ 0.002 rad/s at start; smartLoc Berlin's
    # drifts 0.06°/s), drifting slowly with temperature (1e-4 rad/s/√s)
    odometry_heading_start_s: float = 5.0
    odometry_heading0_rad: float = 0.3
    sigma_heading_rw_rad_sqrt_s: float = 5e-3
    sigma_yaw_rate_bias0_rad_s: float = 0.002
    sigma_yaw_rate_bias_rw_rad_s_sqrt_s: float = 1e-4
    sigma_lateral_m_s: float = 0.2  # side slip and the heading's own noise, across the track
    # --- per-satellite belief (the paper's second-order rule, per satellite; belief.py)
    r_inflation_max: float = 100.0  # R_s(β) = R_nom,s · this^(1 − β): ≤ 10× the σ at no trust
    theta_min: float = -4.0
    theta_max: float = 4.0
    # damped Newton learning rate per epoch of one satellite: a reflection starts abruptly, so the belief
    # must cross its range within ~1 s (5 epochs); 0.25 and 0.5 followed NLOS onsets too slowly
    eta: float = 1.0
    lambda_reg: float = 0.1
    alpha_fast: float = 0.5
    alpha_slow: float = 0.95
    omega_fast: float = 0.7
    # ν of the Student-t (1 dof) in the belief's loss and the student-t row: NLOS errors are a heavy
    # mixture (tens of metres on a third of the satellites in a deep canyon), so a heavy tail, ν = 2
    student_dof: float = 2.0
    # Prior on θ from C/N0 and elevation (and the map): ℓ += κ/2 (θ − θ_prior)², with
    # θ_prior = prior_cn0_per_db (C/N0 − prior_cn0_mid) + prior_el_per_deg (el − prior_el_mid): a
    # strong, high signal is expected in line of sight, a weak low one is not (NLOS loses dB).
    prior_weight: float = 0.1
    prior_cn0_per_db: float = 0.15
    prior_cn0_mid_dbhz: float = 35.0
    prior_el_per_deg: float = 0.05
    prior_el_mid_deg: float = 25.0
    # A map (``TightNavigator(line_of_sight=…)``): θ_prior += prior_map_nlos where it hides the satellite from
    # the predicted position, prior_map_los where it shows it, blended by the probability over the
    # position's uncertainty (belief.blocked_probability). Chosen on the canyon's tuning flights: trusting
    # the satellites the map shows helps; distrusting the hidden ones (in a canyon most of them, many
    # with small errors) costs, even with the map at the true position
    prior_map_nlos: float = 0.0
    prior_map_los: float = 2.0
    # the map is read around the predicted position over its horizontal σ widened by this (m per axis: a
    # canyon's filter is often more confident than right), candidate positions weighted by how well their
    # shadows explain the signals' C/N0 and elevation (map_shadow_matching; belief.blocked_probability)
    map_position_sigma_m: float = 10.0
    map_shadow_matching: bool = True
    # Shadow matching as a horizontal position measurement (companion.tight.shadow; any row with a
    # map; docs/tight.md "Shadow matching"): candidates on a grid around the predicted position along its
    # horizontal covariance's principal axes (σ widened by shadow_sigma_floor_m), shadow_spacing_m apart,
    # half-widths shadow_grid_sigmas σ clamped to [shadow_half_width_min_m, shadow_half_width_max_m], each
    # scored by how well the map's hidden/seen verdicts there explain the signals' C/N0 and elevation (the
    # belief's prior as P(line of sight); log-likelihood × shadow_tempering), under a flat prior. The
    # posterior's axes narrower than shadow_max_variance_ratio × the flat grid's are fused (the grid divided
    # out), their variance × shadow_variance_scale, at least shadow_sigma_min_m², gated at shadow_gate_sigma
    # against the prediction; "before": fused on the prediction, the satellites' innovations then taken
    # from it; "after": after the pseudoranges. Needs at least shadow_min_satellites satellites. Off.
    # Chosen on the canyon's tuning flights (default-tuning, profiles 0-3 × seeds 1000-1001, the map row's
    # mean per-flight median / p95 9.13 / 30.31 m): ratio 0.25, variance × 2 / × 1: 8.58 / 29.54, 8.47 /
    # 29.52; ratio 0.5, × 1: 8.18 / 29.58; ratio 0.7, × 1 / × 2: 8.21 / 30.08, 8.52 / 29.96; ratio 0.5 with
    # a 5 σ gate: 8.56 / 29.79; "after" as "before" to 0.1 m; the logit's a, b: a logistic fit of the
    # simulator's line-of-sight flags on θ_prior, 42,271 signals of profiles 0-3, seed 1000 (docs/tight.md)
    shadow_matching: bool = False
    shadow_stage: Literal["before", "after"] = "before"
    shadow_spacing_m: float = 2.0
    shadow_grid_sigmas: float = 3.0
    shadow_sigma_floor_m: float = 5.0
    shadow_half_width_min_m: float = 12.0
    shadow_half_width_max_m: float = 24.0
    shadow_tempering: float = 1.0
    # P(line of sight) = σ(shadow_logit_scale θ_prior + shadow_logit_offset): the belief's C/N0 + elevation
    # prior recalibrated as a probability (shadow.p_los; logistic fit on the tuning flights, see docs)
    shadow_logit_scale: float = 0.9
    shadow_logit_offset: float = -2.4
    shadow_max_variance_ratio: float = 0.5
    shadow_variance_scale: float = 1.0
    shadow_sigma_min_m: float = 1.0  # the fused rows' σ floor
    shadow_gate_sigma: float = 3.0  # χ² per row against the prediction
    shadow_min_satellites: int = 4  # fewer: no fix
    # What the belief's consistency is measured on: "prefit" (each satellite's innovation against the
    # prediction), "leave-one-out" (against the prediction corrected by the epoch's other satellites,
    # weighted by their beliefs: weighting.leave_one_out), "robust" (the same, the others weighted as
    # the student-t row weighs them; these two did not help on the canyon's tuning flights, docs/tight.md)
    # or "snapshot": against the solution of the epoch's OTHER satellites, robustly re-fitted about the
    # prediction (companion.tight.snapshot: hat-matrix leave-one-out residuals), meant to remove the
    # prediction's error and the clock's common mode, which every satellite shares. Off: on the canyon's
    # tuning flights it did not help (seeds 1000-1001 / 1002-1003, mean per-flight median / p95 against
    # prefit: these defaults −0.24 / −0.20 and +0.02 / +0.75 m; position and clocks free, σ 10 m: +1.2 /
    # +5.0 and +0.8 / +4.4 m): in a canyon where most satellites are reflected the epoch's own solution
    # absorbs the reflections (docs/tight.md)
    belief_innovation: Literal["prefit", "leave-one-out", "robust", "snapshot"] = "prefit"
    # "snapshot": the prediction's position is known to this on top of P (m per axis; inf: the epoch alone);
    # the clocks as predicted (their P) or free (re-solved from the epoch); Student-t reweighting passes of
    # the fit (early residuals scaled by belief_early_factor in the weights: NLOS only delays); the belief's
    # innovation ỹ = (1 − blend) y + blend ỹ_snapshot (1: the snapshot's alone)
    belief_snapshot_sigma_m: float = 1.0
    belief_snapshot_clocks_free: bool = False
    belief_snapshot_iterations: int = 2
    belief_snapshot_blend: float = 1.0
    # The belief's nominal variance R_nom: "los" (a line-of-sight signal's, C/N0 only: the belief and
    # its prior carry the rest) or "cn0-elevation" (the single-point solution's σ model, 1/sin² el too)
    belief_sigma_model: Literal["los", "cn0-elevation"] = "cn0-elevation"
    # R_nom = (this × that σ model's σ)²: the variance at full trust is a line-of-sight signal's, below the
    # single-point solution's σ model, which carries the average reflection's share at low C/N0 and
    # elevation (a reflected satellite looked consistent against it and kept its weight: docs/tight.md).
    # 0.5 (1.5 m at zenith and 45 dB-Hz) chosen on the canyon's tuning flights (1: 12.4 / 44.3 m, 0.7: 11.0 /
    # 36.2, 0.5: 10.0 / 30.3, 0.35: 9.0 / 26.9, 0.25: 9.2 / 24.3); smartLoc does not confirm below 0.5
    belief_sigma_scale: float = 0.5
    # Joint consistency: when the epoch's median y²/S is above χ²(1)'s median, the whole epoch disagrees with
    # the prediction (the state is off, not every satellite): each satellite's S is scaled by that ratio in
    # the belief's step, so a satellite is judged against the epoch, not against a pulled prediction
    belief_epoch_scale: bool = True
    # NLOS only delays a signal: a reflection's pseudorange is late, never early, and the common part of the
    # reflections' delays goes into the receiver clock, which makes the clean satellites look early. The
    # belief's consistency (its step and the joint consistency's median; not the gate, not the fused R)
    # sees an early innovation (y < 0) times this: 1 = symmetric. 0.5 chosen on the canyon's tuning flights
    # (R_nom the full σ model then; 1: 13.9 / 48.0 m, 0.71: 13.1 / 45.7, 0.5: 12.4 / 44.3, 0: 12.5 / 45.8;
    # docs/tight.md)
    belief_early_factor: float = 0.5
    # Student-t reweighting passes (as the student-t row's) on top of the beliefs' variances: 0 = none
    belief_student_iterations: int = 0
    # --- Student-t row: iteratively reweighted update
    student_iterations: int = 3  # reweighted updates per epoch
    # --- FDE row: χ² test of the epoch's normalised innovations, worst excluded while it fails
    fde_p_false_alarm: float = 1e-3  # the χ² test's false-alarm probability (RAIM/FDE's)
    fde_max_exclusions: int = 4
    # --- reported accuracy (NavEstimate.cov_diag, GPS_INPUT's horiz/vert_accuracy, the feeds' covariances):
    # the position covariance × max(1, NIS per degree of freedom of the used pseudoranges over the last
    # accuracy_window_s, exponentially weighted), the variance-of-unit-weight test a receiver applies to
    # its reported accuracy: where the measurement model is wrong (reflections the belief did not
    # catch) P alone is over-confident; per axis (N, E pooled; D) at least
    # min(P σ_w²/r + min(σ_s², P σ_s² c_s/r), σ²) from the epochs' own snapshot positions over the same
    # window (consistency.snapshot_parts: their scatter split into a white part σ_w² and a Gauss-Markov
    # part σ_s², c_s its correlation over the filter's memory, r a snapshot's variance as weighted, σ² one
    # snapshot's variance), for what the filter follows and its innovations do not show. A report only.
    # 0: report P as it is.
    accuracy_window_s: float = 20.0
    # The one-signed delays in the reported accuracy: a reflected signal only ever arrives late, so a street's
    # pseudorange errors have a mean that averages out over no window; what differs between the satellites
    # (larger at low elevation: the height) moves the position. Each axis's reported variance is at least
    # (this × b)², b the epoch's snapshot correction were every used satellite late by its own fused σ
    # (snapshot.delay_bias): the mean delay in units of that σ. 0.4 chosen on the canyon's tuning flights
    # (docs/tight.md "Reported accuracy"); 0: off. A report only; needs accuracy_window_s > 0.
    accuracy_delay_fraction: float = 0.4
    # A common-mode floor on the reported accuracy (m, a pseudorange σ; 0 = none): the position variances
    # reported get + accuracy_floor_m² × the used satellites' position DOPs (diag of (GᵀG)⁻¹, per N, E, D)
    # in quadrature: errors correlated over longer than the window (and those every satellite shares)
    # do not average out over epochs nor show in the innovations, so the error is at least that of one
    # epoch's snapshot solution with that σ (docs/tight.md "Reported accuracy"). Opt-in.
    accuracy_floor_m: float = 0.0
    # --- out-of-sequence
    history_s: float = 2.0  # epochs this late are still fused exactly
    future_tolerance_s: float = 0.05
    imu_hold_max_s: float = 0.1
    # The hold limit can follow the log's own IMU period: max(imu_hold_max_s, this × the period), as the
    # loose filter's field of this name (history.py, "The hold limit"). 0 (default): off, the fixed limit.
    imu_hold_periods: float = 0.0
    # A sample held over time it did not measure (an interval longer than 1.5 IMU periods: samples were
    # lost) adds process noise to position and velocity, as the loose filter's (the estimator's field of
    # this name; history.py, "Held time"): the held sample's white noise (sigma_acc_m_s2² horizontally,
    # sigma_acc_vertical_m_s2² vertically, per period) and the change of the acceleration meanwhile, a random
    # walk of this density (m/s² per √s: velocity variance σ² L³ / 3 over an interval of L s, a gap's coast
    # included; the coast adds the acceleration it drops besides; 1.0, the loose filter's value). 0: the
    # white part only.
    imu_hold_acc_rw_m_s2_sqrt_s: float = 1.0
    gravity_m_s2: float = 9.80665

    def validate(self) -> None:
        if self.motion not in MOTIONS:
            raise ValueError(f"motion {self.motion!r}: choose from {', '.join(MOTIONS)}")
        for name in ("sigma_acc_m_s2", "sigma_acc_vertical_m_s2", "q_clock_m2_s", "q_drift_m2_s3",
                     "sigma_clock0_m", "sigma_drift0_m_s", "sigma_velocity0_m_s",
                     "sigma_velocity0_vertical_m_s", "sigma_uniform_m",
                     "sigma_floor_m", "sigma_range_rate_m_s", "gate_sigma", "reset_timeout_s",
                     "clock_jump_m", "sigma_speed_m_s", "sigma_baro_m", "baro_gate_sigma", "eta",
                     "lambda_reg", "student_dof", "history_s", "imu_hold_max_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        check_accuracy_window(self.accuracy_window_s)
        for name in ("imu_hold_acc_rw_m_s2_sqrt_s", "imu_hold_periods", "sigma_baro_drift_m_sqrt_s",
                     "baro_period_s", "baro_datum_sigma_m", "baro_restart_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name}: must be a finite number >= 0, got {v!r}")
        datum = self.baro_datum_m
        if math.isinf(datum) or (math.isfinite(datum) and not self.baro_datum_sigma_m > 0.0):
            raise ValueError("baro_datum_m: finite (with baro_datum_sigma_m > 0) or NaN (unknown)")
        if not (math.isfinite(self.accuracy_delay_fraction) and self.accuracy_delay_fraction >= 0.0):
            raise ValueError(f"accuracy_delay_fraction: must be a finite number >= 0, "
                             f"got {self.accuracy_delay_fraction!r}")
        if not (math.isfinite(self.accuracy_floor_m) and self.accuracy_floor_m >= 0.0):
            raise ValueError(f"accuracy_floor_m: must be a finite number >= 0, got {self.accuracy_floor_m!r}")
        if not (0.0 < self.cn0_calibration_quantile < 1.0 and self.cn0_calibration_prior_obs >= 0.0
                and not math.isinf(self.cn0_calibration_ref_dbhz)):
            raise ValueError("cn0_calibration_quantile in (0, 1), cn0_calibration_prior_obs >= 0 and a "
                             "finite cn0_calibration_ref_dbhz (NaN: off) needed")
        if not self.r_inflation_max >= 1.0:
            raise ValueError("r_inflation_max: must be >= 1")
        if not self.theta_min < 0.0 < self.theta_max:
            raise ValueError("theta_min < 0 < theta_max needed")
        if not 0.0 < self.alpha_fast < self.alpha_slow < 1.0:
            raise ValueError("alpha_fast, alpha_slow: need 0 < alpha_fast < alpha_slow < 1")
        if not (math.isfinite(self.belief_sigma_scale) and self.belief_sigma_scale > 0.0):
            raise ValueError(f"belief_sigma_scale: must be a finite number > 0, "
                             f"got {self.belief_sigma_scale!r}")
        if not (math.isfinite(self.belief_early_factor) and 0.0 <= self.belief_early_factor <= 1.0):
            raise ValueError(f"belief_early_factor: must be in [0, 1], got {self.belief_early_factor!r}")
        if self.belief_sigma_model not in ("los", "cn0-elevation"):
            raise ValueError(f"belief_sigma_model {self.belief_sigma_model!r}: choose los or cn0-elevation")
        if self.belief_innovation not in ("prefit", "leave-one-out", "robust", "snapshot"):
            raise ValueError(f"belief_innovation {self.belief_innovation!r}: choose prefit, leave-one-out, "
                             "robust or snapshot")
        if not (self.belief_snapshot_sigma_m >= 0.0 and self.belief_snapshot_iterations >= 0
                and 0.0 <= self.belief_snapshot_blend <= 1.0):
            raise ValueError("belief_snapshot_sigma_m >= 0 (inf allowed), belief_snapshot_iterations >= 0, "
                             "0 <= belief_snapshot_blend <= 1 needed")
        if self.shadow_stage not in ("before", "after"):
            raise ValueError(f"shadow_stage {self.shadow_stage!r}: choose before or after")
        if not (math.isfinite(self.shadow_logit_scale) and math.isfinite(self.shadow_logit_offset)):
            raise ValueError("shadow_logit_scale, shadow_logit_offset: finite numbers needed")
        for name in ("shadow_spacing_m", "shadow_grid_sigmas", "shadow_half_width_min_m", "shadow_tempering",
                     "shadow_max_variance_ratio", "shadow_variance_scale", "shadow_sigma_min_m",
                     "shadow_gate_sigma"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        hw_min, hw_max = self.shadow_half_width_min_m, self.shadow_half_width_max_m
        if not (self.shadow_sigma_floor_m >= 0.0 and hw_max >= hw_min
                and math.isfinite(hw_max) and self.shadow_max_variance_ratio < 1.0
                and self.shadow_min_satellites >= 1):
            raise ValueError("shadow_sigma_floor_m >= 0, shadow_half_width_min_m <= shadow_half_width_max_m "
                             "(finite), shadow_max_variance_ratio < 1, shadow_min_satellites >= 1 needed")
        side = 2 * math.floor(hw_max / self.shadow_spacing_m) + 1
        if side * side > SHADOW_MAX_CANDIDATES:
            raise ValueError(f"shadow_half_width_max_m / shadow_spacing_m: {side * side} candidates an "
                             f"epoch, at most {SHADOW_MAX_CANDIDATES} (a wider spacing or a narrower grid)")
        if self.student_iterations < 1 or self.fde_max_exclusions < 0 or self.belief_student_iterations < 0:
            raise ValueError("student_iterations >= 1, fde_max_exclusions >= 0, "
                             "belief_student_iterations >= 0 needed")

    @classmethod
    def for_ground_vehicle(cls, **over: object) -> TightConfig:
        """GNSS alone on a car (smartLoc): constant velocity with 1 m/s²/√Hz horizontally (a car
        changes speed by ~2 m/s in 2 s in town) and 0.1 vertically (roads are smooth); its vertical
        velocity at a start within 0.2 m/s (a 2 % grade at 10 m/s)."""
        base: dict[str, object] = dict(motion="constant-velocity", sigma_acc_m_s2=1.0,
                                       sigma_acc_vertical_m_s2=0.1, sigma_velocity0_vertical_m_s=0.2,
                                       sigma_acc_bias0_m_s2=0.0,
                                       sigma_acc_bias_rw_m_s2_sqrt_s=0.0, sigma_acc_ned0_m_s2=0.0,
                                       sigma_acc_ned_rw_m_s2_sqrt_s=0.0)
        base.update(over)
        return cls(**base)  # type: ignore[arg-type]
