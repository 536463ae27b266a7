"""Align an IMU's clock (and check its heading) against a truth trajectory: pure numeric, no I/O.

A log whose IMU and truth come from two devices (e.g. an IMU unit and an RTK receiver) stamps
them on two clocks. The offset is found where the motion agrees best: the IMU's specific force
rotated to NED plus gravity is the acceleration ``a(t)``; the truth's second difference
``(p[k+1] − 2 p[k] + p[k−1]) / h²`` is exactly the average of ``a`` over ``[t_k − h, t_k + h]``
with triangular weights. So the IMU side is made the same way: ``a`` integrated twice
(trapezoids) to ``P(t)``, and the same second difference taken of ``P`` at ``t_k + offset``
(the integration constants cancel). Both sides then go through the same moving average of
``smooth_samples`` truth samples: a truth position quantised or noisy at the centimetre level
makes its second difference at 10 Hz noisy by ~1 m/s² (0.01 m / 0.01 s²), far above the signal's
high frequencies.

Horizontal axes only (a truth height is often quantised, e.g. to 0.1 m: 10 m/s² of noise).
The cost at an offset is the least-squares residual after the best rotation about the vertical
(2-D Procrustes), so a heading error of the IMU's attitude does not bias the offset; that
rotation is reported as ``yaw_deg``: the angle (positive clockwise seen from above, i.e. east of
north) by which the IMU's horizontal acceleration must be turned to match the truth — the IMU
heading's error is ``−yaw_deg``.

Search: a grid over ``±max_offset_s`` at ``grid_step_s``, then a bounded scalar minimisation
around the best grid point (``scipy.optimize.minimize_scalar``). The truth samples compared are
the same for every offset (those whose window stays inside the IMU span at every offset), so the
costs are comparable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.errors import UserError


@dataclass(frozen=True)
class ClockFitConfig:
    max_offset_s: float = 1.5  # search the offset (IMU time − truth time) in ±this
    grid_step_s: float = 0.005  # grid before the local refinement
    smooth_samples: int = 5  # moving average applied to both sides (truth samples; 0.5 s at 10 Hz)
    min_samples: int = 30  # fewer truth samples compared than this: no fit (an error)
    min_signal_rms_m_s2: float = 0.3  # a truth accelerating less than this (RMS per axis) cannot time the IMU


@dataclass(frozen=True)
class ClockFit:
    """``t_imu = t_truth + offset_s``."""

    offset_s: float
    yaw_deg: float  # rotation turning the IMU's horizontal acceleration onto the truth's (see module doc)
    residual_rms_m_s2: float  # horizontal residual at the fit (after the rotation), RMS per axis
    residual_rms_no_yaw_m_s2: float  # the same without the rotation (what a heading error costs)
    signal_rms_m_s2: float  # horizontal RMS of the truth's smoothed second difference
    samples: int  # truth samples compared

    def as_dict(self) -> dict[str, float | int]:
        return {"offset_s": self.offset_s, "yaw_deg": self.yaw_deg,
                "residual_rms_m_s2": self.residual_rms_m_s2,
                "residual_rms_no_yaw_m_s2": self.residual_rms_no_yaw_m_s2,
                "signal_rms_m_s2": self.signal_rms_m_s2, "samples": self.samples}


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """(m, k) -> (m - n + 1, k): the mean of each n consecutive rows."""
    if n <= 1:
        return x
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    return (c[n:] - c[:-n]) / n


def _second_difference(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Second divided difference at the interior samples (exact for any spacing)."""
    h0, h1 = np.diff(t)[:-1, None], np.diff(t)[1:, None]
    v0 = (p[1:-1] - p[:-2]) / h0
    v1 = (p[2:] - p[1:-1]) / h1
    return (v1 - v0) / ((h0 + h1) / 2.0)


def _double_integral(t: np.ndarray, a: np.ndarray) -> np.ndarray:
    from scipy.integrate import cumulative_trapezoid

    v = cumulative_trapezoid(a, t, axis=0, initial=0.0)
    return cumulative_trapezoid(v, t, axis=0, initial=0.0)


