from __future__ import annotations

import pickle

import numpy as np
import pytest

from hiros_core import (
    AZURE_KINECT,
    KINECT_V2,
    Calibration,
    CalibrationError,
    CameraCalibration,
    LayoutError,
    RigidTransform,
    Skeleton,
    SkeletonGroup,
    camera_from_frame,
    get_layout,
    load_calibration,
    save_calibration,
    stack_rows,
)


def test_azure_layout_tree_and_mirror() -> None:
    assert AZURE_KINECT.n_joints == 32
    assert AZURE_KINECT.index("HandTipLeft") == 9
    assert AZURE_KINECT.parents[AZURE_KINECT.index("KneeRight")] == AZURE_KINECT.index("HipRight")
    assert len(AZURE_KINECT.link_children) == 31
    mirror = AZURE_KINECT.mirror
    assert mirror[AZURE_KINECT.index("ElbowLeft")] == AZURE_KINECT.index("ElbowRight")
    assert np.array_equal(mirror[mirror], np.arange(32))
    assert mirror[AZURE_KINECT.index("Nose")] == AZURE_KINECT.index("Nose")
    assert KINECT_V2.n_joints == 25
    assert np.array_equal(KINECT_V2.mirror[KINECT_V2.mirror], np.arange(25))


def test_body_joints_are_found_by_name_in_both_kinect_layouts() -> None:
    """Hips before shoulders on each side, the spine bottom up, the facing pointers."""
    for layout in (AZURE_KINECT, KINECT_V2):
        body, at = layout.body, layout.index
        assert body.left == (at("HipLeft"), at("ShoulderLeft"))
        assert body.right == (at("HipRight"), at("ShoulderRight"))
        assert body.neck == at("Neck")
        assert body.torso[0] == layout.parents.index(-1)
        assert body.torso[-1] == at("Neck")
        assert body.feet == ((at("AnkleLeft"), at("FootLeft")), (at("AnkleRight"), at("FootRight")))
        left, right = body.sides
        assert np.array_equal(layout.mirror[left], right)
    assert AZURE_KINECT.body.head == (AZURE_KINECT.index("Head"), AZURE_KINECT.index("Nose"))
    assert KINECT_V2.body.head == ()  # Kinect v2 has no nose


def test_body_joints_leave_out_what_a_layout_lacks(tmp_path) -> None:
    path = tmp_path / "few.yaml"
    path.write_text(
        "name: few\njoints: [Pelvis, Neck, HipLeft, HipRight, ShoulderLeft]\n"
        "parents: [-1, 0, 0, 0, 1]\n"
    )
    body = get_layout(path).body
    assert body.right == (3, -1)  # no right shoulder
    assert body.torso == (0, 1)
    assert body.feet == ()
    assert body.head == ()
    left, right = body.sides
    assert left.tolist() == [2]
    assert right.tolist() == [3]


def test_layout_from_yaml_and_errors(tmp_path) -> None:
    path = tmp_path / "three.yaml"
    path.write_text("name: three\njoints: [Root, Mid, TipLeft]\nparents: [-1, 0, 1]\n")
    layout = get_layout(path)
    assert layout.joint_names == ("Root", "Mid", "TipLeft")
    assert layout.link_names[2] == "Mid-TipLeft"
    path.write_text("joints: [A, B]\nparents: [-1, 5]\n")
    with pytest.raises(LayoutError, match="invalid parent"):
        get_layout(path)
    with pytest.raises(LayoutError, match="unknown skeleton layout"):
        get_layout("openpose")


def test_from_positions_marks_missing_joints_and_builds_links() -> None:
    positions = np.arange(96, dtype=float).reshape(32, 3)
    positions[5] = np.nan
    skeleton = Skeleton.from_positions(positions, skeleton_id=4, src_frame="k02_depth_camera_link")
    assert not skeleton.marker_present[5]
    assert skeleton.marker_present.sum() == 31
    assert not skeleton.link_present[5]  # ShoulderLeft missing: its link too
    assert not skeleton.link_present[6]  # and the link of its child
    np.testing.assert_allclose(skeleton.links[1, 1:4], (positions[0] + positions[1]) / 2)
    assert skeleton.camera == "k02"
    group = SkeletonGroup(0, "k02_depth_camera_link", [skeleton, skeleton.copy()])
    assert group.positions().shape == (2, 32, 3)
    assert group.same_as(group.copy())


def test_camera_names_from_frames() -> None:
    assert camera_from_frame("k01_depth_camera_link") == "k01"
    assert camera_from_frame("/world") == "world"


