"""What the optimizer remembers of every track of one layout, as stacked per-row arrays.

One row per track id (:class:`Memory` hands rows out and takes them back): the learning window
of measured link lengths, and the motion the fit predicts from (last output positions, their
velocity, the fitted link vectors, the stamp). Keeping them stacked lets one call do a whole
frame's work for all its people: :meth:`Memory.fit` (prior, outlier weights, fit, new motion)
and :meth:`Memory.learn` (window, motion), each one numba kernel (:mod:`hiros_optimizer.compiled`).
Their numpy statement, the same numbers in the same order, is ``ReferenceMemory`` of
``test/support/optimizer_reference.py``, which a test holds them to.

"No motion known" (a new track, or one unseen for longer than the timeout) is a row with
``timed`` False, NaN positions and vectors and zero velocities: the prior and the fallback
vectors are then NaN by arithmetic alone, with no case of their own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hiros_core.kinematics import link_lengths
from hiros_core.layouts import Layout
from hiros_optimizer import kernel_args

__all__ = ["FitSettings", "Memory"]


@dataclass(frozen=True)
class FitSettings:
    """The optimizer parameters a frame's fit uses (see ``OptimizerParams``)."""

    confidence_floor: float
    outlier_threshold: float
    outlier_distance: float
    prior_weight: float
    track_timeout: float
    sweeps: int
    refinements: int

    @property
    def kernel_values(self) -> kernel_args.FitSettings:
        """The settings bundle of ``compiled.fit_frame``, typed as the kernel expects."""
        return kernel_args.FitSettings(
            float(self.confidence_floor),
            float(self.outlier_threshold),
            float(self.outlier_distance),
            float(self.prior_weight),
            float(self.track_timeout),
            int(self.sweeps),
            int(self.refinements),
        )


class Memory:
    """Per-track state of one layout, one row per track (module docstring).

    Attributes:
        layout: the layout of every row.
        tree: its kinematic tables.
        window: ``(S, J, N)`` measured link lengths of the last N learning frames (NaN: none).
        filled: ``(S,)`` frames pushed into each window.
        positions: ``(S, J, 3)`` last output positions (absent joints keep their last one).
        velocities: ``(S, J, 3)`` from the last two outputs.
        vectors: ``(S, J, 3)`` last fitted link vectors (NaN while learning).
        time_ns: ``(S,)`` stamp of the last frame.
        timed: ``(S,)`` False where no motion is known.

    """

    def __init__(self, layout: Layout, window: int) -> None:
        self.layout = layout
        self.tree = layout.tree
        self._link_ends = (
            np.asarray(layout.link_parents, dtype=np.intp),
            np.asarray(layout.link_children, dtype=np.intp),
        )
        self._free: list[int] = []
        n = layout.n_joints
        self.window = np.full((0, n, window), np.nan)
        self.filled = np.zeros(0, dtype=np.int64)
        self.positions = np.full((0, n, 3), np.nan)
        self.velocities = np.zeros((0, n, 3))
        self.vectors = np.full((0, n, 3), np.nan)
        self.time_ns = np.zeros(0, dtype=np.int64)
        self.timed = np.zeros(0, dtype=bool)

    def allocate(self) -> int:
        """A fresh row (empty window, no motion), growing the arrays when none is free."""
        if not self._free:
            old = len(self.timed)
            extra = max(4, old)
            for name in ("window", "positions", "vectors"):
                self._grow(name, extra, np.nan)
            for name in ("filled", "velocities", "time_ns", "timed"):
                self._grow(name, extra, 0)
            self._free.extend(range(old + extra - 1, old - 1, -1))
        row = self._free.pop()
        self.restart_window(row)
        self.forget_motion(np.array([row]))
        return row

    def release(self, row: int) -> None:
        """Give a row back (its track moved to another layout)."""
        self._free.append(row)

    def _grow(self, name: str, extra: int, fill: float) -> None:
        array = getattr(self, name)
        pad = np.full((extra, *array.shape[1:]), fill, dtype=array.dtype)
        setattr(self, name, np.concatenate([array, pad]))

    def restart_window(self, row: int) -> None:
        """Learn this row's lengths again from its next frames."""
        self.window[row] = np.nan
        self.filled[row] = 0

    def forget_motion(self, rows: np.ndarray) -> None:
        """No prediction for these rows any more (their lengths are kept)."""
        self.timed[rows] = False
        self.positions[rows] = np.nan
        self.velocities[rows] = 0.0
        self.vectors[rows] = np.nan

    # ------------------------------------------------------------------ one frame, numpy

    # ------------------------------------------------------------------ one frame

    def learn(
        self,
        rows: np.ndarray,
        stamps: np.ndarray,
        markers: np.ndarray,
        present: np.ndarray,
        *,
        settings: FitSettings,
    ) -> None:
        """Push the people's measured link lengths into their windows; remember their motion.

        ``markers`` ``(P, J, 20)`` and ``present`` ``(P, J)`` are the people's rows; a joint
        counts towards a length only when its confidence is above 0 (NaN counts as 1).
        """
        from hiros_optimizer.compiled import learn_frame

        frame = kernel_args.FrameRows(markers, present, rows, stamps)
        timeout = float(settings.track_timeout)
        learn_frame(self.tree.parents, frame, self._state, self.window, self.filled, timeout)

    def record(self, rows: np.ndarray, markers: np.ndarray, present: np.ndarray) -> None:
        """Push the people's measured link lengths into their windows (no motion).

        Also for people already fitted to some learnt links, while others are learnt: their
        raw measurement, before the fit. A joint counts only when its confidence is above 0.
        """
        counted = _weights(markers, present, 0.0) > 0
        measured = np.where(counted[..., None], markers[..., 1:4], np.nan)
        self.window[rows, :, self.filled[rows] % self.window.shape[2]] = link_lengths(
            measured, self.tree.parents
        )
        self.filled[rows] += 1

    def fit(
        self,
        rows: np.ndarray,
        stamps: np.ndarray,
        markers: np.ndarray,
        present: np.ndarray,
        lengths: np.ndarray,
        *,
        settings: FitSettings,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Fit the people of ``markers`` to their ``lengths`` ``(P, J)``; positions in place.

        Each person's prior is their last output moved by their velocity; their weights are
        the confidences (at least the floor), down-weighted for outliers
        (:meth:`_outlier_factors`). Present joints take the fitted positions. Returns the
        fitted people's link rows and link presence (``model.link_rows``; the compiled fit
        builds them in the same call).
        """
        from hiros_optimizer.compiled import fit_frame_links

        tree = kernel_args.FitTree(self.tree.parents, self.tree.order, self.tree.level_starts)
        frame = kernel_args.FrameRows(markers, present, rows, stamps)
        return fit_frame_links(
            tree, frame, lengths, self._state, settings.kernel_values, self._link_ends
        )

    @property
    def _state(self) -> kernel_args.MemoryState:
        """The memory arrays as the kernels' bundle (the same arrays, changed in place)."""
        return kernel_args.MemoryState(
            self.time_ns, self.timed, self.positions, self.velocities, self.vectors
        )


def _weights(markers: np.ndarray, present: np.ndarray, floor: float) -> np.ndarray:
    """``(P, J)`` fit weights: the confidence (NaN counts as 1), at least ``floor``; 0 absent."""
    confidence = markers[..., 0]
    confidence = np.where(np.isfinite(confidence), confidence, 1.0)
    return np.where(present, np.clip(confidence, floor, None), 0.0)
