"""Issue 21 case 17: non-finite and absurd joints are counted, never passed on as present."""

from __future__ import annotations

import numpy as np

from hiros_sim import SimParams, simulate
from hiros_tracker import Tracker


def test_case17_nan_inf_and_far_joints_are_marked_absent_and_counted() -> None:
    result = simulate(SimParams(n_cameras=2, n_people=1, duration=4.0, seed=4, noise=False))
    tracker = Tracker(calibration=result.calibration)
    injected = 0
    passed_on = 0
    outputs = 0
    frames = sorted((g.stamp_ns, name, k) for name, groups in result.camera_groups.items()
                    for k, g in enumerate(groups))  # fmt: skip
    for _, name, k in frames:
        group = result.camera_groups[name][k]
        for skeleton in group.skeletons:
            skeleton.marker_present[:3] = True
            skeleton.positions[:3] = [[np.nan] * 3, [np.inf, 0, 0], [1e30, 0, 0]]
            injected += 1
        out = tracker.update(group)
        outputs += len(out.skeletons)
        for skeleton in out.skeletons:
            finite = np.isfinite(skeleton.positions).all(axis=1)
            passed_on += int((skeleton.marker_present & ~finite).sum())
            assert not skeleton.marker_present[:3].any()
    assert outputs > 0
    assert passed_on == 0
    assert tracker.drops["nan joint"] == 2 * injected
    assert tracker.drops["joint too far"] == injected
