import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import hiros_calib.live
from hiros_calib.extrinsics import relative_error
from hiros_calib.live import (
    EVENTS_KEPT,
    MAX_FRAME_RATE,
    LiveCalibrator,
    LiveCalibratorParams,
    _matched_residuals,
)
from hiros_calib.sync import CameraClock
from hiros_calib.tracks import BodyTrack
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.geometry import RigidTransform
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import SkeletonGroup


def _feed(scene, live, until=None, step_every=3):
    """Frames in arrival order (arrival = reference time + 20 ms), stepping as a node would."""
    frames = []
    for name, groups in scene.camera_groups.items():
        cam = scene.truth.cameras[name]
        for g in groups:
            arrival = round((cam.to_reference_time(g.stamp) + 0.02) * 1e9)
            frames.append((arrival, g))
    frames.sort(key=lambda f: f[0])
    changes = []
    for k, (arrival, group) in enumerate(frames):
        if until is not None and arrival > until * 1e9:
            break
        live.update(group, arrival)
        if k % step_every == 0 and live.step(arrival):
            changes.append(arrival * 1e-9)
    return changes


def _feed_jumped(scene, live, jump_at, step_every=3):
    """Like ``_feed``, with arrivals from the capture instant: a camera whose clock jumped
    still delivers its frames on time."""
    frames = []
    for name, groups in scene.camera_groups.items():
        cam = scene.truth.cameras[name]
        capture = np.array([cam.to_reference_time(g.stamp) for g in groups])
        if name == "cam1":  # its stamps moved 0.5 s ahead after the jump; its frames did not
            capture = np.where(capture >= jump_at + 0.5, capture - 0.5, capture)
        frames.extend((round((t + 0.02) * 1e9), g) for t, g in zip(capture, groups, strict=True))
    frames.sort(key=lambda f: f[0])
    for k, (arrival, group) in enumerate(frames):
        live.update(group, arrival)
        if k % step_every == 0:
            live.step(arrival)


def _pose_error(live, truth_pose, camera="cam1"):
    est = live.calibration.cameras[camera].extrinsics
    return relative_error(est, truth_pose)


@pytest.mark.slow
def test_live_calibrates_then_recalibrates_a_moved_camera(make_scene):
    turn = Rotation.from_rotvec([0.0, 0.0, np.radians(12.0)])
    scene0 = make_scene(angles_deg=(0.0, 100.0), duration=1.0)
    position = scene0.truth.cameras["cam1"].translation
    # rotate the camera about its own position and shift it 30 cm: a bumped tripod
    move = RigidTransform(turn, position - turn.apply(position) + np.array([0.3, 0.0, 0.0]))
    scene = make_scene(
        angles_deg=(0.0, 100.0), duration=45.0, noise=0.005, moves={1: (100.0 + 28.0, move)}
    )
    params = LiveCalibratorParams(buffer_length=20.0, first_estimate_after=12.0, update_period=8.0)
    live = LiveCalibrator(params)
    truth = scene.truth.cameras
    before = truth["cam0"].extrinsics.inverse() @ truth["cam1"].extrinsics
    after = truth["cam0"].extrinsics.inverse() @ move @ truth["cam1"].extrinsics

    _feed(scene, live)
    events = " | ".join(f"{t * 1e-9:.1f} {m}" for t, m in live.events)
    moved_at = truth["cam0"].to_reference_time(128.0)  # cam0 is the reference clock
    calibrated = [t * 1e-9 for t, m in live.events if m == "cam1: calibrated"]
    detected = [t * 1e-9 for t, m in live.events if m.startswith("cam1: moved")]
    assert calibrated, events
    assert calibrated[0] < moved_at
    # detected and recalibrated within 10 s of data after the move
    assert detected, events
    assert moved_at < detected[0] < moved_at + 10.0, events
    assert any(moved_at < t < moved_at + 10.0 for t in calibrated[1:]), events
    angle, distance = _pose_error(live, after)
    assert angle < 0.5, events
    assert distance < 0.02, events
    assert relative_error(live.calibration.cameras["cam1"].extrinsics, before)[0] > 10.0
    assert live.calibration.cameras["cam1"].time_offset == pytest.approx(
        truth["cam1"].time_offset, abs=3e-3
    )


def test_stamps_far_back_restart_the_cameras_buffer_small_steps_are_dropped():
    """One frame stamped far ahead (or a restarted camera clock) used to make every later
    frame of the camera 'out_of_order', for good."""

    live = LiveCalibrator(LiveCalibratorParams())
    second = 1_000_000_000
    stamps = [1, 2, 3, 2**31 * second, 4, 5, 4.5, 6]  # a glitch, then a small step back
    for index, stamp in enumerate(stamps):
        live.update(SkeletonGroup(round(stamp * second), "cam0"), index)
    assert live.snapshot()["buffered"] == {"cam0": 3}  # 4, 5, 6
    assert live.drops == {"stamps_went_back": 1, "out_of_order": 1}
    assert "cam0: stamps went back" in live.events[-1][1]


