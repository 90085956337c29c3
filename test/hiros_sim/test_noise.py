import numpy as np
import pytest

from hiros_core.layouts import AZURE_KINECT
from hiros_sim import default_bvh_files, read_bvh
from hiros_sim.noise import (
    LEGS,
    ar1_noise,
    fit_body_model,
    flip_front_back,
    in_view,
    level_feet_bias,
    occluded,
    plant_legs,
    planted_feet,
)
from hiros_sim.people import body_forward, prepare_clip

IDX = AZURE_KINECT.index
# world (Z up) -> camera frame (x right, y down, z forward) of a camera at (0, -3, 1) looking +y
WORLD_TO_CAMERA = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@pytest.fixture(scope="module")
def standing():
    """A standing pose in the world, facing -y (towards the camera at y = -3)."""
    clip = prepare_clip(read_bvh(default_bvh_files()[0]))
    pose = clip.positions[0]
    forward = body_forward(pose)
    yaw = np.arctan2(forward[1], forward[0])
    turn = -np.pi / 2 - yaw  # face -y
    c, s = np.cos(turn), np.sin(turn)
    return pose @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T


def _camera(pose, yaw=0.0):
    c, s = np.cos(yaw), np.sin(yaw)
    turned = pose @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    return (turned - [0.0, -3.0, 1.0]) @ WORLD_TO_CAMERA.T


def test_face_hidden_from_behind_only(standing):
    front = occluded(_camera(standing)[None, None])[0, 0]
    back = occluded(_camera(standing, np.pi)[None, None])[0, 0]
    face = [IDX(n) for n in ("Nose", "EyeLeft", "EyeRight")]
    assert not front[face].any()
    assert back[face].all()
    assert not back[IDX("Pelvis")]


def test_person_behind_another_is_hidden(standing):
    near = _camera(standing)
    far = near + np.array([0.0, 0.0, 1.5])  # 1.5 m further along the optical axis
    hidden = occluded(np.stack([near, far])[:, None])
    assert hidden[1, 0, IDX("SpineChest")]
    assert not hidden[0, 0, IDX("SpineChest")]


def test_in_view():
    points = np.array([[0, 0, 2.0], [0, 0, 0.2], [0, 0, 9.0], [3.0, 0, 2.0], [0, -1.0, 2.0]])
    assert in_view(points, (75.0, 65.0), (0.5, 5.5)).tolist() == [True, False, False, False, True]


def test_flip_front_back_faces_the_other_way(standing):
    cam = _camera(standing, np.pi)[None]  # facing away from the camera
    forward_world = body_forward(standing)
    c, s = np.cos(np.pi), np.sin(np.pi)
    forward = (np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ forward_world) @ WORLD_TO_CAMERA.T
    flipped = flip_front_back(cam, forward[None])[0]
    # the nose now points towards the camera (-z) and the labels say left is on camera right
    assert flipped[IDX("Nose"), 2] < flipped[IDX("Head"), 2]
    assert flipped[IDX("ShoulderLeft"), 0] > flipped[IDX("ShoulderRight"), 0]
    np.testing.assert_allclose(flipped[IDX("Pelvis")], cam[0, IDX("Pelvis")])


def test_ar1_noise_statistics():
    rng = np.random.default_rng(0)
    noise = ar1_noise(rng, (200, 300, 3), 0.8)
    assert noise.std() == pytest.approx(1.0, abs=0.05)
    lag1 = np.mean(noise[:, 1:] * noise[:, :-1])
    assert lag1 == pytest.approx(0.8, abs=0.05)
    assert noise[:, 0].std() == pytest.approx(1.0, abs=0.1)  # stationary from the first frame


