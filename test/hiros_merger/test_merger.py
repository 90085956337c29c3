import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_merger import Merger, MergerParams
from hiros_merger import merger as merger_module
from hiros_merger.merger import FLIPPED_WEIGHT, OTHER_FRAME

J = AZURE_KINECT.n_joints
T0 = 1_000_000_000_000  # ns
WRIST = AZURE_KINECT.index("WristLeft")


@pytest.fixture
def constants(monkeypatch):
    """Set the merger's fusion constants (``DEPTH_GAIN=0.0``, ...) for one test."""

    def set_them(**values: float) -> None:
        for name, value in values.items():
            monkeypatch.setattr(merger_module, name, value)

    return set_them


def _person(rng=None) -> np.ndarray:
    """A fixed upright-ish pose (J, 3) facing +x, left towards +y, z up."""
    rng = rng or np.random.default_rng(0)
    pose = np.zeros((J, 3))
    for joint, parent in enumerate(AZURE_KINECT.parents):
        if parent >= 0:
            step = rng.normal(0.0, 0.1, 3)
            name = AZURE_KINECT.joint_names[joint]
            step[1] = 0.15 if "Left" in name else -0.15 if "Right" in name else 0.0
            step[2] = -0.2 if name.startswith(("Hip", "Knee", "Ankle", "Foot")) else 0.15
            pose[joint] = pose[parent] + step
    return pose + np.array([0.0, 0.0, 1.0])


def _detection(positions, camera, *, track=0, t_ns=T0, confidence=2 / 3, velocity=None):
    skeleton = Skeleton.from_positions(
        positions,
        skeleton_id=track,
        src_time_ns=t_ns,
        src_frame=f"{camera}_depth_camera_link",
        confidences=np.full(J, confidence),
    )
    if velocity is not None:
        skeleton.velocities[:] = velocity
    return skeleton


def _calibration(positions: dict[str, tuple[float, float, float]]) -> Calibration:
    return Calibration(
        "k01",
        "world",
        {
            name: CameraCalibration(frame_id=f"{name}_depth_camera_link", translation=np.array(p))
            for name, p in positions.items()
        },
    )


def _group(skeletons, t_ns=T0):
    return SkeletonGroup(t_ns, "world", skeletons)


def test_identical_views_fuse_to_the_same_skeleton():
    pose = _person()
    merger = Merger()
    group = _group([_detection(pose, cam) for cam in ("k01", "k02", "k03")])
    out = merger.update(group)
    assert [s.id for s in out.skeletons] == [0]
    merged = out.skeletons[0]
    np.testing.assert_allclose(merged.positions, pose, atol=1e-9)
    assert merged.src_time_ns == T0
    assert merged.src_frame == "world"
    assert out.frame_id == "world"
    assert out.stamp_ns == T0
    np.testing.assert_allclose(merged.confidences, 2 / 3)
    assert merged.link_present.sum() == J - 1


def test_one_camera_outlier_limb_does_not_pull_the_result():
    pose = _person()
    rng = np.random.default_rng(1)
    views = [pose + rng.normal(0.0, 0.01, pose.shape) for _ in range(3)]
    views[2][WRIST] += [0.0, -1.0, 0.0]  # k03 puts the left wrist far on the other side
    group = _group([_detection(v, f"k0{i + 1}") for i, v in enumerate(views)])
    merged = Merger().update(group).skeletons[0]
    plain_mean = np.mean([v[WRIST] for v in views], axis=0)
    assert np.linalg.norm(plain_mean - pose[WRIST]) > 0.15
    assert np.linalg.norm(merged.positions[WRIST] - pose[WRIST]) < 0.03