def _knock(make_scene, degrees, shift, **options):
    """A scene whose cam1 turns ``degrees`` about the vertical and slides ``shift`` m at 128 s."""
    turn = Rotation.from_rotvec([0.0, 0.0, np.radians(degrees)])
    position = make_scene(angles_deg=(0.0, 100.0), duration=1.0).truth.cameras["cam1"].translation
    move = RigidTransform(turn, position - turn.apply(position) + np.array([shift, 0.0, 0.0]))
    scene = make_scene(angles_deg=(0.0, 100.0), moves={1: (100.0 + 28.0, move)}, **options)
    return scene, move


@pytest.mark.slow
def test_a_small_knock_is_found_by_every_joint_moving_the_same_way(make_scene):
    """With noisy skeletons a 2.5° knock hardly raises the median joint distance (the noise sets
    it) but displaces the joints all alike, which ``moved_shift`` catches."""
    scene, _ = _knock(make_scene, 2.5, 0.03, duration=40.0, noise=0.07)
    moved_at = scene.truth.cameras["cam0"].to_reference_time(128.0)
    params = LiveCalibratorParams(buffer_length=20.0, first_estimate_after=12.0, update_period=8.0)
    found = {}
    for shift in (params.moved_shift, np.inf):
        live = LiveCalibrator(LiveCalibratorParams(**{**vars(params), "moved_shift": shift}))
        _feed(scene, live)
        found[shift] = [t * 1e-9 for t, m in live.events if m.startswith("cam1: moved")]
        assert not [m for t, m in live.events if t * 1e-9 < moved_at and "moved" in m]
    detected = found[params.moved_shift]
    assert detected
    assert moved_at < detected[0] < moved_at + 10.0
    assert not found[np.inf], found  # the median distance alone misses it


@pytest.mark.slow
def _loaded(scene, turn_deg: float) -> tuple[Calibration, RigidTransform]:
    """A calibration as a file would hold it (world = cam0) with cam1 turned ``turn_deg``,
    and cam1's true pose."""
    truth = scene.truth.cameras
    true_pose = truth["cam0"].extrinsics.inverse() @ truth["cam1"].extrinsics
    turned = Rotation.from_rotvec([0.0, 0.0, np.radians(turn_deg)]) * true_pose.rotation
    start = Calibration(reference="cam0", world_frame="world")
    start.cameras = {
        "cam0": CameraCalibration(**{**vars(truth["cam0"]), "translation": np.zeros(3),
                                     "rotation": np.array([0.0, 0.0, 0.0, 1.0])}),
        "cam1": CameraCalibration(**{**vars(truth["cam1"]), "translation": true_pose.translation,
                                     "rotation": turned.as_quat()}),
    }  # fmt: skip
    return start, true_pose


_NO_CHECK = {
    "buffer_length": 20.0,
    "first_estimate_after": 12.0,
    "update_period": 8.0,
    "moved_floor": np.inf,
    "moved_shift": np.inf,
}


@pytest.mark.slow
def test_a_wrong_pose_is_replaced_once_estimates_keep_disagreeing_with_it(make_scene):
    """A pose that new estimates all contradict (loaded from a stale file, or a recalibration
    from a few seconds gone wrong) used to stay for good, each estimate dropped as
    'estimate_disagrees'. With the check off, only the estimates can mend it."""
    scene = make_scene(angles_deg=(0.0, 100.0), duration=40.0, noise=0.005)
    start, true_pose = _loaded(scene, 20.0)
    live = LiveCalibrator(LiveCalibratorParams(**_NO_CHECK), calibration=start)
    _feed(scene, live)
    events = " | ".join(f"{t * 1e-9:.1f} {m}" for t, m in live.events)
    replaced = [m for _, m in live.events if m.startswith("cam1: replaced")]
    assert replaced, events
    assert "2 estimates in a row disagreed with it by" in replaced[0]
    assert float(replaced[0].split(" by ")[1].split(" deg")[0]) == pytest.approx(20.0, abs=0.5)
    assert "and fit their frames better" in replaced[0]
    angle, distance = _pose_error(live, true_pose)
    assert angle < 0.5, events
    assert distance < 0.02, events
    assert live.drops["estimate_disagrees"] == 1


