import numpy as np

from hiros_core.layouts import AZURE_KINECT, KINECT_V2
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_visualizer.markers import LINE_LIST, SPHERE_LIST, TEXT_VIEW_FACING, skeleton_markers


def person(seed, layout=AZURE_KINECT, skeleton_id=0):
    positions = np.random.default_rng(seed).normal(size=(layout.n_joints, 3))
    return Skeleton.from_positions(positions, layout, skeleton_id=skeleton_id)


def test_three_markers_per_person_with_its_joints_links_and_label():
    a, b = person(0, skeleton_id=4), person(1, skeleton_id=7)
    a.marker_present[5] = False  # absent joint: neither a sphere nor in a line
    a.positions[9] = np.nan  # present but unknown: left out too
    data = skeleton_markers(SkeletonGroup(5, "world", [a, b]), "filter")
    assert data.ids.tolist() == [12, 13, 14, 21, 22, 23]
    assert data.types.tolist() == [SPHERE_LIST, LINE_LIST, TEXT_VIEW_FACING] * 2
    assert data.namespaces == ["filter"] * 6
    assert data.texts[2::3] == ["id 4", "id 7"]
    assert len(data.points[0]) == 30
    assert len(data.points[3]) == 32
    drawn = [
        (p, c)
        for p, c in zip(AZURE_KINECT.link_parents, AZURE_KINECT.link_children, strict=True)
        if not {5, 9} & {int(p), int(c)}
    ]
    assert len(data.points[1]) == 2 * len(drawn)
    np.testing.assert_array_equal(data.points[1][:2], a.positions[list(drawn[0])])
    top = a.positions[a.marker_present & np.isfinite(a.positions).all(1)][:, 2].max()
    assert data.poses[2, 2] == top + 0.25
    assert (data.colors[0] == data.colors[2]).all()
    assert (data.colors[0] != data.colors[3]).any()


def test_mixed_layouts_and_empty_groups():
    data = skeleton_markers(
        SkeletonGroup(0, "w", [person(2, KINECT_V2, 1), person(3, AZURE_KINECT, 2)])
    )
    assert len(data.points[0]) == 25
    assert len(data.points[3]) == 32
    assert len(skeleton_markers(SkeletonGroup(0, "w", []))) == 0
