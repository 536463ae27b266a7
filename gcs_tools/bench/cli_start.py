"""Start-up time of the command line: ``beliefnav bench cli --json``.

Wall time from starting a fresh interpreter to the end of ``beliefnav --help`` (the target: under
1 s; it imports no command's module) and of each command's own ``--help`` (which imports that
command's module only), median of a few runs, plus a bare ``python -c pass`` for the interpreter's
own share. The modules the top-level help imported are listed, so a heavy import creeping back in
is named.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from typing import Any

from gcs_tools.cli import COMMANDS

TARGET_S = 1.0  # beliefnav --help
HEAVY = ("numpy", "matplotlib", "scipy", "zenoh", "pymavlink", "aiohttp")  # none needed to print help


def _wall_s(argv: list[str], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(argv, capture_output=True, check=True, timeout=120)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def measure(args: argparse.Namespace) -> dict[str, Any]:
    repeats = 3 if getattr(args, "quick", False) else 7
    py = [sys.executable]
    code = ("import sys; from gcs_tools.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            f"print('HEAVY', *(m for m in {HEAVY!r} if m in sys.modules))")
    heavy = subprocess.run([*py, "-c", code], capture_output=True, text=True, timeout=120)
    last = heavy.stdout.strip().splitlines()[-1].split()
    help_s = _wall_s([*py, "-m", "gcs_tools", "--help"], repeats)
    return {
        "python_bare_s": _wall_s([*py, "-c", "pass"], repeats),
        "help_s": help_s,
        "help_target_s": TARGET_S,
        "help_met": help_s < TARGET_S,
        "help_heavy_imports": last[1:] if last[:1] == ["HEAVY"] else ["(not measured)"],
        "command_help_s": {name: _wall_s([*py, "-m", "gcs_tools", name, "--help"], max(1, repeats // 3))
                           for name in COMMANDS},
    }
