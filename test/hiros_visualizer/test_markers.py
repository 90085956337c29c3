import numpy as np

from hiros_core.codec import encode_marker_array
from hiros_core.layouts import AZURE_KINECT, KINECT_V2
from hiros_core.model import Skeleton, SkeletonGroup, stack_rows
from hiros_visualizer.markers import (
    LINE_LIST,
    SPHERE_LIST,
    TEXT_VIEW_FACING,
    VisualizerParams,
    encode_skeleton_markers,
    skeleton_markers,
)


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


def test_encoded_markers_equal_the_general_encoding_frame_after_frame():
    rng = np.random.default_rng(5)
    params = VisualizerParams(joint_size=0.03)
    people = [person(4, skeleton_id=3), person(5, skeleton_id=8)]
    frames = []
    for step in range(6):
        frame = [p.copy() for p in people]
        for p in frame:
            p.positions[:] += rng.normal(scale=0.01, size=p.positions.shape)
        if step >= 2:  # a new shape: a joint goes missing, another becomes unknown
            frame[0].marker_present[7] = False
            frame[1].positions[3] = np.nan
        if step == 4:  # a person leaves: yet another shape
            frame = frame[:1]
        frames.append(SkeletonGroup(1_000_000_000 * step + 17, "world", frame))
    frames.append(SkeletonGroup(9, "world", [person(6, KINECT_V2, 1), person(7, skeleton_id=2)]))
    frames.append(SkeletonGroup(10, "world", []))
    tie = person(8, skeleton_id=4)
    tie.positions[[2, 5]] = (-0.0, 0.0, 9.0)  # two highest joints; the label's x is -0.0 + 0.0
    frames.append(SkeletonGroup(11, "world", [tie]))
    for group in frames:
        for namespace in ("merger", "filter"):
            expected = encode_marker_array(skeleton_markers(group, namespace, params))
            assert encode_skeleton_markers(group, namespace, params) == expected
            # the same people as the rows of one stack (read from it, not copied)
            assert encode_skeleton_markers(stacked(group), namespace, params) == expected


def stacked(group):
    """The group with its skeletons (of one layout) made rows of one ``SkeletonRows``."""
    skeletons = group.skeletons
    if not skeletons or any(s.layout is not skeletons[0].layout for s in skeletons):
        return group
    made = stack_rows(skeletons).skeletons(
        [s.id for s in skeletons], [s.src_time_ns for s in skeletons], "", skeletons[0].layout
    )
    assert np.shares_memory(stack_rows(made).markers, made[-1].markers)
    return SkeletonGroup(group.stamp_ns, group.frame_id, made)


def test_ids_near_the_int32_limits_are_drawn():
    """Marker ids (3 per person) stay in int32 for any int32 skeleton id."""
    big, low = person(0, skeleton_id=2**31 - 1), person(1, skeleton_id=-(2**31))
    group = SkeletonGroup(5, "world", [big, low])
    ids = skeleton_markers(group).ids.tolist()
    assert all(-(2**31) <= i < 2**31 for i in ids)
    assert len(set(ids)) == 6
    assert encode_skeleton_markers(group) == encode_marker_array(skeleton_markers(group))


def test_compiled_visible_joints_equal_numpy():
    from hiros_visualizer.compiled import visible_joints

    rng = np.random.default_rng(3)
    rows = rng.normal(size=(3, 6, 20))
    rows[0, 1, 1], rows[1, 2, 2], rows[2, 3, 3], rows[2, 4, 2] = np.nan, np.inf, -np.inf, np.nan
    rows[0, 5, 0] = np.nan  # another column: not a coordinate
    present = rng.random((3, 6)) > 0.2
    for column in (1, 0):
        positions = rows[..., column : column + 3]
        expected = present & np.isfinite(positions).all(axis=2)
        assert np.array_equal(visible_joints(rows, column, present), expected)
