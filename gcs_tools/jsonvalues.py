"""Summaries as plain JSON values: numpy scalars and arrays become Python numbers and lists."""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from companion.errors import UserError


def plain_json(value: Any, *, nan_to_none: bool) -> Any:
    """Recursively convert dicts, lists, tuples, numpy arrays and scalars to plain JSON values.

    ``nan_to_none``: NaN/inf become ``None`` (strict JSON files); otherwise they stay floats
    (in-memory results that are compared or aggregated)."""
    if isinstance(value, dict):
        return {str(k): plain_json(v, nan_to_none=nan_to_none) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_json(v, nan_to_none=nan_to_none) for v in value]
    if isinstance(value, np.ndarray):
        return plain_json(value.tolist(), nan_to_none=nan_to_none)
    if isinstance(value, np.generic):
        value = value.item()
    if nan_to_none and isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_results(out_dir: Path, result: Any, markdown: str) -> str:
    """``out_dir/results.json`` (plain JSON, NaN as null) and ``out_dir/results.md`` (the directory made);
    returns the markdown (to print)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "results.json").write_text(json.dumps(plain_json(result, nan_to_none=True), indent=1) + "\n")
    (out_dir / "results.md").write_text(markdown)
    return markdown


def write_results_or_error(out_dir: Path, compute: Callable[[], Any], markdown: Callable[[Any], str]) -> int:
    """An evaluation command's ending: ``compute()``'s result written (``write_results``) and its markdown
    printed, 0; a ``UserError`` it raised printed as one line ``beliefnav: error: …`` on stderr (as every
    command's), 2."""
    try:
        result = compute()
    except UserError as exc:
        print(f"beliefnav: error: {exc}", file=sys.stderr)
        return 2
    print(write_results(out_dir, result, markdown(result)))
    return 0
