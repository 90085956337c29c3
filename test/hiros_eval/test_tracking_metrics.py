"""The tracking metrics on output whose first frames see no one."""

from __future__ import annotations

import math

from hiros_core.model import SkeletonGroup
from hiros_eval.tracking import camera_mpjpe
from hiros_sim import SimParams, simulate


def test_camera_mpjpe_accepts_a_first_frame_without_people() -> None:
    """A camera whose first frame sees no one (people not in view yet) is scored on the rest:
    the oracle's side swap finds the layout in a later frame instead of failing."""
    result = simulate(SimParams(n_people=1, duration=4.0, seed=3))
    plain = camera_mpjpe(result.camera_groups, result.calibration, result.truth, oracle_sides=True)
    padded_groups = {
        camera: [SkeletonGroup(groups[0].stamp_ns - 1, groups[0].frame_id, []), *groups]
        for camera, groups in result.camera_groups.items()
    }
    padded = camera_mpjpe(padded_groups, result.calibration, result.truth, oracle_sides=True)
    assert padded == plain
    assert all(math.isfinite(value) for value in padded.values())
