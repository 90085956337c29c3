"""``calibrate_recording``: a recording calibrated, with progress and the reader's problems."""

from __future__ import annotations

from pathlib import Path

import pytest

from hiros_calib.offline import READING, STAMPS_AS_LOG_TIMES, calibrate_recording
from hiros_core.codec import encode_group
from hiros_core.errors import RecordingError
from hiros_core.recording import SKELETON_GROUP, RecordingWriter


def write_logged_at_stamps(scene, path: Path, cameras: list[str]) -> Path:
    """``cameras``' frames as SkeletonGroup topics, each logged at its own stamp."""
    messages = sorted((g.stamp_ns, name, g) for name in cameras for g in scene.camera_groups[name])
    with RecordingWriter(path) as writer:
        for log_time, name, group in messages:
            writer.write(f"/{name}/skeletons", SKELETON_GROUP, encode_group(group), log_time)
    return path


@pytest.mark.slow
def test_progress_goes_from_reading_through_the_calibrators_stages(make_scene, tmp_path):
    scene = make_scene(angles_deg=(0.0, 90.0), duration=15.0, seed=4)
    path = write_logged_at_stamps(scene, tmp_path / "rec.mcap", ["cam0", "cam1"])
    calls: list[tuple[str, float]] = []
    result = calibrate_recording(path, progress=lambda stage, done: calls.append((stage, done)))
    stages, done = zip(*calls, strict=True)
    assert calls[:2] == [(READING, 0.0), ("body tracks", 0.1)]
    assert {"clock offsets", "camera poses"} <= set(stages)
    assert list(done) == sorted(done)
    assert done[-1] <= 1.0
    truth = scene.truth.cameras["cam1"].time_offset
    assert result.calibration.cameras["cam1"].time_offset == pytest.approx(truth, abs=3e-3)
    assert result.notes[0] == STAMPS_AS_LOG_TIMES  # log times at the stamps: no arrival


def test_one_camera_is_refused_naming_what_was_found(make_scene, tmp_path):
    scene = make_scene(angles_deg=(0.0, 90.0), duration=2.0)
    path = write_logged_at_stamps(scene, tmp_path / "rec.mcap", ["cam0"])
    with pytest.raises(RecordingError, match=r"two or more cameras, found \['cam0'\]"):
        calibrate_recording(path)


def test_the_readers_problems_are_handed_back_when_it_raises(make_scene, tmp_path):
    scene = make_scene(angles_deg=(0.0, 90.0), duration=2.0)
    data = bytearray(write_logged_at_stamps(scene, tmp_path / "rec.mcap", ["cam0"]).read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside the chunk's compressed records
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    problems: list[str] = []
    with pytest.raises(RecordingError):
        calibrate_recording(damaged, problems=problems)
    assert any("is damaged" in problem for problem in problems)
