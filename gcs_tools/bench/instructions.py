"""Instructions per benchmark stream, which the machine's load does not change (valgrind's callgrind).

``python -m gcs_tools.bench.instructions estimator|tight [--duration-s S] [--tree DIR]`` runs one stream
of ``bench estimator`` (20 s: 200 Hz IMU + attitude, 20 Hz fixes with the correlated latency,
``estimate()`` at 50 Hz, ``gcs_tools.bench.estimator.streaming_wall_s``) or of ``bench tight`` (20 s: 20
satellites at 5 Hz, the loop of ``gcs_tools.bench.tight._stream``) under
``valgrind --tool=callgrind --collect-atstart=no``, after one warm-up stream (imports on first use
left out) and a ``gc.collect()``, counting only inside the stream: it runs within a
``functools.reduce`` call, which callgrind's ``--toggle-collect`` switches collection on and off
around (nothing in the filters calls it). ``--tree``: the code of another checkout (its C cores built),
put first on ``PYTHONPATH``; the stream's code below uses only what the benchmarks of 2026-11-27
01:00 on have. Prints one line (``--json``: an object). Needs valgrind; the count varies by about
0.3 % from run to run (docs/benchmarks.md, "Instruction counts").
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

TOGGLE = "functools_reduce"  # the C function the stream runs inside

# Run in the measured process (python -c): argv[1] the filter, argv[2] the stream's length (s).
WORKLOAD = r'''
import functools, gc, sys
import numpy as np
from companion.domain.samples import AttitudeSample, ImuSample
which, duration = sys.argv[1], float(sys.argv[2])
if which == "estimator":
    from gcs_tools.bench import estimator as be
    samples = be.flight(duration, None)
    def stream():
        return be.streaming_wall_s(samples)[2].estimate()
else:
    from companion.tight import RawGnss, TightConfig
    from companion.wiring import tight_navigator_for
    from gcs_tools.bench import tight as bt
    from gcs_tools.gnss.synthetic import store
    st = store()
    n_ep = int(duration * bt.GNSS_HZ)
    epochs = bt._epochs(st, n_ep)
    q, f, gyro = np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, -9.80665]), np.zeros(3)
    every, out_every = bt.IMU_HZ // bt.GNSS_HZ, bt.IMU_HZ // bt.OUT_HZ
    def stream():
        nav = tight_navigator_for(None, "second-order", config=TightConfig(elevation_mask_deg=-90.0),
                                  ephemerides=st)
        for i in range(int(duration * bt.IMU_HZ)):
            t_us = 1_000_000 + i * (1_000_000 // bt.IMU_HZ)
            nav.push(AttitudeSample(t_us, q))
            nav.push(ImuSample(t_us, f, gyro))
            if i % every == 0 and i // every < n_ep:
                nav.push(RawGnss(t_us, epochs[i // every]))
            if i % out_every == 0:
                nav.estimate()
        return nav.estimate()
stream()
gc.collect()
est = functools.reduce(lambda acc, _: stream(), [None], None)
print("final", np.asarray(est.p_ned_m).tolist())
'''


def count(which: str, duration_s: float, tree: Path | None = None) -> dict[str, object]:
    """Instructions of one stream (callgrind's total with collection on inside it only)."""
    env = dict(os.environ, PYTHONHASHSEED="0")
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(tree), env.get("PYTHONPATH", "")) if p)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        proc = subprocess.run(
            ["valgrind", "--tool=callgrind", "--collect-atstart=no", f"--toggle-collect={TOGGLE}",
             "--dump-instr=no", f"--callgrind-out-file={out}", sys.executable, "-c", WORKLOAD, which,
             str(duration_s)], env=env, capture_output=True, text=True, cwd=tmp, check=False)
        if proc.returncode != 0:
            raise RuntimeError(f"valgrind failed ({proc.returncode}): {proc.stderr[-2000:]}")
        m = re.search(r"^totals:\s+(\d+)", out.read_text(), re.M)
    if m is None:
        raise RuntimeError("no totals in callgrind's output")
    final = [line for line in proc.stdout.splitlines() if line.startswith("final")]
    return {"filter": which, "duration_s": duration_s, "tree": str(tree) if tree else None,
            "instructions": int(m.group(1)), "per_simulated_s": int(m.group(1)) / duration_s,
            "final_position": final[-1][6:] if final else None}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(allow_abbrev=False, prog="python -m gcs_tools.bench.instructions",
                                     description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("filter", choices=("estimator", "tight"))
    parser.add_argument("--duration-s", type=float, default=20.0, help="the stream's length (default 20)")
    parser.add_argument("--tree", type=Path, default=None, help="another checkout's code (C cores built)")
    parser.add_argument("--json", action="store_true", help="one JSON object")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.duration_s) and args.duration_s > 0.0):
        parser.error(f"--duration-s: must be a finite number > 0, got {args.duration_s!r}")
    if args.tree is not None and not args.tree.is_dir():
        parser.error(f"--tree: not a directory: {args.tree}")
    if shutil.which("valgrind") is None:
        parser.error("valgrind not found on PATH (install valgrind: the count is callgrind's)")
    try:
        r = count(args.filter, args.duration_s, args.tree)
    except RuntimeError as exc:  # valgrind or the workload failed: its last line
        last = str(exc).strip().splitlines()[-1] if str(exc).strip() else "valgrind failed"
        parser.exit(1, f"{parser.prog}: error: {last}\n")
    if args.json:
        print(json.dumps(r))
    else:
        of = f" of {r['tree']}" if r["tree"] else ""
        print(f"{r['filter']}: {r['instructions']:,} instructions per {r['duration_s']:g} s stream "
              f"({float(r['per_simulated_s']) / 1e6:.2f} M per simulated s){of}")  # type: ignore[arg-type]
    return 0


if __name__ == "__main__":
    sys.exit(main())
