"""A layout's joint tree as index tables, and link lengths: what the optimizer and the filter share.

``Layout.tree`` builds the tables once per layout; the optimizer's fixed-length fit
(``hiros_optimizer.kinematics``) and the filter's length keeper (``hiros_filter.lengths``)
both walk them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hiros_core.layouts import Layout

__all__ = ["KinematicTree", "link_lengths"]


@dataclass(frozen=True)
class KinematicTree:
    """Index tables of a layout's joint tree, computed once per layout.

    Attributes:
        parents: ``(J,)`` parent of each joint, ``-1`` for roots.
        levels: joint indices grouped by depth; ``levels[0]`` holds the roots.
        subtree: ``(J, J)`` float, ``subtree[c, j] = 1`` when ``j`` is ``c`` or below it.
        level_subtrees: ``subtree`` rows of each level (who is below each of its joints).
        level_below: the transposes of ``level_subtrees``, contiguous (moves subtrees).
        subtree_t: ``subtree.T``, contiguous (link vectors -> positions by one product).
        has_parent: ``(J,)`` True for joints that end a link.
        parent_of: ``(J, J)`` float, ``parent_of[c, p] = 1`` when ``p`` is ``c``'s parent, so
            ``flags @ parent_of`` moves per-link flags (by child) to the parents.
        order: ``(J,)`` the joints level by level (parents before children).
        level_starts: ``(levels + 1,)`` where each level begins in ``order``.

    """

    parents: np.ndarray
    levels: tuple[np.ndarray, ...]
    subtree: np.ndarray
    level_subtrees: tuple[np.ndarray, ...]
    level_below: tuple[np.ndarray, ...]
    subtree_t: np.ndarray
    has_parent: np.ndarray
    parent_of: np.ndarray
    order: np.ndarray
    level_starts: np.ndarray

    @classmethod
    def from_layout(cls, layout: Layout) -> KinematicTree:
        """Build the tables; the layout guarantees a valid forest (checked in ``Layout``)."""
        parents = np.asarray(layout.parents, dtype=np.int64)
        n = len(parents)
        depth = np.full(n, -1)
        # Depth by repeated relaxation: at most tree-height passes, done once per layout.
        depth[parents < 0] = 0
        while (depth < 0).any():
            ready = (depth < 0) & (depth[parents] >= 0) & (parents >= 0)
            depth[ready] = depth[parents[ready]] + 1
        subtree = np.eye(n)
        for joint in range(n):
            ancestor = parents[joint]
            while ancestor >= 0:
                subtree[ancestor, joint] = 1.0
                ancestor = parents[ancestor]
        levels = tuple(np.flatnonzero(depth == d) for d in range(depth.max() + 1))
        parent_of = np.zeros((n, n))
        children = np.flatnonzero(parents >= 0)
        parent_of[children, parents[children]] = 1.0
        return cls(
            parents=parents,
            levels=levels,
            subtree=subtree,
            level_subtrees=tuple(subtree[level] for level in levels),
            level_below=tuple(np.ascontiguousarray(subtree[level].T) for level in levels),
            subtree_t=np.ascontiguousarray(subtree.T),
            has_parent=parents >= 0,
            parent_of=parent_of,
            order=np.concatenate(levels).astype(np.int64),
            level_starts=np.cumsum([0, *map(len, levels)]).astype(np.int64),
        )


def link_lengths(positions: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """``(..., J)`` distance of each joint from its parent; NaN for roots and missing ends."""
    parent_positions = positions[..., np.maximum(parents, 0), :]
    lengths = np.linalg.norm(positions - parent_positions, axis=-1)
    lengths[..., parents < 0] = np.nan
    return lengths
