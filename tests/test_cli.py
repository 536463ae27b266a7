import subprocess
import sys


def test_cli_lists_commands_and_rejects_unknown():
    out = subprocess.run([sys.executable, "-m", "gcs_tools", "--help"], capture_output=True, text=True)
    assert out.returncode == 0
    for name in ("replay", "fly", "sitl", "bench", "evaluate", "dashboard"):
        assert name in out.stdout
    bad = subprocess.run([sys.executable, "-m", "gcs_tools", "nonsense"], capture_output=True, text=True)
    assert bad.returncode == 2
