"""UNIPD-BPE CSV, k4abt JSON and generic CSV readers: shared files and bad inputs."""

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from hiros_convert import convert, read_generic_csv, read_k4abt_json, read_unipd_csv
from hiros_core.errors import RecordingError
from hiros_core.layouts import AZURE_KINECT, KINECT_V2

UNIPD = Path(__file__).resolve().parents[3] / "shared" / "data" / "unipd_bpe_sample"
POS = UNIPD / "sbj01_bend1KinectPos.csv"
needs_data = pytest.mark.skipif(not POS.is_file(), reason="shared data not present")


@needs_data
def test_unipd_take():
    drops = Counter()
    (groups,) = read_unipd_csv(POS, drops=drops).values()
    # 357 rows, two of them all zeros (nobody tracked)
    assert len(groups) == 355
    assert drops["untracked_frame"] == 2
    assert drops["bad_row"] == 2  # two short rows in the Quat file
    assert drops["no_orientation"] == 0
    first = groups[0]
    assert first.frame_id == "k01_depth_camera_link"
    assert first.stamp_ns == 1635261007408 * 1_000_000
    (skeleton,) = first.skeletons
    assert skeleton.id == 1
    assert skeleton.marker_present.sum() == 32
    np.testing.assert_allclose(
        skeleton.positions[0], [0.32026028633117676, -0.7932485938072205, 3.2349939346313477]
    )
    assert 2.0 < np.nanmedian(skeleton.positions[:, 2]) < 4.0  # metres in front of the camera
    np.testing.assert_allclose(np.linalg.norm(skeleton.orientations, axis=1), 1.0, atol=1e-5)
    stamps = np.array([g.stamp_ns for g in groups])
    assert (np.diff(stamps) > 0).all()
    np.testing.assert_allclose(np.median(np.diff(stamps)) / 1e6, 33.0, atol=1.5)


@needs_data
def test_unipd_without_quat_file(tmp_path):
    copy = tmp_path / "takeKinectPos.csv"
    copy.write_bytes(POS.read_bytes())
    (groups,) = read_unipd_csv(copy, camera="k03").values()
    assert groups[0].frame_id == "k03_depth_camera_link"
    assert np.isnan(groups[0].skeletons[0].orientations).all()


def test_unipd_missing_columns(tmp_path):
    path = tmp_path / "xKinectPos.csv"
    path.write_text("time,a,b\n1,2,3\n")
    with pytest.raises(RecordingError, match="PelvisPosX"):
        read_unipd_csv(path)


def _k4abt_body(body_id, offset_mm):
    positions = (np.arange(32 * 3).reshape(32, 3) + offset_mm).tolist()
    orientations = [[1.0, 0.0, 0.0, 0.0]] * 32  # w, x, y, z identity
    return {"body_id": body_id, "joint_positions": positions, "joint_orientations": orientations}


def test_k4abt_json(tmp_path):
    frames = [
        {
            "timestamp_usec": 66666,
            "num_bodies": 2,
            "bodies": [_k4abt_body(2, 0), _k4abt_body(1, 1000)],
        },
        {"timestamp_usec": 100000, "num_bodies": 0, "bodies": []},
        {"timestamp_usec": 133333, "num_bodies": 1, "bodies": [{"body_id": 1}]},  # malformed
        {"num_bodies": 1, "bodies": [_k4abt_body(1, 0)]},  # no timestamp
        {
            "timestamp_usec": 166666,
            "num_bodies": 1,
            "bodies": [_k4abt_body(1, 0) | {"joint_confidence_levels": [3] * 30 + [1, 0]}],
        },
    ]
    path = tmp_path / "body.json"
    path.write_text(json.dumps({"frames": frames, "joint_names": list(AZURE_KINECT.joint_names)}))
    drops = Counter()
    (groups,) = read_k4abt_json(path, camera="k02", drops=drops).values()
    assert drops["bad_body"] == 1
    assert drops["bad_frame"] == 1
    assert [g.stamp_ns for g in groups] == [66_666_000, 166_666_000]
    assert [s.id for s in groups[0].skeletons] == [1, 2]
    np.testing.assert_allclose(groups[0].skeletons[1].positions[1], [0.003, 0.004, 0.005])
    np.testing.assert_allclose(groups[0].skeletons[0].positions[0], [1.0, 1.001, 1.002])
    np.testing.assert_array_equal(groups[0].skeletons[0].orientations[0], [0, 0, 0, 1])
    assert np.isnan(groups[0].skeletons[0].confidences).all()
    np.testing.assert_allclose(groups[1].skeletons[0].confidences[29:], [1, 1 / 3, 0])


