import filter_reference
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hiros_core.kinematics import link_lengths
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup, sec_to_ns
from hiros_filter import Filter, FilterParams

RATE = 30.0
TREE = AZURE_KINECT.tree
PARENTS = np.asarray(AZURE_KINECT.parents)
J = AZURE_KINECT.n_joints


def swinging_person(n_frames, seed=0):
    """(T, J, 3) positions whose links keep fixed lengths while every link swings."""
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(0.08, 0.45, J)
    rest = rng.normal(size=(J, 3))
    rest /= np.linalg.norm(rest, axis=1, keepdims=True)
    t = np.arange(n_frames) / RATE
    amplitude = rng.uniform(0.3, 0.9, (J, 3))
    frequency = rng.uniform(0.3, 1.5, (J, 3))
    angles = amplitude[None] * np.sin(2 * np.pi * frequency[None] * t[:, None, None])
    directions = Rotation.from_rotvec(angles.reshape(-1, 3)).apply(np.tile(rest, (n_frames, 1)))
    vectors = directions.reshape(n_frames, J, 3) * lengths[None, :, None]
    vectors[:, 0] = np.stack([0.5 * t, np.sin(t), np.ones_like(t)], axis=1)
    return np.einsum("cj,tck->tjk", TREE.subtree, vectors)


def run(stage, trajectory):
    out = []
    for frame, positions in enumerate(trajectory):
        stamp = sec_to_ns(frame / RATE)
        skeleton = Skeleton.from_positions(positions, skeleton_id=0, src_time_ns=stamp)
        out.append(stage.update(SkeletonGroup(stamp, "world", [skeleton])).skeletons[0])
    return out


def test_fixed_input_lengths_are_kept_by_the_filter():
    trajectory = swinging_person(120)
    true_lengths = link_lengths(trajectory[0], PARENTS)
    kept = run(Filter(), trajectory)
    lengths = np.stack([link_lengths(s.positions, PARENTS) for s in kept])
    np.testing.assert_allclose(lengths[:, 1:], np.tile(true_lengths[1:], (120, 1)), rtol=1e-9)
    # Without it the smoothing shortens turning links by clearly more than that.
    loose = run(Filter(FilterParams(keep_link_lengths=False)), trajectory)
    loose_lengths = np.stack([link_lengths(s.positions, PARENTS) for s in loose])
    assert np.nanmax(np.abs(loose_lengths / true_lengths - 1)) > 1e-3
    # The directions (and so the joint angles) are the filter's own: only lengths change.
    vectors = (kept[-1].positions - kept[-1].positions[np.maximum(PARENTS, 0)])[1:]
    loose_vectors = (loose[-1].positions - loose[-1].positions[np.maximum(PARENTS, 0)])[1:]
    cosine = np.sum(vectors * loose_vectors, axis=-1) / (
        np.linalg.norm(vectors, axis=-1) * np.linalg.norm(loose_vectors, axis=-1)
    )
    np.testing.assert_allclose(cosine, 1.0, atol=1e-12)


def test_velocities_and_accelerations_agree_with_fixed_lengths():
    out = run(Filter(), swinging_person(90, seed=1))[-1]
    parent = np.maximum(PARENTS, 0)
    link = (out.positions - out.positions[parent])[1:]
    relative_velocity = (out.velocities - out.velocities[parent])[1:]
    relative_acceleration = (out.accelerations - out.accelerations[parent])[1:]
    # d/dt |l|^2 = 0 and d^2/dt^2 |l|^2 = 0: l.dv = 0 and l.da = -|dv|^2.
    np.testing.assert_allclose(np.sum(link * relative_velocity, axis=-1), 0.0, atol=1e-12)
    np.testing.assert_allclose(
        np.sum(link * relative_acceleration, axis=-1),
        -np.sum(relative_velocity**2, axis=-1),
        atol=1e-10,
    )


def test_rigid_rotation_gives_the_rotation_velocity():
    omega = np.array([0.0, 0.0, 1.0])  # rad/s about z through the origin
    times = np.arange(120) / RATE
    pose = swinging_person(1, seed=2)[0]
    trajectory = np.stack([Rotation.from_rotvec(omega * t).apply(pose) for t in times])
    out = run(Filter(), trajectory)[-1]
    expected_velocity = np.cross(omega, trajectory[-1])
    expected_acceleration = np.cross(omega, expected_velocity)
    np.testing.assert_allclose(out.velocities, expected_velocity, atol=0.02)
    np.testing.assert_allclose(out.accelerations, expected_acceleration, atol=0.1)
    np.testing.assert_allclose(out.positions, trajectory[-1], atol=2e-3)