def test_level_feet_bias_gives_both_feet_one_smaller_height_offset():
    rng = np.random.default_rng(3)
    bias = rng.normal(0.0, 0.026, (2, 5, AZURE_KINECT.n_joints, 3))  # drifting: one per frame
    before = bias.copy()
    pitch = np.array(
        [[1.0, 0.0, 0.0], [0.0, np.cos(0.3), -np.sin(0.3)], [0.0, np.sin(0.3), np.cos(0.3)]]
    )
    up = pitch @ WORLD_TO_CAMERA[:, 2]  # the world's z seen by a camera pitched by 0.3 rad
    level_feet_bias(bias, up, 0.2)
    for part in ("Ankle", "Foot"):
        left, right = IDX(f"{part}Left"), IDX(f"{part}Right")
        np.testing.assert_allclose(bias[..., left, :] @ up, 0.2 * before[..., left, :] @ up)
        np.testing.assert_allclose(bias[..., right, :] @ up, bias[..., left, :] @ up)
        for joint in (left, right):  # moved along up only
            moved = bias[..., joint, :] - before[..., joint, :]
            np.testing.assert_allclose(np.cross(moved, up), 0.0, atol=1e-15)
    feet = [IDX(j) for j in ("AnkleLeft", "FootLeft", "AnkleRight", "FootRight")]
    others = [j for j in range(AZURE_KINECT.n_joints) if j not in feet]
    np.testing.assert_array_equal(bias[..., others, :], before[..., others, :])


def _random_poses(standing, rng, frames=400):
    """``(frames, 32, 3)`` copies of the standing pose, each turned and moved at random."""
    yaw = rng.uniform(0.0, 2.0 * np.pi, frames)
    c, s = np.cos(yaw), np.sin(yaw)
    zero, one = np.zeros(frames), np.ones(frames)
    turn = np.stack([c, -s, zero, s, c, zero, zero, zero, one], axis=-1).reshape(frames, 3, 3)
    return np.einsum("nab,jb->nja", turn, standing) + rng.normal(0.0, 1.0, (frames, 1, 3))


def test_fit_body_model_without_noise_is_the_truth(standing):
    truth = _random_poses(standing, np.random.default_rng(0), 20)
    fitted = fit_body_model(truth, truth, np.ones(20), np.ones((20, 32)))
    np.testing.assert_allclose(fitted, truth, atol=1e-12)


def test_fit_body_model_keeps_limb_ratios(standing):
    """Whatever the evidence, every limb is its true length times the frame's scale."""
    rng = np.random.default_rng(1)
    truth = _random_poses(standing, rng, 50)
    evidence = truth + rng.normal(0.0, 0.05, truth.shape)
    scale = rng.uniform(0.9, 1.1, 50)
    gain = np.ones((50, 32))
    gain[:, IDX("ThumbLeft")] = 1.2
    fitted = fit_body_model(evidence, truth, scale, gain)
    parents = np.asarray(AZURE_KINECT.parents)[1:]
    true_lengths = np.linalg.norm(truth[:, 1:] - truth[:, parents], axis=-1)
    lengths = np.linalg.norm(fitted[:, 1:] - fitted[:, parents], axis=-1)
    np.testing.assert_allclose(lengths, scale[:, None] * gain[:, 1:] * true_lengths, rtol=1e-9)
    # the scale is about the centroid: the body's centre stays where the evidence put it
    unscaled = fit_body_model(evidence, truth, np.ones(50), gain)
    np.testing.assert_allclose(fitted.mean(axis=1), unscaled.mean(axis=1), atol=1e-12)


def test_fit_body_model_errors_are_coherent_and_do_not_grow(standing):
    """Independent evidence noise becomes errors correlated with the parent's, about as large
    at the hand tip (8 links from the root) as at the pelvis."""
    rng = np.random.default_rng(2)
    truth = _random_poses(standing, rng)
    sigma = 0.02
    fitted = fit_body_model(
        truth + rng.normal(0.0, sigma, truth.shape), truth, np.ones(len(truth)), np.ones((400, 32))
    )
    error = fitted - truth
    rms = np.sqrt(np.mean(error**2, axis=(0, 2)))  # (32,) per axis
    for joint in ("Pelvis", "WristLeft", "HandTipLeft", "AnkleRight", "Nose"):
        assert 0.8 * sigma < rms[IDX(joint)] < 1.25 * sigma, joint
    parents = np.asarray(AZURE_KINECT.parents)
    child, parent = error[:, 1:].reshape(-1, 3), error[:, parents[1:]].reshape(-1, 3)
    correlation = np.sum(child * parent) / np.sqrt(np.sum(child**2) * np.sum(parent**2))
    assert correlation > 0.2  # independent joint noise would give 0


