"""Evaluation of a whole run against the simulator's truth, its report and its exports."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from hiros_core.calibration import load_calibration
from hiros_core.geometry import RigidTransform
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_eval.export import person_series, write_angles_csv, write_positions_csv, write_trc
from hiros_eval.report import write_report
from hiros_eval.run import align_to_truth, evaluate_run, read_run, series_lag
from hiros_pipeline import run_recording
from hiros_sim import SimParams, simulate, write_recording


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("eval")
    result = simulate(SimParams(n_cameras=2, n_people=2, duration=8.0, seed=8, enter_leave=False))
    write_recording(result, folder)
    calibration = load_calibration(folder / "calibration.yaml")
    summary = run_recording(
        folder / "recording.mcap", calibration, folder / "out.mcap", keep_outputs=True
    )
    return folder, result, summary


def test_true_calibration_scores_zero_and_stages_are_scored(run) -> None:
    _folder, result, summary = run
    evaluation = evaluate_run(
        summary.outputs, result.calibration, result.calibration, result.truth, result.camera_groups
    )
    for accuracy in evaluation.calibration.values():
        assert accuracy.rotation_error_deg == pytest.approx(0.0, abs=1e-6)
        assert accuracy.translation_error_cm == pytest.approx(0.0, abs=1e-6)
    assert set(evaluation.stages) == {"tracker", "merger", "optimizer", "filter"}
    assert 0.0 < evaluation.stages["merger"].mpjpe < 0.5
    assert set(evaluation.cameras) == {"k01", "k02"}
    assert evaluation.stages["merger"].identity.id_switches == 0


def test_reading_back_the_mcap_gives_the_same_outputs(run) -> None:
    folder, _, summary = run
    outputs, used = read_run(folder / "out.mcap")
    assert used.reference == load_truth_reference(folder)
    for stage, groups in summary.outputs.items():
        assert len(outputs[stage]) == len(groups)
        assert all(a.same_as(b) for a, b in zip(outputs[stage], groups, strict=True))


def load_truth_reference(folder: Path) -> str:
    return load_calibration(folder / "calibration.yaml").reference


def test_alignment_moves_estimates_into_the_truth_world() -> None:
    from hiros_core.calibration import Calibration, CameraCalibration

    pose = RigidTransform.from_quaternion([0, 0, np.sin(0.3), np.cos(0.3)], [1.0, 2.0, 0.5])
    true = Calibration(
        "k01",
        cameras={
            "k01": CameraCalibration(
                "k01_depth_camera_link",
                time_offset=0.0,
                translation=pose.translation,
                rotation=pose.quaternion,
            )
        },
    )
    used = Calibration("k01", cameras={"k01": CameraCalibration("k01_depth_camera_link")})
    points = np.random.default_rng(0).normal(size=(32, 3))
    group = SkeletonGroup(
        5, "k01_depth_camera_link", [Skeleton.from_positions(points, src_time_ns=5)]
    )
    (aligned,) = align_to_truth([group], used, true)
    np.testing.assert_allclose(aligned.skeletons[0].positions, pose.apply(points), atol=1e-12)
    assert aligned.stamp_ns == 5


def test_report_and_exports_are_written(run, tmp_path: Path) -> None:
    _, result, summary = run
    evaluation = evaluate_run(summary.outputs, result.calibration, result.calibration, result.truth)
    report = write_report(evaluation, tmp_path / "report", facts=[("frames in", "123")])
    page = report.read_text()
    assert "pipeline stages against the truth" in page
    filter_mpjpe = f"{evaluation.stages['filter'].mpjpe * 100:.1f} cm from the truth"
    assert filter_mpjpe in page  # the headline says it in words
    assert page.count("<figcaption>") == 5
    assert "<dt>lag</dt>" in page
    assert "<td>frames in</td><td>123</td>" in page
    assert all(
        (tmp_path / "report" / name).stat().st_size > 1000
        for name in (
            "error_per_stage.png",
            "error_per_joint.png",
            "angle_error.png",
            "joint_angles.png",
            "error_timeline.png",
        )
    )
    people = person_series(summary.outputs["filter"])
    _person, (times, positions) = next(iter(people.items()))
    write_positions_csv(tmp_path / "p.csv", times, positions)
    write_angles_csv(tmp_path / "a.csv", times, positions)
    write_trc(tmp_path / "p.trc", times, positions)
    table = np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1)
    assert table.shape == (len(times), 1 + 32 * 3)
    np.testing.assert_allclose(table[:, 1:4], positions[:, 0], atol=1e-6)
    trc = (tmp_path / "p.trc").read_text().splitlines()
    assert trc[0].startswith("PathFileType\t4")
    assert trc[2].split("\t")[2] == str(len(times))
    assert len(trc) == 6 + len(times)


def test_read_run_hands_on_what_it_could_not_read(run, tmp_path: Path) -> None:
    folder, _, _ = run
    path = folder / "out.mcap"
    with path.open("rb") as stream:
        chunk = make_reader(stream).get_summary().chunk_indexes[-1]
    data = bytearray(path.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    problems: list[str] = []
    outputs, _ = read_run(damaged, problems)
    whole, _ = read_run(path)
    assert 0 < len(outputs["filter"]) < len(whole["filter"])
    assert "is damaged" in problems[0]


class _SwayingTruth:
    """Two people whose 32 joints sway sideways (1 Hz and 0.7 Hz) and drift forward."""

    times = np.arange(0.0, 10.0, 1 / 30)
    positions = np.zeros((2, 1, 32, 3))

    def at(self, times: np.ndarray) -> np.ndarray:
        out = np.zeros((2, len(times), 32, 3))
        for p, frequency in enumerate((1.0, 0.7)):
            out[p, :, :, 0] = 0.3 * np.sin(2 * np.pi * frequency * times)[:, None]
            out[p, :, :, 1] = 0.5 * times[:, None] + np.arange(32) * 0.01
        return out


@pytest.mark.parametrize("delay", [0.06, 0.0, -0.03])
def test_series_lag_finds_how_late_a_stage_is(delay: float) -> None:
    truth = _SwayingTruth()
    rng = np.random.default_rng(4)
    series = {}
    for person in (0, 1):
        times = np.sort(rng.uniform(1.0, 9.0, 400))
        late = truth.at(times - delay)[person] + rng.normal(0, 0.02, (len(times), 32, 3))
        series[person] = (times, late, truth.at(times)[person])
    assert series_lag(series, truth) == pytest.approx(delay, abs=0.003)
    assert np.isnan(series_lag({}, truth))
