"""``gcs_tools.bench.instructions``: the stream it counts is the benchmark's, and runs (here without
valgrind, whose count the docs quote: docs/benchmarks.md, "Instruction counts")."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from gcs_tools.bench import estimator as be
from gcs_tools.bench.instructions import WORKLOAD


@pytest.mark.parametrize("which", ["estimator", "tight"])
def test_the_workload_runs_one_stream(which):
    """The measured process's code, run as it is: a warm-up stream, then the counted one inside
    functools.reduce, ending at a position; the estimator's is the benchmark's own stream's."""
    proc = subprocess.run([sys.executable, "-c", WORKLOAD, which, "1.0"], capture_output=True, text=True,
                          timeout=300, check=True)
    final = [line for line in proc.stdout.splitlines() if line.startswith("final")]
    assert len(final) == 1
    position = json.loads(final[0][6:])  # a list of three floats
    assert len(position) == 3 and all(isinstance(v, float) for v in position)
    if which == "estimator":
        est = be.streaming_wall_s(be.flight(1.0, None))[2].estimate()
        assert est is not None and position == est.p_ned_m.tolist()


@pytest.mark.parametrize("argv, says", [
    (["estimator", "--duration-s", "nan"], "--duration-s: must be a finite number > 0"),
    (["tight", "--duration-s", "-1"], "--duration-s: must be a finite number > 0"),
    (["estimator", "--tree", "/nonexistent/tree"], "--tree: not a directory"),
])
def test_bad_options_are_one_line_errors(argv, says, capsys):
    from gcs_tools.bench.instructions import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and says in err[-1]


def test_without_valgrind_one_line_error(monkeypatch, capsys):
    from gcs_tools.bench import instructions

    monkeypatch.setattr(instructions.shutil, "which", lambda name: None)
    with pytest.raises(SystemExit) as exc:
        instructions.main(["estimator"])
    assert exc.value.code == 2 and "valgrind not found" in capsys.readouterr().err.strip().splitlines()[-1]


def test_a_failing_valgrind_run_is_one_line(monkeypatch, capsys):
    from gcs_tools.bench import instructions

    def fail(*a, **k):
        raise RuntimeError("valgrind failed (1): ==1== warning\nvalgrind: the 'impossible' happened")

    monkeypatch.setattr(instructions, "count", fail)
    monkeypatch.setattr(instructions.shutil, "which", lambda name: "/usr/bin/valgrind")
    with pytest.raises(SystemExit) as exc:
        instructions.main(["tight", "--duration-s", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 1 and len(err) == 1 and "the 'impossible' happened" in err[0]
