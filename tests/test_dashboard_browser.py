"""The dashboard in real headless Chromium: during a live SITL flight (the three processes publish),
and with two synthetic vehicles plus malformed payloads (vehicle selector, counted errors)."""

import json
import shutil
import time
from pathlib import Path

import pytest
from telemetry_helpers import child, free_port, hub_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]


needs_chromium = pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                   reason="Debian chromium is not installed (make browser)")


def _screenshot(page, path: Path) -> None:
    page.screenshot(path=str(path))
    assert path.stat().st_size > 20_000  # a blank page is ~5 kB
    print(f"screenshot: {path}")


def _sim_state_count(tlog: Path) -> int:
    from companion.mavlink.tlog import read_tlog

    return sum(1 for _ in read_tlog(tlog, ["SIM_STATE"]))


@needs_chromium
def test_dashboard_plots_a_live_sitl_flight_in_chromium(tmp_path):
    """Dashboard first (the hub), page open, then `beliefnav sitl` on the small test mission: every
    truth, GNSS and estimator message the processes published reaches the page's plots."""
    playwright = pytest.importorskip("playwright.sync_api")
    pytest.importorskip("simvehicle")
    env = hub_env()
    port = free_port()
    out = tmp_path / "sitl"
    with child(["-m", "gcs_tools", "dashboard", "--port", str(port)], env) as dash, \
            playwright.sync_playwright() as p:
        assert dash.stdout.readline().startswith("dashboard on http://127.0.0.1:")
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1300, "height": 900})
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function("() => window.dashboardStats.frames > 0", timeout=10_000)
            with child(["-m", "gcs_tools", "sitl", "--mission", "test", "--out", str(out), "--no-progress",
                        "--vehicle-id", "sitl1", "--wall-timeout-s", "40"], env) as sitl:
                page.wait_for_function(
                    "() => { const v = window.dashboardVehicles.sitl1; return v && v.route && ['truth',"
                    " 'est', 'ref', 'beta', 'err', 'latency'].every(s => (v.series[s] || []).length > 20); }",
                    timeout=30_000)
                f0, t0 = page.evaluate("window.dashboardStats.frames"), time.monotonic()
                sitl_out, sitl_err = sitl.communicate(timeout=45)
                rate_hz = (page.evaluate("window.dashboardStats.frames") - f0) / (time.monotonic() - t0)
            assert sitl.returncode == 0, sitl_err
            assert "reached_goal" in sitl_out
            vehicle = json.loads((out / "vehicle.json").read_text())
            estimator = json.loads((out / "estimator.json").read_text())
            n_truth, n_gnss = _sim_state_count(out / "run.tlog"), vehicle["gnss_sent"]
            assert vehicle["telemetry"]["published"] == n_truth + n_gnss
            # nothing lost on the way vehicle/estimator -> Zenoh -> dashboard -> SSE -> page
            page.wait_for_function(
                f"() => window.dashboardVehicles.sitl1.series.truth.length === {n_truth}"
                f" && window.dashboardVehicles.sitl1.series.latency.length === {n_gnss}", timeout=5_000)
            msgs = page.evaluate("window.dashboardVehicles.sitl1.messages")
            companion = sum(n for k, n in msgs.items() if k.startswith("companion/"))
            assert companion == estimator["telemetry"]["published"]
            n_est = page.evaluate("window.dashboardVehicles.sitl1.series.est.length")
            assert n_est == msgs["companion/estimate"]
            assert msgs["bridge/route"] >= 1 and msgs["bridge/setpoint"] > 500
            assert rate_hz >= 10, rate_hz
            assert page.evaluate("window.dashboardStats.malformed") == 0
            assert "gnss_fused" in page.inner_text("#counters")
            _screenshot(page, tmp_path / "dashboard_sitl.png")
        finally:
            browser.close()
        dash.terminate()
        dash.communicate(timeout=20)
    assert dash.returncode == 0


@needs_chromium
def test_dashboard_shows_two_vehicles_and_malformed_payloads_in_chromium(tmp_path):
    playwright = pytest.importorskip("playwright.sync_api")
    env = hub_env()
    port = free_port()
    with child(["-m", "gcs_tools", "dashboard", "--port", str(port)], env) as dash:
        assert dash.stdout.readline().startswith("dashboard on http://127.0.0.1:")
        synth = ["-m", "gcs_tools.synth", "--duration-s", "60", "--wait-subscriber"]
        with child([*synth, "--vehicle", "uav1", "--malformed", "2"], env), \
                child([*synth, "--vehicle", "uav2", "--seed", "1"], env), \
                playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            try:
                page = browser.new_page(viewport={"width": 1300, "height": 900})
                page.goto(f"http://127.0.0.1:{port}/")
                page.wait_for_function(
                    "() => ['uav1', 'uav2'].every(n => window.dashboardVehicles[n]"
                    " && ['truth', 'est', 'beta', 'err', 'latency', 'ref'].every("
                    "   s => (window.dashboardVehicles[n].series[s] || []).length > 5)"
                    " && window.dashboardVehicles[n].route)", timeout=30_000)
                # updates at >= 10 Hz, counted by the page on its own clock
                f0, t0 = page.evaluate("window.dashboardStats.frames"), time.monotonic()
                page.wait_for_timeout(2000)
                rate_hz = (page.evaluate("window.dashboardStats.frames") - f0) / (time.monotonic() - t0)
                assert rate_hz >= 10, rate_hz
                assert page.evaluate("window.dashboardStats.draws") > 10
                assert page.evaluate("window.dashboardStats.malformed") == 2
                assert "malformed payloads: 2" in page.inner_text("#malformed")
                assert page.eval_on_selector_all("#vehicle option", "os => os.map(o => o.value).sort()") == [
                    "uav1", "uav2"]
                assert "gnss_fused" in page.inner_text("#counters")
                page.select_option("#vehicle", "uav2")
                page.wait_for_timeout(300)
                _screenshot(page, tmp_path / "dashboard.png")
            finally:
                browser.close()
        dash.terminate()
        _, err = dash.communicate(timeout=20)
    assert dash.returncode == 0
    assert "2 malformed" in err


def test_port_in_use_is_one_line_error():
    import socket

    env = hub_env()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with child(["-m", "gcs_tools", "dashboard", "--port", str(port)], env) as dash:
            _, err = dash.communicate(timeout=30)
    assert dash.returncode == 2
    want = f"beliefnav: error: port {port} on 127.0.0.1 is already in use (choose another with --port)"
    assert err.strip() == want