def _procrustes_yaw(imu: np.ndarray, truth: np.ndarray) -> float:
    """The rotation about the vertical (radians, north toward east) best turning ``imu`` onto ``truth``."""
    cross = float(np.sum(imu[:, 0] * truth[:, 1] - imu[:, 1] * truth[:, 0]))
    dot = float(np.sum(imu * truth))
    return math.atan2(cross, dot)


def _rotate(x: np.ndarray, psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.column_stack((c * x[:, 0] - s * x[:, 1], s * x[:, 0] + c * x[:, 1]))


def fit_clock_offset(t_imu_s: np.ndarray, a_ned_m_s2: np.ndarray, t_truth_s: np.ndarray,
                     p_truth_ned_m: np.ndarray, cfg: ClockFitConfig | None = None) -> ClockFit:
    """Offset and heading check of an IMU against a truth trajectory (see the module doc).

    ``a_ned_m_s2`` (n, ≥2): the IMU's acceleration in NED (specific force rotated + gravity) at
    ``t_imu_s`` (n,), increasing; ``p_truth_ned_m`` (m, ≥2) at ``t_truth_s`` (m,), increasing.
    Raises UserError when the spans overlap too little to compare ``min_samples`` samples.
    """
    cfg = cfg or ClockFitConfig()
    t_imu = np.asarray(t_imu_s, dtype=float)
    a = np.asarray(a_ned_m_s2, dtype=float)[:, :2]
    t_gt = np.asarray(t_truth_s, dtype=float)
    p = np.asarray(p_truth_ned_m, dtype=float)[:, :2]
    d2_truth = _moving_average(_second_difference(t_gt, p), cfg.smooth_samples)
    n = cfg.smooth_samples
    lo = t_gt[: len(t_gt) - 2 - n + 1]  # first truth time each smoothed value depends on
    hi = t_gt[n + 1:]  # last one
    keep = (lo - cfg.max_offset_s >= t_imu[0]) & (hi + cfg.max_offset_s <= t_imu[-1])
    if int(keep.sum()) < cfg.min_samples:
        raise UserError(f"IMU and truth overlap too little to fit their clock offset "
                        f"({int(keep.sum())} truth samples usable, {cfg.min_samples} needed; "
                        f"offsets searched within ±{cfg.max_offset_s} s)")
    truth = d2_truth[keep]
    signal = float(np.sqrt(np.mean(truth**2)))
    if signal < cfg.min_signal_rms_m_s2:
        raise UserError(f"the truth shows too little acceleration to fit the IMU's clock offset "
                        f"({signal:.2f} m/s² RMS, at least {cfg.min_signal_rms_m_s2} needed)")
    P = _double_integral(t_imu, a)

    def imu_side(offset_s: float) -> np.ndarray:
        pk = np.column_stack([np.interp(t_gt + offset_s, t_imu, P[:, i]) for i in range(2)])
        return _moving_average(_second_difference(t_gt, pk), n)[keep]

    def cost(offset_s: float) -> float:
        imu = imu_side(offset_s)
        r = truth - _rotate(imu, _procrustes_yaw(imu, truth))
        return float(np.mean(r * r))

    grid = np.arange(-cfg.max_offset_s, cfg.max_offset_s + cfg.grid_step_s / 2, cfg.grid_step_s)
    costs = np.array([cost(float(o)) for o in grid])
    best = float(grid[int(np.argmin(costs))])
    from scipy.optimize import minimize_scalar

    lo_o, hi_o = max(-cfg.max_offset_s, best - cfg.grid_step_s), min(cfg.max_offset_s, best + cfg.grid_step_s)
    res = minimize_scalar(cost, bounds=(lo_o, hi_o), method="bounded", options={"xatol": 1e-5})
    offset = float(res.x) if res.fun <= costs.min() else best
    imu = imu_side(offset)
    psi = _procrustes_yaw(imu, truth)
    return ClockFit(
        offset_s=offset,
        yaw_deg=math.degrees(psi),
        residual_rms_m_s2=math.sqrt(cost(offset)),
        residual_rms_no_yaw_m_s2=float(np.sqrt(np.mean((truth - imu) ** 2))),
        signal_rms_m_s2=signal,
        samples=int(keep.sum()),
    )
