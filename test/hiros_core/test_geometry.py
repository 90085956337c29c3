import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hiros_core.geometry import RigidTransform, kabsch, kabsch_batch


def _angle_deg(found: RigidTransform, truth: RigidTransform) -> float:
    return float(np.degrees((found.rotation.inv() * truth.rotation).magnitude()))


def test_kabsch_recovers_a_known_transform_with_weights():
    rng = np.random.default_rng(1)
    truth = RigidTransform(Rotation.from_rotvec([0.3, -1.2, 2.0]), np.array([1.0, -2.0, 0.5]))
    source = rng.normal(size=(50, 3))
    target = truth.apply(source)
    target[:5] += 3.0  # outliers, weighted out
    weights = np.ones(50)
    weights[:5] = 0.0
    found = kabsch(target, source, weights)
    assert _angle_deg(found, truth) < 1e-6
    assert np.linalg.norm(found.translation - truth.translation) < 1e-9


def test_kabsch_never_returns_a_reflection():
    source = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    target = source * np.array([1, 1, -1.0])  # a mirror image: best proper rotation only
    found = kabsch(target, source)
    assert np.linalg.det(found.rotation.as_matrix()) == pytest.approx(1.0)


def test_kabsch_batch_solves_each_problem_on_its_own():
    rng = np.random.default_rng(2)
    truths = [
        RigidTransform(Rotation.from_rotvec(rng.normal(size=3)), rng.normal(size=3))
        for _ in range(4)
    ]
    source = rng.normal(size=(4, 10, 3))
    target = np.stack([t.apply(s) for t, s in zip(truths, source, strict=True)])
    rotations, translations = kabsch_batch(target, source)
    for truth, rotation, translation in zip(truths, rotations, translations, strict=True):
        assert rotation == pytest.approx(truth.rotation.as_matrix(), abs=1e-9)
        assert translation == pytest.approx(truth.translation, abs=1e-9)
