"""Camera poses from people's joints once the clocks agree (after Eichler et al., 2022, 3.3).

For each camera pair:

1. **Association.** Body tracks overlapping in (corrected) time are paired when their pose
   signatures agree in metres: the same person has the same limb lengths and the same pose at
   the same instant, another person does not. Each track pairs with at most one track of the
   other camera at a time (greedy on the mismatch).
2. **Correspondences.** For every frame of camera a the joints of camera b are interpolated
   at the same reference instant; joints a camera sees badly (low confidence, missing) get
   weight 0 and are left out.
3. **Mirror-proof start.** An SDK seeing a person from behind may swap left and right. The
   midline joints and the midpoints of left/right joint pairs do not change under that swap,
   so a first pose is fitted on them alone: Kabsch (SVD) inside RANSAC, each minimal sample
   taking one point from the torso, one from the arms and one from the legs (body parts
   spread the sample), from different frames.
4. **Per-frame mirror choice.** With that pose, each frame keeps the straight or the
   left/right-swapped correspondence of the full joint set, whichever fits better.
5. **Robust refinement** of all correspondences: Gauss-Newton with iteratively reweighted
   least squares on the robust loss (``soft_l1``, ``huber``, ``cauchy`` or ``linear``) of
   each 3D residual, analytic Jacobians (:func:`~hiros_calib.extrinsics.robust.robust_solve`).

All cameras are then refined jointly (:func:`solve_poses`): every pair's correspondences in
one least-squares problem over all camera poses (reference fixed), so loops close.
Poses are camera -> world with ``p_world = R p_camera + t`` (DESIGN.md).

What limits the accuracy is the data, not a bias of these steps: the SDKs' joint errors
(mostly one shift of the whole body per frame, and fixed per-person joint offsets) and their
larger error on bodies seen from the side. The experiments behind that, and what was tried
without gain, are in ``docs/pose-accuracy.md``.

The modules: :mod:`.params` (``ExtrinsicsParams``, the method's constants and ``Sampling``),
:mod:`.correspondences` (steps 1-2), :mod:`.pair_pose` (3-5 for one camera pair),
:mod:`.robust` (the robust solve every refinement runs), :mod:`.joint` (all cameras at
once), :mod:`.halves` (the two halves of time a pose's check solves on, and the distance
between two poses) and :mod:`.lever` (how far the joints moved about where they stood, which
the rotation rests on).
"""

from hiros_calib.extrinsics.correspondences import (
    Correspondences,
    associate,
    joint_tables,
    pair_correspondences,
)
from hiros_calib.extrinsics.halves import SPLIT_BLOCK, relative_error, second_half
from hiros_calib.extrinsics.joint import CameraPose, solve_poses
from hiros_calib.extrinsics.lever import motion_lever
from hiros_calib.extrinsics.pair_pose import PairPose, baseline_pair_pose, estimate_pair_pose
from hiros_calib.extrinsics.params import FULL_SAMPLING, QUICK_SAMPLING, ExtrinsicsParams, Sampling
from hiros_core.geometry import kabsch

__all__ = [
    "FULL_SAMPLING",
    "QUICK_SAMPLING",
    "SPLIT_BLOCK",
    "CameraPose",
    "Correspondences",
    "ExtrinsicsParams",
    "PairPose",
    "Sampling",
    "associate",
    "baseline_pair_pose",
    "estimate_pair_pose",
    "joint_tables",
    "kabsch",
    "motion_lever",
    "pair_correspondences",
    "relative_error",
    "second_half",
    "solve_poses",
]
