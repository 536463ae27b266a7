"""A receiver's C/N0 calibration, from its own signals: C/N0 relative to its running distribution.

The σ model and the belief's prior read C/N0 in absolute dB-Hz (``TightConfig.cn0_ref_dbhz``,
``prior_cn0_mid_dbhz``), constants that hold for the receiver they were chosen on. Another receiver
reports the same signal several dB higher or lower (antenna gain, front-end noise figure, its own
estimator: a phone's C/N0 is ~10 dB below a survey receiver's), which would make every satellite look
weaker or stronger than it is: a larger or smaller σ and a prior pushed as a whole toward distrust or
trust. What does not depend on the receiver is where a signal lies in the receiver's own distribution:
the strongest signals of any receiver are its line-of-sight ones.

``Cn0Calibration`` keeps a histogram (``BIN_DB`` bins) of every C/N0 the receiver reported so far
(a receiver's calibration is a constant: no forgetting) and estimates its ``quantile`` q (linear
within a bin); the offset is (q − ``reference_dbhz``) · n / (n + ``prior_obs``): shrunk towards 0 (the
reference receiver) while few signals were seen. ``calibrated(cn0)`` is C/N0 minus the offset, what the
reference receiver would have reported. The reference is the same quantile on the simulator's tuning
flights (``TightConfig.cn0_calibration_ref_dbhz``). Deterministic in arrival order.
"""

from __future__ import annotations

import numpy as np

from companion.tight import _tight

BIN_DB = 1.0  # receivers report C/N0 in whole dB-Hz (u-blox, smartLoc) or finer
LO_DBHZ, HI_DBHZ = 0.0, 80.0


class Cn0Calibration:
    def __init__(self, quantile: float, reference_dbhz: float, prior_obs: float) -> None:
        self.quantile = quantile
        self.reference_dbhz = reference_dbhz
        self.prior_obs = prior_obs
        self._edges = np.arange(LO_DBHZ - 0.5 * BIN_DB, HI_DBHZ + BIN_DB, BIN_DB)
        self._hist = np.zeros(len(self._edges) - 1)
        self.n = 0

    def add(self, cn0_dbhz: np.ndarray) -> None:
        """Count an epoch's C/N0 values (non-finite ones ignored, the rest clipped to the histogram)."""
        # numpy's clip, bin index and bincount, in C (tested bit for bit against them)
        self.n += _tight.cn0_add(self._hist, self._edges, cn0_dbhz, LO_DBHZ, HI_DBHZ, BIN_DB)

    def level_dbhz(self) -> float:
        """The histogram's ``quantile`` (NaN before any value), linear within its bin."""
        if self.n == 0:
            return float("nan")
        return float(_tight.cn0_level(self._hist, self._edges, self.quantile * self.n, BIN_DB))  # in C

    def offset_db(self) -> float:
        """The receiver's C/N0 minus the reference receiver's, shrunk towards 0 while n is small."""
        if self.n == 0:
            return 0.0
        return (self.level_dbhz() - self.reference_dbhz) * self.n / (self.n + self.prior_obs)

    def calibrated(self, cn0_dbhz: np.ndarray) -> np.ndarray:
        """These values (an epoch's, after ``add``) as the reference receiver would report them."""
        return np.asarray(cn0_dbhz, dtype=float) - self.offset_db()
