"""Single-point solution: iterative weighted least squares on one epoch, RAIM/FDE, Doppler velocity.

Unknowns: receiver ECEF position and one clock offset per satellite system present (metres of
range: inter-system biases and the BDT/GLONASS time offsets are absorbed). Model per satellite:

    y_i = P_i + c·dt_sv,i − I_i − T_i = ρ_i(r) + c·dt_sys(i) + ε_i     (raw pseudoranges)
    y_i = P_i                                                        (``GnssEpoch.corrected``)

with ρ the Sagnac-corrected range (:mod:`companion.gnss.geometry`), I Klobuchar (when the epoch's
ephemeris store gives its parameters) and T Saastamoinen. Gauss–Newton from the previous solution
or the Earth's centre; weights 1/σ_i² with σ_i from :class:`SppConfig` (``weighting``).

RAIM/FDE (``SppConfig.raim``): the weighted sum of squared residuals is tested against the χ²
quantile with ``m − (3 + k)`` degrees of freedom at ``raim_p_false_alarm``; while it fails and
redundancy remains, the satellite with the largest standardised residual
``|r_i| / (σ_i √(1 − h_ii))`` is excluded and the solution recomputed (at most
``raim_max_exclusions``).

Velocity: from pseudorange rates (−λ·Doppler) with the satellite velocities, one receiver clock
drift, the Sagnac rate term (the time derivative of the range's Sagnac term; RTKLIB's ``resdop``
has the opposite sign, a known error of a few mm/s), weighted alike.

An epoch without a solution has ``ok`` False and its ``reason``: "too few satellites", "no convergence",
"gdop", or "singular geometry" (the normal matrix has no inverse: collinear lines of sight, zero
weights); a velocity whose geometry is singular is NaN.

Cost per epoch (``beliefnav bench gnss``, this project's 2-core machine): 0.4 ms for a smartLoc
epoch (15 satellites, pre-corrected) to 1 ms with the atmosphere models; each RAIM exclusion adds a
solve. Vectorised over satellites; the per-iteration Python overhead dominates.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from companion.gnss.atmosphere import iono_frequency_scale, klobuchar_m, saastamoinen_m
from companion.gnss.constants import C_M_S, OMEGA_E_RAD_S
from companion.gnss.geometry import ecef_to_enu_matrix, ecef_to_geodetic, sagnac_range_m
from companion.gnss.observations import GnssEpoch
from companion.gnss.systems import System
from companion.gnss.timescale import week_tow

WEIGHTINGS = ("uniform", "elevation", "cn0", "cn0-elevation", "given")
ACCURACIES = ("a-priori", "a-posteriori")
_ON_EARTH_M = 6.0e6  # an estimate this far from the centre has a meaningful elevation


@dataclass(frozen=True)
class SppConfig:
    """Single-point solution settings (units in the names)."""

    # σ model: "uniform" σ = sigma_uniform_m; "elevation" σ² = a² + b² / sin² el;
    # "cn0" σ² = a² + c² · 10^((cn0_ref − C/N0) / 10); "cn0-elevation" σ² = a² + b² · 10^(…) / sin² el
    # (thermal noise variance ∝ 1 / (C/N0), mapped by elevation: a weak low signal is doubly penalised);
    # "given" the epoch's pseudorange_var_m2 (smartLoc's column). GLONASS σ × glonass_sigma_factor.
    weighting: str = "cn0-elevation"
    sigma_uniform_m: float = 5.0
    sigma_floor_m: float = 0.5  # a: receiver noise floor
    sigma_zenith_m: float = 3.0  # b: multipath/atmosphere at the zenith, grows as 1/sin(el)
    sigma_cn0_m: float = 3.0  # c: at cn0_ref_dbhz, grows as 1/√(C/N0)
    cn0_ref_dbhz: float = 45.0
    glonass_sigma_factor: float = 1.5  # RTKLIB EFACT_GLO: GLONASS code is noisier (FDMA, 511 chips)
    elevation_mask_deg: float = 5.0  # ignored until the position is on the Earth
    earth_rotation: bool = True  # Sagnac term (False only to show its size)
    iono: bool = True  # Klobuchar on raw pseudoranges, when the parameters are known
    tropo: bool = True  # Saastamoinen on raw pseudoranges
    max_iterations: int = 12
    convergence_m: float = 1e-4
    max_gdop: float = 30.0  # RTKLIB MAXGDOP: a worse geometry is no solution
    raim: bool = False
    raim_p_false_alarm: float = 1e-3
    raim_max_exclusions: int = 4
    # h_acc/v_acc: the covariance from the σ model ("a-priori") or scaled by the residuals'
    # unit variance when that is above 1 ("a-posteriori": what a receiver would report)
    accuracy: str = "a-posteriori"
    sigma_range_rate_m_s: float = 0.5  # Doppler velocity σ at the zenith / cn0_ref (same shape as σ)

    def __post_init__(self) -> None:
        if self.weighting not in WEIGHTINGS:
            raise ValueError(f"weighting {self.weighting!r}: choose from {', '.join(WEIGHTINGS)}")
        if self.accuracy not in ACCURACIES:
            raise ValueError(f"accuracy {self.accuracy!r}: choose from {', '.join(ACCURACIES)}")


@dataclass(frozen=True, slots=True)
class Dops:
    gdop: float
    pdop: float
    hdop: float
    vdop: float
    tdop: float


_NO_DOPS = Dops(*(math.nan,) * 5)


@dataclass(frozen=True, slots=True, eq=False)
class SppSolution:
    """One epoch's single-point solution. Per-satellite arrays are in the epoch's row order."""

    t_gps_s: float
    ok: bool
    reason: str  # "" when ok; else why there is no solution
    p_ecef_m: np.ndarray  # (3,)
    clock_systems: tuple[System, ...]  # systems with a clock unknown, in column order
    clock_bias_m: np.ndarray  # (k,) receiver clock offsets × c per system
    cov_ecef_m2: np.ndarray  # (3, 3) position covariance (per SppConfig.accuracy)
    h_acc_m: float  # 1-σ per horizontal axis, √((σ_n² + σ_e²) / 2)
    v_acc_m: float  # 1-σ vertical
    dops: Dops
    residuals_m: np.ndarray  # (n,) y − model at the solution (NaN: not computable)
    sigma_m: np.ndarray  # (n,) a-priori σ used as weight
    used: np.ndarray  # (n,) bool: in the final solution
    excluded: np.ndarray  # (n,) bool: removed by RAIM/FDE
    elevation_deg: np.ndarray  # (n,) at the solution
    azimuth_deg: np.ndarray  # (n,)
    chi2: float  # weighted SSE of the final solution
    dof: int
    unit_variance: float  # chi2 / dof (NaN for dof 0)
    raim_passed: bool | None  # None: not tested (RAIM off, or no redundancy)
    iterations: int
    v_ecef_m_s: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # NaN: no Doppler
    clock_drift_m_s: float = math.nan
    vel_acc_m_s: float = math.nan  # 1-σ speed accuracy per axis (RMS of the three)

    @property
    def n_used(self) -> int:
        return int(self.used.sum())


def sigma_model_m(epoch: GnssEpoch, el_rad: np.ndarray, config: SppConfig) -> np.ndarray:
    """A-priori pseudorange σ (m) per observation (``SppConfig.weighting``)."""
    w = config.weighting
    n = epoch.n
    if w == "given":
        var = np.where(
            np.isfinite(epoch.pseudorange_var_m2) & (epoch.pseudorange_var_m2 > 0),
            epoch.pseudorange_var_m2,
            config.sigma_uniform_m**2,
        )
    elif w == "uniform":
        var = np.full(n, config.sigma_uniform_m**2)
    else:
        cn0 = np.where(np.isfinite(epoch.cn0_dbhz), epoch.cn0_dbhz, config.cn0_ref_dbhz)
        weak = 10.0 ** ((config.cn0_ref_dbhz - cn0) / 10.0)  # 1 / (C/N0 linear), 1 at the reference
        slant = 1.0 / np.maximum(np.sin(el_rad), 0.05) ** 2
        var = np.full(n, config.sigma_floor_m**2)
        if w == "elevation":
            var = var + config.sigma_zenith_m**2 * slant
        elif w == "cn0":
            var = var + config.sigma_cn0_m**2 * weak
        else:  # both: a weak AND low signal is worse than either alone
            var = var + config.sigma_zenith_m**2 * weak * slant
    sigma = np.sqrt(var)
    return np.where(epoch.system == System.GLONASS, sigma * config.glonass_sigma_factor, sigma)


class Geometry:
    """Ranges, line of sight, elevation and atmosphere at one receiver position."""

    def __init__(
        self,
        epoch: GnssEpoch,
        x: np.ndarray,
        config: SppConfig,
        klobuchar: tuple[np.ndarray, np.ndarray] | None,
    ) -> None:
        self.rho, self.los = sagnac_range_m(epoch.sat_pos_ecef_m, x, config.earth_rotation)
        self.on_earth = float(np.linalg.norm(x)) > _ON_EARTH_M
        n = epoch.n
        self.atm = np.zeros(n)
        if self.on_earth:
            lat, lon, h = (float(v) for v in ecef_to_geodetic(x))
            self.enu = ecef_to_enu_matrix(lat, lon)
            d = self.los @ self.enu.T
            self.el = np.arcsin(np.clip(d[:, 2], -1.0, 1.0))
            self.az = np.arctan2(d[:, 0], d[:, 1]) % (2 * np.pi)
            if not epoch.corrected:
                if config.tropo:
                    self.atm = self.atm + saastamoinen_m(lat, h, self.el)
                if config.iono and klobuchar is not None:
                    self.atm = self.atm + klobuchar_m(
                        klobuchar[0], klobuchar[1], lat, lon, self.az, self.el, week_tow(epoch.t_gps_s)[1]
                    ) * iono_frequency_scale(epoch.system)
        else:
            self.enu = np.eye(3)
            given = np.deg2rad(epoch.elevation_deg)
            self.el = np.where(np.isfinite(given), given, np.pi / 2)
            self.az = np.where(np.isfinite(epoch.azimuth_deg), np.deg2rad(epoch.azimuth_deg), np.nan)


def geometry_at(
    epoch: GnssEpoch,
    p_ecef_m: np.ndarray,
    config: SppConfig = SppConfig(),
    klobuchar: tuple[np.ndarray, np.ndarray] | None = None,
) -> Geometry:
    """The solver's model at a given receiver position: ranges (Sagnac per ``config``), line of
    sight, elevation, azimuth and the atmosphere it takes off raw pseudoranges (``atm``, metres;
    zero for corrected epochs)."""
    return Geometry(epoch, np.asarray(p_ecef_m, float), config, klobuchar)


def _design(los: np.ndarray, cols: np.ndarray, k: int) -> np.ndarray:
    h = np.zeros((len(los), 3 + k))
    h[:, :3] = -los
    h[np.arange(len(los)), 3 + cols] = 1.0
    return h


class SingularGeometryError(ValueError):
    """The normal matrix of an epoch's fit has no usable inverse (collinear lines of sight, zero weights,
    too few distinct satellites): the epoch is unsolved (``reason`` "singular geometry"), never a crash."""


def _inverse(n: np.ndarray) -> np.ndarray:
    """``n``'s inverse; :class:`SingularGeometryError` when it has none a covariance can come from (singular,
    or rounding made a variance non-finite or negative)."""
    try:
        q = np.linalg.inv(n)
    except np.linalg.LinAlgError:
        raise SingularGeometryError("singular normal matrix") from None
    if not (np.isfinite(q).all() and (np.diag(q) > 0.0).all()):
        raise SingularGeometryError("ill-conditioned normal matrix")
    return q


def _wls(h: np.ndarray, r: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    hw = h * w[:, None]
    q = _inverse(h.T @ hw)
    return q @ (hw.T @ r), q


@functools.lru_cache(maxsize=256)
def chi2_threshold(p_false_alarm: float, dof: int) -> float:
    """The χ² test's threshold: ``chi2.ppf(1 - p_false_alarm, dof)``, the value scipy.stats gives, from the
    inverse survival function it evaluates (``scipy.special.chdtri`` at ``1 - (1 - p)``): scipy.stats itself
    is not imported (~0.7-1.5 s of CPU, which fell inside a tight navigator's first epoch)."""
    from scipy.special import chdtri

    return float(chdtri(dof, 1.0 - (1.0 - p_false_alarm)))


def preload_chi2() -> None:
    """Import what the χ² test needs (scipy.special, ~0.3 s of CPU) now: at a filter's or a receiver's
    start-up, not inside its first epoch (a live receiver's first fix would wait for it)."""
    chi2_threshold(SppConfig().raim_p_false_alarm, 1)


def solve_position(
    epoch: GnssEpoch,
    config: SppConfig = SppConfig(),
    *,
    p0_ecef_m: np.ndarray | None = None,
    klobuchar: tuple[np.ndarray, np.ndarray] | None = None,
) -> SppSolution:
    """Weighted least-squares position (and, when pseudorange rates are given, velocity)."""
    n = epoch.n
    y = epoch.pseudorange_m if epoch.corrected else epoch.pseudorange_m + C_M_S * epoch.sat_clock_s
    usable = np.isfinite(y) & np.isfinite(epoch.sat_pos_ecef_m).all(axis=1)
    excluded = np.zeros(n, dtype=bool)
    x = np.zeros(3) if p0_ecef_m is None or not np.isfinite(p0_ecef_m).all() else np.array(p0_ecef_m, float)
    raim_passed: bool | None = None
    total_iter = 0
    while True:
        res = _iterate(epoch, y, usable & ~excluded, x, config, klobuchar)
        total_iter += res["iterations"]
        if not res["ok"] or not config.raim:
            break
        dof = res["dof"]
        if dof < 1:
            raim_passed = None
            break
        if res["chi2"] <= chi2_threshold(config.raim_p_false_alarm, dof):
            raim_passed = True
            break
        if int(excluded.sum()) >= config.raim_max_exclusions or dof < 2:
            raim_passed = False
            break
        std = res["standardised"]
        worst = int(np.nanargmax(np.where(res["used"], np.abs(std), -np.inf)))
        if not np.isfinite(std[worst]):
            raim_passed = False
            break
        excluded[worst] = True
        x = res["x"]
    return _solution(epoch, res, excluded, raim_passed, total_iter, config)


def _iterate(
    epoch: GnssEpoch,
    y: np.ndarray,
    candidate: np.ndarray,
    x0: np.ndarray,
    config: SppConfig,
    klobuchar: tuple[np.ndarray, np.ndarray] | None,
) -> dict:
    x = x0.copy()
    systems = tuple(System(int(s)) for s in np.unique(epoch.system[candidate]))
    k = len(systems)
    col_of = {s: i for i, s in enumerate(systems)}
    cols_all = np.array([col_of.get(System(int(s)), 0) for s in epoch.system], dtype=int)
    clocks = np.zeros(k)
    mask_rad = np.deg2rad(config.elevation_mask_deg)
    out: dict = {
        "ok": False,
        "reason": "too few satellites",
        "x": x,
        "clocks": clocks,
        "systems": systems,
        "iterations": 0,
        "used": np.zeros(epoch.n, bool),
        "dof": 0,
        "chi2": math.nan,
    }
    it = 0
    geo: Geometry | None = None
    used = candidate.copy()
    while it < config.max_iterations:
        it += 1
        geo = Geometry(epoch, x, config, klobuchar)
        used = candidate & ((geo.el >= mask_rad) if geo.on_earth else True)
        # a system whose clock has no satellite left keeps its column out of the fit
        present = np.array([bool((used & (epoch.system == s)).any()) for s in systems], dtype=bool)
        m = int(used.sum())
        if m < 3 + int(present.sum()):
            out.update(iterations=it, used=used, reason="too few satellites")
            return out
        sigma = sigma_model_m(epoch, geo.el, config)
        model = geo.rho + clocks[cols_all] + geo.atm
        r = (y - model)[used]
        h = _design(geo.los[used], cols_all[used], k)[:, np.r_[True, True, True, present]]
        try:
            dx, _ = _wls(h, r, 1.0 / sigma[used] ** 2)
        except SingularGeometryError:
            out.update(iterations=it, used=used, reason="singular geometry")
            return out
        x = x + dx[:3]
        clocks[present] += dx[3:]
        if float(np.linalg.norm(dx[:3])) < config.convergence_m and geo.on_earth:
            break
    else:
        if geo is None or float(np.linalg.norm(dx[:3])) > 1.0:
            out.update(iterations=it, used=used, reason="no convergence", x=x)
            return out
    geo = Geometry(epoch, x, config, klobuchar)
    sigma = sigma_model_m(epoch, geo.el, config)
    resid = y - (geo.rho + clocks[cols_all] + geo.atm)
    present = np.array([bool((used & (epoch.system == s)).any()) for s in systems], dtype=bool)
    h_full = _design(geo.los, cols_all, k)[:, np.r_[True, True, True, present]]
    w = 1.0 / sigma**2
    hu = h_full[used]
    n_mat = hu.T @ (hu * w[used][:, None])
    try:
        q = _inverse(n_mat)
        qg = _inverse(hu.T @ hu)  # unweighted, for DOPs
    except SingularGeometryError:
        out.update(iterations=it, used=used, reason="singular geometry", x=x)
        return out
    lev = np.einsum("ij,jk,ik->i", h_full, q, h_full) * w  # h_ii of the weighted hat matrix
    standardised = np.where(used, resid / (sigma * np.sqrt(np.maximum(1.0 - lev, 1e-12))), np.nan)
    standardised = np.where(used & (lev > 1.0 - 1e-9), np.nan, standardised)
    chi2 = float(np.sum(w[used] * resid[used] ** 2))
    dof = int(used.sum()) - hu.shape[1]
    penu = geo.enu @ qg[:3, :3] @ geo.enu.T
    if not (np.diag(penu) > 0.0).all():  # rounding left no covariance (a near-singular geometry)
        out.update(iterations=it, used=used, reason="singular geometry", x=x)
        return out
    tdop = math.sqrt(float(np.mean(np.diag(qg)[3:]))) if qg.shape[0] > 3 else math.nan
    dops = Dops(
        math.sqrt(float(np.trace(qg))),
        math.sqrt(float(np.trace(penu))),
        math.sqrt(float(penu[0, 0] + penu[1, 1])),
        math.sqrt(float(penu[2, 2])),
        tdop,
    )
    ok = dops.gdop <= config.max_gdop
    out.update(ok=ok, reason="" if ok else "gdop", x=x, clocks=clocks, iterations=it, used=used, dof=dof,
               chi2=chi2, q=q, geo=geo, sigma=sigma, resid=resid, standardised=standardised, dops=dops,
               present=present)
    return out


def _solution(
    epoch: GnssEpoch,
    res: dict,
    excluded: np.ndarray,
    raim_passed: bool | None,
    iterations: int,
    config: SppConfig,
) -> SppSolution:
    n = epoch.n
    nan3 = np.full(3, np.nan)
    if "geo" not in res:
        return SppSolution(
            epoch.t_gps_s,
            False,
            res["reason"],
            nan3,
            (),
            np.zeros(0),
            np.full((3, 3), np.nan),
            math.nan,
            math.nan,
            _NO_DOPS,
            np.full(n, np.nan),
            np.full(n, np.nan),
            np.zeros(n, bool),
            excluded,
            np.full(n, np.nan),
            np.full(n, np.nan),
            math.nan,
            0,
            math.nan,
            raim_passed,
            iterations,
        )
    geo: Geometry = res["geo"]
    dof = res["dof"]
    unit_var = res["chi2"] / dof if dof > 0 else math.nan
    scale = max(1.0, unit_var) if config.accuracy == "a-posteriori" and dof > 0 else 1.0
    cov = res["q"][:3, :3] * scale
    cov_enu = geo.enu @ cov @ geo.enu.T
    present = res["present"]
    systems = tuple(s for s, p in zip(res["systems"], present, strict=True) if p)
    v, drift, vacc = nan3, math.nan, math.nan
    if res["ok"] and np.isfinite(epoch.pseudorange_rate_m_s).any():
        v, drift, vacc = _velocity(epoch, res["x"], geo, res["used"], config)
    return SppSolution(
        epoch.t_gps_s,
        bool(res["ok"]),
        res["reason"],
        res["x"].copy(),
        systems,
        res["clocks"][present].copy(),
        cov,
        math.sqrt(0.5 * float(cov_enu[0, 0] + cov_enu[1, 1])),
        math.sqrt(float(cov_enu[2, 2])),
        res["dops"],
        res["resid"],
        res["sigma"],
        res["used"],
        excluded,
        np.rad2deg(geo.el),
        np.rad2deg(geo.az),
        res["chi2"],
        dof,
        unit_var,
        raim_passed,
        iterations,
        v,
        drift,
        vacc,
    )


def _sigma_reference_m(config: SppConfig) -> float:
    """σ of an ideal observation (zenith, C/N0 at the reference) under the configured model."""
    w = config.weighting
    if w in ("uniform", "given"):
        return config.sigma_uniform_m
    return math.sqrt(
        config.sigma_floor_m**2 + (config.sigma_cn0_m if w == "cn0" else config.sigma_zenith_m) ** 2
    )


def _velocity(
    epoch: GnssEpoch, x: np.ndarray, geo: Geometry, used: np.ndarray, config: SppConfig
) -> tuple[np.ndarray, float, float]:
    """Receiver velocity (ECEF) and clock drift (m/s) from pseudorange rates (RTKLIB resdop)."""
    ok = used & np.isfinite(epoch.pseudorange_rate_m_s) & np.isfinite(epoch.sat_vel_ecef_m_s).all(axis=1)
    if ok.sum() < 4:
        return np.full(3, np.nan), math.nan, math.nan
    los, vs, rs = geo.los[ok], epoch.sat_vel_ecef_m_s[ok], epoch.sat_pos_ecef_m[ok]
    clk_drift = (
        np.zeros(int(ok.sum())) if epoch.corrected else C_M_S * np.nan_to_num(epoch.sat_clock_drift_s_s[ok])
    )
    # the pseudorange σ model's shape, scaled so that an ideal observation has sigma_range_rate_m_s
    sigma = sigma_model_m(epoch, geo.el, config)[ok] * (
        config.sigma_range_rate_m_s / _sigma_reference_m(config)
    )
    prr = epoch.pseudorange_rate_m_s[ok]
    v = np.zeros(4)
    h = np.column_stack((-los, np.ones(len(los))))
    q = np.eye(4)
    r = np.zeros(len(los))
    for _ in range(3):
        sagnac = (
            OMEGA_E_RAD_S / C_M_S * (vs[:, 0] * x[1] + rs[:, 0] * v[1] - vs[:, 1] * x[0] - rs[:, 1] * v[0])
        )
        sat_los = np.einsum("ij,ij->i", vs, los)
        geo_rate = sat_los - los @ v[:3]
        # light-time rate: the signal left the satellite at t − ρ/c, so its velocity enters × (1 − ρ̇/c)
        model = geo_rate - sat_los * geo_rate / C_M_S + sagnac + v[3] - clk_drift
        r = prr - model
        try:
            dv, q = _wls(h, r, 1.0 / sigma**2)
        except SingularGeometryError:  # no velocity from this geometry; the position stands
            return np.full(3, np.nan), math.nan, math.nan
        v = v + dv
    dof = len(r) - 4
    if config.accuracy == "a-posteriori" and dof > 0:
        r = r - h @ dv
        scale = max(1.0, float(np.sum((r / sigma) ** 2)) / dof)
    else:
        scale = 1.0
    return v[:3], float(v[3]), math.sqrt(float(np.trace(q[:3, :3]) * scale / 3.0))
