"""Arrows, joint angles, per-joint frames, and the markers of people who left."""

import numpy as np
import pytest

from hiros_core.codec import decode_marker_array
from hiros_core.errors import ConfigError
from hiros_core.layouts import AZURE_KINECT, KINECT_V2
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_eval.body import JOINT_ANGLES, joint_angles
from hiros_visualizer import Drawing, OverlayParams, joint_transforms, overlays_from_names
from hiros_visualizer.overlays import (
    ARROW,
    ARROW_TIME,
    DELETE,
    DELETEALL,
    angle_markers,
    arrow_markers,
)


def person(seed, skeleton_id, layout=AZURE_KINECT):
    rng = np.random.default_rng(seed)
    skeleton = Skeleton.from_positions(rng.normal(size=(layout.n_joints, 3)), layout,
                                       skeleton_id=skeleton_id)  # fmt: skip
    skeleton.velocities[:] = rng.normal(size=(layout.n_joints, 3))
    skeleton.accelerations[:] = rng.normal(size=(layout.n_joints, 3))
    return skeleton


def test_arrows_go_from_each_joint_along_its_motion():
    a = person(0, 4)
    a.velocities[3] = np.nan  # unknown velocity: no arrow
    a.velocities[5] = 0.0  # at rest: no arrow
    params = OverlayParams(velocity_arrows=True)
    data = arrow_markers(SkeletonGroup(7, "world", [a]), "filter", "velocity", params, 0.25)
    assert set(data.types.tolist()) == {ARROW}
    assert set(data.namespaces) == {"filter/velocity"}
    joints = [i - 64 * 4 for i in data.ids.tolist()]
    assert joints == [j for j in range(AZURE_KINECT.n_joints) if j not in (3, 5)]
    for joint, points in zip(joints, data.points, strict=True):
        np.testing.assert_allclose(
            points, [a.positions[joint], a.positions[joint] + ARROW_TIME * a.velocities[joint]]
        )
    accel = arrow_markers(SkeletonGroup(7, "world", [a]), "filter", "acceleration", params, 0.25)
    np.testing.assert_allclose(
        accel.points[0][1] - accel.points[0][0], ARROW_TIME**2 * a.accelerations[0]
    )


def test_joint_angles_as_text_beside_their_joint():
    a, b = person(1, 2), person(2, 3, KINECT_V2)  # no Azure Kinect names: left out
    data = angle_markers(
        SkeletonGroup(0, "world", [a, b]), "filter", ["knee_left", "elbow_right"], 0.25
    )
    expected = joint_angles(a.positions)
    assert data.texts == [
        f"knee_left {expected['knee_left']:.0f}°",
        f"elbow_right {expected['elbow_right']:.0f}°",
    ]
    knee = a.positions[AZURE_KINECT.index("KneeLeft")]
    np.testing.assert_allclose(data.poses[0, :3], knee + np.array([0.08, 0.0, 0.0]))
    with pytest.raises(ValueError, match="unknown joint angles"):
        Drawing("filter", overlays=OverlayParams(joint_angles=["nose"]))


def test_people_who_leave_are_deleted_at_once():
    overlays = OverlayParams(velocity_arrows=True, joint_angles=["knee_left"])
    drawing = Drawing("filter", overlays=overlays)
    both = drawing.draw(SkeletonGroup(1, "world", [person(0, 4), person(1, 9)]))
    assert len(both) == 3  # skeletons, velocity arrows, angles: nobody to delete yet
    assert {m for message in both for m in decode_marker_array(message).actions} == {0}
    (deleted, *drawn) = drawing.draw(SkeletonGroup(2, "world", [person(0, 4)]))
    gone = decode_marker_array(deleted)
    assert set(gone.actions.tolist()) == {DELETE}
    keys = set(zip(gone.namespaces, gone.ids.tolist(), strict=True))
    assert {("filter", 27), ("filter", 28), ("filter", 29)} <= keys  # 3 * 9 + kind
    assert ("filter/velocity", 64 * 9 + 31) in keys
    assert ("filter/angles", 64 * 9) in keys
    assert not any(ns == "filter" and i // 3 == 4 for ns, i in keys)  # person 4 stays
    assert len(drawn) == 3
    assert drawing.draw(SkeletonGroup(3, "world", [])) == []  # a stage's frame without output
    (everything,) = drawing.finish(4, "world")
    assert decode_marker_array(everything).actions.tolist() == [DELETEALL]
    assert drawing.finish(5, "world") == []


def test_per_joint_frames():
    a = person(3, 5)
    a.marker_present[2] = False
    a.orientations[:] = [0.0, 0.0, 0.0, 1.0]
    a.orientations[4] = np.nan
    edges = {e.child: e for e in joint_transforms(SkeletonGroup(0, "world", [a]), "hiros/")}
    assert len(edges) == AZURE_KINECT.n_joints - 1
    pelvis = edges["hiros/person_5/Pelvis"]
    assert pelvis.parent == "world"
    np.testing.assert_allclose(pelvis.translation, a.positions[0])
    name = AZURE_KINECT.joint_names[4]
    np.testing.assert_allclose(edges[f"hiros/person_5/{name}"].rotation, [0, 0, 0, 1])


def test_overlays_from_names():
    params = overlays_from_names(["velocity", "knee_left", "elbow_right", "knee_left"])
    assert params == OverlayParams(velocity_arrows=True, joint_angles=["knee_left", "elbow_right"])
    every = overlays_from_names(["acceleration", "angles"])
    assert every.acceleration_arrows
    assert not every.velocity_arrows
    assert every.joint_angles == list(JOINT_ANGLES)
    assert overlays_from_names([]) == OverlayParams()
    with pytest.raises(ConfigError, match="unknown overlays speed, knee: choose among velocity"):
        overlays_from_names(["speed", "velocity", "knee"])
