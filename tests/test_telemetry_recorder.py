"""Recorder: nothing lost at full rate (sent vs recorded), malformed counted, plot redraws from it."""

import json

import numpy as np
import pytest
from telemetry_helpers import child, hub_env

from gcs_tools.recorder.recording import read_recording, series

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def test_recorder_loses_nothing_and_plot_redraws(tmp_path):
    env = hub_env()
    out = tmp_path / "run.jsonl"
    with child(["-m", "gcs_tools", "record", "--out", str(out)], env) as rec:
        assert rec.stdout.readline().startswith("recording")
        # 4 s of flight at 4x real time: ~1200 messages/s from three publishing sessions
        with child(["-m", "gcs_tools.synth", "--duration-s", "4", "--speed", "4", "--wait-subscriber",
                    "--malformed", "2"], env) as synth:
            s_out, s_err = synth.communicate(timeout=60)
            assert synth.returncode == 0, s_err
        sent = json.loads(s_out.strip().splitlines()[-1])
        assert all(c["encode_errors"] == c["put_errors"] == 0 for c in sent.values())
        rec.terminate()  # SIGTERM: the recorder flushes and closes its session
        r_out, r_err = rec.communicate(timeout=20)
    n_sent = sum(c["published"] for c in sent.values())
    assert f"recorded {n_sent} messages (2 malformed)" in r_err
    lines = out.read_bytes().splitlines()
    assert len(lines) == n_sent + 2

    recording = read_recording(out)
    assert recording.vehicles == ["uav1"] and recording.malformed == 2
    by = recording.messages["uav1"]
    assert len(by["estimate"]) == len(by["truth"]) == 200 and len(by["gnss"]) == 40
    s = series(recording, "uav1")
    # synthetic truth lies on a circle of radius 40 m: the interpolated truth must too
    assert np.allclose(np.hypot(s["p_true_ned_m"][:, 0], s["p_true_ned_m"][:, 1]), 40.0, atol=0.01)
    assert np.all(s["est_error_m"] < 5) and s["beta"].min() >= 0 and s["beta"].max() <= 1

    with child(["-m", "gcs_tools", "plot", str(out), "--out", str(tmp_path / "fig")], env) as plot:
        p_out, p_err = plot.communicate(timeout=60)
        assert plot.returncode == 0, p_err
    for name in ("uav1_map.png", "uav1_belief.png"):
        assert (tmp_path / "fig" / name).stat().st_size > 10_000


def test_plot_of_garbage_is_one_line_error(tmp_path):
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"key": "beliefnav/uav1/companion/estimate", "payload": {"t_us": "x"}}\nnot json\n')
    env = hub_env()
    with child(["-m", "gcs_tools", "plot", str(bad)], env) as plot:
        _, err = plot.communicate(timeout=30)
    assert plot.returncode == 2
    assert err.strip() == f"beliefnav: error: {bad}: no telemetry in this recording (2 malformed lines)"


def test_plot_of_a_vehicle_not_recorded_names_the_recorded_ones(tmp_path):
    """`plot --vehicle` with a typo says which vehicles the recording holds, as `export --vehicle-id` does."""
    rec = tmp_path / "run.jsonl"
    payload = {"t_us": 165000, "p_ned_m": [5.0, 47.0, -15.0], "v_ned_m_s": [0.0, 0.0, 0.0],
               "b_ned_m": [0.0, 0.0, 0.0], "cov_diag": [0.02] * 3 + [1.0] * 3 + [0.04] * 3, "beta": 0.5,
               "nis": None, "method": "second-order", "sent_unix_ns": 1795858207326480822}
    line = {"key": "beliefnav/uav1/companion/estimate", "recv_unix_ns": 1795858207327754033,
            "payload": payload}
    rec.write_text(json.dumps(line) + "\n")
    assert read_recording(rec).vehicles == ["uav1"]
    with child(["-m", "gcs_tools", "plot", str(rec), "--vehicle", "uav2", "--out", str(tmp_path / "fig")],
               hub_env()) as plot:
        _, err = plot.communicate(timeout=30)
    assert plot.returncode == 2
    assert err.strip() == f"beliefnav: error: {rec}: no vehicle 'uav2' (valid: uav1)"
    assert not (tmp_path / "fig").exists()


def test_plot_of_a_run_directory_says_what_plot_reads(tmp_path):
    """A user pointing `plot` at a run folder is told it reads a `beliefnav record` file."""
    run_dir = tmp_path / "runs" / "sitl"
    run_dir.mkdir(parents=True)
    with child(["-m", "gcs_tools", "plot", str(run_dir)], hub_env()) as plot:
        _, err = plot.communicate(timeout=30)
    assert plot.returncode == 2
    assert err.strip() == (f"beliefnav: error: {run_dir}: a directory; give a recording made by "
                           "`beliefnav record` (.jsonl)")
