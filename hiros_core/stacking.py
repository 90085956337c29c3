"""A frame's skeletons as stacked rows per layout: what the optimizer and the filter work on.

Both stages fit or filter all people of a frame in one kernel call, so they stack everyone's
marker rows once (:func:`stack_frame`), check them on the stack instead of one skeleton at a
time, and build the output skeletons as rows of the result (:func:`output_skeletons`). A
frame's skeletons usually come as one stack already (the previous stage made them so), which
``stack_rows`` hands back without copying: the stage copies only the rows it writes.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from hiros_core.layouts import Layout
from hiros_core.model import Skeleton, SkeletonRows, stack_rows

__all__ = ["LayoutRows", "output_skeletons", "stack_frame"]


@dataclass
class LayoutRows:
    """The usable skeletons of one layout in a frame, stacked.

    Attributes:
        layout: their layout.
        markers: ``(n, J, 20)`` copies of their marker rows (a stage's output rows).
        present: ``(n, J)`` copies of their marker presence.
        source: their rows as they came (read-only: they are the input skeletons' own).

    """

    layout: Layout
    markers: np.ndarray
    present: np.ndarray
    source: SkeletonRows

    def take(self, rows: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """``markers`` and ``present`` of ``rows``: the arrays themselves when that is all."""
        if self._all(rows):
            return self.markers, self.present
        return self.markers[rows], self.present[rows]

    def input_links(self, rows: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the input link rows and link presence of ``rows``."""
        source = self.source
        if self._all(rows):
            return source.links.copy(), source.link_present.copy()
        return source.links[rows], source.link_present[rows]

    def input_boxes(self, rows: list[int]) -> np.ndarray:
        """A copy of the input bounding boxes of ``rows``."""
        boxes = self.source.bounding_boxes
        return boxes.copy() if self._all(rows) else boxes[rows]

    def _all(self, rows: list[int]) -> bool:
        return len(rows) == len(self.present) and rows == list(range(len(rows)))


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
        source = stack_rows(
            skeletons if len(indices) == len(skeletons) else [skeletons[i] for i in indices]
        )
        stack = LayoutRows(
            skeletons[indices[0]].layout,
            source.markers.copy(),
            source.marker_present.copy(),
            source,
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

    A compiled kernel (``hiros_core.compiled.unusable_rows``; its numpy statement is
    ``test/support/optimizer_reference.py``'s): at a few people the five numpy calls it takes
    cost more than the rest of the stacking. Imported at the first call, as the stages load
    their kernels (``hiros_core.compiled`` states the rule).
    """
    from hiros_core.compiled import unusable_rows

    return unusable_rows(markers, present)


def output_skeletons(
    skeletons: list[Skeleton], track_ids: list[int], rows: SkeletonRows
) -> list[Skeleton]:
    """New skeletons of ``skeletons``' people and stamps, skeleton ``n`` with row ``n`` of ``rows``.

    ``rows`` become the skeletons' own (not copied): the new skeletons are its views
    (``SkeletonRows.skeletons``), so the next stage and the encoder get the stack for free.
    """
    return rows.skeletons(
        track_ids,
        [s.src_time_ns for s in skeletons],
        [s.src_frame for s in skeletons],
        skeletons[0].layout,
        [s.confidence for s in skeletons],
        max_sizes=[(s.max_markers, s.max_links) for s in skeletons],
    )
