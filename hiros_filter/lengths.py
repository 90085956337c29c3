"""Keep the optimizer's limb lengths in the filter's output, with consistent derivatives.

A linear filter smooths each coordinate on its own, so a link that turns comes out shorter
(the average of two directions is shorter than either) and a link that speeds up or slows down
comes out longer or shorter: the lengths the optimizer fixed vary again by a few percent.
Smoothing is linear, so filtering the joint positions and then taking differences is the same
as filtering the link vectors; rescaling each filtered link vector back to its length therefore
keeps the smoothed *directions* (and so the joint angles) and only restores the lengths. The
skeleton is rebuilt from the root outwards (every joint moves with the corrections of the links
above it) and translated so that the mean of its joints stays where the filter put it (the
best translation in the least-squares sense).

Derivatives follow the same constraint. A link of constant length ``L`` along the unit vector
``u`` has a relative velocity ``dv`` perpendicular to ``u`` and a relative acceleration whose
component along ``u`` is the centripetal ``-|dv|² / L``; the along-link parts of the filtered
relative velocities and accelerations are replaced by those values and the whole body is
rebuilt in the same way (mean kept).

Which links to hold is read from the input itself: a link whose length is the same (to 1e-9
relative) in two consecutive input frames of a track is one the optimizer constrains; links
it leaves free (and people it has not calibrated yet) vary from frame to frame and are left as
the filter made them.
"""

from __future__ import annotations

import numpy as np

from hiros_core.kinematics import KinematicTree

__all__ = ["LengthKeeper"]


class LengthKeeper:
    """A layout's tree and input link lengths for the projection onto fixed lengths.

    The projection itself (module docstring) is the compiled ``hiros_filter.compiled.
    keep_lengths``; its numpy statement is ``test/support/filter_reference.py``'s.
    """

    def __init__(self, tree: KinematicTree) -> None:
        self.tree = tree
        self._parent = np.maximum(tree.parents, 0)

    def lengths(self, positions: np.ndarray) -> np.ndarray:
        """``(n, J)`` link lengths of ``(n, J, 3)`` positions (NaN for roots, missing ends)."""
        vectors = positions - positions[:, self._parent]
        lengths = np.sqrt(np.add.reduce(vectors * vectors, axis=-1))
        lengths[:, ~self.tree.has_parent] = np.nan
        return lengths
