"""Fixtures of the optimizer tests: small synthetic people with exactly known limb lengths.

The helpers are handed out as fixtures because tests run with ``--import-mode=importlib``,
where test modules cannot import sibling modules.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup, sec_to_ns


def _moving_person(n_frames, seed=0, rate=30.0):
    """(T, J, 3) positions of a person whose links keep fixed lengths, and those lengths (J,)."""
    rng = np.random.default_rng(seed)
    tree = AZURE_KINECT.tree
    n = AZURE_KINECT.n_joints
    lengths = rng.uniform(0.08, 0.45, n)
    lengths[0] = np.nan
    rest = rng.normal(size=(n, 3))
    rest /= np.linalg.norm(rest, axis=1, keepdims=True)
    t = np.arange(n_frames) / rate
    amplitude = rng.uniform(0.2, 0.6, (n, 3))
    frequency = rng.uniform(0.2, 1.0, (n, 3))
    angles = amplitude[None] * np.sin(2 * np.pi * frequency[None] * t[:, None, None])
    rotations = Rotation.from_rotvec(angles.reshape(-1, 3))
    directions = rotations.apply(np.tile(rest, (n_frames, 1))).reshape(n_frames, n, 3)
    vectors = directions * np.nan_to_num(lengths)[None, :, None]
    vectors[:, 0] = np.stack([0.5 * t, np.sin(t), np.full_like(t, 1.0)], axis=1)
    positions = np.einsum("cj,tck->tjk", tree.subtree, vectors)
    return positions, lengths


def _group_at(frame, people, rate=30.0, ids=None):
    """A SkeletonGroup of frame ``frame`` of each ``(T, J, 3)`` array in ``people``."""
    stamp = sec_to_ns(frame / rate)
    ids = range(len(people)) if ids is None else ids
    skeletons = [
        Skeleton.from_positions(p[frame], skeleton_id=i, src_time_ns=stamp, src_frame="world")
        for i, p in zip(ids, people, strict=True)
    ]
    return SkeletonGroup(stamp, "world", skeletons)


@pytest.fixture
def moving_person():
    """``moving_person(n_frames, seed=0, rate=30.0) -> (positions (T, J, 3), lengths (J,))``."""
    return _moving_person


@pytest.fixture
def group_at():
    """``group_at(frame, people, rate=30.0, ids=None) -> SkeletonGroup``."""
    return _group_at
