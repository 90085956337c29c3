from dataclasses import replace

import numpy as np
import pytest

from hiros_core.errors import ConfigError
from hiros_core.layouts import AZURE_KINECT
from hiros_sim import CONFIDENCE_OF_LEVEL, SimParams, simulate
from hiros_sim.sdk import bumped_pose

IDX = AZURE_KINECT.index
SHORT = SimParams(n_cameras=3, n_people=3, duration=8.0, seed=3)


@pytest.fixture(scope="module")
def clean():
    return simulate(replace(SHORT, noise=False))


@pytest.fixture(scope="module")
def noisy():
    return simulate(replace(SHORT, ghost_rate=30.0, swap_rate=20.0, id_change_rate=10.0))


def test_truth_in_camera_is_the_clean_stream(clean):
    """The truth moved into each camera with the true calibration and clock gives its stream."""
    checked = 0
    for name, groups in clean.camera_groups.items():
        cam = clean.calibration.camera(name)
        to_camera = cam.extrinsics.inverse()
        for group, labels in zip(groups, clean.labels[name], strict=True):
            assert group.frame_id == f"{name}_depth_camera_link"
            t_ref = cam.to_reference_time(group.stamp_ns * 1e-9)
            world = clean.truth.at(np.array([t_ref]))[:, 0]
            for skeleton, person in zip(group.skeletons, labels, strict=True):
                assert skeleton.src_time_ns == group.stamp_ns
                expected = to_camera.apply(world[person])
                np.testing.assert_allclose(skeleton.positions, expected, atol=1e-6)
                checked += 1
    assert checked > 1000


def test_a_bumped_camera_sees_from_its_new_pose_after_the_bump(clean):
    bump = {"bump_camera": "k03", "bump_time": 4.0, "bump_rotation": 5.0, "bump_shift": 0.1}
    bumped = simulate(replace(SHORT, noise=False, **bump))
    cam = clean.calibration.camera("k03")
    moved = bumped_pose(cam, bumped.params)
    truth = bumped.calibration.camera("k03")  # the truth keeps the first pose
    np.testing.assert_array_equal(truth.translation, cam.translation)
    np.testing.assert_array_equal(truth.rotation, cam.rotation)
    before = after = 0
    for old, new in zip(clean.camera_groups["k03"], bumped.camera_groups["k03"], strict=True):
        t_ref = cam.to_reference_time(new.stamp_ns * 1e-9)
        pose = moved if t_ref >= SHORT.clock_start + 4.0 else cam
        before, after = before + (pose is cam), after + (pose is moved)
        for kept, seen in zip(old.skeletons, new.skeletons, strict=True):
            world = cam.extrinsics.apply(kept.positions)
            expected = pose.extrinsics.inverse().apply(world)
            np.testing.assert_allclose(seen.positions, expected, atol=1e-6)
    assert before > 50
    assert after > 50
    assert clean.camera_groups["k01"][5].skeletons[0].positions == pytest.approx(
        bumped.camera_groups["k01"][5].skeletons[0].positions
    )


def _silent_sdk(**changes) -> SimParams:
    """``SHORT`` with the noise model on and every magnitude zero, but for ``changes``."""
    zero = {
        "noise_base": 0.0,
        "noise_per_metre": 0.0,
        "joint_bias": 0.0,
        "body_scale_cv": 0.0,
        "thumb_length_cv": 0.0,
        "jitter": 0.0,
        "drop_rate": 0.0,
        "miss_rate": 0.0,
        "flip_rate": 0.0,
        "flip_probability": 0.0,
        "swap_rate": 0.0,
        "ghost_rate": 0.0,
        "id_change_rate": 0.0,
    }
    return replace(SHORT, **{**zero, **changes})


def test_noise_model_with_zero_magnitudes_is_the_truth(clean):
    """Noise on but every magnitude zero: the SDK's fitted body model is exactly the truth."""
    quiet = simulate(_silent_sdk())
    for name, groups in clean.camera_groups.items():
        assert len(groups) == len(quiet.camera_groups[name])
        for expected, group in zip(groups, quiet.camera_groups[name], strict=True):
            assert group.stamp_ns == expected.stamp_ns
            for want, got in zip(expected.skeletons, group.skeletons, strict=True):
                np.testing.assert_allclose(got.positions, want.positions, atol=1e-9)


