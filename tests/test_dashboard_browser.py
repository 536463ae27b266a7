"""The dashboard in real headless Chromium: during a live SITL flight (the three processes publish),
and with two synthetic vehicles plus malformed payloads (vehicle selector, counted errors, zoom, pan,
hover), and `chromium --headless --screenshot` of the snapshot view (a real, checked PNG)."""

import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest
from telemetry_helpers import child, free_port, hub_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

# BELIEFNAV_CHROMIUM: any Chromium binary (e.g. one installed without root by `playwright install chromium`)
CHROMIUM = os.environ.get("BELIEFNAV_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]


needs_chromium = pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                   reason="no Chromium (make browser, or set BELIEFNAV_CHROMIUM)")


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
            assert "reached goal" in sitl_out
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
            assert page.evaluate("window.dashboardView().selected") == "sitl1"
            # the flight is over: after 2 s of silence the page says so (the vehicle is at its goal)
            page.wait_for_function(
                "() => document.getElementById('freshness').textContent.startsWith('ended at goal')",
                timeout=10_000)
            assert "stale" in page.inner_text("#counters")  # "companion ok" no more
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
                view = page.evaluate("window.dashboardView()")
                assert view["selected"] == view["order"][-1]  # the newest vehicle is shown
                page.select_option("#vehicle", "uav2")
                page.wait_for_timeout(300)
                _zoom_pan_hover(page)
                _screenshot(page, tmp_path / "dashboard.png")
            finally:
                browser.close()
        dash.terminate()
        _, err = dash.communicate(timeout=20)
    assert dash.returncode == 0
    assert "2 malformed" in err


def _zoom_pan_hover(page) -> None:
    """Drag zooms all three charts to one narrower x range and stops following; hover shows values;
    shift-drag pans; double-click follows live again."""
    box = page.locator("#beta .u-over").bounding_box()
    y = box["y"] + box["height"] / 2
    before = page.evaluate("window.dashboardView()")
    assert before["follow"]
    page.mouse.move(box["x"] + box["width"] * 0.5, y)
    page.wait_for_timeout(200)
    values = page.eval_on_selector_all("#beta .u-legend .u-value", "vs => vs.map(v => v.textContent)")
    assert values[1] != "–" and 0 <= float(values[1]) <= 1, values  # β under the cursor
    page.mouse.move(box["x"] + box["width"] * 0.3, y)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] * 0.6, y, steps=5)
    page.mouse.up()
    page.wait_for_timeout(300)
    zoomed = page.evaluate("window.dashboardView()")
    assert not zoomed["follow"]
    ranges = list(zoomed["x"].values())
    assert all(r == ranges[0] for r in ranges)  # the charts stay in step
    width = ranges[0][1] - ranges[0][0]
    b0 = before["x"]["beta"]
    assert 0.15 * (b0[1] - b0[0]) < width < 0.5 * (b0[1] - b0[0])
    page.keyboard.down("Shift")
    page.mouse.move(box["x"] + box["width"] * 0.6, y)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] * 0.4, y, steps=5)
    page.mouse.up()
    page.keyboard.up("Shift")
    panned = page.evaluate("window.dashboardView()")["x"]["beta"]
    assert panned[0] > ranges[0][0] and abs((panned[1] - panned[0]) - width) < 1e-6 * max(1.0, width)
    page.mouse.dblclick(box["x"] + box["width"] * 0.5, y)
    page.wait_for_function("() => window.dashboardView().follow", timeout=3_000)


@needs_chromium
def test_headless_chromium_screenshot_of_the_snapshot_view(tmp_path):
    """`chromium --headless --screenshot` of /?snapshot=1 returns (the page opens no event stream) and
    the PNG shows the charts in the palette's colours and a map."""
    from PIL import Image

    from gcs_tools import palette

    env = hub_env()
    port = free_port()
    with child(["-m", "gcs_tools", "dashboard", "--port", str(port)], env) as dash:
        assert dash.stdout.readline().startswith("dashboard on http://127.0.0.1:")
        with child(["-m", "gcs_tools.synth", "--duration-s", "4", "--wait-subscriber", "--vehicle", "uav3"],
                   env) as synth:
            synth.communicate(timeout=60)
        png = tmp_path / "snapshot.png"
        t0 = time.monotonic()
        shot = subprocess.run([CHROMIUM, "--headless", *ARGS, "--window-size=1300,900",
                               "--virtual-time-budget=10000", f"--screenshot={png}",
                               f"http://127.0.0.1:{port}/?snapshot=1"], capture_output=True, timeout=90)
        elapsed_s = time.monotonic() - t0
        dash.terminate()
        dash.communicate(timeout=20)
    assert shot.returncode == 0, shot.stderr[-2000:]
    print(f"chromium --screenshot returned in {elapsed_s:.1f} s")
    img = Image.open(png).convert("RGB")
    assert img.size == (1300, 900)
    counts = {rgb: k for k, rgb in img.getcolors(maxcolors=1 << 24)}

    def n(hex_colour: str) -> int:
        rgb = tuple(int(hex_colour[i:i + 2], 16) for i in (1, 3, 5))
        return counts.get(rgb, 0)

    q = palette.QUANTITY
    for meaning in ("beta", "nis", "est_error", "latency", "building"):
        assert n(q[meaning]) > 50, (meaning, n(q[meaning]))  # each plotted in its colour
    assert len(counts) > 200  # not a blank page


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
