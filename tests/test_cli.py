import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_cli_lists_commands_and_rejects_unknown():
    out = subprocess.run([sys.executable, "-m", "gcs_tools", "--help"], capture_output=True, text=True)
    assert out.returncode == 0
    for name in ("replay", "fly", "sitl", "bench", "evaluate", "dashboard"):
        assert name in out.stdout
    bad = subprocess.run([sys.executable, "-m", "gcs_tools", "nonsense"], capture_output=True, text=True)
    assert bad.returncode == 2


def test_top_level_help_imports_no_command_and_no_heavy_library():
    """`beliefnav --help` lists every command without importing any command's module (the start-up
    target is 1 s: `beliefnav bench cli`); the description reads like a product."""
    code = ("import sys; from gcs_tools.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print('LOADED', *sorted(m for m in sys.modules if m.startswith(('gcs_tools.', 'simvehicle', "
            "'numpy', 'matplotlib', 'scipy', 'zenoh', 'pymavlink', 'aiohttp'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    help_text, loaded = out.stdout.rsplit("LOADED", 1)
    assert loaded.split() == ["gcs_tools.cli"]
    assert "GNSS/IMU navigation for quadrotors between buildings" in help_text
    for name in ("fly", "sitl", "replay", "companion", "dashboard", "export", "gnss"):
        assert f"\n    {name} " in help_text


def test_parse_errors_are_one_line_with_a_hint():
    cases = ((["fly", "--seed", "x"], "beliefnav: error: fly: argument --seed: invalid int value: 'x'"),
             (["flyy"], "beliefnav: error: command 'flyy': not one of "),
             (["fly", "--scenario", "realstic"], "did you mean 'realistic'?"),
             (["replay", "x.tlog", "--home", "-37.8,144.7,0"],  # a southern latitude taken for an option
              "argument --home: expected one argument (if its value starts with '-': --home=-VALUE)"),
             # a misspelt option names the command and points at that command's help, not the top level's
             (["top", "--vehicel", "uav1"],
              "beliefnav: error: top: unrecognized arguments: --vehicel uav1 (see `beliefnav top --help`)"),
             # a negative or NaN run time would have meant "never stop"
             (["record", "--duration-s", "-1"], "record: argument --duration-s: -1 must be a finite number"),
             (["top", "--duration-s", "nan"], "top: argument --duration-s: nan must be a finite number"),
             (["dashboard", "--duration-s", "x"], "dashboard: argument --duration-s: 'x' is not a number"))
    for argv, want in cases:
        done = subprocess.run([sys.executable, "-m", "gcs_tools", *argv], capture_output=True, text=True,
                              timeout=60)
        assert done.returncode == 2 and done.stdout == ""
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and want in lines[0], done.stderr


def test_flight_summary_gnss_line_adds_up_and_names_the_rejections():
    from gcs_tools.summaries import gnss_line

    counters = {"gnss_fused": 2660, "gnss_rejected_too_old": 1, "gnss_rejected_innovation": 0}
    assert gnss_line({"sent": 2665, "fused": 2660, "rejected": 1}, counters) == (
        "GNSS fixes: 2,665 sent, 2,660 fused, 1 rejected (1 too old), 4 not yet delivered at the end")
    counters = {"gnss_rejected_innovation": 7, "gnss_rejected_future": 2}
    assert gnss_line({"sent": 109, "fused": 100, "rejected": 9}, counters) == (
        "GNSS fixes: 109 sent, 100 fused, 9 rejected (7 by the innovation gate, 2 from the future)")
    # counters that do not add up to the total (another source of rejections): no reasons claimed
    line = "GNSS fixes: 10 sent, 8 fused, 2 rejected"
    assert gnss_line({"sent": 10, "fused": 8, "rejected": 2}, {}) == line
    line = "GNSS fixes: 10 sent, 10 fused, none rejected"
    assert gnss_line({"sent": 10, "fused": 10, "rejected": 0}) == line


def test_bench_lines_print_a_list_of_records_one_per_line():
    """`bench robustness` without --json printed its 60 glitch cases as one JSON line of 20 kB."""
    from gcs_tools.bench.cli import human_lines

    lines = human_lines({"wall_s": 6.6412, "glitch": [
        {"glitch": "jump 10 m, 8 s", "ok": True, "distance_m": {"median": 0.123456, "max": 2.0}},
        {"glitch": "heading 90°", "ok": False, "distance_m": {"median": 1.0, "max": 2.5}}],
        "route_length_m": [175.3, 363.1]})
    assert lines == [f"{'wall_s':<48} 6.641",
                     f"{'glitch.0':<48} glitch=jump 10 m, 8 s  ok=True  distance_m.median=0.1235  "
                     "distance_m.max=2",
                     f"{'glitch.1':<48} glitch=heading 90°  ok=False  distance_m.median=1  "
                     "distance_m.max=2.5",
                     f"{'route_length_m':<48} [175.3, 363.1]"]


def test_a_port_out_of_range_is_one_line_before_anything_starts():
    """A TCP port the OS cannot bind (a typo such as 80800) is refused by the parser, not by a
    traceback from bind() in the server or in the simulated vehicle's process."""
    cases = ((["dashboard", "--port", "80800"],
              "dashboard: argument --port: 80800 is not a TCP port (1-65535)"),
             (["sitl", "--mission", "test", "--scenario", "canyon", "--ubx-port", "70000", "--out", "{tmp}"],
              "sitl: argument --ubx-port: 70000 is not a TCP port (1-65535)"),
             (["dashboard", "--port", "http"],
              "dashboard: argument --port: 'http' is not a TCP port (1-65535)"))
    for argv, want in cases:
        with tempfile.TemporaryDirectory() as tmp:
            done = subprocess.run([sys.executable, "-m", "gcs_tools", *(a.format(tmp=tmp) for a in argv)],
                                  capture_output=True, text=True, timeout=60)
            assert os.listdir(tmp) == []
        assert done.returncode == 2, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"beliefnav: error: {want}"), done.stderr


