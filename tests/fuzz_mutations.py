"""Seeded mutations of text and binary input files, for the file-reader fuzz tests."""

from __future__ import annotations

import re

import numpy as np

NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eEdD][-+]?\d+)?")
EXTREMES = (b"nan", b"NaN", b"inf", b"-inf", b"1e308", b"-1e308", b"9.9D+99", b"0", b"-1", b"-0.0",
            b"1e-320", b"99999999999999999999", b"x", b"", b"--", b"1,5", b"0x10", b"\xff\xfe")


def _same_width(new: bytes, width: int) -> bytes:
    return new[:width].rjust(width) if width >= len(new[:width]) else new


def mutate_lines(rng: np.random.Generator, data: bytes, times: int) -> bytes:
    """Delete, duplicate, swap lines; replace a number by an extreme value (in its columns or not);
    shift a number (times going back or jumping)."""
    lines = data.split(b"\n")
    for _ in range(times):
        if not lines:
            break
        i = int(rng.integers(len(lines)))
        what = int(rng.integers(6))
        if what == 0:
            del lines[i]
        elif what == 1:
            lines.insert(i, lines[int(rng.integers(len(lines)))])
        elif what == 2:
            j = int(rng.integers(len(lines)))
            lines[i], lines[j] = lines[j], lines[i]
        else:
            found = list(NUMBER.finditer(lines[i]))
            if not found:
                continue
            m = found[int(rng.integers(len(found)))]
            if what == 3:
                new = EXTREMES[int(rng.integers(len(EXTREMES)))]
            elif what == 4:
                new = _same_width(EXTREMES[int(rng.integers(len(EXTREMES)))], m.end() - m.start())
            else:  # a number moved: back, a little forward, far forward
                try:
                    v = float(m.group().replace(b"D", b"E").replace(b"d", b"e"))
                except ValueError:
                    continue
                v = v + float(rng.choice([-1.0, -3600.0, 0.5, 7.0, 86400.0 * 400]))
                new = _same_width(f"{v:.7g}".encode(), m.end() - m.start())
            lines[i] = lines[i][:m.start()] + new + lines[i][m.end():]
    return b"\n".join(lines)


def mutate_bytes(rng: np.random.Generator, data: bytes, times: int) -> bytes:
    """Bit flips, junk inserted, spans deleted."""
    out = bytearray(data)
    for what in rng.integers(3, size=times).tolist():
        if not out:
            break
        at = int(rng.integers(len(out)))
        if what == 0:
            out[at] ^= 1 << int(rng.integers(8))
        elif what == 1:
            out[at:at] = rng.bytes(int(rng.integers(1, 32)))
        else:
            del out[at:at + int(rng.integers(1, 64))]
    return bytes(out)


def mutations(rng: np.random.Generator, data: bytes, n: int, text: bool = True) -> list[tuple[str, bytes]]:
    """``n`` seeded mutations of ``data`` (and the whole-file ones: empty, junk, truncated, re-encoded)."""
    out: list[tuple[str, bytes]] = [
        ("empty", b""),
        ("junk", rng.bytes(2000)),
        ("head", data[: int(rng.integers(1, max(2, len(data) // 20)))]),
    ]
    if text:
        out.append(("utf16", data.decode("latin-1").encode("utf-16")))
    for k in range(n):
        what = k % 3
        if what == 0:
            out.append((f"cut{k}", data[: int(rng.integers(len(data)))]))
        elif what == 1 and text:
            out.append((f"lines{k}", mutate_lines(rng, data, int(rng.integers(1, 12)))))
        else:
            out.append((f"bytes{k}", mutate_bytes(rng, data, int(rng.integers(1, 20)))))
    return out
