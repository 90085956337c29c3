"""The facing check: a track whose sides disagree with the cameras is turned back, and a person
standing with their back to every camera keeps their sides though the SDKs report them facing."""

import numpy as np
import pytest

from hiros_core.layouts import AZURE_KINECT
from hiros_tracker import Tracker, TrackerParams

MIRROR = np.asarray(AZURE_KINECT.mirror)
AT = 2.0
"""s into the scene at which the track is mirrored."""


def _mirrored(skeleton, truth) -> bool:
    true = truth(skeleton.src_time)[0]
    as_labelled = np.nanmean(np.linalg.norm(true - skeleton.positions, axis=1))
    swapped = np.nanmean(np.linalg.norm(true[MIRROR] - skeleton.positions, axis=1))
    return bool(swapped < as_labelled)


@pytest.mark.parametrize(
    ("speed", "within"),
    [
        (0.0, 1.0),  # standing: cameras that clearly contradict it turn it (measured 0.3 s)
        (0.8, 0.75),  # walking backwards by its sides: the doubt turns it (measured 0.5 s)
    ],
)
def test_a_track_drifted_into_the_mirror_is_turned_back_by_the_cameras(scenes, speed, within):
    # Left in the mirror as a drift of its labels leaves it (noisy-sdk, turns at the end of a
    # walk): pose and held axis mirrored, its facing log-odds still those of 2 s of agreeing
    # detections (about +270). Every camera's detections now disagree with it.
    scene = scenes.render([scenes.straight((-1.0, 0.2), (speed, 0.0))], duration=5.0, seed=3)
    tracker = Tracker(TrackerParams(), scene.calibration)
    outputs, mirrored_at = [], None
    for frame in scene.frames:
        group = tracker.update(frame)
        outputs += [(s.src_time - scenes.T0, _mirrored(s, scene.truth)) for s in group.skeletons]
        if mirrored_at is None and outputs and outputs[-1][0] > AT:
            table = tracker._table  # the drift, put in by hand
            for row in range(table.n):
                held = table.sides[row].copy()
                table.relabel(row, MIRROR)
                table.sides[row] = -held
            mirrored_at = outputs[-1][0]
    wrong = [t for t, mirrored in outputs if mirrored]
    assert wrong, "the mirrored track reached the output"
    assert min(wrong) > mirrored_at - 0.05  # nothing mirrored before
    assert max(wrong) < mirrored_at + within


WALK_UNTIL = 3.0
"""s: the person walks away from the cameras' ring until then, and then stands."""


def _walk_then_stand(t: float) -> tuple[np.ndarray, float]:
    """Outside the ring, walking out along +x at 0.6 m/s, then standing, always facing +x."""
    return np.array([4.5 + 0.6 * min(t, WALK_UNTIL), 0.0]), 0.0


@pytest.mark.parametrize(
    ("standing_memory", "keeps_sides"),
    [(TrackerParams().facing_memory_standing, True), (3.0, False)],
)
def test_a_person_standing_with_their_back_to_every_camera_keeps_their_sides(
    scenes, standing_memory, keeps_sides
):
    # Every camera sees their back. Once they stand, every SDK reports them facing it: the
    # body reflected through its frontal plane, left and right exchanged (as a flip is). Such
    # detections contradict the track only weakly, one by one, for as long as the person
    # stands; what the walk taught the track must outlast them.
    calibration = scenes.camera_ring(3)
    pelvis = AZURE_KINECT.joint_names.index("Pelvis")

    def reported_facing_the_camera(name, t, person, local):
        if t < WALK_UNTIL:
            return local
        to_world = calibration.cameras[name].extrinsics
        world = to_world.apply(local)
        depth = world[:, 0] - world[pelvis, 0]  # along the body's front, +x
        world[:, 0] -= 2.0 * depth
        return to_world.inverse().apply(world[MIRROR])

    scene = scenes.render(
        [_walk_then_stand], duration=WALK_UNTIL + 8.0, seed=4, modify=reported_facing_the_camera
    )
    tracker = Tracker(TrackerParams(facing_memory_standing=standing_memory), scene.calibration)
    outputs = scenes.run_tracker(tracker, scene.frames)
    standing = [
        _mirrored(s, scene.truth)
        for group in outputs
        for s in group.skeletons
        if s.src_time - scenes.T0 > WALK_UNTIL
    ]
    assert len(standing) > 200
    assert (not any(standing)) == keeps_sides


def test_a_standing_track_doubts_only_what_several_cameras_clearly_contradict():
    from hiros_tracker.facing import VERDICT_LIFETIME_S, _doubt_step
    from hiros_tracker.tracks import TrackTable

    def step(verdicts, view, walk=0.0, camera=0, age=0.0):
        table = TrackTable(AZURE_KINECT.n_joints, n_cameras=3)
        table.add(1, np.zeros((AZURE_KINECT.n_joints, 3)), 0)
        now = 10**10
        table.camera_verdicts[0] = verdicts
        table.camera_verdicts_ns[0] = now - int(age * 1e9)
        return _doubt_step(table.hit_fields(), 0, camera, now, view, walk)

    # camera 0's detection gives ``view``; ``verdicts`` are the cameras' last ones before it
    side, front, back = -2.2, -1.1, -0.25  # contradictions seen from the side, front, back
    support = 0.25
    assert step([0.0, back, back], side) == 0.0  # one side view against it: no run
    assert step([0.0, back, back], back) == 0.0  # seen from behind by all: no run
    assert step([0.0, front, back], side) == 0.0  # a front view's contradiction is not clear
    assert step([0.0, side, back], side) == 2.2  # two side views against it: fed
    assert step([0.0, side, side], back) == 0.25  # ... by each contradicting camera
    assert step([0.0, side, support], side) == 0.0  # one camera supports it: the run ends
    assert step([0.0, side, side], side, age=VERDICT_LIFETIME_S + 0.1) == 0.0  # stale verdicts
    assert step([0.0, back, back], back, walk=-1.0) == 0.25  # walking backwards: fed
    assert step([0.0, side, side], side, walk=1.0) == 0.0  # walking forwards: ends