def test_rigid_transform_moves_a_whole_skeleton() -> None:
    transform = RigidTransform.from_quaternion(
        [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)], [1, 0, 0]
    )
    skeleton = Skeleton.from_positions(np.tile([1.0, 0.0, 0.0], (32, 1)))
    skeleton.orientations[:] = [0, 0, 0, 1]
    skeleton.velocities[:] = [1.0, 0.0, 0.0]
    moved = transform.apply_to_skeleton(skeleton)
    np.testing.assert_allclose(moved.positions[0], [1.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(moved.velocities[0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(
        np.abs(moved.orientations[0]), [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    )
    back = transform.inverse().apply_to_skeleton(moved)
    np.testing.assert_allclose(back.positions, skeleton.positions, atol=1e-12)


def test_calibration_file_round_trip_and_time_formula(tmp_path) -> None:
    calibration = Calibration(
        "k01",
        cameras={
            "k01": CameraCalibration("k01_depth_camera_link"),
            "k02": CameraCalibration(
                "k02_depth_camera_link", time_offset=1.5, drift=1e-4, drift_epoch=10.0,
                translation=np.array([1.0, 2.0, 3.0]), quality={"peak": np.float64(0.9)},
            ),
        },
    )  # fmt: skip
    path = tmp_path / "calib.yaml"
    save_calibration(calibration, path)
    loaded = load_calibration(path)
    k02 = loaded.camera("k02")
    assert k02.to_reference_time(20.0) == pytest.approx(20.0 + 1.5 + 1e-4 * 10.0)
    assert k02.quality["peak"] == pytest.approx(0.9)
    np.testing.assert_allclose(k02.extrinsics.apply(np.zeros(3)), [1.0, 2.0, 3.0])
    with pytest.raises(CalibrationError, match="not in the calibration"):
        loaded.camera("k09")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("cameras: 3", "mapping"),
        ("cameras: {k01: {rotation: [0, 0, 0, 2]}}", "unit quaternion"),
        ("cameras: {k01: {translation: [1, 2]}}", "translation needs 3"),
        ("reference: k05\ncameras: {k01: {}}", "reference camera"),
        ("cameras: {k01: {time_offset: soon}}", "could not convert"),
    ],
)
def test_bad_calibration_files_name_the_problem(tmp_path, text: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=message):
        load_calibration(path)
    with pytest.raises(CalibrationError, match="cannot read"):
        load_calibration(tmp_path / "missing.yaml")


@pytest.mark.parametrize("shape", [(), (4,), (2, 3), (0,)])
def test_compiled_link_rows_equal_the_numpy_form(shape) -> None:
    from hiros_core import compiled
    from hiros_core.layouts import KINECT_V2
    from hiros_core.model import _numpy_link_rows

    rng = np.random.default_rng(len(shape))
    for layout in (AZURE_KINECT, KINECT_V2):
        for strided in (False, True):
            rows = rng.normal(size=(*shape, layout.n_joints, 40 if strided else 20))
            markers = rows[..., ::2] if strided else rows
            markers[rng.random(markers.shape) < 0.1] = np.nan
            present = rng.random((*shape, layout.n_joints)) < 0.8
            expected = _numpy_link_rows(markers, present, layout)
            got = compiled.link_rows(markers, present, layout.link_parents, layout.link_children)
            assert got[0].shape == expected[0].shape
            assert np.array_equal(got[0], expected[0], equal_nan=True)
            assert np.array_equal(got[1], expected[1])
            assert got[1].shape == expected[1].shape


def test_groups_pickle_as_stacked_arrays_and_come_back_equal() -> None:
    rng = np.random.default_rng(4)
    people = [
        Skeleton.from_positions(rng.normal(size=(32, 3)), skeleton_id=i, src_time_ns=7 + i,
                                src_frame=f"k0{i}_depth_camera_link")
        for i in range(3)
    ]  # fmt: skip
    people[1].positions[5] = np.nan
    people[1].marker_present[5] = False
    people[2].confidence = 0.25
    group = SkeletonGroup(123, "world", people)
    back = pickle.loads(pickle.dumps(group))
    assert back.same_as(group)
    assert back.skeletons[0].layout is AZURE_KINECT
    back.skeletons[0].positions[:] = 0.0  # rows of one skeleton are its own
    assert np.isfinite(back.skeletons[1].positions[0]).all()
    assert back.skeletons[1].positions[0, 0] == group.skeletons[1].positions[0, 0]


def test_groups_of_mixed_layouts_pickle_skeleton_by_skeleton() -> None:
    group = SkeletonGroup(
        5, "world", [Skeleton.empty(AZURE_KINECT, skeleton_id=1), Skeleton.empty(KINECT_V2)]
    )
    back = pickle.loads(pickle.dumps(group))
    assert back.same_as(group)
    assert back.skeletons[1].layout.name == "kinect_v2"
    assert pickle.loads(pickle.dumps(SkeletonGroup(1, "w"))).skeletons == []


def test_stack_rows_shares_a_frames_stack_and_copies_otherwise() -> None:
    rng = np.random.default_rng(5)
    positions = rng.normal(size=(4, 32, 3))
    people = Skeleton.many_from_positions(positions, skeleton_ids=[3, 4, 5, 6])
    whole = stack_rows(people)
    assert np.array_equal(whole.markers[..., 1:4], positions)
    assert np.shares_memory(whole.markers, people[0].markers)
    middle = stack_rows(people[1:3])
    assert np.shares_memory(middle.links, people[1].links)
    assert np.array_equal(middle.link_present, whole.link_present[1:3])
    reordered = stack_rows([people[2], people[1]])
    assert not np.shares_memory(reordered.markers, people[1].markers)
    assert np.array_equal(reordered.markers[0], people[2].markers, equal_nan=True)
    people[0].markers = people[0].markers.copy()  # a replaced field breaks the sharing
    copied = stack_rows(people)
    assert not np.shares_memory(copied.markers, people[1].markers)
    assert np.array_equal(copied.bounding_boxes, whole.bounding_boxes, equal_nan=True)


def test_unpickled_groups_stack_without_copying() -> None:
    people = Skeleton.many_from_positions(np.ones((2, 32, 3)), skeleton_ids=[1, 2])
    back = pickle.loads(pickle.dumps(SkeletonGroup(9, "world", people)))
    rows = stack_rows(back.skeletons)
    assert np.shares_memory(rows.markers, back.skeletons[1].markers)
    assert back.same_as(SkeletonGroup(9, "world", people))
