"""``hiros run`` over a short simulated recording: outputs, accounting, determinism."""

from __future__ import annotations

from pathlib import Path

import pytest

from hiros_core.calibration import load_calibration
from hiros_core.recording import RecordingReader
from hiros_pipeline import STAGES, PipelineParams, run_recording
from hiros_sim import SimParams, simulate, write_recording


@pytest.fixture(scope="module")
def short_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sim")
    result = simulate(SimParams(n_cameras=2, n_people=2, duration=8.0, seed=3))
    write_recording(result, folder)
    return folder


def test_every_stage_writes_and_every_frame_is_accounted_for(
    short_recording: Path, tmp_path: Path
) -> None:
    calibration = load_calibration(short_recording / "calibration.yaml")
    out = tmp_path / "out.mcap"
    summary = run_recording(short_recording / "recording.mcap", calibration, out, PipelineParams())
    with RecordingReader(short_recording / "recording.mcap") as reader:
        camera_messages = sum(1 for _ in reader.messages())
    bridge_dropped = sum(v for k, v in summary.dropped.items() if k.startswith("reader"))
    assert sum(summary.frames_in.values()) + bridge_dropped == camera_messages
    with RecordingReader(out) as reader:
        topics = set(reader.topics)
    assert {f"/hiros/{stage}" for stage in STAGES} <= topics
    assert {"/hiros/filter/markers", "/hiros/calibration"} <= topics
    for stage in STAGES:
        assert summary.published[stage] > 0
    assert 1 <= len(summary.people["merger"]) <= 4


def test_runs_are_deterministic(short_recording: Path, tmp_path: Path) -> None:
    calibration = load_calibration(short_recording / "calibration.yaml")
    first, second = tmp_path / "a.mcap", tmp_path / "b.mcap"
    run_recording(short_recording / "recording.mcap", calibration, first)
    run_recording(short_recording / "recording.mcap", calibration, second)
    with RecordingReader(first) as a, RecordingReader(second) as b:
        assert [m.data for m in a.messages()] == [m.data for m in b.messages()]
