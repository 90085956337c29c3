"""KinectMultiTrack CSV reader against the shared files and hand-made bad inputs."""

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from hiros_convert import read_multitrack_csv
from hiros_core.errors import RecordingError
from hiros_core.layouts import KINECT_V2

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "kinect_multitrack"
STUDY_10 = DATA / "Study_10_Kinect_1_Time_4_10_14_PM.csv"
STUDY_24 = DATA / "Study_24_Kinect_1_Time_2_49_46_PM.csv"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="shared data not present")

HEADER = "Study_Id, Tracker_Time, Person#, Skeleton_Time, Kinect#, " + ", ".join(
    f"{j}_{a}" for j in KINECT_V2.joint_names for a in "XYZ"
)


def _row(person, ticks, camera, value="0.5"):
    return f"1, 10, {person}, {ticks}, {camera}, " + ", ".join([value] * 75)


@needs_data
def test_study_10_frames_cameras_and_values():
    drops = Counter()
    streams = read_multitrack_csv(STUDY_10, drops)
    assert sorted(streams) == ["kinect_138_251_207_136", "kinect_138_251_213_82"]
    # distinct (camera, Skeleton_Time) pairs counted with awk on the file
    assert len(streams["kinect_138_251_207_136"]) == 1791
    assert len(streams["kinect_138_251_213_82"]) == 1728
    assert drops["repeated_detection"] == 1866 * 2 - 1791 - 1728
    first = streams["kinect_138_251_207_136"][0]
    assert first.stamp_ns == 301860976585 * 100
    assert first.frame_id == "kinect_138_251_207_136_depth_camera_link"
    skeleton = first.skeletons[0]
    assert skeleton.layout is KINECT_V2
    assert skeleton.marker_present.all()
    ankle_left = skeleton.positions[KINECT_V2.index("AnkleLeft")]
    np.testing.assert_allclose(ankle_left, [0.3064703, -0.8221844, 2.226937])
    for groups in streams.values():
        stamps = np.array([g.stamp_ns for g in groups])
        assert (np.diff(stamps) > 0).all()


@needs_data
def test_study_24_two_people_share_frames():
    streams = read_multitrack_csv(STUDY_24)
    assert [len(v) for v in streams.values()] == [521, 481]
    counts = Counter(len(g.skeletons) for g in streams["kinect_138_251_207_136"])
    assert counts[2] > 0
    assert set(counts) <= {1, 2}
    ids = {s.id for g in streams["kinect_138_251_207_136"] for s in g.skeletons}
    assert ids == {0, 1}


def test_other_header_spelling_na_and_bad_rows(tmp_path):
    path = tmp_path / "multitrack.csv"
    rows = [
        HEADER,
        _row(0, 2000, "10.0.0.1"),
        _row(0, 1000, "10.0.0.1"),
        _row(0, 1000, "10.0.0.1"),  # the same camera frame sampled twice
        _row(1, 1000, "10.0.0.2", value="NA"),  # nothing tracked
        "1, 2, 3",  # wrong width
    ]
    na_row = _row(1, 3000, "10.0.0.2").split(", ")
    na_row[5:8] = ["NA", "NA", "NA"]  # SpineBase, the first joint column, missing
    rows.append(", ".join(na_row))
    path.write_text("\n".join(rows) + "\n")
    drops = Counter()
    streams = read_multitrack_csv(path, drops)
    assert drops == Counter(repeated_detection=1, no_joints=1, bad_row=1)
    assert [g.stamp_ns for g in streams["kinect_10_0_0_1"]] == [100_000, 200_000]
    (group,) = streams["kinect_10_0_0_2"]
    present = group.skeletons[0].marker_present
    assert not present[KINECT_V2.index("SpineBase")]
    assert present.sum() == 24


def test_missing_columns_and_missing_file(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("a, b, c\n1, 2, 3\n")
    with pytest.raises(RecordingError, match="Kinect_Id"):
        read_multitrack_csv(path)
    with pytest.raises(RecordingError, match="cannot read"):
        read_multitrack_csv(tmp_path / "absent.csv")
