"""Clips as people: the SDK's foot joints rest where the real Azure Kinect puts them."""

from __future__ import annotations

import numpy as np
import pytest

from hiros_calib.tracks import extract_tracks
from hiros_calib.world import FOOT_JOINT_HEIGHT
from hiros_core.layouts import AZURE_KINECT
from hiros_sim import simulate
from hiros_sim.bvh import read_bvh
from hiros_sim.fit import take_scene
from hiros_sim.params import default_bvh_files
from hiros_sim.people import SDK_FOOT_HEIGHTS, prepare_clip


def _resting_height(joint: np.ndarray, rate: float) -> float:
    """Median height of a ``(T, 3)`` joint over the frames it moves < 0.15 m/s over 0.4 s."""
    half = round(0.2 * rate)
    speed = np.linalg.norm(joint[2 * half :] - joint[: -2 * half], axis=1) * rate / (2 * half)
    return float(np.median(joint[half:-half][speed < 0.15, 2]))


@pytest.mark.parametrize("path", default_bvh_files())
def test_a_clip_rests_its_foot_joints_at_the_sdks_heights(path: str) -> None:
    motion = read_bvh(path)
    clip = prepare_clip(motion)
    for kind, height in SDK_FOOT_HEIGHTS.items():
        for side in ("Left", "Right"):
            joint = clip.positions[:, AZURE_KINECT.index(f"{kind}{side}")]
            assert _resting_height(joint, motion.rate) == pytest.approx(height, abs=0.005)
    # the rest of the body stays where the mocap put it: the knees keep their motion
    knee = clip.positions[:, AZURE_KINECT.index("KneeLeft"), 2]
    assert 0.3 < np.median(knee) < 0.6
    # the foot link keeps one length, as the SDK's limbs do (the mocap's toe does not)
    for side in ("Left", "Right"):
        link = (
            clip.positions[:, AZURE_KINECT.index(f"Foot{side}")]
            - clip.positions[:, AZURE_KINECT.index(f"Ankle{side}")]
        )
        length = np.linalg.norm(link, axis=1)
        assert 0.08 < np.median(length) < 0.25
        np.testing.assert_allclose(length, np.median(length), rtol=1e-9)


@pytest.mark.slow
def test_the_simulated_sdk_rests_its_feet_as_the_real_take_does() -> None:
    # the take's scene (hiros_sim.fit.simulated_errors'): one camera 3.3 m from one person
    # bending; the SDK's resting foot joint sits where the real one did on the take
    # (FOOT_JOINT_HEIGHT, read off it; test_world holds that): a planted foot stays on its
    # evidence. Without the per-joint bias, which is zero-mean but moves one seed's mean by
    # centimetres (8-14 cm per seed).
    heights = {"Foot": [], "Ankle": []}
    for seed in range(4):
        scene = simulate(take_scene(seed=seed, joint_bias=0.0))
        ((camera, groups),) = scene.camera_groups.items()
        pose = scene.calibration.camera(camera).extrinsics
        tracks = extract_tracks(groups, camera)
        for kind, values in heights.items():
            values.append(
                np.median(
                    [
                        _resting_height(pose.apply(track.positions[:, joint]), 30.0)
                        for track in tracks
                        for joint in (
                            track.layout.joint_names.index(f"{kind}{side}")
                            for side in ("Left", "Right")
                        )
                    ]
                )
            )
    assert np.mean(heights["Foot"]) == pytest.approx(FOOT_JOINT_HEIGHT["Foot"], abs=0.003)
    # and the ankle where the real one rested on the take (docs/world-frame.md)
    assert np.mean(heights["Ankle"]) == pytest.approx(0.176, abs=0.003)
