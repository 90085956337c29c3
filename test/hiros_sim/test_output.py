import io

import numpy as np
import pytest

from hiros_cli.main import main
from hiros_core.calibration import load_calibration
from hiros_core.errors import RecordingError
from hiros_core.recording import RecordingReader, iter_groups
from hiros_sim import SimParams, load_truth, save_truth, simulate, write_recording


@pytest.fixture(scope="module")
def small():
    return simulate(SimParams(n_cameras=2, setup="facing", n_people=2, duration=4.0, seed=1))


def test_recording_round_trip(small, tmp_path):
    write_recording(small, tmp_path)
    with RecordingReader(tmp_path / "recording.mcap") as reader:
        messages = list(reader)
    assert {m.topic for m in messages} == {"/k01/body_tracking_data", "/k02/body_tracking_data"}
    assert {m.msgtype for m in messages} == {"visualization_msgs/msg/MarkerArray"}
    log_times = [m.log_time_ns for m in messages]
    assert log_times == sorted(log_times)
    read = {}
    for source, group in iter_groups(tmp_path / "recording.mcap"):
        assert source == group.camera
        read.setdefault(group.camera, []).append(group)
    assert sorted(read) == ["k01", "k02"]
    for name, groups in small.camera_groups.items():
        # iter_groups yields in log-time order; each camera's stamps stay increasing
        got = sorted(read[name], key=lambda g: g.stamp_ns)
        assert len(got) == len(groups)
        for a, b in zip(groups, got, strict=True):
            assert a.stamp_ns == b.stamp_ns
            assert [s.id for s in a.skeletons] == [s.id for s in b.skeletons]
            if a.skeletons:
                np.testing.assert_allclose(b.positions(), a.positions(), atol=1e-12)
                np.testing.assert_allclose(b.confidences(), a.confidences(), atol=1e-12)


def test_the_folder_opens_as_a_rosbag2_bag(small, tmp_path):
    # rosbag2's own layout: metadata.yaml lists the file beside it, so that a bag reader (and
    # hiros calibrate DIR, without a warning) takes the folder for what it is
    from rosbags.rosbag2 import Reader

    write_recording(small, tmp_path)
    with RecordingReader(tmp_path / "recording.mcap") as reader:
        count = sum(1 for _ in reader)
    with Reader(tmp_path) as bag:
        assert bag.message_count == count
        assert {c.topic for c in bag.connections} == {
            "/k01/body_tracking_data",
            "/k02/body_tracking_data",
        }
    with RecordingReader(tmp_path) as reader:
        assert reader.problems == []
        assert sum(1 for _ in reader) == count
    write_recording(small, tmp_path)  # replaced, metadata.yaml with it
    with Reader(tmp_path) as bag:
        assert bag.message_count == count


def test_truth_and_calibration_files(small, tmp_path):
    save_truth(small, tmp_path)
    truth = load_truth(tmp_path)
    np.testing.assert_array_equal(truth.times, small.truth.times)
    np.testing.assert_allclose(truth.positions, small.truth.positions, atol=1e-4)
    assert truth.clip_names == small.truth.clip_names
    calibration = load_calibration(tmp_path / "calibration.yaml")
    for name, cam in small.calibration.cameras.items():
        np.testing.assert_allclose(calibration.cameras[name].translation, cam.translation)
        assert calibration.cameras[name].time_offset == cam.time_offset
    with np.load(tmp_path / "truth.npz") as data:
        total = sum(len(g.skeletons) for gs in small.camera_groups.values() for g in gs)
        assert len(data["det_person"]) == total


def test_load_truth_error(tmp_path):
    with pytest.raises(RecordingError, match="cannot read simulation truth"):
        load_truth(tmp_path)


def test_a_cut_or_foreign_truth_file_is_a_recording_error(small, tmp_path):
    save_truth(small, tmp_path)
    whole = (tmp_path / "truth.npz").read_bytes()
    damaged = bytearray(whole)
    damaged[len(whole) // 2] ^= 0xFF
    array = io.BytesIO()
    np.save(array, np.zeros(3))
    for content in (whole[:1000], bytes(damaged), array.getvalue()):
        (tmp_path / "truth.npz").write_bytes(content)
        with pytest.raises(RecordingError, match="cannot read simulation truth"):
            load_truth(tmp_path)


def test_setup_from_calibration_file(small, tmp_path):
    save_truth(small, tmp_path)
    again = simulate(
        SimParams(setup=str(tmp_path / "calibration.yaml"), n_people=1, duration=4.0, seed=2)
    )
    for name, cam in small.calibration.cameras.items():
        np.testing.assert_allclose(again.calibration.cameras[name].rotation, cam.rotation)
        assert again.calibration.cameras[name].time_offset == cam.time_offset


def test_command_line(tmp_path, capsys):
    out = tmp_path / "sim"
    code = main(
        ["simulate", "--out", str(out), "--cameras", "2", "--people", "1", "--duration", "3",
         "--rate", "15", "--no-noise", "--truth-only"]
    )  # fmt: skip
    assert code == 0
    assert (out / "truth.npz").is_file()
    assert (out / "calibration.yaml").is_file()
    assert "k02" in capsys.readouterr().out


def test_command_line_errors(tmp_path, capsys):
    assert main(["simulate"]) == 1
    assert "--out" in capsys.readouterr().err
    assert main(["simulate", "--out", str(tmp_path), "--people", "9"]) == 1
    assert "n_people" in capsys.readouterr().err
    assert main(["simulate", "--out", str(tmp_path), "--set", "warp_speed=9"]) == 1
    assert "SimParams field" in capsys.readouterr().err
    assert main(["simulate", "--out", str(tmp_path), "--set", "fov=90"]) == 1


def test_command_line_knobs():
    import argparse

    from hiros_cli.commands.simulate import _params, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(
        ["--out", "x", "--set", "fov=90,70", "--set", "flip_rate=0", "--set", "enter_leave=no"]
    )
    params = _params(args)
    assert params.fov == (90.0, 70.0)
    assert params.flip_rate == 0.0
    assert params.enter_leave is False
