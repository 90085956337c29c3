"""Damaged calibration files: each is refused with a CalibrationError naming the field."""

from __future__ import annotations

import pytest

from hiros_core import Calibration, CalibrationError, CameraCalibration
from hiros_core.calibration import load_calibration, save_calibration

GOOD = "k01: {time_offset: 1.5, drift: 1.0e-5, drift_epoch: 1.7e9, translation: [1, 2, 3]}"


@pytest.mark.parametrize(
    ("camera", "message"),
    [
        ("k01: {translation: [.nan, 0, 0]}", "translation .* is out of range"),
        ("k01: {translation: [.inf, 0, 0]}", "translation .* is out of range"),
        ("k01: {translation: [1.0e+30, 0, 0]}", "translation .* is out of range"),  # case 16
        ("k01: {time_offset: .nan}", "time_offset nan is out of range"),
        ("k01: {time_offset: 1.0e+300}", "time_offset .* is out of range"),
        ("k01: {drift: .inf}", "drift inf is out of range"),
        ("k01: {drift: -1}", "drift -1.0 is out of range"),
        ("k01: {drift_epoch: 1.0e+300}", "drift_epoch .* is out of range"),
        ("k01: {quality: 5}", "quality must be a mapping"),
        ("k01: {quality: [1, 2]}", "quality must be a mapping"),
    ],
)
def test_values_no_stage_can_use_are_refused(tmp_path, camera: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(f"cameras: {{{camera}}}")
    with pytest.raises(CalibrationError, match=f"bad.yaml: camera k01: {message}"):
        load_calibration(path)


def test_plausible_values_still_load(tmp_path) -> None:
    path = tmp_path / "good.yaml"
    path.write_text(f"cameras: {{{GOOD}}}")
    camera = load_calibration(path).camera("k01")
    assert camera.time_offset == 1.5
    assert camera.drift_epoch == 1.7e9


def test_a_binary_file_is_not_read_as_text(tmp_path) -> None:
    path = tmp_path / "recording.mcap"
    path.write_bytes(b"\x89MCAP0\r\n\xff\xfe")
    with pytest.raises(CalibrationError, match="cannot read calibration file"):
        load_calibration(path)


def test_an_unwritable_path_is_a_calibration_error(tmp_path) -> None:
    calibration = Calibration("k01", cameras={"k01": CameraCalibration("k01_depth_camera_link")})
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("")
    for path in (tmp_path / "folder", tmp_path / "file" / "calib.yaml"):
        with pytest.raises(CalibrationError, match="cannot write calibration file"):
            save_calibration(calibration, path)


def test_case16_two_cameras_with_one_frame_id_are_refused(tmp_path) -> None:
    path = tmp_path / "twins.yaml"
    path.write_text("cameras: {k01: {frame_id: cam_link}, k02: {frame_id: cam_link}}")
    with pytest.raises(CalibrationError, match=r"twins\.yaml: cameras k01 and k02 have the same"):
        load_calibration(path)


def test_a_calibration_is_saved_whole_or_not_at_all(tmp_path, monkeypatch) -> None:
    path = tmp_path / "calib.yaml"
    path.write_text("reference: k01\ncameras: {k01: {frame_id: old}}\n")
    calibration = Calibration("k01", cameras={"k01": CameraCalibration("new")})

    def full_disk(self, text, *args, **kwargs):
        self.open("w").write(text[:10])
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(type(path), "write_text", full_disk)
    with pytest.raises(CalibrationError, match="No space left"):
        save_calibration(calibration, path)
    monkeypatch.undo()
    assert load_calibration(path).camera("k01").frame_id == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calib.yaml"]
