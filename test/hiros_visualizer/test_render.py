"""The rendering replays a marker topic as a viewer does and draws it."""

import numpy as np

from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_core.recording import MARKER_ARRAY, RecordingWriter
from hiros_visualizer import Drawing
from hiros_visualizer.render import markers_at, render

T0 = 1_700_000_000_000_000_000


def _person(skeleton_id):
    rng = np.random.default_rng(skeleton_id)
    positions = rng.normal([0.0, 0.0, 1.0], 0.3, size=(AZURE_KINECT.n_joints, 3))
    return Skeleton.from_positions(positions, AZURE_KINECT, skeleton_id=skeleton_id)


def test_markers_of_people_who_left_are_not_drawn(tmp_path):
    path = tmp_path / "out.mcap"
    drawing = Drawing("filter")
    frames = [[4, 9], [4, 9], [4], [4]]
    with RecordingWriter(path) as writer:
        for index, ids in enumerate(frames):
            group = SkeletonGroup(T0 + index * 10**8, "world", [_person(i) for i in ids])
            for message in drawing.draw(group):
                writer.write("/hiros/filter/markers", MARKER_ARRAY, message, group.stamp_ns)
    before, _ = markers_at(path, "/hiros/filter/markers", 0.15)
    after, calibration = markers_at(path, "/hiros/filter/markers", 0.35)
    assert len(before) == 6  # joints, limbs, label of both people
    assert len(after) == 3
    assert {m.texts[0] for m in after} == {"", "id 4"}
    assert calibration is None
    png = render(after, calibration, tmp_path / "view.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
