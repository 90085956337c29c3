"""``hiros calibrate`` end to end on a small recording written from a synthetic scene."""

from __future__ import annotations

from pathlib import Path

import pytest

from hiros_cli.main import main
from hiros_core.calibration import load_calibration
from hiros_core.codec import encode_group
from hiros_core.recording import SKELETON_GROUP, RecordingWriter

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def recording(make_scene, tmp_path_factory):
    scene = make_scene(angles_deg=(0.0, 180.0), duration=15.0, noise=0.005, seed=2)
    path = tmp_path_factory.mktemp("rec") / "scene.mcap"
    writer = RecordingWriter(path)
    messages = sorted(
        (round((scene.truth.cameras[name].to_reference_time(g.stamp) + 0.03) * 1e9), name, g)
        for name, groups in scene.camera_groups.items()
        for g in groups
    )
    for log_time, name, group in messages:
        writer.write(f"/{name}/skeletons", SKELETON_GROUP, encode_group(group), log_time)
    writer.close()
    return scene, path


def test_calibrate_writes_the_file_and_plots(recording, tmp_path: Path, capsys) -> None:
    scene, path = recording
    out, plots = tmp_path / "calib.yaml", tmp_path / "plots"
    assert main(["calibrate", str(path), "--out", str(out), "--plots", str(plots)]) == 0
    calibration = load_calibration(out)
    assert calibration.reference == "cam0"
    truth = scene.truth.cameras["cam1"]
    assert calibration.cameras["cam1"].time_offset == pytest.approx(truth.time_offset, abs=3e-3)
    assert calibration.cameras["cam1"].quality["inlier_ratio"] > 0.9
    assert sorted(p.name for p in plots.iterdir()) == [
        "correlation.png",
        "joint_residuals.png",
        "offset_over_time.png",
    ]
    assert "cam0-cam1" in capsys.readouterr().out


def test_calibrate_takes_a_named_reference_and_rejects_an_unknown_one(recording, tmp_path, capsys):
    _, path = recording
    out = tmp_path / "calib.yaml"
    assert main(["calibrate", str(path), "--out", str(out), "--reference", "cam1"]) == 0
    assert load_calibration(out).reference == "cam1"
    assert main(["calibrate", str(path), "--out", str(out), "--reference", "nope"]) == 1
    assert "reference camera 'nope' is not among the cameras" in capsys.readouterr().err


def test_what_the_reader_lost_is_printed(recording, tmp_path, capsys):
    _, path = recording
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside the chunk's compressed records
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    main(["calibrate", str(damaged), "--out", str(tmp_path / "calib.yaml")])
    printed = " ".join(capsys.readouterr().out.split())
    assert "warning: " in printed
    assert "is damaged (its CRC does not match)" in printed


def test_a_recording_without_camera_topics_names_its_topics(tmp_path, capsys):
    path = tmp_path / "chatter.mcap"
    with RecordingWriter(path) as writer:
        writer.write("/chatter", "std_msgs/msg/String", b"\x00\x01\x00\x00\x01\x00\x00\x00\x00", 1)
    assert main(["calibrate", str(path), "--out", str(tmp_path / "calib.yaml")]) == 1
    assert "holds no camera skeletons" in capsys.readouterr().err


def test_log_times_that_are_only_the_stamps_do_not_narrow_the_search(make_scene, tmp_path, capsys):
    # as converted from files without a receiver clock: each frame logged at its own stamp,
    # and the two device clocks 5 s apart, outside the window an arrival prior would search
    scene = make_scene(angles_deg=(0.0, 90.0), duration=15.0, offsets=(0.0, 5.0), seed=4)
    path = tmp_path / "stamps.mcap"
    writer = RecordingWriter(path)
    messages = sorted(
        (g.stamp_ns, name, g) for name, groups in scene.camera_groups.items() for g in groups
    )
    for log_time, name, group in messages:
        writer.write(f"/{name}/skeletons", SKELETON_GROUP, encode_group(group), log_time)
    writer.close()
    out = tmp_path / "calib.yaml"
    assert main(["calibrate", str(path), "--out", str(out)]) == 0
    assert "log times are the frames' own stamps" in capsys.readouterr().out
    truth = scene.truth.cameras["cam1"].time_offset
    assert load_calibration(out).cameras["cam1"].time_offset == pytest.approx(truth, abs=3e-3)


def test_poses_from_an_earlier_calibration_keep_its_poses_and_find_the_clocks(
    recording, tmp_path, capsys
):
    _scene, path = recording
    walk = tmp_path / "walk.yaml"
    assert main(["calibrate", str(path), "--out", str(walk)]) == 0
    out = tmp_path / "take.yaml"
    assert main(["calibrate", str(path), "--poses-from", str(walk), "--out", str(out)]) == 0
    printed = " ".join(capsys.readouterr().out.split())  # (rich wraps long lines)
    assert "poses and world kept from" in printed
    assert "known poses: the cam0-cam1 joints lie" in printed
    known, found = load_calibration(walk), load_calibration(out)
    for name, camera in found.cameras.items():
        assert camera.translation == pytest.approx(known.cameras[name].translation)
        assert camera.rotation == pytest.approx(known.cameras[name].rotation)
        assert camera.time_offset == pytest.approx(known.cameras[name].time_offset, abs=2e-3)
    assert (
        found.cameras["cam0"].quality["floor_up_from"]
        == known.cameras["cam0"].quality["floor_up_from"]
    )
    assert main(["calibrate", str(path), "--poses-from", str(walk), "--world", "camera",
                 "--out", str(out)]) == 1  # fmt: skip
    assert "--world and --poses-from" in capsys.readouterr().err
