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


def test_write_results_or_error_writes_on_success_and_is_one_line_on_a_user_error(tmp_path, capsys):
    from companion.errors import UserError
    from gcs_tools.jsonvalues import write_results_or_error

    assert write_results_or_error(tmp_path / "ok", lambda: {"x": float("nan")}, lambda r: "# table\n") == 0
    assert json.loads((tmp_path / "ok" / "results.json").read_text()) == {"x": None}
    assert (tmp_path / "ok" / "results.md").read_text() == "# table\n"
    assert capsys.readouterr().out == "# table\n\n"

    def bad() -> None:
        raise UserError("--rows: choose from a, b")

    assert write_results_or_error(tmp_path / "bad", bad, lambda r: "never") == 2
    printed = capsys.readouterr()  # on stderr, as every command's error (it was on stdout)
    assert printed.err == "beliefnav: error: --rows: choose from a, b\n" and printed.out == ""
    assert not (tmp_path / "bad").exists()
