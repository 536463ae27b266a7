"""Standard normal draws served from pre-drawn blocks (one generator call per block, not per period).

numpy's ``Generator.standard_normal`` is sequential: drawing n values and then m values gives
the same numbers as drawing n + m at once. So serving draws from blocks leaves every model's
random stream exactly as if it called the generator itself (tested), at a fraction of the cost
of one small generator call per control period.
"""

from __future__ import annotations

import numpy as np

BLOCK_SIZE = 6000  # values per generator call (100 IMU periods of 10 x 6)


class NormalBlocks:
    """``take(n)`` = the next ``n`` values of ``rng.standard_normal``, in order."""

    def __init__(self, rng: np.random.Generator, block_size: int = BLOCK_SIZE) -> None:
        self._rng = rng
        self._block_size = block_size
        self._buf = np.empty(0)
        self._next = 0

    def take(self, n: int) -> np.ndarray:
        """The next ``n`` standard normals (a read-only view; copy before writing)."""
        i = self._next
        if i + n > len(self._buf):
            fresh = self._rng.standard_normal(max(self._block_size, n))
            self._buf = np.concatenate([self._buf[i:], fresh]) if i < len(self._buf) else fresh
            self._buf.setflags(write=False)
            i = 0
        self._next = i + n
        return self._buf[i:i + n]
