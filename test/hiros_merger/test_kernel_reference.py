"""The fusion kernel held equal to its numpy statement (``test/support/merger_reference.py``).

Hypothesis draws the seeds of random frames and the settings: a few people near each other
(occluding), seen by a few cameras (some unknown), each detection noisy with absent joints,
NaN confidences and velocities, some flipped front to back, some with a limb far off, and
padding slots; extrapolation and side views both on and off.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from merger_reference import reference_fuse

from hiros_core.layouts import AZURE_KINECT
from hiros_merger import kernels
from hiros_merger.kernel_args import FuseSettings, Fusion, TrackDetections
from hiros_merger.merger import MergerParams, _body_layout, _fuse_settings

BODY = _body_layout(AZURE_KINECT)
N_JOINTS = AZURE_KINECT.n_joints
ARM = np.array([AZURE_KINECT.index(n) for n in ("ElbowRight", "WristRight", "HandRight")])


def _person(rng: np.random.Generator) -> np.ndarray:
    """A random upright pose ``(J, 3)`` facing +x (left towards +y, z up), at the origin."""
    pose = np.zeros((N_JOINTS, 3))
    for joint, parent in enumerate(AZURE_KINECT.parents):
        if parent >= 0:
            step = rng.normal(0.0, 0.1, 3)
            name = AZURE_KINECT.joint_names[joint]
            step[1] = 0.15 if "Left" in name else -0.15 if "Right" in name else 0.0
            step[2] = -0.2 if name.startswith(("Hip", "Knee", "Ankle", "Foot")) else 0.15
            pose[joint] = pose[parent] + step
    return pose + np.array([0.0, 0.0, 1.0])


def _detection(rng: np.random.Generator, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One camera's marker rows ``(J + 2, 20)`` and presence of ``pose``, with its mistakes."""
    seen = pose + rng.normal(0.0, 0.03, pose.shape)
    if rng.random() < 0.2:  # front/back flip: reflected through the frontal plane
        seen[:, 0] = 2 * pose[0, 0] - seen[:, 0]
    if rng.random() < 0.25:  # a limb far off
        seen[ARM] += rng.normal(0.0, 0.6, 3)
    rows = np.full((N_JOINTS + 2, 20), np.nan)
    rows[:N_JOINTS, 0] = rng.choice([0.0, 1 / 3, 2 / 3, 1.0, np.nan], N_JOINTS)
    rows[:N_JOINTS, 1:4] = seen
    rows[:N_JOINTS, 8:11] = rng.normal(0.0, 0.5, (N_JOINTS, 3))
    rows[:N_JOINTS][rng.random(N_JOINTS) < 0.1, 8] = np.nan
    present = np.zeros(N_JOINTS + 2, dtype=bool)
    present[:N_JOINTS] = rng.random(N_JOINTS) > 0.1
    return rows, present


def _frame(rng: np.random.Generator) -> TrackDetections:
    """Detections of 1-4 people by 1-4 cameras, as ``kernels.merge`` hands them to ``fuse``."""
    n_tracks, n_cameras = int(rng.integers(1, 5)), int(rng.integers(1, 5))
    cameras = rng.uniform(-4.0, 4.0, (n_cameras, 3)) + np.array([0.0, 0.0, 1.5])
    cameras[rng.random(n_cameras) < 0.2] = np.nan  # not calibrated
    table = np.full((n_tracks, n_cameras), -1)  # a track seen by fewer cameras is padded
    where = np.full((n_tracks, n_cameras, 3), np.nan)
    rows, present = [], []
    for m in range(n_tracks):
        turn = rng.uniform(-np.pi, np.pi)
        rotation = np.array(
            [[np.cos(turn), -np.sin(turn), 0.0], [np.sin(turn), np.cos(turn), 0.0], [0, 0, 1]]
        )
        pose = _person(rng) @ rotation.T + np.array([*rng.uniform(-1.5, 1.5, 2), 0.0])
        watching = np.sort(rng.permutation(n_cameras)[: rng.integers(1, n_cameras + 1)])
        for c, camera in enumerate(watching):
            row, seen = _detection(rng, pose)
            table[m, c] = len(rows)
            where[m, c] = cameras[camera]
            rows.append(row)
            present.append(seen)
    ages = np.where(table >= 0, rng.uniform(-0.05, 0.15, table.shape), 0.0)
    return TrackDetections(np.array(rows), np.array(present), table, ages, where)


PARAMS = st.builds(MergerParams, max_extrapolation=st.sampled_from([0.0, 0.1]))


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    params=PARAMS,
    iterations=st.integers(0, 4),
    weights=st.fixed_dictionaries(
        {
            "confidence_power": st.sampled_from([1.0, 1.5, 2.0]),
            "oblique_gain": st.sampled_from([0.0, 1.0]),
            "occlusion_radius": st.sampled_from([0.0, 0.2, 0.4]),
        }
    ),
    tilt=st.sampled_from([np.nan, 0.0, 0.2]),
)
def test_fuse_equals_the_numpy_statement(
    seed: int, params: MergerParams, iterations: int, weights: dict[str, float], tilt: float
) -> None:
    """Over the parameters and, beyond the merger's constants, the robust mean's iterations,
    the confidence's power, the view weight and the occlusion radius (0: off; the kernels
    take them all as settings)."""
    detections = _frame(np.random.default_rng(seed))
    settings_ = _fuse_settings(params)
    fuse_settings = FuseSettings(
        settings_.weights._replace(**weights),
        settings_.robust._replace(iterations=iterations),
    )
    up = np.array([tilt, 0.0, 1.0]) / np.hypot(tilt, 1.0)  # NaN: the scene's up not known yet
    got = kernels.fuse(detections, fuse_settings, BODY, up)
    want = reference_fuse(detections, fuse_settings, BODY, up)
    for name in Fusion._fields:
        np.testing.assert_allclose(
            getattr(got, name), getattr(want, name), rtol=1e-9, atol=1e-12, err_msg=name
        )
