import merger_reference
import numpy as np

from hiros_merger import weights


def test_occlusion_matches_the_rule_tried_against_every_torso_point():
    rng = np.random.default_rng(3)
    torso = np.array([0, 1, 2, 3])
    n_occluded = 0
    for _ in range(20):
        n_tracks, n_slots, n_joints = 4, 3, 12
        centres = rng.uniform(-2.0, 2.0, (n_tracks, 3))
        fused = centres[:, None] + rng.normal(0.0, 0.3, (n_tracks, n_joints, 3))
        positions = fused[:, None] + rng.normal(0.0, 0.02, (n_tracks, n_slots, n_joints, 3))
        cameras = np.broadcast_to(rng.uniform(-4.0, 4.0, (1, n_slots, 3)), (n_tracks, n_slots, 3))
        cameras = np.ascontiguousarray(cameras)
        weight = rng.uniform(0.1, 1.0, (n_tracks, n_slots, n_joints))
        known = np.ones((n_tracks, n_slots), dtype=bool)
        expected = merger_reference.occluded(
            fused, positions, cameras, torso, weight, radius=0.3, factor=0.5
        )
        got = weight.copy()
        weights.occluded(fused, positions, cameras, known, torso, 0.3, got, 0.5)
        assert np.array_equal(got, expected)
        n_occluded += int((got != weight).sum())
    assert n_occluded > 0
