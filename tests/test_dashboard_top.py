"""``beliefnav top`` shows the live numbers (and the malformed count) of a synthetic run."""

import pytest
from telemetry_helpers import child, hub_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(60)]


def test_top_shows_live_numbers():
    env = {**hub_env(), "COLUMNS": "200"}
    with child(["-m", "gcs_tools", "top", "--duration-s", "4"], env) as top:
        assert top.stderr.readline().startswith("top: subscribed")  # subscriber first: nothing missed
        with child(["-m", "gcs_tools.synth", "--vehicle", "uav7", "--duration-s", "3", "--speed", "2",
                    "--wait-subscriber", "--malformed", "1"], env) as synth:
            synth.communicate(timeout=30)
        out, err = top.communicate(timeout=30)
    assert top.returncode == 0, err
    last = out[out.rindex("beliefnav vehicles"):]
    assert "uav7" in last and "second-order" in last
    assert "OFFBOARD armed" in last or "HOLD armed" in last  # the vehicle's flight mode
    assert "3D fix, 12 sats" in last
    assert "fixes rejected by the innovation gate" in last and "GNSS fixes fused" in last  # labels
    assert "malformed payloads: 1" in last
    for header in ("t [s]", "est. error [m]", "GNSS latency [s]", "altitude [m]", "messages [count]"):
        assert header in last  # a unit in every column header
    # the state column, as the dashboard's badge: the synthetic run ends with a clean-finish health, so
    # the last frame may already say "ended" (or still "live"); never an empty column
    assert any(state in last for state in ("live", "ended", "stale"))