@pytest.mark.slow
def test_disagreeing_estimates_must_also_fit_better_to_replace_the_pose(make_scene, monkeypatch):
    """Estimates agreeing among themselves are not enough: data that cannot pin a pose down
    (one person walking on the spot) gives consistent but wrong ones. They must fit their
    frames ``REPLACE_MARGIN`` better than the current pose; a margin no fit can meet keeps
    even a pose 20° off."""
    monkeypatch.setattr(hiros_calib.live, "REPLACE_MARGIN", 1.0)
    scene = make_scene(angles_deg=(0.0, 100.0), duration=40.0, noise=0.005)
    start, _ = _loaded(scene, 20.0)
    live = LiveCalibrator(LiveCalibratorParams(**_NO_CHECK), start)
    _feed(scene, live)
    assert not [m for _, m in live.events if "replaced" in m]
    assert live.drops["estimate_disagrees"] >= 3


def test_the_check_pairs_people_by_where_the_current_poses_put_them():
    """Two people alike in shape and motion, 1 m apart, seen with 2 cm of noise: their pose
    signatures cannot tell them apart (on this seed the signature association pairs them
    crosswise, a 1 m residual: what flagged an unmoved camera on the simulator). With the
    poses known, each is paired with the body at the same place."""

    rng = np.random.default_rng(1)
    times = np.arange(90) / 30.0
    shape = rng.uniform(-0.3, 0.3, (1, 32, 3))
    walk = np.stack([np.cos(times), np.sin(times), np.zeros_like(times)], axis=1)[:, None]
    people = [shape + walk, shape + walk + np.array([1.0, 0.0, 0.0])]

    def tracks():
        return [
            BodyTrack(
                "a", k, AZURE_KINECT, times, p + rng.normal(0, 0.02, p.shape), np.ones((90, 32))
            )
            for k, p in enumerate(people)
        ]

    clock = CameraClock("a", "ok", "", 0.0, 0.0, 0.0)
    vectors = _matched_residuals(
        (tracks(), tracks()), (clock, clock), RigidTransform.identity(), LiveCalibratorParams()
    )
    assert len(vectors) == 2 * 90 * 19  # both people, every mirror-proof point of every frame
    assert np.median(np.linalg.norm(vectors, axis=1)) < 0.05


@pytest.mark.slow
def test_a_camera_clock_that_jumps_is_found_and_its_new_offset_recovered(make_scene):
    """cam1's clock jumps 0.5 s ahead (a driver restart, a host clock step): the same people
    then land in different places, the check flags it and the recalibration finds the new
    offset."""

    scene = make_scene(angles_deg=(0.0, 100.0), duration=45.0, noise=0.005)
    truth = scene.truth.cameras
    jump_ns, jump_at = 500_000_000, truth["cam0"].to_reference_time(128.0)

    def later(group: SkeletonGroup) -> SkeletonGroup:
        skeletons = [
            dataclasses.replace(s, src_time_ns=s.src_time_ns + jump_ns) for s in group.skeletons
        ]
        return SkeletonGroup(group.stamp_ns + jump_ns, group.frame_id, skeletons)

    scene.camera_groups["cam1"] = [
        later(g) if truth["cam1"].to_reference_time(g.stamp) >= jump_at else g
        for g in scene.camera_groups["cam1"]
    ]
    params = LiveCalibratorParams(buffer_length=20.0, first_estimate_after=12.0, update_period=8.0)
    live = LiveCalibrator(params)
    _feed_jumped(scene, live, jump_at)
    events = " | ".join(f"{t * 1e-9 - jump_at:.1f} {m}" for t, m in live.events)
    detected = [t * 1e-9 for t, m in live.events if m.startswith("cam1: moved or clock jumped")]
    assert detected, events
    assert jump_at < detected[0] < jump_at + 10.0, events
    # t_ref = t_cam + offset: stamps 0.5 s later, so the offset is 0.5 s smaller
    assert live.calibration.cameras["cam1"].time_offset == pytest.approx(
        truth["cam1"].time_offset - 0.5, abs=3e-3
    ), events


def test_a_camera_that_falls_silent_and_comes_back_is_reported():

    live = LiveCalibrator(LiveCalibratorParams(first_estimate_after=1e6, silent_after=5.0))
    second = 1_000_000_000
    for tenth in range(200):  # 20 s at 10 Hz; cam1 is silent from 4 s to 12 s
        now = tenth * second // 10
        for camera in ("cam0", "cam1"):
            if camera == "cam1" and 40 <= tenth < 120:
                continue
            live.update(SkeletonGroup(now, camera), now)
        live.step(now)
        if tenth == 110:
            assert live.snapshot()["silent"] == ["cam1"]
    messages = [m for _, m in live.events]
    # its last frame came at 3.9 s; checks run each second
    assert messages == ["cam1: no frames for 5.1 s", "cam1: frames again after 8.1 s"]
    assert live.snapshot()["silent"] == []