def test_varying_lengths_are_left_as_filtered():
    rng = np.random.default_rng(3)
    trajectory = swinging_person(60, seed=3) + rng.normal(scale=0.01, size=(60, J, 3))
    kept = run(Filter(), trajectory)
    loose = run(Filter(FilterParams(keep_link_lengths=False)), trajectory)
    for a, b in zip(kept, loose, strict=True):
        np.testing.assert_array_equal(a.positions, b.positions)
        np.testing.assert_array_equal(a.velocities, b.velocities)


def test_missing_joint_keeps_the_other_lengths_and_nothing_explodes():
    trajectory = swinging_person(60, seed=4)
    true_lengths = link_lengths(trajectory[0], PARENTS)
    elbow = AZURE_KINECT.index("ElbowLeft")
    trajectory[20:26, elbow] = np.nan
    out = run(Filter(), trajectory)
    assert not out[22].marker_present[elbow]
    lengths = link_lengths(out[22].positions, PARENTS)
    wrist = AZURE_KINECT.index("WristLeft")
    others = np.ones(J, dtype=bool)
    others[[0, elbow, wrist]] = False
    np.testing.assert_allclose(lengths[others], true_lengths[others], rtol=1e-9)
    # Links next to the returning elbow are held again one frame after it is back.
    np.testing.assert_allclose(
        link_lengths(out[-1].positions, PARENTS)[1:], true_lengths[1:], rtol=1e-9
    )
    assert all(np.isfinite(s.positions[s.marker_present]).all() for s in out)
    assert all(np.isfinite(s.velocities[s.marker_present]).all() for s in out)


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**16), mode=st.sampled_from(["kalman", "butterworth"]))
def test_compiled_filter_equals_the_numpy_statement(seed, mode):
    """Two tracks, held and free links, a joint lost past max_gap (restart), a late frame,
    orientations with sign flips and a gap (Kalman mode: the one-call frame kernel)."""
    rng = np.random.default_rng(seed)
    first = swinging_person(80, seed=seed)
    second = swinging_person(80, seed=seed + 1) + rng.normal(scale=0.01, size=(80, J, 3))
    first[30:50, 7] = np.nan  # 20 frames > max_gap 0.5 s: the joint restarts
    turning = Rotation.from_rotvec(rng.normal(scale=0.3, size=(80 * J, 3))).as_quat()
    turning = turning.reshape(80, J, 4) * rng.choice([-1.0, 1.0], size=(80, J, 1))
    turning[10:14, 3] = np.nan  # an orientation missing for a few frames
    stages = [
        filter_reference.ReferenceFilter(FilterParams(filter=mode)),
        Filter(FilterParams(filter=mode)),
    ]
    outputs = [[], []]
    for frame in range(80):
        if frame == 40:
            continue  # a dropped frame: dt of two periods
        stamp = sec_to_ns(frame / RATE)
        skeletons = [
            Skeleton.from_positions(
                p[frame], skeleton_id=i, src_time_ns=stamp, orientations=turning[frame]
            )
            for i, p in enumerate((first, second))
        ]
        for stage, out in zip(stages, outputs, strict=True):
            group = SkeletonGroup(stamp, "world", [s.copy() for s in skeletons])
            out.append(stage.update(group).skeletons)
    for reference, compiled in zip(*outputs, strict=True):
        for a, b in zip(reference, compiled, strict=True):
            np.testing.assert_array_equal(a.marker_present, b.marker_present)
            np.testing.assert_allclose(b.markers, a.markers, atol=1e-9, equal_nan=True)
            np.testing.assert_array_equal(a.link_present, b.link_present)
            np.testing.assert_allclose(b.links, a.links, atol=1e-9, equal_nan=True)


def test_compiled_filter_follows_its_tables_when_they_grow():
    """Six people: the track tables (4 slots at first) are re-allocated mid-run."""
    people = [swinging_person(12, seed=seed) for seed in range(6)]
    stages = [filter_reference.ReferenceFilter(), Filter()]
    for frame in range(12):
        stamp = sec_to_ns(frame / RATE)
        count = 2 if frame < 5 else 6  # the newcomers arrive once the kernel has run
        skeletons = [
            Skeleton.from_positions(p[frame], skeleton_id=i, src_time_ns=stamp)
            for i, p in enumerate(people[:count])
        ]
        reference, compiled = (
            stage.update(SkeletonGroup(stamp, "world", [s.copy() for s in skeletons])).skeletons
            for stage in stages
        )
        for a, b in zip(reference, compiled, strict=True):
            np.testing.assert_allclose(b.markers, a.markers, atol=1e-9, equal_nan=True)
    assert len(stages[1]._layouts["azure_kinect"].time_ns) > 4
