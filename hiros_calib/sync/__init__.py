"""Clock offsets between cameras from the people's own motion.

Method (Eichler et al., Sensors 2022, section 3.2, extended):

1. Every body track gets a camera-independent :mod:`~hiros_calib.signature`, resampled on a
   common grid of camera-clock multiples of ``GRID_STEP``; for the coarse search its time
   derivative is used, which whitens the slow posture changes and sharpens the peak.
2. For a camera pair, every pair of body tracks (one per camera) gives a normalised
   cross-correlation curve over all lags at once (FFT; channels pooled: the sum of
   per-channel covariances over the square root of the summed variances).
3. Consensus: curves whose peak is high and sharp (robust z-score of the peak over the
   curve, the role of Eichler's coefficient of variation) vote for their peak lag, the best
   ``BEST_FRACTION`` choose the winning lag and every good curve near it joins.
4. Sub-frame refinement: a parabola through the pooled curve's peak, then the lag that
   maximises the pooled correlation of the cubic-spline interpolated signatures, searched as
   a continuous variable, so 30 Hz streams give millisecond offsets. Both signatures are
   evaluated on one fine grid, so neither stream's sample instants are favoured.
5. Drift: the same continuous refinement in sliding windows gives the lag over time.
6. N cameras: :func:`solve_clocks` fits one offset (and drift) per camera to all pairwise
   window measurements by robust least squares, reference camera fixed, so the offsets are
   globally consistent (loops close).

The modules, in that order: :mod:`.params` (``SyncParams``), :mod:`.correlation` (steps 1-2),
:mod:`.pair` (3-4, a camera pair's lag and its candidate lags), :mod:`.refine` (4-5),
:mod:`.contest` (candidate lags compared window by window), :mod:`.loops` (the rules around
camera loops), :mod:`.solve` (6) and :mod:`.cameras` (all of it for N cameras);
:mod:`.clock` holds the results and the sign convention.
"""

from hiros_calib.sync.cameras import synchronise
from hiros_calib.sync.clock import CameraClock, PairOffset, Settle
from hiros_calib.sync.contest import CONTEST_DECISIVE_T, contest_candidates
from hiros_calib.sync.loops import close_loops, overrule_weak_pairs
from hiros_calib.sync.pair import estimate_pair_offset
from hiros_calib.sync.params import SyncParams
from hiros_calib.sync.solve import clock_epochs, solve_clocks

__all__ = [
    "CONTEST_DECISIVE_T",
    "CameraClock",
    "PairOffset",
    "Settle",
    "SyncParams",
    "clock_epochs",
    "close_loops",
    "contest_candidates",
    "estimate_pair_offset",
    "overrule_weak_pairs",
    "solve_clocks",
    "synchronise",
]