def test_sitl_refuses_an_unusable_signing_key_file_before_starting_anything():
    """An empty key file or a passphrase of two words: one line from `beliefnav sitl` itself, and no
    process started nor output folder made (it used to come from the estimator's child process)."""
    with tempfile.TemporaryDirectory() as tmp:
        for name, text, want in (("empty.key", "", "is empty"),
                                 ("two.key", "two words\n", "a passphrase must be one word")):
            key = os.path.join(tmp, name)
            with open(key, "w") as f:
                f.write(text)
            out = os.path.join(tmp, "out")
            done = subprocess.run([sys.executable, "-m", "gcs_tools", "sitl", "--mission", "test",
                                   "--signing-key-file", key, "--out", out],
                                  capture_output=True, text=True, timeout=60)
            assert done.returncode == 2, done.stderr
            lines = done.stderr.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith(f"beliefnav: error: signing key file {key}"), lines
            assert want in lines[0] and not os.path.exists(out)


def test_replay_gnss_errors_typo_or_missing_series_says_which():
    """`--gnss-errors modle` suggests 'model'; a series CSV that is not there says "no such file"."""
    log = "tests/data/quad106.tlog"
    for value, want in (("modle", "--gnss-errors 'modle': no such file, and not 'none' or 'model' "
                                  "(did you mean 'model'?)"),
                        ("runs/nosuch.csv", "--gnss-errors 'runs/nosuch.csv': no such file, and not 'none' "
                                            "or 'model'")):
        with tempfile.TemporaryDirectory() as tmp:
            done = subprocess.run([sys.executable, "-m", "gcs_tools", "replay", log, "--gnss-errors", value,
                                   "--out", os.path.join(tmp, "out")],
                                  capture_output=True, text=True, timeout=60, cwd=ROOT)
        assert done.returncode == 2, done.stderr
        assert done.stderr.strip().splitlines() == [f"beliefnav: error: {want}"], done.stderr
