import json
import math

import numpy as np

from gcs_tools.jsonvalues import plain_json


def test_numpy_values_become_plain_and_nan_is_kept_or_nulled():
    value = {"a": np.float64(1.5), 2: [np.int64(3), (np.array([1.0, np.nan]),)], "b": float("inf")}
    kept = plain_json(value, nan_to_none=False)
    assert kept["a"] == 1.5 and type(kept["a"]) is float and type(kept["2"][0]) is int
    assert kept["2"][1][0][0] == 1.0 and math.isnan(kept["2"][1][0][1]) and kept["b"] == math.inf
    strict = plain_json(value, nan_to_none=True)
    assert strict == {"a": 1.5, "2": [3, [[1.0, None]]], "b": None}
    json.dumps(strict, allow_nan=False)  # strict JSON: raises if any NaN/inf were left
