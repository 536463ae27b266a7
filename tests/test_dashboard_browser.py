"""The dashboard in real headless Chromium: during a live SITL flight (the three processes publish),
and with two synthetic vehicles plus malformed payloads (vehicle selector, counted errors, zoom, pan,
hover), and `chromium --headless --screenshot` of the snapshot view (a real, checked PNG)."""

import json
import os
import shlex
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
                        "--no-figures",
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
            # nothing lost on the way vehicle/estimator -> Zenoh -> dashboard -> SSE -> page; every
            # fix on the map (placed about the route's home)
            page.wait_for_function(
                f"() => window.dashboardVehicles.sitl1.series.truth.length === {n_truth}"
                f" && window.dashboardVehicles.sitl1.series.latency.length === {n_gnss}"
                f" && window.dashboardVehicles.sitl1.series.fix.length === {n_gnss}", timeout=5_000)
            msgs = page.evaluate("window.dashboardVehicles.sitl1.messages")
            assert vehicle["telemetry"]["published"] == n_truth + n_gnss + msgs["vehicle/status"]
            assert 0 < msgs["vehicle/status"] <= 70  # 1 Hz of a ~60 s flight, and on changes
            companion = sum(n for k, n in msgs.items() if k.startswith("companion/"))
            assert companion == estimator["telemetry"]["published"]
            n_est = page.evaluate("window.dashboardVehicles.sitl1.series.est.length")
            assert n_est == msgs["companion/estimate"]
            assert msgs["bridge/route"] >= 1 and msgs["bridge/setpoint"] > 500
            assert rate_hz >= 10, rate_hz
            assert page.evaluate("window.dashboardStats.malformed") == 0
            assert page.evaluate("window.dashboardView().selected") == "sitl1"
            # the status bar: what QGroundControl shows first
            text = {k: page.inner_text(f"#f-{k}") for k in ("mode", "armed", "fix", "sats", "hdop", "alt",
                                                              "lat", "beta")}
            assert text["mode"] in ("OFFBOARD", "HOLD") and text["armed"] == "ARMED", text
            assert text["fix"] == "3D fix" and int(text["sats"]) > 3, text
            assert text["hdop"] == "–"  # the simulated receiver reports none: not made up
            assert abs(float(text["alt"].removesuffix(" m")) - 15.0) < 2.0  # the test city flies at 15 m
            assert text["lat"].endswith(" s") and 0 <= float(text["lat"].removesuffix(" s")) < 2  # seconds
            # counters in words, the raw names on demand
            counters = page.inner_text("#counters")
            assert "GNSS fixes fused" in counters and "fixes rejected by the innovation gate" in counters
            assert "gnss_fused" not in counters
            page.click("#all-counters summary")
            assert "companion/gnss_fused" in page.inner_text("#raw-counters")
            # the legends show the newest values, not "–"
            legend = page.eval_on_selector_all("#beta .u-legend .u-value", "vs => vs.map(v => v.textContent)")
            last_beta = page.evaluate("(() => { const b = window.dashboardVehicles.sitl1.series.beta;"
                                      " return b[b.length - 1][1]; })()")
            assert float(legend[1]) == pytest.approx(last_beta, abs=6e-4), legend
            latency = page.eval_on_selector_all("#latency .u-legend .u-value", "vs => vs[1].textContent")
            assert latency.endswith(" s")
            # the flight is over: after 2 s of silence the page says so (the vehicle is at its goal),
            # and the processes it stopped say "ended", not "stale"
            page.wait_for_function(
                "() => document.getElementById('freshness').textContent.startsWith('ended at goal')",
                timeout=10_000)
            processes = page.inner_text("#processes")
            assert "ended" in processes and "stale" not in processes, processes
            assert page.evaluate("window.dashboardVehicles.sitl1.status.companion") == "ended"  # last word
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
        synth = ["-m", "gcs_tools.synth", "--duration-s", "120", "--speed", "6", "--wait-subscriber"]
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
                # the plots redraw (a wait, not an instant check: on a slowed VM the count stood at 10 here)
                page.wait_for_function("() => window.dashboardStats.draws > 10", timeout=10_000)
                assert page.evaluate("window.dashboardStats.malformed") == 2
                assert "malformed payloads: 2" in page.inner_text("#malformed")
                assert page.eval_on_selector_all("#vehicle option", "os => os.map(o => o.value).sort()") == [
                    "uav1", "uav2"]
                assert "GNSS fixes fused" in page.inner_text("#counters")
                view = page.evaluate("window.dashboardView()")
                assert view["selected"] == view["order"][-1]  # the newest vehicle is shown
                page.select_option("#vehicle", "uav2")
                page.wait_for_timeout(300)
                _time_window(page)
                _zoom_pan_hover(page)
                _screenshot(page, tmp_path / "dashboard.png")
            finally:
                browser.close()
        dash.terminate()
        _, err = dash.communicate(timeout=20)
    assert dash.returncode == 0
    assert "2 malformed" in err


