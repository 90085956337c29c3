"""A person every camera lost re-takes their id; a camera's poor view of a person is no new one."""

import numpy as np

from hiros_tracker import Tracker, TrackerParams


def _ids_per_person(scenes, scene, params):
    tracker = Tracker(params, scene.calibration)
    outputs = scenes.run_tracker(tracker, scene.frames)
    seen = scenes.identities(outputs, scene.truth)
    return {person: set(ids) for person, ids in seen.items()}, tracker


def _leaving_and_returning(scenes, modify=None):
    """Person 0 walks slowly and is out of every view from 2 to 5 s (past ``track_timeout``);
    person 1 stands 2 m away all along."""

    def hide(camera, t, person, pose):
        if person == 0 and 2.0 < t < 5.0:
            return None
        return pose if modify is None else modify(camera, t, person, pose)

    people = [scenes.straight((-0.5, 0.0), (0.1, 0.0)), scenes.straight((1.5, 1.5), (0.0, 0.0))]
    return scenes.render(people, duration=7.0, modify=hide)


def test_a_person_returning_after_the_track_timeout_keeps_their_id(scenes):
    scene = _leaving_and_returning(scenes)
    ids, tracker = _ids_per_person(scenes, scene, TrackerParams())
    assert ids == {0: {0}, 1: {1}}
    assert sorted(tracker.track_ids) == [0, 1]
    without, _ = _ids_per_person(scenes, scene, TrackerParams(reid_timeout=0.0))
    assert len(without[0]) == 2, "without re-identification the return is a new id"


def test_a_person_of_another_build_is_not_taken_for_the_one_who_left(scenes):
    def hide_and_replace(camera, t, person, pose):
        if person == 0 and t > 2.0:
            return None  # person 0 leaves for good at x = -0.3 m ...
        if person == 2 and t < 4.5:
            return None  # ... and 2.5 s later (its track expired) person 2 appears there
        return pose

    def render(scale):
        def grown(camera, t, person, pose):
            pose = hide_and_replace(camera, t, person, pose)
            if pose is None or person != 2:
                return pose
            floor = pose[np.argmax(np.linalg.norm(pose, axis=1))]  # any fixed point will do
            return floor + scale * (pose - floor)

        people = [
            scenes.straight((-0.5, 0.0), (0.1, 0.0)),
            scenes.straight((1.5, 1.5), (0.0, 0.0)),
            scenes.straight((-0.3, 0.0), (0.0, 0.0)),
        ]
        return scenes.render(people, duration=6.0, modify=grown)

    same_build, _ = _ids_per_person(scenes, render(1.0), TrackerParams())
    assert same_build[2] == same_build[0], "someone alike where the lost one was re-takes the id"
    scene = render(1.25)
    tall = Tracker(TrackerParams(), scene.calibration)
    outputs = scenes.run_tracker(tall, scene.frames)
    ids = {s.id for g in outputs for s in g.skeletons if s.src_time - scenes.T0 > 5.5}
    assert 0 not in ids, "a person 25 % taller is someone else"
    assert len(ids) == 2


def test_a_cameras_displaced_view_of_a_person_it_follows_is_no_new_track(scenes):
    def displace(camera, t, person, pose):
        if camera == "k01" and 1.0 < t < 4.0:
            return pose + np.array([0.8, 0.0, 0.0])  # 0.8 m off: beyond the gate
        return pose

    def run(body_ids):
        scene = scenes.render(
            [scenes.straight((0.0, 0.0), (0.0, 0.0))], n_cameras=2, duration=5.0,
            modify=displace, body_ids=body_ids,
        )  # fmt: skip
        tracker = Tracker(TrackerParams(), scene.calibration)
        outputs = scenes.run_tracker(tracker, scene.frames)
        return {s.id for g in outputs for s in g.skeletons}, tracker

    ids, tracker = run(None)  # k01 keeps its body id for the person
    assert ids == {0}
    assert tracker.drops["duplicate of a confirmed track"] > 0
    ids, _ = run(lambda camera, t, person: 7 if camera == "k01" and 1.0 < t < 4.0 else 1)
    assert len(ids) == 2, "under a new body id it is another body as far as anyone can tell"


def test_a_gap_with_no_frame_from_any_camera_does_not_count_towards_the_timeout(scenes):
    """Twelve seconds in which no camera sends a frame (a paused recording, every driver
    down) are not time the person was lost: still there after it, they keep their id. The
    same twelve seconds with the cameras sending frames that do not show them is a person
    lost past ``reid_timeout`` (10 s): a new id."""
    people = [scenes.straight((0.0, 0.0), (0.0, 0.0))]

    def out_of_view(camera, t, person, pose):
        return None if 2.0 < t < 14.0 else pose

    scene = scenes.render(people, duration=16.0)
    paused = [f for f in scene.frames if not 2.0 < f.stamp_ns * 1e-9 - scenes.T0 < 14.0]
    assert len(paused) < len(scene.frames) / 2
    tracker = Tracker(TrackerParams(), scene.calibration)
    outputs = scenes.run_tracker(tracker, paused)
    assert set(scenes.identities(outputs, scene.truth)[0]) == {0}
    hidden = scenes.render(people, duration=16.0, modify=out_of_view)
    ids, _ = _ids_per_person(scenes, hidden, TrackerParams())
    assert len(ids[0]) == 2
