import numpy as np

from hiros_merger import kernels


def _occluded_reference(fused, positions, cameras, torso, weight, *, radius, factor):
    """The occlusion rule over every (detection, joint, other track's torso point) in numpy."""
    n_tracks = len(fused)
    rel = positions - cameras[:, :, None]  # (M, C, J, 3) joint - camera
    length = np.linalg.norm(rel, axis=-1)
    unit = rel / length[..., None]
    q = fused[None, None, :, torso] - cameras[:, :, None, None]  # (M, C, M', T, 3)
    along = np.einsum("mcja,mcota->mcjot", unit, q)
    across_sq = (q * q).sum(-1)[:, :, None] - along**2
    blocked = (across_sq < radius**2) & (along > 0) & (along < length[..., None, None] - radius)
    blocked[np.arange(n_tracks), :, :, np.arange(n_tracks)] = False  # not by its own torso
    return np.where(blocked.any(axis=(-2, -1)), weight * factor, weight)


def test_occlusion_matches_the_rule_tried_against_every_torso_point():
    rng = np.random.default_rng(3)
    torso = np.array([0, 1, 2, 3])
    occluded = 0
    for _ in range(20):
        n_tracks, n_slots, n_joints = 4, 3, 12
        centres = rng.uniform(-2.0, 2.0, (n_tracks, 3))
        fused = centres[:, None] + rng.normal(0.0, 0.3, (n_tracks, n_joints, 3))
        positions = fused[:, None] + rng.normal(0.0, 0.02, (n_tracks, n_slots, n_joints, 3))
        cameras = np.broadcast_to(rng.uniform(-4.0, 4.0, (1, n_slots, 3)), (n_tracks, n_slots, 3))
        cameras = np.ascontiguousarray(cameras)
        weight = rng.uniform(0.1, 1.0, (n_tracks, n_slots, n_joints))
        known = np.ones((n_tracks, n_slots), dtype=bool)
        expected = _occluded_reference(
            fused, positions, cameras, torso, weight, radius=0.3, factor=0.5
        )
        got = weight.copy()
        kernels._occluded(fused, positions, cameras, known, torso, 0.3, got, 0.5)
        assert np.array_equal(got, expected)
        occluded += int((got != weight).sum())
    assert occluded > 0
