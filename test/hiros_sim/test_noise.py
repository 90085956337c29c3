import numpy as np
import pytest

from hiros_core.layouts import AZURE_KINECT
from hiros_sim import default_bvh_files, read_bvh
from hiros_sim.noise import ar1_noise, fit_body_model, flip_front_back, in_view, occluded
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