def test_the_check_follows_a_person_whose_id_changed_in_one_camera():
    """One camera gave the person a new id halfway: both of its tracks pair with the other
    camera's single track, one after the other, so no frame is left out."""

    rng = np.random.default_rng(3)
    times = np.arange(90) / 30.0
    person = rng.uniform(-0.3, 0.3, (1, 32, 3)) + times[:, None, None] * np.array([1.0, 0, 0])
    whole = BodyTrack("a", 1, AZURE_KINECT, times, person, np.ones((90, 32)))
    halves = [
        BodyTrack("b", k + 1, AZURE_KINECT, times[part], person[part], np.ones((45, 32)))
        for k, part in enumerate((slice(0, 45), slice(45, 90)))
    ]
    clock = CameraClock("a", "ok", "", 0.0, 0.0, 0.0)
    vectors = _matched_residuals(
        ([whole], halves), (clock, clock), RigidTransform.identity(), LiveCalibratorParams()
    )
    assert len(vectors) == 90 * 19
    assert np.abs(vectors).max() < 1e-9


def test_the_events_kept_are_bounded_and_handed_out_once():
    """A node running for weeks logs each event as it comes; the calibrator keeps only the
    newest ``EVENTS_KEPT`` of them, and counts every one by kind."""

    live = LiveCalibrator(LiveCalibratorParams())
    second = 1_000_000_000
    restarts = EVENTS_KEPT + 20
    for k in range(restarts + 1):  # each frame 2 s before the last: the buffer restarts
        live.update(SkeletonGroup((10 * restarts - 2 * k) * second, "cam0"), k)
    assert len(live.events) == EVENTS_KEPT
    assert live.event_count == restarts
    assert live.tally == {"restarted": restarts}
    assert live.diagnostics()["events.restarted"] == str(restarts)
    newest, count = live.events_since(restarts - 3)
    assert count == restarts
    assert newest == list(live.events)[-3:]
    assert live.events_since(0)[0] == list(live.events)  # the older ones are gone
    assert live.events_since(count) == ([], count)


def test_a_camera_stamping_too_fast_does_not_grow_the_window():
    """Stamps 1 ms apart (a clock creeping forward) would put 60 000 frames in a 60 s window;
    the window keeps ``MAX_FRAME_RATE`` frames per second of it and counts the rest."""

    live = LiveCalibrator(LiveCalibratorParams(buffer_length=2.0))
    frames = 1000
    for k in range(frames):
        live.update(SkeletonGroup(k * 1_000_000, "cam0"), k)
    kept = round(2.0 * MAX_FRAME_RATE)
    assert live.snapshot()["buffered"] == {"cam0": kept}
    assert live.drops["window_over_rate"] == frames - kept
    assert live.processed == frames


def _feed_simulated(scene, live):
    """A simulated recording's frames as a node receives them (reference time + 20 ms)."""
    frames = sorted(
        (round((scene.calibration.cameras[name].to_reference_time(g.stamp) + 0.02) * 1e9), k, g)
        for name, groups in scene.camera_groups.items()
        for k, g in enumerate(groups)
    )
    for k, (arrival, _, group) in enumerate(frames):
        live.update(group, arrival)
        if k % 3 == 0:
            live.step(arrival)


@pytest.mark.slow
def test_known_poses_let_a_person_on_one_spot_be_timed_live(tmp_path):
    """One person exercising on one spot: every estimate of the pose is flagged, so the node
    has no calibration; with the poses of an earlier calibration (``poses_from``) its clocks
    are estimated and the known poses kept."""
    from hiros_core.calibration import save_calibration
    from hiros_eval.calibration import compare_calibration
    from hiros_sim import simulate
    from hiros_sim.presets import preset_params

    scene = simulate(preset_params("exercise-on-spot", seed=2, duration=40.0))
    truth = scene.calibration
    plain = LiveCalibrator(LiveCalibratorParams(reference="k01"))
    _feed_simulated(scene, plain)
    assert "k02" not in plain.calibration.cameras
    assert plain.drops["estimate_flagged"] > 0

    known = tmp_path / "walk.yaml"
    save_calibration(truth, known)
    live = LiveCalibrator(LiveCalibratorParams(reference="k01", poses_from=str(known)))
    _feed_simulated(scene, live)
    k02 = live.calibration.cameras["k02"]
    assert not k02.flagged
    assert k02.translation == pytest.approx(truth.cameras["k02"].translation, abs=1e-6)
    stamps = {c: np.array([g.stamp for g in gs]) for c, gs in scene.camera_groups.items()}
    assert compare_calibration(live.calibration, truth, stamps)["k02"].time_error_ms < 10.0
