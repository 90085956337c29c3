"""A frame's skeletons as stacked rows per layout: what the optimizer and the filter work on.

Both stages fit or filter all people of a frame in one kernel call, so they stack everyone's
marker rows once (:func:`stack_frame`), check them on the stack instead of one skeleton at a
time, and build each output skeleton around its row of the result (:func:`with_rows`).
"""

from __future__ import annotations

import sys
from collections import Counter
from dataclasses import dataclass

import numpy as np

from hiros_core.layouts import Layout
from hiros_core.model import Skeleton

__all__ = ["LayoutRows", "stack_frame", "with_rows"]


@dataclass
class LayoutRows:
    """The usable skeletons of one layout in a frame, stacked.

    Attributes:
        layout: their layout.
        markers: ``(n, J, 20)`` copies of their marker rows (a stage's output rows).
        present: ``(n, J)`` their marker presence.

    """

    layout: Layout
    markers: np.ndarray
    present: np.ndarray

    def take(self, rows: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """``markers`` and ``present`` of ``rows``: the arrays themselves when that is all."""
        if len(rows) == len(self.present) and rows == list(range(len(rows))):
            return self.markers, self.present
        return self.markers[rows], self.present[rows]


def stack_frame(
    skeletons: list[Skeleton], drops: Counter[str]
) -> list[tuple[LayoutRows, int] | None]:
    """Each skeleton's stack and row, or None for one the stage cannot use (counted).

    Unusable: marker rows that do not match the layout, or a present joint whose position is
    not finite.
    """
    places: list[tuple[LayoutRows, int] | None] = [None] * len(skeletons)
    by_layout: dict[str, list[int]] = {}
    for index, skeleton in enumerate(skeletons):
        if skeleton.markers.shape[0] != skeleton.layout.n_joints:
            drops["marker rows do not match the layout"] += 1
            continue
        by_layout.setdefault(skeleton.layout.name, []).append(index)
    for indices in by_layout.values():
        stack = LayoutRows(
            skeletons[indices[0]].layout,
            np.array([skeletons[i].markers for i in indices]),
            np.array([skeletons[i].marker_present for i in indices]),
        )
        bad = _unusable_rows(stack.markers, stack.present)
        for row, index in enumerate(indices):
            if bad[row]:
                drops["non-finite position of a present joint"] += 1
            else:
                places[index] = (stack, row)
    return places


def _unusable_rows(markers: np.ndarray, present: np.ndarray) -> np.ndarray:
    """``(n,)`` True where a present joint's position is not finite.

    The compiled check when numba is loaded (the stages load it), else numpy: at a few people
    the five numpy calls cost more than the rest of the stacking.
    """
    if "numba" in sys.modules:
        from hiros_optimizer.compiled import unusable_rows

        return unusable_rows(markers, present)
    return (present & ~np.isfinite(markers[..., 1:4]).all(axis=-1)).any(axis=-1)


def with_rows(
    skeleton: Skeleton,
    track_id: int,
    *,
    markers: np.ndarray,
    links: np.ndarray,
    present: np.ndarray,
    link_present: np.ndarray,
) -> Skeleton:
    """A new skeleton of ``skeleton``'s person and stamp with these rows (views are fine)."""
    return Skeleton(
        track_id, skeleton.src_time_ns, skeleton.src_frame, skeleton.layout, markers, links,
        present, link_present, skeleton.confidence, skeleton.bounding_box.copy(),
        skeleton.max_markers, skeleton.max_links,
    )  # fmt: skip
