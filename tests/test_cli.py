import subprocess
import sys


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
             (["fly", "--scenario", "realstic"], "did you mean 'realistic'?"))
    for argv, want in cases:
        done = subprocess.run([sys.executable, "-m", "gcs_tools", *argv], capture_output=True, text=True,
                              timeout=60)
        assert done.returncode == 2 and done.stdout == ""
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and want in lines[0], done.stderr