def test_clean_stream_covers_everyone_in_view(clean):
    # with no noise nobody visible is missed and there are no ghosts
    for labels in clean.labels.values():
        persons = np.concatenate(labels)
        assert (persons >= 0).all()
        assert set(persons.tolist()) <= set(clean.truth.person_ids.tolist())


def test_clocks_and_rate(clean):
    cal = clean.calibration
    assert cal.reference == "k01"
    assert cal.cameras["k01"].time_offset == 0.0
    offsets = [cam.time_offset for cam in cal.cameras.values()]
    assert max(abs(o) for o in offsets) <= SHORT.max_time_offset
    for name, groups in clean.camera_groups.items():
        stamps = np.array([g.stamp_ns for g in groups])
        np.testing.assert_allclose(np.diff(stamps), 1e9 / SHORT.rate, atol=2)
        # camera clock read through the calibration lands inside the truth's span
        t_ref = cal.cameras[name].to_reference_time(stamps * 1e-9)
        assert clean.truth.times[0] <= t_ref.min()
        assert t_ref.max() <= clean.truth.times[-1]


def test_camera_frame_convention(clean):
    """Depth frame: z forward (people in front), y down (head above pelvis means smaller y)."""
    for groups in clean.camera_groups.values():
        for group in groups[::20]:
            for skeleton in group.skeletons:
                pos = skeleton.positions
                assert pos[IDX("Pelvis"), 2] > 0.5
                assert pos[IDX("Head"), 1] < pos[IDX("Pelvis"), 1]


def test_room_setup_has_a_facing_pair(clean):
    cams = clean.calibration.cameras
    forward = {n: c.extrinsics.rotation.apply([0.0, 0.0, 1.0]) for n, c in cams.items()}
    h1, h2 = forward["k01"][:2], forward["k02"][:2]
    cos = np.dot(h1, h2) / np.linalg.norm(h1) / np.linalg.norm(h2)
    assert cos < -0.98
    for cam in cams.values():
        assert 1.0 <= cam.translation[2] <= 2.0
        assert forward[next(iter(cams))][2] < 0  # tilted down


def test_truth_shape_and_presence(clean):
    truth = clean.truth
    assert truth.positions.shape == (3, len(truth.times), 32, 3)
    assert truth.rate == pytest.approx(120.0, rel=1e-4)
    assert np.isfinite(truth.positions[0]).all()  # the first person is always there


def test_deterministic_with_seed(noisy):
    again = simulate(replace(SHORT, ghost_rate=30.0, swap_rate=20.0, id_change_rate=10.0))
    for name, groups in noisy.camera_groups.items():
        assert len(groups) == len(again.camera_groups[name])
        assert all(a.same_as(b) for a, b in zip(groups, again.camera_groups[name], strict=True))
    other = simulate(replace(SHORT, seed=4))
    first = noisy.camera_groups["k02"][10].skeletons[0].positions
    assert not np.allclose(first, other.camera_groups["k02"][10].skeletons[0].positions)


def test_noisy_stream_has_the_sdk_mistakes(noisy, clean):
    labels = np.concatenate([np.concatenate(v) for v in noisy.labels.values()])
    assert (labels == -1).any()  # ghosts
    ids = {s.id for g in noisy.camera_groups["k01"] for s in g.skeletons}
    assert len(ids) > 3  # body ids change
    levels = {
        round(c * 3) for g in noisy.camera_groups["k01"] for s in g.skeletons for c in s.confidences
    }
    assert levels <= {0, 1, 2}
    assert 2 in levels
    assert 1 in levels
    # joint noise of the right size: the pelvis error is centimetres, not millimetres or metres
    errors = []
    for name, groups in noisy.camera_groups.items():
        cam = noisy.calibration.camera(name)
        to_camera = cam.extrinsics.inverse()
        for group, persons in zip(groups, noisy.labels[name], strict=True):
            t_ref = cam.to_reference_time(group.stamp_ns * 1e-9)
            world = noisy.truth.at(np.array([t_ref]))[:, 0]
            for skeleton, person in zip(group.skeletons, persons, strict=True):
                if person >= 0:
                    truth = to_camera.apply(world[person, IDX("Pelvis")])
                    errors.append(np.linalg.norm(skeleton.positions[IDX("Pelvis")] - truth))
    median = np.median(errors)
    assert 0.01 < median < 0.12