def test_detections_at_different_stamps_are_brought_to_the_output_time():
    pose = _person()
    velocity = np.array([1.0, 0.0, 0.0])
    late = T0 + 30_000_000
    older = _detection(pose, "k01", t_ns=T0, velocity=velocity)
    newer = _detection(pose + velocity * 0.03, "k02", t_ns=late, velocity=velocity)
    merger = Merger()
    merger.update(_group([older], T0))
    out = merger.update(_group([newer], late))
    assert out.stamp_ns == late
    np.testing.assert_allclose(out.skeletons[0].positions, pose + velocity * 0.03, atol=1e-9)

    still = Merger(MergerParams(max_extrapolation=0.0))
    still.update(_group([older], T0))
    stale = still.update(_group([newer], late)).skeletons[0]
    assert np.abs(stale.positions[:, 0] - (pose[:, 0] + 0.03)).max() > 0.005


def test_confident_camera_outweighs_an_unsure_one(constants):
    constants(OUTLIER_SCALE=10.0)
    pose = _person()
    sure = _detection(pose, "k01", confidence=2 / 3)
    unsure = _detection(pose + np.array([0.0, 0.0, 0.1]), "k02", confidence=1 / 3)
    merged = Merger().update(_group([sure, unsure]))
    offset = merged.skeletons[0].positions[:, 2] - pose[:, 2]
    np.testing.assert_allclose(offset, 0.1 * (1 / 9) / (4 / 9 + 1 / 9), atol=1e-5)


def test_camera_behind_the_person_counts_as_much_as_one_in_front(constants):
    """The back view is as precise as the front: only side views weigh less (the random
    pose's front is skewed a little, so the two cameras' side factors differ by < 2 %)."""
    constants(OUTLIER_SCALE=10.0, DEPTH_GAIN=0.0)
    pose = _person()  # faces +x
    calibration = _calibration({"k01": (4.0, 0.0, 1.5), "k02": (-4.0, 0.0, 1.5)})
    params = MergerParams()
    front = _detection(pose, "k01")
    back = _detection(pose + np.array([0.0, 0.0, 0.1]), "k02")
    merged = Merger(params, calibration).update(_group([front, back])).skeletons[0]
    blind = Merger(params).update(_group([front, back])).skeletons[0]
    np.testing.assert_allclose(blind.positions[:, 2] - pose[:, 2], 0.05, atol=1e-9)
    assert np.median(merged.positions[:, 2] - pose[:, 2]) == pytest.approx(0.05, abs=0.005)


def test_camera_seeing_the_side_counts_less(constants):
    """``OBLIQUE_GAIN`` 1: a camera at the person's side weighs less than one in front (down
    to (1 + 1)^-2 = 1/4 exactly at the side; the random pose's front is skewed a little)."""
    constants(OUTLIER_SCALE=100.0, DEPTH_GAIN=0.0)
    pose = _person()  # faces +x
    calibration = _calibration({"k01": (4.0, 0.0, 1.0), "k02": (0.0, 4.0, 1.0)})
    front = _detection(pose, "k01")
    side = _detection(pose + np.array([0.0, 0.0, 0.1]), "k02")
    merged = Merger(MergerParams(), calibration).update(_group([front, side])).skeletons[0]
    offset = np.median(merged.positions[:, 2] - pose[:, 2])
    assert 0.0 < offset < 0.045
    constants(OBLIQUE_GAIN=0.0)
    merged = Merger(MergerParams(), calibration).update(_group([front, side])).skeletons[0]
    assert np.median(merged.positions[:, 2] - pose[:, 2]) == pytest.approx(0.05, abs=1e-6)


def test_occluded_joints_count_less(constants):
    constants(OUTLIER_SCALE=10.0, DEPTH_GAIN=0.0, OBLIQUE_GAIN=0.0)
    pose = _person()
    other = pose + np.array([2.0, 0.0, 0.0])  # a second person between k01 and the first one
    calibration = _calibration({"k01": (4.0, 0.0, 1.5), "k02": (0.0, 4.0, 1.5)})
    params = MergerParams()
    through = _detection(pose + np.array([0.0, 0.0, 0.1]), "k01")
    clear = _detection(pose, "k02")
    group = _group(
        [through, clear, _detection(other, "k01", track=1), _detection(other, "k02", track=1)]
    )
    merged = Merger(params, calibration).update(group).skeletons[0]
    torso = AZURE_KINECT.index("SpineChest")
    assert merged.positions[torso, 2] - pose[torso, 2] < 0.05 - 1e-3
    constants(OCCLUSION_RADIUS=0.0)
    free = Merger(params, calibration)
    same = free.update(group).skeletons[0]
    assert same.positions[torso, 2] - pose[torso, 2] == pytest.approx(0.05)


