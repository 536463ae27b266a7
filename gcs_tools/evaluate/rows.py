"""Ablation rows from a YAML file (``beliefnav evaluate --rows FILE``).

A row is an estimator method with its OWN hyper-parameters, so one campaign can compare
``fixed-beta`` at two β, or every method at the values the tuning sweep chose for it::

    # label: {method: NAME, set: {SECTION.FIELD: VALUE, ...}}
    rows:
      naive: {method: naive}
      fixed-beta-0.5: {method: fixed-beta, set: {estimator.beta_fixed: 0.5}}

Row overrides are applied after the campaign's ``--set`` overrides (they win).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from companion.errors import UserError
from companion.mission import load_yaml
from gcs_tools.evaluate import tuning
from gcs_tools.evaluate.campaign import Row


def load_rows(path: Path) -> list[Row]:
    data = load_yaml(path)
    rows = data.get("rows")
    if not isinstance(rows, dict) or not rows:
        raise UserError(f"--rows {path}: expected a non-empty 'rows:' mapping of label -> {{method, set}}")
    return [_row(str(label), body, f"--rows {path}: rows.{label}") for label, body in rows.items()]


def _row(label: str, body: Any, where: str) -> Row:
    from companion.estimator import check_method

    if not isinstance(body, dict) or "method" not in body or set(body) - {"method", "set"}:
        raise UserError(f"{where}: expected {{method: NAME, set: {{SECTION.FIELD: VALUE}}}}")
    method = body["method"]
    check_method(str(method), f"{where}: unknown method")
    sets = body.get("set") or {}
    if not isinstance(sets, dict):
        raise UserError(f"{where}.set: expected a mapping SECTION.FIELD: VALUE")
    overrides = tuple(tuning.parse_override(f"{k}={v}") for k, v in sets.items())
    return Row(label, str(method), overrides)


def select(rows: list[Row], text: str | None) -> list[Row]:
    """The rows named in ``--methods`` (comma-separated labels), all when ``text`` is None."""
    if text is None:
        return rows
    by_label = {r.label: r for r in rows}
    wanted = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [w for w in wanted if w not in by_label]
    if unknown or not wanted:
        raise UserError(f"--methods: unknown row {unknown[0] if unknown else text!r} "
                        f"(rows in the file: {', '.join(by_label)})")
    return [by_label[w] for w in wanted]
