"""Hyper-parameters of the ablation plugins (``fixed-beta``, ``map-beta``, ``windowed-ml``, ``hmm-trust``,
``map-hmm``).

They live in their own mission section ``belief_plugins:`` (``--set belief_plugins.FIELD=V``), so
the estimator's ``EstimatorConfig`` stays as it is. A plugin receives them (and the mission's map)
at construction in its ``methods.MethodContext``; ``companion.wiring.navigator_for`` builds that
from a mission.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class PluginConfig:
    # --- map-beta: β scheduled from the map's clearance d at the estimated position,
    # β(d) = beta_open + (beta_canyon − beta_open) · clip((d_near − d) / ramp, 0, 1)
    map_beta_open: float = 0.9  # belief in open sky
    map_beta_canyon: float = 0.2  # belief deep in a street canyon
    map_d_near_m: float = 15.0  # clearance below which the belief starts to drop
    map_ramp_m: float = 10.0  # the belief reaches beta_canyon at d_near − ramp
    # --- map-hmm: a clean (map_beta_open) / degraded (map_beta_canyon) chain whose prior is the
    # schedule's weight at the estimated position, updated by tempered innovation likelihoods (map_hmm.py)
    mhmm_dwell_s: float = 1.0  # mean time (s) before the level is re-drawn from the map's prior
    mhmm_evidence: float = 0.3  # κ: power of each fix's likelihood (0 = the map alone, 1 = full Bayes)
    mhmm_prior_floor: float = 0.05  # ε: the map's prior of either level is at least this
    # --- windowed-ml: β = argmin over a grid of the innovation NLL summed over the last N fixes
    window_fixes: int = 40  # N (2 s at 20 Hz)
    window_grid: int = 41  # β grid points in [window_beta_min, window_beta_max]
    window_beta_min: float = 0.0
    window_beta_max: float = 1.0
    window_gain: float = 0.5  # β ← β + gain · (β* − β) per fix (1 = jump to the window optimum)
    # --- hmm-trust: posterior over discrete trust levels (hmm_trust.py)
    hmm_levels: int = 3  # 2 = clean + degraded; 3 adds the outlier level
    hmm_beta_clean: float = 1.0  # trust of the clean level: σ_b(β), R(β) of the trust model
    hmm_beta_degraded: float = 0.0  # trust of the degraded level: σ_b(β), R(β) of the trust model
    hmm_dwell_s: float = 2.0  # mean dwell time (s) of the clean and degraded levels
    hmm_outlier_dwell_s: float = 0.25  # mean dwell time (s) of the outlier level (NLOS episodes, tails)
    hmm_split_vertical: bool = False  # separate chains for the horizontal and the vertical axes
    hmm_outlier_r_factor: float = 25.0  # R / R_nom of the outlier level (25: 5x the nominal std)

    def validate(self) -> None:
        for name in ("map_beta_open", "map_beta_canyon", "window_beta_min", "window_beta_max"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name}: must be in [0, 1], got {getattr(self, name)!r}")
        if not (self.map_ramp_m > 0.0 and self.map_d_near_m >= 0.0):
            raise ValueError("map_ramp_m: must be > 0 and map_d_near_m >= 0")
        if self.window_fixes < 1 or self.window_grid < 2:
            raise ValueError("window_fixes: must be >= 1, window_grid >= 2")
        if self.window_beta_max <= self.window_beta_min:
            raise ValueError("window_beta_max: must exceed window_beta_min")
        if self.hmm_levels not in (2, 3):
            raise ValueError(f"hmm_levels: must be 2 or 3, got {self.hmm_levels!r}")
        if not 0.0 <= self.hmm_beta_degraded < self.hmm_beta_clean <= 1.0:
            raise ValueError("hmm_beta_degraded, hmm_beta_clean: need 0 <= degraded < clean <= 1, got "
                             f"{self.hmm_beta_degraded!r}, {self.hmm_beta_clean!r}")
        if not 0.0 <= self.mhmm_evidence <= 1.0:
            raise ValueError(f"mhmm_evidence: must be in [0, 1], got {self.mhmm_evidence!r}")
        if not 0.0 <= self.mhmm_prior_floor < 0.5:
            raise ValueError(f"mhmm_prior_floor: must be in [0, 0.5), got {self.mhmm_prior_floor!r}")
        for name in ("hmm_dwell_s", "hmm_outlier_dwell_s", "mhmm_dwell_s"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0.0):
                raise ValueError(f"{name}: must be a finite number of seconds > 0, "
                                 f"got {getattr(self, name)!r}")
        if not (math.isfinite(self.hmm_outlier_r_factor) and self.hmm_outlier_r_factor >= 1.0):
            raise ValueError(f"hmm_outlier_r_factor: must be finite and >= 1, "
                             f"got {self.hmm_outlier_r_factor!r}")
        if not 0.0 < self.window_gain <= 1.0:
            raise ValueError(f"window_gain: must be in (0, 1], got {self.window_gain!r}")
