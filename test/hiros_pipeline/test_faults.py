"""Faults the pipeline must survive: a camera that drops out, a truncated recording."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from hiros_core.calibration import load_calibration
from hiros_core.recording import RecordingReader, iter_groups
from hiros_eval.tracking import identity_metrics
from hiros_pipeline import Pipeline, run_recording


@pytest.fixture(scope="module")
def scene(simulated_scene: Callable[..., Path]) -> Path:
    return simulated_scene(
        "faults", n_cameras=3, n_people=2, duration=16.0, seed=5,
        enter_leave=False,
    )  # fmt: skip


def test_a_camera_silent_for_five_seconds_keeps_ids_and_calibration(scene: Path) -> None:
    from hiros_sim import load_truth

    calibration = load_calibration(scene / "calibration.yaml")
    pipeline = Pipeline(calibration=calibration)
    merged = []
    first = None
    dropped = 0
    for source, group in iter_groups(scene / "recording.mcap"):
        first = group.stamp_ns if first is None else first
        if source == "k02" and 5e9 <= group.stamp_ns - first < 10e9:
            dropped += 1
            continue  # k02 unplugged for 5 s
        merged.append(pipeline.update(group).merger)
    merged.append(pipeline.flush().merger)
    assert dropped > 100
    assert not pipeline.tracker.uncalibrated
    metrics = identity_metrics([g for g in merged if g.skeletons], load_truth(scene))
    assert metrics.id_switches == 0
    assert metrics.tracks == 2


def test_truncated_recording_is_reported_and_the_rest_processed(
    scene: Path, tmp_path: Path
) -> None:
    whole = scene / "recording.mcap"
    data = whole.read_bytes()
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(data[: len(data) // 2 + 1234])  # cut mid-chunk, no summary
    calibration = load_calibration(scene / "calibration.yaml")
    summary = run_recording(truncated, calibration, tmp_path / "out.mcap")
    assert any("ends early" in problem for problem in summary.problems)
    assert sum(summary.frames_in.values()) > 100
    assert summary.frames_total == summary.processed + sum(summary.dropped.values())
    assert summary.frames_total == sum(summary.frames_in.values())  # the cut took unknown ones
    assert summary.published["filter"] > 0


def test_bad_frames_are_counted_not_fatal(tmp_path: Path, scene: Path) -> None:
    """NaN skeletons, empty groups and an unknown camera go through with counted drops."""
    calibration = load_calibration(scene / "calibration.yaml")
    pipeline = Pipeline(calibration=calibration)
    groups = [g for _, g in iter_groups(scene / "recording.mcap")][:60]
    for group in groups[:20]:
        pipeline.update(group)
    broken = groups[20].copy()
    for skeleton in broken.skeletons:
        skeleton.positions[:] = np.nan
    stranger = groups[21].copy()
    stranger.frame_id = "k99_depth_camera_link"
    for skeleton in stranger.skeletons:
        skeleton.src_frame = stranger.frame_id
    empty = groups[22].copy()
    empty.skeletons = []
    for group in (broken, stranger, empty, *groups[23:]):
        pipeline.update(group)
    pipeline.flush()
    assert "k99" in pipeline.tracker.uncalibrated
    assert sum(pipeline.drops.values()) >= 1


def test_unreadable_recording_gives_one_clear_sentence(tmp_path: Path) -> None:
    from hiros_cli.main import main

    bogus = tmp_path / "nothing.mcap"
    bogus.write_bytes(b"not an mcap file at all")
    calibration = tmp_path / "calib.yaml"
    calibration.write_text("reference: k01\ncameras: {k01: {}}\n")
    code = main(
        ["run", str(bogus), "--calibration", str(calibration), "--out", str(tmp_path / "o.mcap")]
    )
    assert code == 1


def test_writer_keeps_every_message_of_a_run(tmp_path: Path, scene: Path) -> None:
    """What is written is what is counted (published groups = messages on the stage topics)."""
    calibration = load_calibration(scene / "calibration.yaml")
    out = tmp_path / "out.mcap"
    summary = run_recording(scene / "recording.mcap", calibration, out)
    with RecordingReader(out) as reader:
        counts: dict[str, int] = {}
        for message in reader.messages():
            counts[message.topic] = counts.get(message.topic, 0) + 1
    for stage, published in summary.published.items():
        assert counts[f"/hiros/{stage}"] == published