def test_planted_feet_rest_where_the_foot_is_still(standing):
    frames = 90  # 3 s at 30 Hz: the right foot steps forward at 1 m/s during the second
    poses = np.repeat(standing[None], frames, axis=0)
    step = np.clip((np.arange(frames) - 30) / 30.0, 0.0, 1.0)
    poses[:, IDX("FootRight"), 0] += step
    planted = planted_feet(poses[None], 30.0)[0]
    assert planted[10:-10, 0].all()  # the left foot never moves (but for the ends)
    assert not planted[[0, -1]].any()  # the speed is not measured at the ends
    assert not planted[35:55, 1].any()
    assert planted[75:84, 1].all()
    assert planted[6:24, 1].all()


def _leg_lengths(skeletons, leg):
    parents = np.asarray(AZURE_KINECT.parents)
    return np.linalg.norm(skeletons[..., leg, :] - skeletons[..., parents[list(leg)], :], axis=-1)


def test_plant_legs_without_noise_is_the_truth(standing):
    truth = _random_poses(standing, np.random.default_rng(3), 20)[None]
    placed = plant_legs(truth, truth, truth, np.ones((1, 20)), np.ones((1, 20, 2), bool))
    np.testing.assert_allclose(placed, truth, atol=1e-9)


def test_plant_legs_puts_a_planted_foot_on_its_evidence(standing):
    """The knee gives: the foot on its evidence where the leg reaches, every link its length."""
    rng = np.random.default_rng(4)
    truth = _random_poses(standing, rng, 200)[None]
    sigma = np.full(32, 0.03)
    sigma[list(LEGS[0][2:])] = 0.01  # a planted ankle and foot are seen better
    evidence = truth + rng.normal(0.0, 1.0, truth.shape) * sigma[:, None]
    scale = rng.uniform(0.95, 1.05, (1, 200))
    fitted = fit_body_model(evidence, truth, scale, np.ones((1, 200, 32)))
    planted = np.zeros((1, 200, 2), bool)
    planted[..., 0] = True  # the left foot rests, the right one swings
    placed = plant_legs(fitted, evidence, truth, scale, planted)
    hip, knee, ankle, foot = LEGS[0]
    untouched = np.setdiff1d(np.arange(32), [knee, ankle, foot])
    np.testing.assert_array_equal(placed[..., untouched, :], fitted[..., untouched, :])
    true_lengths = _leg_lengths(truth, (knee, ankle, foot)) * scale[..., None]
    np.testing.assert_allclose(_leg_lengths(placed, (knee, ankle, foot)), true_lengths, rtol=1e-9)
    reach = true_lengths[..., 0] + true_lengths[..., 1]
    hip_to_ankle = np.linalg.norm(placed[..., ankle, :] - placed[..., hip, :], axis=-1)
    within = hip_to_ankle < reach - 1e-6
    assert 0.5 < within.mean() < 1.0  # most legs bend, some cannot reach
    miss = np.linalg.norm(placed[..., foot, :] - evidence[..., foot, :], axis=-1)
    np.testing.assert_allclose(miss[within], 0.0, atol=1e-9)
    # out of reach, the leg is straight and its foot stops short of its evidence
    np.testing.assert_allclose(hip_to_ankle[~within], reach[~within], rtol=1e-9)
    assert np.all(miss[~within] > 0.0)
    # the rigid fit's feet carry the leg's errors: the planted ones are nearer their evidence
    rigid_miss = np.linalg.norm(fitted[..., foot, :] - evidence[..., foot, :], axis=-1)
    assert np.median(miss) < 0.5 * np.median(rigid_miss)
