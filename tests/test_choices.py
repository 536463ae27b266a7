"""Mistyped options are one line naming the valid choices and the nearest one."""

import subprocess
import sys

import pytest

from companion.errors import UserError
from gcs_tools import choices


def test_method_typo_names_every_method_and_the_nearest():
    from companion.estimator import METHODS

    with pytest.raises(UserError) as exc:
        choices.method("secnd-order")
    msg = str(exc.value)
    assert msg.startswith("--method 'secnd-order': not one of ") and all(m in msg for m in METHODS)
    assert msg.endswith("(did you mean 'second-order'?)")
    assert choices.methods("naive, second-order") == ["naive", "second-order"]
    with pytest.raises(UserError, match="'navie'.*did you mean 'naive'"):
        choices.methods("navie,second-order")


def test_mission_typo_lists_packaged_missions(tmp_path):
    with pytest.raises(UserError) as exc:
        choices.mission("defualt")
    assert str(exc.value) == ("--mission 'defualt': no such file and not a packaged mission "
                              "(packaged: default, test, default-tuning, mild, mild-tuning; "
                              "did you mean 'default'?)")
    m = choices.mission("test")
    assert choices.profile(m, 2) == 2
    with pytest.raises(UserError, match=r"--profile 3: mission 'test-city' has profiles 0 through-canyon, "):
        choices.profile(m, 3)


def test_export_format_typo_is_rejected_by_the_cli():
    done = subprocess.run([sys.executable, "-m", "gcs_tools", "export", "x", "--format", "mcapp"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "invalid choice: 'mcapp' (choose from 'mcap', 'csv')" in done.stderr


def test_positive_numbers_refuse_zero_negative_and_non_finite():
    assert choices.positive(None, "--rate-hz") is None and choices.positive(0.5, "--rate-hz") == 0.5
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(UserError, match=r"^--rate-hz must be a finite number > 0, got "):
            choices.positive(bad, "--rate-hz")


@pytest.mark.parametrize("command", [
    ("gcs_tools.evaluate.tight_sim", "--rate-hz", "0"),
    ("gcs_tools.evaluate.tight_sim", "--rate-hz", "nan"),
    ("gcs_tools.evaluate.tight_sim", "--max-duration-s", "0"),
    ("gcs_tools.evaluate.attitude_check", "--max-duration-s", "0"),
    ("gcs_tools.evaluate.smartloc_export", "--max-duration-s", "-1"),
])
def test_evaluation_commands_refuse_a_bad_number_before_flying(tmp_path, command):
    module, option, value = command
    done = subprocess.run([sys.executable, "-m", module, option, value, "--seeds", "0", "--profiles", "0",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stdout + done.stderr
    expected = f"{option} must be a finite number > 0, got {float(value)!r}"
    assert done.stderr.strip().splitlines()[-1].endswith(expected)
    assert not (tmp_path / "out" / "results.json").exists()
