from collections import Counter

import numpy as np

from hiros_calib.tracks import extract_tracks, joint_weights
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup


def _group(t, ids, frame="k01_depth_camera_link"):
    stamp = round(t * 1e9)
    skeletons = [
        Skeleton.from_positions(
            np.full((32, 3), float(i)), AZURE_KINECT, skeleton_id=i, src_time_ns=stamp,
            confidences=np.full(32, 2.0),
        )
        for i in ids
    ]  # fmt: skip
    return SkeletonGroup(stamp, frame, skeletons)


def test_tracks_split_on_gaps_and_drop_repeats_and_short_tracks():
    times = [*np.arange(0, 1, 0.033), *np.arange(2, 3, 0.033)]
    groups = [_group(t, [1, 2] if t < 0.5 else [1]) for t in times]
    groups.append(_group(times[3], [1]))  # the same stamp again
    drops = Counter()
    tracks = extract_tracks(groups, "k01", max_gap=0.25, min_frames=20, drops=drops)
    # body 1: two tracks (the 1 s gap splits it); body 2: 16 frames only, too short
    assert [(t.body_id, len(t.times)) for t in tracks] == [(1, 31), (1, 31)]
    assert drops == Counter({"repeated_stamp": 1, "short_track": 1})
    assert all(np.all(np.diff(t.times) > 0) for t in tracks)


def test_joint_weights_scale_by_the_driver_range_and_leave_out_weak_joints():
    confidences = np.array([[3.0, 2.0, 1.0, np.nan]])
    present = np.array([[True, True, True, False]])
    weights = joint_weights(confidences, present, min_confidence=0.5)
    np.testing.assert_allclose(weights, [[1.0, 2 / 3, 0.0, 0.0]])
    # no confidences at all (Kinect v2 files): every present joint counts fully
    unknown = joint_weights(np.full((1, 3), np.nan), np.array([[True, True, False]]), 0.5)
    np.testing.assert_allclose(unknown, [[1.0, 1.0, 0.0]])
