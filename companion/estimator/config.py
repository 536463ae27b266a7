"""The estimator's parameters: one frozen dataclass, every field with its unit.

Paper values (the paper's Section V.A) are marked "paper"; every other value is our choice and
says why. Mission YAML files override fields (``companion.wiring.mission_estimator_config``).

Trust model (the paper gives ``Q_b(β)`` but not ``R(β)``):

* bias process noise (eq. 13): ``Q_b(β) = (1 − α(Δt)²) σ_b(β)² I`` with
  ``σ_b(β) = sigma_bias_max_m · (1 − β) + sigma_bias_floor_m`` (the paper's ``1 − β + ε``
  scaled by the largest multipath bias std, so ``σ_b`` has its unit) and
  ``α(Δt) = exp(−Δt / bias_tau_s)``, so blocks of steps compose exactly;
* measurement covariance: ``R(β) = R_nom · r_inflation_max ** (1 − β)``. Monotone decreasing
  in β, ``R(1) = R_nom`` (full trust), ``R(0) = r_inflation_max · R_nom`` (bounded
  distrust). Log-linear, so equal steps of β scale the GNSS weight by equal factors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from companion.domain.physics import STANDARD_GRAVITY_M_S2
from companion.estimator.consistency import check_accuracy_window


@dataclass(frozen=True)
class EstimatorConfig:
    # --- process model (eq. 12-13)
    # White-acceleration density of the process model (m/s² per √Hz: Q_vv = σ² T). The paper's IMU
    # noise is 0.08 m/s² per 200 Hz sample (density 0.006); the filter's input error is dominated by
    # attitude error × g (1° ≈ 0.17 m/s²) and vibration, and 0.3 keeps the real quad106 log's NIS
    # consistent (β ≈ 0.98 in open sky; 0.08 gives β ≈ 0.75 there).
    sigma_acc_m_s2: float = 0.3
    bias_tau_s: float = 3.0  # paper Γ_mp: correlation time of the GNSS multipath bias state
    sigma_bias_max_m: float = 1.2  # paper: largest multipath bias std; σ_b(β=0) ≈ this
    sigma_bias_floor_m: float = 0.01  # ε of eq. 13: bias std kept at full trust (β = 1)
    # Accelerometer bias state a (body FRD axes, model.py): prior std at the first fix and random-
    # walk density. A MEMS accelerometer bias is tens of mg (0.1-0.3 m/s²). The density is PX4
    # EKF2's EKF2_ACC_B_NOISE default (3e-3 m/s³/√Hz); on the real quad106 log it gave the smallest
    # dead-reckoning error of 1e-3, 3e-3, 5e-3, 1e-2, 3e-2 (docs/estimator.md). 0 and 0 give the
    # paper's 9-state filter (a mission whose IMU has no bias can say so in its estimator: section).
    sigma_acc_bias0_m_s2: float = 0.2
    sigma_acc_bias_rw_m_s2_sqrt_s: float = 0.003
    # NED acceleration error state d (model.py): the autopilot's attitude error × g (1° of tilt is
    # 0.17 m/s² horizontal), fixed in NED, which a body-frame bias cannot follow through a yaw turn.
    # Prior std and random-walk density (the first wave's NED-bias values); kept for quad106's dead
    # reckoning (measured: docs/estimator.md, IMU error states).
    sigma_acc_ned0_m_s2: float = 0.2
    sigma_acc_ned_rw_m_s2_sqrt_s: float = 0.01
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2  # added on NED z: a_ned = R f_frd + [0, 0, g]

    # --- measurement model (eq. 14)
    sigma_gnss_horizontal_m: float = 0.08  # paper: nominal GNSS noise std, north and east
    sigma_gnss_vertical_m: float = 0.08  # paper gives one value; vertical kept equal
    r_inflation_max: float = 1.5625  # R(0) / R(1) = (0.10 / 0.08)²: paper noise under multipath / nominal
    # The bias range at the receiver's scale (0: off, the default): σ_b(β) and the bias's prior are multiplied
    # by max(1, this × the fix's nominal horizontal std / sigma_bias_max_m), so the largest bias std is at
    # least this many times the receiver's own 1σ (reported, or learned). The paper's 1.2 m is the bias of a
    # 0.08 m receiver; a single-point receiver stating 8 m has biases of 5-50 m. Measured (docs/estimator.md,
    # "The bias range at the receiver's scale"), 1 helps the belief methods on real IMU flights with a clean
    # Doppler velocity and hurts the flying filter on the calibrated canyon receiver: off by default.
    # Receivers of 1.2 m / this or better are unchanged either way.
    sigma_bias_max_per_gnss_std: float = 0.0

    # --- initial covariance (at the first good fix; position from the fix itself)
    sigma_velocity0_m_s: float = 1.0  # velocity is unknown at start-up
    sigma_bias0_m: float = 0.1  # initial multipath bias std

    # --- time handling and out-of-sequence fusion (Algorithm 1)
    history_s: float = 2.0  # fixes with validity older than (latest IMU − this) are rejected (≥ 1.5 s)
    future_tolerance_s: float = 0.05  # a fix valid up to this far ahead of the latest IMU waits for it
    # Longest an IMU sample is held: a longer interval is a gap (counted; the filter coasts at
    # constant velocity after this, with process noise: history.py, "Held time"). 10 periods at 200 Hz;
    # quad106's ~50 Hz IMU has 1 such gap. A slower IMU holds longer: imu_hold_periods.
    imu_hold_max_s: float = 0.05
    # The hold limit can follow the log's own IMU period: max(imu_hold_max_s, this × the period), the
    # period the median of the last 8 sample intervals (history.py, "The hold limit"). 0 (default): off,
    # the fixed limit. 2.5: an IMU at 10-20 Hz is integrated sample to sample, one lost sample (2
    # periods, ± half a period of jitter) is held, two or more are a gap; above 50 Hz the limit stays
    # imu_hold_max_s. Off by default: on a real flight's IMU at 10 Hz (path 5, 3 seeds) the fixed limit
    # was better with a receiver velocity for both kinds of slow IMU and without one for a point-sampled
    # IMU (1.65 against 1.97 m); 2.5 is better only for a mean-of-interval IMU without velocity.
    imu_hold_periods: float = 0.0
    # A sample held over time it did not measure (an interval longer than 1.5 IMU periods: samples were
    # lost) adds process noise (history.py, "Held time"): the held sample's white noise (σ_q² per period)
    # and the change of the acceleration meanwhile, a random walk of this density (m/s² per √s: velocity
    # variance σ² L³ / 3 over an interval of L s, a gap's coast included; the coast adds the acceleration
    # it drops besides). 1.0: the simulated quadrotor flying the tuning mission on its
    # estimate (python -m gcs_tools.evaluate.hold_probe: default-tuning, seeds 1000-1001, the true
    # acceleration held 40-45 ms, a lost datagram's hold, gives σ = 0.95-0.96 vertical, 0.26-0.33
    # horizontal: thrust changes most), rounded up. 0: the white part only.
    imu_hold_acc_rw_m_s2_sqrt_s: float = 1.0

    # --- belief adaptation (eq. 15-21)
    theta0: float = 0.0  # initial belief logit (β0 = 0.5: undecided)
    theta_max: float = 6.0  # θ ≤ this: β ≤ 0.9975, so the sigmoid never freezes at full trust
    # θ ≥ this: β ≥ 0.047. The θ-gradient carries β(1 − β), 0.0025 at θ = −6: a belief that low
    # takes minutes to come back (first-order stayed at 0.007 through 40 s of clean GNSS after
    # 60 s of 3 m multipath); at −3 the factor is 18× larger and it recovers in ~10 s (tested).
    # R(β) and σ_b(β) differ by < 5 % between the two floors.
    theta_min: float = -3.0
    # paper: learning rate of the damped Newton step (eq. 20). Where eta's value comes from, by layer:
    # this default (the paper's; replay of a foreign log), then a mission's estimator: section (the
    # packaged cities set 0.5, tuned on default-tuning for the simulated sensors), then a campaign
    # row's or --set override (``estimator.eta``; the ablation's rows-*.yaml). Later layers win.
    eta: float = 0.15
    lambda_reg: float = 0.1  # paper: Newton step regulariser λ_reg (eq. 20)
    alpha_fast: float = 0.5  # fast curvature accumulator decay per fix (eq. 18), 0 < α_f ≪ α_s
    alpha_slow: float = 0.95  # slow curvature accumulator decay per fix (eq. 18)
    omega_fast: float = 0.7  # weight of the fast accumulator (eq. 19)
    h_fast0: float = 1.0  # initial accumulators (> 0, Algorithm 1 line 3)
    h_slow0: float = 1.0
    eta_first_order: float = 0.15  # first-order baseline: θ ← θ − η₁ ∇θ (same gradient, plain step)
    loss: Literal["student-t", "gaussian"] = "student-t"  # innovation NLL form (companion.estimator.belief)
    student_dof: float = 7.815  # ν of the Student-t loss = χ²₀.₉₅(3 dof), the paper's threshold
    lambda_smooth_1_m: float = 0.1  # weight λ of the smoothness term ‖Δp‖ (1/m)
    # (ours) weight λ_b of the bias-level term (belief.bias_level; dimensionless): the likelihood of the
    # filter's GNSS-bias estimate under the range σ_b(β) allows. 0 = the paper's loss. With a receiver
    # velocity the bias is observable and a one-step innovation shows only its change, not its level
    # (docs/results/ablation/findings.md); the ablation's rows choose it on the tuning set.
    lambda_bias_level: float = 0.0
    chi2_095: float = 7.815  # paper-literal loss: χ²₀.₉₅ for 3 dof

    # --- innovation gate, glitch recovery, validity (what PX4 EKF2 / ArduPilot EKF3 do; docs/estimator.md)
    # Gate size in standard deviations of the innovation: a fix is rejected when its horizontal
    # NIS (2 dof) or its vertical NIS (1 dof) exceeds gate². 5 is EKF2_GPS_P_GATE's default and
    # ArduPilot's EK3_POS_I_GATE = 500 (in percent of 1σ); a consistent filter then rejects a
    # clean fix with probability exp(−25/2) ≈ 4e-6 (horizontal), so a rejection means a glitch.
    gnss_gate_sigma: float = 5.0
    # The gate's innovation variance uses R floored at this std (m), the fused R is not floored:
    # EKF2 (EKF2_GPS_P_NOISE) and EKF3 (EK3_POSNE_M_NSE) floor GNSS noise at 0.5 m. The gate is
    # there for metre-size glitches, not to police the paper's 0.08 m noise model: with R
    # = 0.08² the real quad106 log had 5-10 % of its clean fixes rejected, with 0.5 m none. So
    # an innovation under gate × 0.5 m = 2.5 m always passes.
    gnss_gate_r_floor_m: float = 0.5
    # A fix failing the gate when no fix passed for this long resets position (and the GNSS bias
    # state) to it, with the fix's R and the initial bias variance: a persistent disagreement is
    # a real change (or a dead-reckoning drift), not a glitch. EKF2 resets after its 5 s no-aid
    # time-out (EKF2_NOAID_TOUT), EKF3 after 7-10 s (gpsRetryTime); 5 s bounds the drift.
    gnss_reset_timeout_s: float = 5.0
    # GNSS step hypothesis: a fix failing the gate within gnss_offset_open_s of a fused fix (the
    # stream was consistent a moment ago: no dead-reckoning drift can explain a 5-sigma jump) is a
    # step of the receiver's output: its innovation becomes an offset; the following fixes that pass
    # the gate relative to it are held (dead reckoning on the receiver's velocity where it passes its
    # gate, else fused as z − offset, which still observes velocity) until a fix passes the gate
    # without it (the step ended). Once the step has lasted gnss_offset_max_s it is the GNSS's new track: the
    # position moves by the offset (velocity and IMU errors, aided throughout, are kept) and the fixes
    # are fused as they come, counted as a reset. 5 s: EKF2 resets into a persistent GNSS
    # disagreement after 5 s (EKF2_NOAID_TOUT), EKF3 after 7 s; held longer, a fading NLOS reflection
    # traps the filter on a track no fix supports (docs/results/ablation: the 60 s of the second wave
    # cost more than they saved). Within gnss_offset_return_s of that, a fix back on the track kept
    # before the step (it passes the gate relative to minus the accepted offset) is the step's end:
    # the position moves back at once (counted as gnss_offset_returns). 1 s spans 5 fixes at 5 Hz.
    # A GNSS that returns after an outage longer than 1 s opens no offset: its fixes pass the gate
    # grown by dead reckoning, or reset after gnss_reset_timeout_s.
    gnss_offset_open_s: float = 1.0
    gnss_offset_max_s: float = 5.0
    gnss_offset_return_s: float = 60.0
    # The position is flagged invalid (NavEstimate.pos_valid False) when no fix was fused for
    # longer than this (time of the estimate − validity of the last fused fix). EKF2_NOAID_TOUT.
    pos_valid_timeout_s: float = 5.0
    # A fix repeating exactly (lat, lon, alt) a position first received more than gnss_frozen_s
    # earlier, the estimated horizontal speed having exceeded gnss_frozen_speed_m_s since, is a frozen
    # receiver output: rejected and counted (gnss_rejected_frozen). The vehicle should have moved
    # 1 m, 10x the 1e-6 degree resolution of quad106's fixes, which repeat at most 5 fixes (0.8 s)
    # in a row; a vehicle at rest may repeat for ever and is never rejected. A frozen fix while
    # moving drags the estimate back (neither EKF2 nor EKF3 checks this).
    gnss_frozen_s: float = 2.0
    gnss_frozen_speed_m_s: float = 0.5
    # Largest R any method may use, as a multiple of the fix's nominal variance (R_nom, or the
    # receiver-reported accuracy): bounds what adaptive and vbakf learn (10× the nominal std).
    r_learned_max_factor: float = 100.0
    # The same bound for a fix whose receiver states neither its accuracy nor a velocity (its R is then
    # its own learned noise): innovations beyond that noise may be the IMU's fault (a wrong attitude
    # input), and an R learned from them makes the filter trust the wrong IMU more (measured on
    # quad106 with a 180° heading fault: adaptive and vbakf 24 m from the GNSS track at 100×, the
    # gate-off filter 9 m). 4 (2× the noise's std).
    r_learned_max_factor_unreported: float = 4.0

    # --- receivers (docs/estimator.md, "Receiver accuracy")
    # A fix without h_acc/v_acc gets a learned R: the receiver's own noise, from its fixes and the IMU alone
    # (never from the filter's state, so a wrong model cannot inflate it into a fly-away): the change between
    # consecutive blocks of the velocity two fixes imply once the IMU's displacement is removed, normalised to
    # one fix's noise, through a log-domain running centre of its magnitude (each fix moves it by at most a
    # factor e^(T/τ), time constant gnss_noise_tau_s), floored at the configured sigma_gnss_*. It starts at
    # sigma_gnss_unreported_m, the GNSS noise EKF2 (EKF2_GPS_P_NOISE) and EKF3 (EK3_POSNE_M_NSE) assume by
    # default. The gate's R is floored for every receiver (reported accuracy or not) at the robust spread of
    # its innovations (the same running centre of |innovation|, time constant gnss_scale_tau_s, minus the
    # prediction's share H P Hᵀ; relative to a step held): a receiver whose accuracy is missing or optimistic
    # cannot make the gate reject most of its fixes, only those beyond gnss_gate_sigma × its own spread.
    sigma_gnss_unreported_m: float = 0.5
    gnss_scale_tau_s: float = 2.0
    # The learned noise's time constant (s): a receiver's noise level changes slowly, and a running
    # centre over ~50 fixes at 5 Hz is known to ~15 % (2 s would leave it ±30 %).
    gnss_noise_tau_s: float = 10.0
    # (ours) The std (m) of a Gauss-Markov multipath bias (correlation time bias_tau_s) assumed in the fixes
    # of a receiver that reports no accuracy (0: off, the default, bit-identical). The learned noise above is
    # what is white from one fix to the next, and a correlated bias changes between fixes too: a 1.2 m bias of
    # 3 s correlation adds 0.26 m at 5 Hz to a 0.1 m white noise (model.bias_share_of_noise_m2). With this > 0
    # that share is removed (in variance, before the floor), so the learned R is the white part a reported
    # accuracy states and the bias is left to the bias state, as the innovation-matching estimate
    # R = C_y − H P Hᵀ leaves the modelled process noise out. 1.2 = sigma_bias_max_m, the filter's own
    # multipath model. Measured on real IMU flights (docs/estimator.md, "The noise of a receiver that states
    # none"): it helps the belief methods a little and makes naive, which has no bias to put that share in,
    # worse; on quad106 it lowers second-order's open-sky belief: off by default.
    sigma_gnss_unreported_bias_m: float = 0.0

    # --- the receiver's velocity (Doppler), fused beside its position (docs/estimator.md)
    # 1σ noise of a velocity component where the receiver reports no speed accuracy, and the floor
    # under a reported one (m/s): EKF2_GPS_V_NOISE and ArduPilot's EK3_VELNE_M_NSE (0.3), and
    # EK3_VELD_M_NSE for the vertical (0.5).
    sigma_gnss_velocity_m_s: float = 0.3
    sigma_gnss_velocity_vertical_m_s: float = 0.5
    # Velocity innovation gate (standard deviations; horizontal NIS, 2 dof, and vertical, 1 dof):
    # EKF2_GPS_V_GATE 5, EK3_VEL_I_GATE 500 %.
    gnss_vel_gate_sigma: float = 5.0

    # --- resets that recover
    # As EKF2's resetVelocityToGnss/resetHorizontalPositionToGnss and EKF3's ResetPosition + ResetVelocity, a
    # reset puts position on the fix, velocity on the receiver's velocity where it gives one, and re-opens the
    # IMU error states to their priors. Where the receiver gives no velocity, the dead-reckoned velocity is
    # kept with this std (m/s) at least: after a reset the velocity is what failed, and the following fixes
    # must be able to correct it (5 m/s: EKF2's variance for a velocity reset without a velocity source, 25
    # m²/s²).
    gnss_reset_sigma_vel_m_s: float = 5.0

    # --- fly-away guard
    # The vehicle's envelope. An estimate faster than these speeds, or whose mean acceleration over
    # envelope_acc_window_s (its velocity minus the velocity smoothed over that window, divided by it; the
    # updates' corrections included) is larger, is not a quadrotor's: it is flagged invalid
    # (NavEstimate.pos_valid False) and the next fix failing the gate resets it. 30 m/s (108 km/h) horizontal
    # and 15 m/s vertical are above what multirotors of this class fly (ArduCopter's and PX4's default speed
    # limits are 5-12 m/s); 20 m/s² ≈ 2 g is a 60° tilt held at full thrust. 1 s: longer than the corrections'
    # chatter at 5-20 Hz, shorter than a fly-away.
    envelope_speed_max_m_s: float = 30.0
    envelope_speed_vertical_max_m_s: float = 15.0
    envelope_acc_max_m_s2: float = 20.0
    envelope_acc_window_s: float = 1.0

    # --- reported accuracy (NavEstimate.cov_diag: GPS_INPUT's accuracies, the feeds' covariances):
    # the position variances × max(1, NIS per degree of freedom of the fused fixes'
    # N, E, D innovations over the last accuracy_window_s, exponentially weighted;
    # companion.estimator.consistency, the tight filter's rule), the variance-of-unit-weight test a
    # receiver applies to its reported accuracy: fix errors correlated over seconds (reflections), which
    # the filter fuses as independent, leave P over-confident; floored per axis by min(c × that, one
    # fix's variance), c the fused fixes' own correlation (1 + ρ)/(1 − ρ) and one fix's variance their
    # scatter or the stated h_acc² (v_acc² vertically) over the same window (consistency.Scatter: N, E
    # pooled; D on its own). A report
    # only: the estimate is unchanged. 20 s: the tight filter's, several of the urban fix errors' 1-10 s
    # correlation times. 0: P as it is.
    accuracy_window_s: float = 20.0

    # --- IMU / GNSS disagreement (a wrong attitude input)
    # An exponentially weighted mean of the horizontal velocity innovations' NIS per degree of freedom, time
    # constant imu_gnss_disagree_tau_s, each NIS clipped at gate² per dof (position fixes alone cannot tell a
    # wrong attitude from a GNSS bias: without a receiver velocity nothing is flagged). Above
    # imu_gnss_disagree_on the IMU-propagated motion persistently disagrees with GNSS: counted
    # (imu_gnss_disagreements), flagged (NavEstimate.imu_gnss_disagreement), and the IMU's white-acceleration
    # density is multiplied by imu_gnss_disagree_acc_factor until the mean falls below imu_gnss_disagree_off,
    # so the filter follows GNSS instead of dead-reckoning on the attitude it was given. A consistent filter's
    # mean is 1 (std ≈ 0.3 over ~10 fixes). A velocity failing its gate on two consecutive fixes while the
    # receiver agrees with itself, and passing with the IMU distrusted, flags it at once.
    imu_gnss_disagree_tau_s: float = 2.0
    imu_gnss_disagree_on: float = 6.0
    imu_gnss_disagree_off: float = 2.0
    imu_gnss_disagree_acc_factor: float = 10.0

    # --- baselines
    beta_fixed: float = 1.0  # naive and adaptive: belief held fixed (full trust; Q_b at its floor)
    adaptive_window_fixes: int = 20  # Mohamed & Schwarz innovation window N (1 s at 20 Hz)
    adaptive_r_floor: float = 0.25  # adaptive R eigenvalues kept ≥ this × the smallest nominal variance
    vb_forgetting: float = 0.98  # vbakf: ρ per fix, memory 1/(1−ρ) = 50 fixes = 2.5 s at 20 Hz
    vb_iterations: int = 3  # vbakf: fixed-point iterations per fix
    vb_prior_dof: float = 10.0  # vbakf: ν of the initial inverse-Wishart density (fixes of evidence)

    def validate(self) -> None:
        positive = (
            "sigma_acc_m_s2", "bias_tau_s", "sigma_bias_max_m", "sigma_bias_floor_m",
            "sigma_gnss_horizontal_m", "sigma_gnss_vertical_m", "sigma_velocity0_m_s",
            "sigma_bias0_m", "imu_hold_max_s", "theta_max", "eta", "lambda_reg", "student_dof",
            "chi2_095", "h_fast0", "h_slow0", "adaptive_r_floor", "gnss_gate_sigma", "gnss_gate_r_floor_m",
            "gnss_reset_timeout_s", "gnss_offset_open_s", "gnss_offset_max_s", "gnss_offset_return_s",
            "pos_valid_timeout_s",
            "gnss_frozen_s",
            "gnss_frozen_speed_m_s", "sigma_gnss_velocity_m_s", "sigma_gnss_velocity_vertical_m_s",
            "gnss_vel_gate_sigma", "gnss_reset_sigma_vel_m_s", "envelope_speed_max_m_s",
            "envelope_speed_vertical_max_m_s", "envelope_acc_max_m_s2", "envelope_acc_window_s",
            "imu_gnss_disagree_tau_s",
            "imu_gnss_disagree_on", "imu_gnss_disagree_off", "imu_gnss_disagree_acc_factor",
            "sigma_gnss_unreported_m", "gnss_scale_tau_s", "gnss_noise_tau_s",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")
        if not self.theta_min < self.theta0 < self.theta_max:
            raise ValueError("theta_min, theta0, theta_max: need theta_min < theta0 < theta_max")
        if self.imu_gnss_disagree_off >= self.imu_gnss_disagree_on:
            raise ValueError("imu_gnss_disagree_off, imu_gnss_disagree_on: need off < on")
        check_accuracy_window(self.accuracy_window_s)
        if self.history_s < 1.5:
            raise ValueError(f"history_s: must be >= 1.5 s, got {self.history_s}")
        k_max = min(self.r_learned_max_factor, self.r_learned_max_factor_unreported)
        if not (math.isfinite(k_max) and k_max >= self.r_inflation_max):
            raise ValueError("r_learned_max_factor, r_learned_max_factor_unreported: must be finite and "
                             ">= r_inflation_max")
        if self.r_inflation_max < 1.0:
            raise ValueError(f"r_inflation_max: must be >= 1, got {self.r_inflation_max}")
        if not 0.0 < self.alpha_fast < self.alpha_slow < 1.0:
            raise ValueError("alpha_fast, alpha_slow: need 0 < alpha_fast < alpha_slow < 1")
        if not 0.0 < self.omega_fast < 1.0:
            raise ValueError(f"omega_fast: must be in (0, 1), got {self.omega_fast}")
        if not 0.0 <= self.beta_fixed <= 1.0:
            raise ValueError(f"beta_fixed: must be in [0, 1], got {self.beta_fixed}")
        if self.adaptive_window_fixes < 2:
            raise ValueError("adaptive_window_fixes: must be >= 2")
        if not (0.0 < self.vb_forgetting <= 1.0 and self.vb_iterations >= 1 and self.vb_prior_dof > 0.0):
            raise ValueError("vb_forgetting, vb_iterations, vb_prior_dof: need 0 < ρ ≤ 1, ≥ 1, > 0")
        for name in ("future_tolerance_s", "lambda_smooth_1_m", "lambda_bias_level",
                     "sigma_bias_max_per_gnss_std", "sigma_gnss_unreported_bias_m",
                     "eta_first_order", "sigma_acc_bias0_m_s2", "sigma_acc_bias_rw_m_s2_sqrt_s",
                     "sigma_acc_ned0_m_s2", "sigma_acc_ned_rw_m_s2_sqrt_s", "imu_hold_acc_rw_m_s2_sqrt_s",
                     "imu_hold_periods"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name}: must be a finite number >= 0")

    # --- derived quantities (pure functions of the fields)
    def r_nominal_m2(self) -> np.ndarray:
        """Nominal GNSS covariance R_nom (3×3, m²), NED."""
        h, v = self.sigma_gnss_horizontal_m**2, self.sigma_gnss_vertical_m**2
        return np.diag([h, h, v])

    def sigma_bias_m(self, beta: float) -> float:
        """σ_b(β) of eq. 13 (m)."""
        return self.sigma_bias_max_m * (1.0 - beta) + self.sigma_bias_floor_m

    def bias_scale(self, r_nominal_h_m2: float) -> float:
        """The receiver's scale of the bias range (≥ 1) for a fix of nominal horizontal R ``r_nominal_h_m2``
        (m²): σ_b(β) and the bias's prior and reset variance are multiplied by it."""
        k = self.sigma_bias_max_per_gnss_std * math.sqrt(r_nominal_h_m2) / self.sigma_bias_max_m
        return k if k > 1.0 else 1.0

    def r_factor(self, beta: float) -> float:
        """R(β) / R_nom = r_inflation_max ** (1 − β): 1 at full trust, r_inflation_max at none."""
        return float(self.r_inflation_max ** (1.0 - beta))

