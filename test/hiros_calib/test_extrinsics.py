import numpy as np
import pytest

from hiros_calib.extrinsics import (
    ExtrinsicsParams,
    associate,
    baseline_pair_pose,
    estimate_pair_pose,
    pair_correspondences,
    relative_error,
)
from hiros_calib.sync import CameraClock
from hiros_calib.tracks import extract_tracks


def _clocks(scene, a, b):
    def clock(name):
        cal = scene.truth.cameras[name]
        return CameraClock(name, "ok", "", cal.time_offset, cal.drift, cal.drift_epoch)

    return clock(a), clock(b)


@pytest.fixture(scope="module")
def facing_cameras(make_scene):
    # two cameras 180 degrees apart: one always sees the person from behind (left/right swapped)
    return make_scene(angles_deg=(0.0, 180.0), duration=12.0, noise=0.005, seed=5)


def test_known_pose_recovered_for_cameras_facing_each_other(facing_cameras):
    scene = facing_cameras
    tracks = {c: extract_tracks(g, c) for c, g in scene.camera_groups.items()}
    clock_a, clock_b = _clocks(scene, "cam0", "cam1")
    params = ExtrinsicsParams()
    correspondences = pair_correspondences(
        tracks["cam0"][0], tracks["cam1"][0], clock_a, clock_b, params
    )
    pose = estimate_pair_pose(correspondences)
    assert pose.ok, pose.reason
    truth = (
        scene.truth.cameras["cam0"].extrinsics.inverse() @ scene.truth.cameras["cam1"].extrinsics
    )
    angle, distance = relative_error(pose.transform, truth)
    assert angle < 0.1
    assert distance < 0.005
    # one of two facing cameras sees the person from behind: swapped pairs are chosen
    assert pose.quality["mirrored_fraction"] > 0.8
    assert pose.quality["inlier_ratio"] > 0.95


def test_swap_choice_matters(facing_cameras):
    """Without the per-frame left/right choice, the same data fit much worse."""
    scene = facing_cameras
    tracks = {c: extract_tracks(g, c) for c, g in scene.camera_groups.items()}
    clock_a, clock_b = _clocks(scene, "cam0", "cam1")
    params = ExtrinsicsParams()
    c = pair_correspondences(tracks["cam0"][0], tracks["cam1"][0], clock_a, clock_b, params)
    pose = estimate_pair_pose(c)
    straight = np.linalg.norm(pose.transform.apply(c.points_b) - c.points_a, axis=2)
    chosen = np.linalg.norm(
        pose.transform.apply(pose.correspondences.points_b) - c.points_a, axis=2
    )
    assert np.median(chosen) < 0.02
    assert np.percentile(straight, 75) > 5 * np.percentile(chosen, 75)


def _truth(scene, a, b):
    return scene.truth.cameras[a].extrinsics.inverse() @ scene.truth.cameras[b].extrinsics


def test_baseline_recovers_a_pose_the_skeletons_agree_on(make_scene):
    scene = make_scene(angles_deg=(0.0, 90.0), duration=10.0, noise=0.005, seed=3)
    tracks = {c: extract_tracks(g, c) for c, g in scene.camera_groups.items()}
    params = ExtrinsicsParams()
    c = pair_correspondences(
        tracks["cam0"][0], tracks["cam1"][0], *_clocks(scene, "cam0", "cam1"), params
    )
    angle, distance = relative_error(baseline_pair_pose(c), _truth(scene, "cam0", "cam1"))
    assert angle < 0.2
    assert distance < 0.01
    assert baseline_pair_pose(c.take(np.arange(1))) is None  # too few joint pairs


def test_baseline_is_misled_by_mirrored_skeletons(facing_cameras):
    """Eichler's method alone takes the swapped left/right joints of the camera behind as
    they are: its pose is far worse than ``estimate_pair_pose``'s on the same pairs."""
    scene = facing_cameras
    tracks = {c: extract_tracks(g, c) for c, g in scene.camera_groups.items()}
    params = ExtrinsicsParams()
    c = pair_correspondences(
        tracks["cam0"][0], tracks["cam1"][0], *_clocks(scene, "cam0", "cam1"), params
    )
    truth = _truth(scene, "cam0", "cam1")
    ours, _ = relative_error(estimate_pair_pose(c).transform, truth)
    baseline = baseline_pair_pose(c)
    assert baseline is not None
    assert relative_error(baseline, truth)[0] > 5 * max(ours, 0.05)