def test_orientations_are_the_weighted_mean_on_so3(constants):
    constants(OUTLIER_SCALE=10.0)
    rng = np.random.default_rng(4)
    pose = _person()
    rotations = [Rotation.random(J, random_state=i) for i in range(3)]
    confidences = [2 / 3, 1 / 3, 2 / 3]
    skeletons = []
    for i, (rotation, confidence) in enumerate(zip(rotations, confidences, strict=True)):
        skeleton = _detection(
            pose + rng.normal(0, 1e-4, pose.shape), f"k0{i + 1}", confidence=confidence
        )
        skeleton.orientations[:] = rotation.as_quat()
        skeletons.append(skeleton)
    merged = Merger().update(_group(skeletons)).skeletons[0]
    weights = np.array(confidences) ** 2
    for joint in (0, 7, 20):
        stacked = Rotation.concatenate([r[joint] for r in rotations])
        expected = stacked.mean(weights=weights)
        angle = (Rotation.from_quat(merged.orientations[joint]) * expected.inv()).magnitude()
        assert angle < 1e-3


def test_output_rate_gives_one_group_per_tick():
    pose = _person()
    merger = Merger(MergerParams(output_rate=10.0))
    stamps = [T0 + k * 33_333_333 for k in range(31)]
    outputs = [merger.update(_group([_detection(pose, "k01", t_ns=t)], t)) for t in stamps]
    ticks = [g.stamp_ns for g in outputs if g.skeletons]
    assert np.all(np.diff(ticks) == 100_000_000)
    assert len(ticks) == 10
    assert all(t % 100_000_000 == 0 for t in ticks)


def test_each_input_gives_one_output_and_stale_tracks_leave():
    pose = _person()
    merger = Merger(MergerParams(window=0.1))
    merger.update(_group([_detection(pose, "k01", track=3, t_ns=T0)]))
    later = T0 + 200_000_000
    out = merger.update(_group([_detection(pose, "k01", track=4, t_ns=later)], later))
    assert [s.id for s in out.skeletons] == [4]
    assert merger.update(_group([], later)).skeletons == []


def test_bad_input_is_dropped_with_a_reason():
    merger = Merger()
    nobody = _detection(_person(), "k01", track=-1)
    empty = Skeleton.empty(skeleton_id=2, src_time_ns=T0, src_frame="k01_depth_camera_link")
    out = merger.update(_group([nobody, empty]))
    assert out.skeletons == []
    assert merger.drops == {"no track id": 1, "no joint": 1}


def test_parameter_file_matches_the_dataclass():
    from dataclasses import asdict

    from hiros_core.parameters import load_config_defaults

    values = load_config_defaults("merger")
    assert {k: values[k] for k in asdict(MergerParams())} == asdict(MergerParams())


def _pointing_forward(pose: np.ndarray) -> np.ndarray:
    """``pose`` upright (its spine above the pelvis), its feet and nose 12 cm in front of the
    ankles and head (+x)."""
    pose = pose.copy()
    spine = [AZURE_KINECT.index(n) for n in ("SpineNaval", "SpineChest", "Neck")]
    pose[spine, :2] = pose[0, :2]
    feet = [AZURE_KINECT.index(n) for n in ("FootLeft", "FootRight", "Nose")]
    ankles = [AZURE_KINECT.index(n) for n in ("AnkleLeft", "AnkleRight", "Head")]
    pose[feet] = pose[ankles] + np.array([0.12, 0.0, -0.02])
    return pose


