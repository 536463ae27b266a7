"""Human labels of the counters a viewer shows first (the dashboard and ``beliefnav top``); every
other counter is shown on demand under its own name."""

from __future__ import annotations

from typing import Any

# (counter, label, shown in red when non-zero): the estimator's, in the order a reader scans them
KEY_COUNTERS: tuple[tuple[str, str, bool], ...] = (
    ("imu_used", "IMU samples used", False),
    ("gnss_fused", "GNSS fixes fused", False),
    ("gnss_rejected_innovation", "fixes rejected by the innovation gate", True),
    ("gnss_offsets", "GNSS steps held as an offset", False),
    ("gnss_resets", "filter reset to GNSS", True),
    ("gnss_out_of_order", "late fixes fused out of order", False),
)
OTHER_REJECTED = "other samples rejected"  # the sum of every other *_rejected_* counter


def headline(counters: dict[str, int]) -> list[tuple[str, int, bool]]:
    """(label, value, alarm) of the key counters a process has, then the other rejections summed."""
    keys = {k for k, _, _ in KEY_COUNTERS}
    rows = [(label, int(counters[k]), red and counters[k] > 0)
            for k, label, red in KEY_COUNTERS if k in counters]
    other = sum(int(n) for k, n in counters.items() if "rejected" in k and k not in keys)
    if rows or other:
        rows.append((OTHER_REJECTED, other, other > 0))
    return rows


def as_json() -> dict[str, Any]:
    """What the page reads (so the dashboard and ``top`` label alike)."""
    return {"key": [list(k) for k in KEY_COUNTERS], "other_rejected": OTHER_REJECTED}