def test_confidence_levels_match_the_bridge_convention():
    np.testing.assert_allclose(CONFIDENCE_OF_LEVEL, [0.0, 1 / 3, 2 / 3, 1.0])


@pytest.mark.parametrize(
    "bad",
    [
        {"n_people": 7},
        {"n_people": 0},
        {"n_cameras": 0},
        {"duration": 1.0},
        {"duration": float("nan")},
        {"duration": float("inf")},
        {"rate": float("nan")},
        {"setup": "nowhere"},
        {"noise_body_share": 1.5},
        {"bump_camera": "k09"},
    ],
)
def test_bad_params(bad):
    with pytest.raises(ConfigError):
        simulate(replace(SHORT, **bad))


@pytest.mark.parametrize(("setup", "count"), [("facing", 2), ("ring", 4)])
def test_setups(setup, count):
    result = simulate(SimParams(n_cameras=count, setup=setup, n_people=1, duration=4.0, rate=5.0))
    assert list(result.camera_groups) == [f"k0{i + 1}" for i in range(count)]
    positions = np.array([c.translation for c in result.calibration.cameras.values()])
    azimuths = np.sort(np.degrees(np.arctan2(positions[:, 1], positions[:, 0])) % 360)
    np.testing.assert_allclose(np.diff(azimuths), 360 / count, atol=1e-6)
    stamps = [g.stamp_ns for g in result.camera_groups["k01"]]
    assert np.median(np.diff(stamps)) == pytest.approx(2e8, rel=0.01)


def test_groups_match_the_model_builder(noisy):
    """The simulator's fast row builder gives what Skeleton.from_positions would."""
    from hiros_core.model import Skeleton

    for group in noisy.camera_groups["k03"][::50]:
        for skeleton in group.skeletons:
            built = Skeleton.from_positions(
                skeleton.positions.copy(),
                AZURE_KINECT,
                skeleton_id=skeleton.id,
                src_time_ns=skeleton.src_time_ns,
                src_frame=skeleton.src_frame,
                confidences=skeleton.confidences.copy(),
            )
            assert built.same_as(skeleton)


def _median_feet_height_errors(result) -> np.ndarray:
    """Per camera and person, the median world-height error (m) of the SDK's two foot joints."""
    feet = [IDX("FootLeft"), IDX("FootRight")]
    errors = {}
    for name, groups in result.camera_groups.items():
        cam = result.calibration.camera(name)
        for group, labels in zip(groups, result.labels[name], strict=True):
            t_ref = cam.to_reference_time(group.stamp_ns * 1e-9)
            world = result.truth.at(np.array([t_ref]))[:, 0]
            for skeleton, person in zip(group.skeletons, labels, strict=True):
                seen = cam.extrinsics.apply(skeleton.positions)[feet, 2]
                errors.setdefault((name, person), []).append(seen - world[person][feet, 2])
    return np.array([np.nanmedian(np.array(e), axis=0) for e in errors.values()])


def test_the_feet_offset_in_height_only_by_foot_height_bias():
    """Large joint offsets, no other noise: the SDK's feet keep the truth's height (a planted
    foot stays on its evidence) unless ``foot_height_bias`` offsets them, in the world's up,
    whichever way each camera is turned."""
    level = _median_feet_height_errors(simulate(_silent_sdk(joint_bias=0.05, foot_height_bias=0.0)))
    raised = _median_feet_height_errors(
        simulate(_silent_sdk(joint_bias=0.05, foot_height_bias=0.05))
    )
    assert np.median(np.abs(level)) < 0.002  # 0.0 measured
    assert np.median(np.abs(raised)) > 0.01  # 1.5 cm measured
