"""Accuracy of a `hiros run` output against the simulator's truth.

Per stage: MPJPE (overall and per joint), limb-length variation, joint-angle RMSE (knee, hip,
elbow, shoulder), identity figures (IDF1, switches, fragments); per camera alone: MPJPE; and the
calibration used against the true one (time, rotation, translation). The output is moved into
the truth's world with the reference camera's true pose and clock, so calibration error counts.
`--report DIR` writes report.html with figures.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console
from rich.table import Table

HELP = "accuracy of a run's output against the simulator's truth (tables, --report HTML)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros evaluate OUT.mcap --truth DIR [--report DIR]``."""
    parser.add_argument("output", type=Path, help="the .mcap written by `hiros run`")
    parser.add_argument(
        "--truth",
        type=Path,
        required=True,
        help="simulator folder (truth.npz, calibration.yaml, recording.mcap)",
    )
    parser.add_argument("--report", type=Path, help="folder for report.html and its figures")


def evaluate_output(output: Path, truth_dir: Path):  # noqa: ANN201 - RunEvaluation
    """Read the run and the truth, compute every figure."""
    from hiros_core.calibration import load_calibration
    from hiros_core.recording import iter_groups
    from hiros_eval.run import evaluate_run, read_run
    from hiros_sim import load_truth

    outputs, used = read_run(output)
    true = load_calibration(truth_dir / "calibration.yaml")
    camera_groups: dict = {}
    recording = truth_dir / "recording.mcap"
    if recording.exists():
        for source, group in iter_groups(recording):
            camera_groups.setdefault(source, []).append(group)
    return evaluate_run(outputs, used, true, load_truth(truth_dir), camera_groups)


def print_evaluation(console: Console, evaluation) -> None:  # noqa: ANN001
    """Three tables: stages, single cameras, calibration."""
    stages = Table(title="pipeline stages against the truth")
    for column in (
        "stage",
        "MPJPE cm",
        "limb CV %",
        "angle RMSE deg",
        "IDF1",
        "switches",
        "fragments",
    ):
        stages.add_column(column, justify="right")
    for stage, s in evaluation.stages.items():
        stages.add_row(
            stage,
            f"{s.mpjpe * 100:.2f}",
            f"{s.limb_cv * 100:.2f}",
            f"{s.angle_rmse.get('mean', float('nan')):.2f}",
            f"{s.identity.idf1:.3f}",
            str(s.identity.id_switches),
            str(s.identity.fragments),
        )
    console.print(stages)
    if evaluation.cameras:
        best = min(evaluation.cameras.values())
        cameras = Table(title="single cameras (true calibration, no tracking)")
        cameras.add_column("camera")
        cameras.add_column("MPJPE cm", justify="right")
        for camera, value in evaluation.cameras.items():
            cameras.add_row(camera, f"{value * 100:.2f}")
        console.print(cameras)
        for stage in ("merger", "filter"):
            if stage in evaluation.stages:
                ratio = evaluation.stages[stage].mpjpe / best
                console.print(f"{stage} MPJPE / best single camera: {ratio:.2f}")
    calibration = Table(title="calibration used against the truth")
    for column in ("camera", "time error ms", "rotation error deg", "translation error cm"):
        calibration.add_column(column, justify="right")
    for camera, a in evaluation.calibration.items():
        calibration.add_row(
            camera,
            f"{a.time_error_ms:.2f}",
            f"{a.rotation_error_deg:.3f}",
            f"{a.translation_error_cm:.2f}",
        )
    console.print(calibration)


def run(args: argparse.Namespace) -> int:
    """Evaluate, print, and optionally write the HTML report."""
    console = Console()
    evaluation = evaluate_output(args.output, args.truth)
    print_evaluation(console, evaluation)
    if args.report:
        from hiros_eval.report import write_report

        path = write_report(evaluation, args.report, f"hiros evaluation of {args.output.name}")
        console.print(f"report: {path}")
    return 0
