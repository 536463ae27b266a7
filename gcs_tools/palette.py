"""One colour per meaning, for every figure (matplotlib) and the dashboard (served as /palette.json).

A colour names one thing everywhere: black is always the truth, blue always the estimate, green
always the belief β. Methods have their own colours, used only where methods are compared.
"""

from __future__ import annotations

from typing import Any

QUANTITY: dict[str, str] = {
    "true": "#000000",  # true position / true GNSS bias (simulation truth)
    "estimated": "#1f77b4",  # the companion's estimate (position, bias)
    "reference": "#7f7f7f",  # planned path / setpoint (drawn dashed)
    "gnss": "#17becf",  # GNSS fixes
    "autopilot": "#8c6d31",  # a flight controller's own estimate (logs)
    "beta": "#2ca02c",  # GNSS trust belief β
    "nis": "#bcbd22",  # normalised innovation squared
    "clearance": "#8c564b",  # distance to the nearest building
    "latency": "#9467bd",  # GNSS latency
    "est_error": "#ff7f0e",  # estimation error ‖p̂ − p‖
    "track_error": "#e377c2",  # tracking error ‖p − p_ref‖
    "building": "#bfbfbf",  # map rectangles (fill)
    "rejected": "#d62728",  # a GNSS fix the filter rejected (its innovation gate)
    "gnss_step": "#cc79a7",  # a GNSS fix held as a step (fused only relative to an open GNSS offset)
    "reset": "#6a3d9a",  # the estimate reset onto a fix (or, tight, onto a single-point solution)
    "sats_used": "#009e73",  # satellites a tightly coupled epoch used
    "uncertainty": "#1f77b4",  # the estimate's 95 % horizontal uncertainty ellipse (as the estimate)
    "real_data": "#a50f15",  # a real data set beside the simulator (calibration)
    "simulated": "#1b9e77",  # the simulator's counterpart of a real data set
}

METHOD: dict[str, str] = {
    "naive": "#d62728",
    "adaptive": "#e6ab02",
    "first-order": "#1b9e77",
    "second-order": "#3f007d",
    "vbakf": "#a6761d",
    "paper-literal": "#fb9a99",
}
OTHER_METHOD = "#b15928"

# Line styles for methods drawn over each other (Fig. 4): dashes keep a lower line visible.
METHOD_DASH: dict[str, Any] = {
    "naive": "-",
    "adaptive": (0, (6, 2)),
    "first-order": (0, (5, 2.5)),
    "second-order": (0, (1.2, 1.2)),
    "vbakf": (0, (3, 1, 1, 1)),
}


# Categorical colours for items of one kind drawn together (mission profiles in Fig. 3): Okabe-Ito
# and Tableau colours that stay apart for colour-blind readers, in an order that keeps neighbours apart.
CATEGORICAL: tuple[str, ...] = (
    "#0072b2", "#e69f00", "#009e73", "#cc79a7", "#56b4e9", "#d55e00", "#000000", "#8c564b",
    "#999933", "#7f7f7f", "#17becf", "#6a3d9a",
)


def category(index: int) -> str:
    """The colour of item ``index`` among items of one kind (cycles after 12)."""
    return CATEGORICAL[index % len(CATEGORICAL)]


def quantity(name: str) -> str:
    return QUANTITY[name]


def method(name: str) -> str:
    return METHOD.get(name, OTHER_METHOD)


def as_json() -> dict[str, Any]:
    """What the dashboard reads (so page and figures never disagree)."""
    return {"quantity": dict(QUANTITY), "method": dict(METHOD)}
