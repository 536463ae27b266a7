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
