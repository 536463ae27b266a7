"""The dashboard in real headless Chromium during a live (synthetic, two-vehicle) telemetry run."""

import shutil
import time
from pathlib import Path

import pytest
from telemetry_helpers import child, free_port, hub_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]


@pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="Debian chromium is not installed (make browser)")
def test_dashboard_plots_live_data_in_chromium(tmp_path):
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
                shot = tmp_path / "dashboard.png"
                page.screenshot(path=str(shot))
                assert shot.stat().st_size > 20_000
                print(f"screenshot: {shot}")
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