@pytest.mark.parametrize(
    ("text", "match"),
    [("{", "not valid JSON"), ('{"frame": []}', "no 'frames' list"), ("[1, 2]", "no 'frames'")],
)
def test_k4abt_json_bad_files(tmp_path, text, match):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(RecordingError, match=match):
        read_k4abt_json(path)


def test_generic_csv(tmp_path):
    path = tmp_path / "generic.csv"
    path.write_text(
        "camera,stamp_ns,body_id,joint,x,y,z,qx,qy,qz,qw,confidence\n"
        "cam_a,2000,4,SpineBase,1,2,3,0,0,0,1,0.5\n"
        "cam_a,2000,4,3,1,2,4,,,,,\n"  # Head by index
        "cam_a,1000,4,SpineBase,0,0,1,NA,NA,NA,NA,NA\n"
        "cam_a,1000,4,SpineBase,9,9,9,,,,,\n"  # duplicate joint: first row kept
        "cam_a,1000,4,Tail,0,0,1,,,,,\n"  # unknown joint
        "cam_b,1000,1,HandLeft,0.5,0.5,2,,,,,0.9\n"
        "short,row\n"
    )
    drops = Counter()
    streams = read_generic_csv(path, layout=KINECT_V2, drops=drops)
    assert drops == Counter(bad_row=1, unknown_joint=1, duplicate_joint=1) + Counter()
    assert sorted(streams) == ["cam_a", "cam_b"]
    first, second = streams["cam_a"]
    assert (first.stamp_ns, second.stamp_ns) == (1000, 2000)
    np.testing.assert_array_equal(first.skeletons[0].positions[0], [0, 0, 1])
    skeleton = second.skeletons[0]
    assert skeleton.id == 4
    assert np.flatnonzero(skeleton.marker_present).tolist() == [0, 3]
    np.testing.assert_array_equal(skeleton.orientations[0], [0, 0, 0, 1])
    assert skeleton.confidences[0] == 0.5
    assert streams["cam_b"][0].skeletons[0].confidences[KINECT_V2.index("HandLeft")] == 0.9


def test_generic_csv_seconds_and_default_camera(tmp_path):
    path = tmp_path / "g.csv"
    path.write_text("stamp,body_id,joint,x,y,z\n1.5,1,Pelvis,0,0,2\n")
    (groups,) = read_generic_csv(path).values()
    assert groups[0].stamp_ns == 1_500_000_000
    assert groups[0].frame_id == "k01_depth_camera_link"


def test_generic_csv_needs_columns(tmp_path):
    path = tmp_path / "g.csv"
    path.write_text("stamp,body_id,x,y,z\n1.5,1,0,0,2\n")
    with pytest.raises(RecordingError, match="joint"):
        read_generic_csv(path)


def test_generic_csv_garbled_rows_cost_only_themselves(tmp_path):
    path = tmp_path / "g.csv"
    path.write_text(
        "camera,stamp_ns,body_id,joint,x,y,z,confidence\n"
        "k01,1000,1,Pelvis,0,0,2,1\n"
        "k01,garbage,1,Pelvis,0,0,2,1\n"  # stamp not an integer
        "k01,99999999999999999999999,1,Pelvis,0,0,2,1\n"  # beyond int64
        "k01,-5,1,Pelvis,0,0,2,1\n"  # before any recording time
        "k01,2000,x,Pelvis,0,0,2,1\n"  # body id not an integer
        "k01,2000,1,Pelvis,a,0,2,1\n"  # x not a number
        "k01,2000,1,Pelvis,0,0,2,high\n"  # confidence not a number
        "k01,3000,1,Pelvis,0,0,2,NA\n"
    )
    drops = Counter()
    (groups,) = read_generic_csv(path, drops=drops).values()
    assert [g.stamp_ns for g in groups] == [1000, 3000]
    assert drops == Counter(bad_row=6)


def test_generic_csv_stamps_in_seconds_that_cannot_be_times_are_bad_rows(tmp_path):
    path = tmp_path / "g.csv"
    path.write_text("stamp,body_id,joint,x,y,z\ninf,1,Pelvis,0,0,2\n1e300,1,Pelvis,0,0,2\n")
    drops = Counter()
    assert not read_generic_csv(path, drops=drops)
    assert drops == Counter(bad_row=2)
    with pytest.raises(RecordingError, match=r"no skeletons to convert \(dropped: bad_row 2\)"):
        convert(path, tmp_path / "out.mcap")
