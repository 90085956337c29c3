"""convert -> read back -> the same groups; format detection; the command line."""

from collections import Counter
from pathlib import Path

import pytest

from hiros_cli.main import main as hiros
from hiros_convert import convert, detect_format, read_multitrack_csv, read_unipd_csv
from hiros_core.errors import CodecError, RecordingError
from hiros_core.recording import RecordingReader, iter_groups

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
POS = DATA / "unipd_bpe_sample" / "sbj01_bend1KinectPos.csv"
STUDY_24 = DATA / "kinect_multitrack" / "Study_24_Kinect_1_Time_2_49_46_PM.csv"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="shared data not present")


def _read_back(path):
    out = {}
    drops = Counter()
    for source, group in iter_groups(path, drops=drops):
        out.setdefault(source, []).append(group)
    assert sum(drops.values()) == 0, drops
    return out


@needs_data
@pytest.mark.parametrize("skeleton_groups", [False, True])
def test_unipd_round_trip(tmp_path, skeleton_groups):
    out = tmp_path / "bend.mcap"
    counts = convert(POS, out, skeleton_groups=skeleton_groups)
    topic = "/k01/skeletons" if skeleton_groups else "/k01/body_tracking_data"
    assert counts == {topic: 355}
    expected = read_unipd_csv(POS)["k01"]
    back = _read_back(out)["k01"]
    assert len(back) == len(expected)
    assert all(a.same_as(b) for a, b in zip(back, expected, strict=True))


@needs_data
@pytest.mark.parametrize("skeleton_groups", [False, True])
def test_multitrack_round_trip_keeps_device_clocks(tmp_path, skeleton_groups):
    out = tmp_path / "study24"
    convert(STUDY_24, out, skeleton_groups=skeleton_groups)
    expected = read_multitrack_csv(STUDY_24)
    back = _read_back(out)
    assert sorted(back) == sorted(expected)
    for camera, groups in expected.items():
        assert len(back[camera]) == len(groups)
        assert all(a.same_as(b) for a, b in zip(back[camera], groups, strict=True))
    with RecordingReader(out) as reader:
        log_times = [m.log_time_ns for m in reader.messages()]
    # log times are the server clock (2015), stamps the cameras' own clocks
    assert 1.42e18 < log_times[0] < 1.43e18
    assert back["kinect_138_251_207_136"][0].stamp_ns < 1e15


def test_detect_format(tmp_path):
    cases = {
        "a.json": "{}",
        "b.csv": "Study_Id, Tracker_Time, Person_Id, Skeleton_Time, Kinect_Id\n",
        "cKinectPos.csv": "time,PelvisPosX\n",
        "d.csv": "camera,stamp_ns,body_id,joint,x,y,z\n",
    }
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
    assert [detect_format(tmp_path / n) for n in cases] == [
        "k4abt-json",
        "multitrack-csv",
        "unipd-csv",
        "csv",
    ]
    (tmp_path / "e.csv").write_text("what,is,this\n")
    with pytest.raises(RecordingError, match="--format"):
        detect_format(tmp_path / "e.csv")
    with pytest.raises(RecordingError, match="does not exist"):
        detect_format(tmp_path / "none.csv")


def test_generic_csv_to_recording_and_empty_input(tmp_path):
    source = tmp_path / "g.csv"
    source.write_text("camera,stamp_ns,body_id,joint,x,y,z\nk05,10,1,Pelvis,0,0,2\n")
    convert(source, tmp_path / "g.mcap")
    ((camera, group),) = list(iter_groups(tmp_path / "g.mcap"))
    assert camera == "k05"
    assert group.skeletons[0].positions[0].tolist() == [0, 0, 2]
    empty = tmp_path / "empty.csv"
    empty.write_text("camera,stamp_ns,body_id,joint,x,y,z\n")
    with pytest.raises(RecordingError, match="no skeletons"):
        convert(empty, tmp_path / "e.mcap")


def test_command_line(tmp_path, capsys):
    source = tmp_path / "g.csv"
    source.write_text("camera,stamp_ns,body_id,joint,x,y,z\nk05,10,1,Pelvis,0,0,2\n")
    assert hiros(["convert", str(source), "--out", str(tmp_path / "g.mcap")]) == 0
    assert "/k05/body_tracking_data" in capsys.readouterr().out
    assert hiros(["convert", str(source), "--out", str(tmp_path / "g.mcap")]) == 1
    assert "exists already" in capsys.readouterr().err
    assert hiros(["convert", str(tmp_path / "no.csv"), "--out", str(tmp_path / "n.mcap")]) == 1


def test_a_failed_conversion_leaves_no_output_and_a_folder_is_named(tmp_path):
    source = tmp_path / "g.csv"
    year_2065 = 3_000_000_000 * 10**9  # beyond builtin_interfaces/Time's int32 seconds
    source.write_text(f"camera,stamp_ns,body_id,joint,x,y,z\nk01,{year_2065},1,Pelvis,0,0,2\n")
    with pytest.raises(CodecError, match="int32 seconds"):
        convert(source, tmp_path / "g.mcap")
    assert not (tmp_path / "g.mcap").exists()
    with pytest.raises(RecordingError, match="is a folder, not a file"):
        detect_format(tmp_path)