def test_two_people_are_associated_by_signature(make_scene):
    scene = make_scene(angles_deg=(0.0, 90.0), duration=10.0, n_people=2, noise=0.005, seed=2)
    tracks = {c: extract_tracks(g, c) for c, g in scene.camera_groups.items()}
    clock_a, clock_b = _clocks(scene, "cam0", "cam1")
    pairs = associate(tracks["cam0"], tracks["cam1"], clock_a, clock_b, ExtrinsicsParams())
    matched = sorted((tracks["cam0"][i].body_id, tracks["cam1"][j].body_id) for i, j, _ in pairs)
    assert matched == [(1, 1), (2, 2)]


def test_no_common_view_refuses():
    pose = estimate_pair_pose(None)
    assert not pose.ok
    assert "never see the same person" in pose.reason


def test_frames_kept_grow_with_the_recording():
    """A long recording keeps frames in proportion to its length, up to ``max_frames``."""
    from hiros_calib.extrinsics import Correspondences, Sampling
    from hiros_calib.extrinsics.pair_pose import _frame_budget

    def pairs(seconds, rate=30.0):
        times = np.arange(0.0, seconds, 1.0 / rate)
        zeros = np.zeros((len(times), 2, 3))
        return Correspondences(zeros, zeros, np.ones((len(times), 2)), np.array([1, 0]),
                               ("a", "b"), np.zeros(2, dtype=np.int64), times)  # fmt: skip

    sampling = Sampling(ransac_iterations=400, frames_per_minute=1000.0, max_frames=5000)
    assert _frame_budget(pairs(30.0), sampling) == 1000  # short: no fewer than a minute's worth
    assert _frame_budget(pairs(180.0), sampling) == pytest.approx(3000, abs=1)
    assert _frame_budget(pairs(600.0), sampling) == 5000


def _moving_joints(excursion: np.ndarray, bodies: np.ndarray | None = None):
    """Correspondences of two joints far apart, each moved by ``excursion`` (F, 3) per frame."""
    from hiros_calib.extrinsics import Correspondences

    frames = len(excursion)
    stand = np.array([[0.0, 0.0, 3.0], [0.0, -1.5, 3.5]])  # where each joint stands (m)
    points = stand[None] + excursion[:, None]
    bodies = bodies if bodies is not None else np.zeros(frames, dtype=np.int64)
    return Correspondences(
        points,
        points,
        np.ones((frames, 2)),
        np.array([1, 0]),
        ("a", "b"),
        np.zeros(2, dtype=np.int64),
        np.arange(frames) / 30.0,
        bodies,
    )


def test_the_motion_lever_is_the_joints_motion_about_their_own_means():
    """Where each joint stands is the SDK's offset to the solve, not a lever: only the
    motion counts, as the RMS distance from each joint's own mean."""
    from hiros_calib.extrinsics import motion_lever

    angle = np.linspace(0.0, 2.0 * np.pi, 600, endpoint=False)
    circle = 0.3 * np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    assert motion_lever(_moving_joints(circle)) == pytest.approx(0.3, rel=1e-6)
    line = np.stack([0.4 * np.sin(angle), np.zeros_like(angle), np.zeros_like(angle)], axis=1)
    assert motion_lever(_moving_joints(line)) == pytest.approx(0.4 / np.sqrt(2.0), rel=1e-6)
    # two body pairs standing 2 m apart, each on the spot: no lever from where they stood
    small = 0.01 / 0.3 * np.concatenate([circle[::2], circle[::2]])  # two 1 cm circles
    apart = np.where((np.arange(600) < 300)[:, None], 0.0, [2.0, 0.0, 0.0]) + small
    bodies = (np.arange(600) >= 300).astype(np.int64)
    assert motion_lever(_moving_joints(apart, bodies)) == pytest.approx(0.01)
    assert motion_lever(_moving_joints(apart)) > 0.9  # as one body: it walked 2 m
    assert motion_lever(None) is None