def test_a_front_back_flipped_view_is_reflected_back(constants):
    """A flip (the SDK's body reflected through the frontal plane; the tracker has put its
    labels back) is reflected back through the plane through its own pelvis, so it adds its
    view instead of bending the person: the arms and legs it swung backwards come forward."""
    pose = _pointing_forward(_person())  # faces +x, z up
    flipped = pose.copy()
    flipped[:, 0] = 2 * pose[0, 0] - pose[:, 0]  # reflected through the frontal plane
    flipped += np.array([0.0, 0.0, 0.05])  # its own error, which it keeps
    constants(OUTLIER_SCALE=10.0)
    merger = Merger()
    merger.update(_group([_detection(pose, "k01")]))  # the people's vertical: z
    np.testing.assert_allclose(merger.up, [0.0, 0.0, 1.0])
    later = T0 + 33_000_000
    group = _group([_detection(v, c, t_ns=later) for v, c in ((pose, "k01"), (flipped, "k02"))])
    merged = merger.update(group).skeletons[0]
    weight = FLIPPED_WEIGHT  # (of the reflected view, against 1 for k01's)
    np.testing.assert_allclose(merged.positions[:, :2], pose[:, :2], atol=1e-9)
    shifted = pose[:, 2] + 0.05 * weight / (1 + weight)
    np.testing.assert_allclose(merged.positions[:, 2], shifted, atol=1e-6)


def test_a_view_pointing_forward_is_not_reflected(constants):
    """Two views a few centimetres apart, feet and nose forward: fused as they are."""
    constants(OUTLIER_SCALE=10.0)
    pose = _pointing_forward(_person())
    other = pose + np.array([0.03, -0.02, 0.01])
    merger = Merger()
    merged = merger.update(_group([_detection(pose, "k01"), _detection(other, "k02")]))
    np.testing.assert_allclose(merged.skeletons[0].positions, (pose + other) / 2, atol=1e-9)


def test_up_is_the_world_z_or_else_the_people_s_vertical():
    """In a gravity-aligned world the people's mean vertical confirms z, which is taken; in a
    camera's frame as the world (y down) their vertical is."""
    pose = _pointing_forward(_person())  # z up
    merger = Merger()
    assert np.isnan(merger.up).all()
    merger.update(_group([_detection(pose, "k01")]))
    np.testing.assert_allclose(merger.up, [0.0, 0.0, 1.0])
    in_camera = pose @ Rotation.from_euler("x", 90, degrees=True).as_matrix().T  # z -> -y
    merger = Merger()
    merger.update(_group([_detection(in_camera, "k01")]))
    vertical = in_camera[AZURE_KINECT.index("Neck")] - in_camera[0]
    np.testing.assert_allclose(merger.up, vertical / np.linalg.norm(vertical))


def test_limbs_are_the_subtrees_off_the_torso():
    from hiros_merger.merger import _body_layout

    groups = _body_layout(AZURE_KINECT).groups
    name = AZURE_KINECT.index
    assert groups[name("Pelvis")] == groups[name("Neck")] == 0
    arm = {groups[name(n)] for n in ("ClavicleLeft", "ShoulderLeft", "ElbowLeft", "ThumbLeft")}
    leg = {groups[name(n)] for n in ("HipRight", "KneeRight", "AnkleRight", "FootRight")}
    assert len(arm) == len(leg) == 1
    assert len({*arm, *leg, groups[name("ElbowRight")], groups[name("Head")], 0}) == 5


def test_a_camera_limb_is_kept_or_dropped_whole():
    """A camera whose arm drifts away along the chain (its shoulder and elbow still near the
    others') loses the whole arm, so the fused arm is not bent by its shoulder and elbow."""
    pose = _person()
    bent = pose.copy()
    drift = {"ShoulderLeft": 0.05, "ElbowLeft": 0.3, "WristLeft": 0.6, "HandLeft": 0.7,
             "HandTipLeft": 0.8, "ThumbLeft": 0.7}  # fmt: skip
    for joint, offset in drift.items():
        bent[AZURE_KINECT.index(joint)] += np.array([0.0, 0.0, offset])
    group = _group([_detection(pose, "k01"), _detection(pose, "k02"), _detection(bent, "k03")])
    whole = Merger(MergerParams()).update(group).skeletons[0]
    np.testing.assert_allclose(whole.positions, pose, atol=1e-9)