def _time_window(page) -> None:
    """The time window is chosen, not fixed: 30 s shows the last 30 s, "all" everything kept."""
    page.wait_for_function("() => { const x = window.dashboardView().x.beta; return x[1] - x[0] > 31; }",
                           timeout=40_000)  # more than 30 s of data
    page.select_option("#window", "30")
    page.wait_for_timeout(300)
    lo, hi = page.evaluate("window.dashboardView()")["x"]["beta"]
    assert hi - lo == pytest.approx(30, abs=0.5)
    page.select_option("#window", "0")
    page.wait_for_timeout(300)
    first = page.evaluate("window.dashboardVehicles.uav2.series.beta[0][0]")
    assert page.evaluate("window.dashboardView()")["x"]["beta"][0] == pytest.approx(first, abs=0.01)
    page.select_option("#window", "120")


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


def _readme_screenshot_command() -> list[str]:
    """The README's screenshot command, word for word (shell-split)."""
    readme = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    block = readme.split("**Ground tools**", 1)[1].split("```bash\n", 1)[1].split("```", 1)[0]
    line = next(x for x in block.splitlines() if x.startswith("chromium "))
    return shlex.split(line)


@needs_chromium
def test_the_readmes_headless_screenshot_works_as_written(tmp_path):
    """The README's `chromium --headless --screenshot=... '/?snapshot=1'` exactly as written (its port
    and file name swapped for free ones; `--no-sandbox` added only when the test runs as root, which
    Chromium otherwise refuses; no `--virtual-time-budget`): the PNG shows the data, not "connecting…"
    (the page draws the snapshot while it loads), with every plot, the map and the status bar."""
    from PIL import Image

    from gcs_tools import palette

    words = _readme_screenshot_command()
    assert words[0] == "chromium" and "--headless" in words and not any("virtual-time" in w for w in words)
    env = hub_env()
    port = free_port()
    png = tmp_path / "dashboard.png"
    argv = [CHROMIUM] + [w.replace("8080", str(port)) if w.startswith("http") else
                         f"--screenshot={png}" if w.startswith("--screenshot") else w for w in words[1:]]
    if os.geteuid() == 0:
        argv.insert(1, "--no-sandbox")
    with child(["-m", "gcs_tools", "dashboard", "--port", str(port)], env) as dash:
        assert dash.stdout.readline().startswith("dashboard on http://127.0.0.1:")
        with child(["-m", "gcs_tools.synth", "--duration-s", "8", "--speed", "4", "--wait-subscriber",
                    "--vehicle", "uav3"], env) as synth:
            synth.communicate(timeout=60)
        t0 = time.monotonic()
        shot = subprocess.run(argv, capture_output=True, timeout=90, cwd=tmp_path)
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
    for meaning in ("beta", "nis", "est_error", "latency", "building", "gnss"):
        assert n(q[meaning]) > 30, (meaning, n(q[meaning]))  # each drawn in its colour
    assert n("#2a7d3a") > 100  # the status bar's green "ARMED" and "3D fix"
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