def test_a_frame_s_later_detection_of_a_track_and_camera_replaces_the_earlier_one():
    pose = _person()
    early = _detection(pose, "k01", t_ns=T0)
    late = _detection(pose + 0.5, "k01", t_ns=T0 + 1_000_000)
    both = Merger().update(_group([early, late], T0 + 1_000_000)).skeletons
    alone = Merger().update(_group([late], T0 + 1_000_000)).skeletons
    assert len(both) == 1
    assert both[0].same_as(alone[0])


def test_a_frame_mixing_joint_counts_fuses_the_first_layout_s_tracks():
    from hiros_core.layouts import KINECT_V2

    pose = _person()
    other = Skeleton.from_positions(
        np.full((KINECT_V2.n_joints, 3), 1.0), KINECT_V2, skeleton_id=7,
        src_time_ns=T0, src_frame="k02_depth_camera_link",
    )  # fmt: skip
    out = Merger().update(_group([_detection(pose, "k01", track=3), other])).skeletons
    assert [s.id for s in out] == [3]
    np.testing.assert_allclose(out[0].positions, pose, atol=1e-9)


def test_one_group_stamped_far_ahead_does_not_stop_the_output():
    """Input going back by more than max_jump restarts the merger: without it, every later
    detection is older than the glitch's and dropped, and no output follows."""
    pose = _person()
    merger = Merger()
    stamps = [T0 + k * 33_333_333 for k in range(20)]
    stamps.insert(5, T0 + 3_000_000_000)  # one tracker output stamped 3 s ahead
    outputs = [merger.update(_group([_detection(pose, "k01", t_ns=t)], t)) for t in stamps]
    assert all(out.skeletons for out in outputs[6:])
    assert merger.drops["stamps went back (restarted)"] == 1
    assert merger.drops["older than the camera's last detection"] == 0


def test_input_in_another_frame_than_the_world_is_left_out():
    """A camera topic wired to the merger: its camera-frame detections are not fused."""
    pose = _person()
    merger = Merger()
    merger.update(_group([_detection(pose, "k01", t_ns=T0)], T0))  # the world: "world"
    t = T0 + 40_000_000
    stray = SkeletonGroup(t, "k02_depth_camera_link", [_detection(pose + 5.0, "k02", t_ns=t)])
    out = merger.update(stray)
    assert out.skeletons == []
    assert out.frame_id == "world"
    assert merger.drops[OTHER_FRAME] == 1
    calibrated = Merger(calibration=Calibration("k01", world_frame="map"))
    out = calibrated.update(_group([_detection(pose, "k01", t_ns=T0)], T0))  # in "world"
    assert out.skeletons == []
    assert calibrated.drops[OTHER_FRAME] == 1
    out = calibrated.update(SkeletonGroup(t, "map", [_detection(pose, "k01", t_ns=t)]))
    assert out.frame_id == "map"
    assert out.skeletons


def test_fusion_beats_the_best_single_camera_on_a_noisy_scene():
    """Three cameras with the SDK's errors (noise, biases, flips, swaps) on a seeded scene: the
    fused people are closer to the truth than the best camera's, even with that camera's
    left/right mistakes undone by an oracle (its noise and bias alone)."""
    from hiros_eval.tracking import arrival_order, camera_mpjpe, output_mpjpe
    from hiros_sim import SimParams, simulate
    from hiros_tracker import Tracker

    result = simulate(SimParams(n_people=2, duration=10.0, seed=4, noise_base=0.02))
    calibration, truth = result.calibration, result.truth
    tracker = Tracker(calibration=calibration)
    merger = Merger(MergerParams(output_rate=30.0), calibration)
    merged = []
    for frame in arrival_order(result.camera_groups, calibration):
        group = merger.update(tracker.update(frame))
        if group.skeletons:
            merged.append(group)
    (fused,) = output_mpjpe(merged, truth).values()
    cameras = camera_mpjpe(result.camera_groups, calibration, truth, oracle_sides=True)
    assert len(cameras) == 3
    assert fused < 0.8 * min(cameras.values())
