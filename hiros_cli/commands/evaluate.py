"""Accuracy of a `hiros run` output, or of a calibration file, against the simulator's truth.

Per stage: MPJPE (overall and per joint), limb-length variation, joint-angle RMSE (knee, hip,
elbow, shoulder), identity figures (IDF1, switches, fragments), lag (how far the output trails
the truth: the delay of the truth that fits it best; negative when it runs ahead); per camera
alone: MPJPE; and the calibration used against the true one (time, rotation, translation).
The output is moved into the truth's world with the reference camera's true pose and clock, so
calibration error counts.
`--report DIR` writes report.html with figures.

Given a calibration file (`hiros calibrate`'s .yaml, or one the `calib` node saved) instead
of a run's output, only the calibration is judged: per camera the time error (ms, mean and
largest over the recording's frames), the rotation error (°) and the translation error (cm),
relative to the file's reference camera. A file in a gravity-aligned world (``hiros
calibrate``'s default) also gets its world judged: the angle between its z axis and the
truth's, and the height of the true floor in its world below where the people walked.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console
from rich.table import Table

from hiros_cli.progress import print_warnings
from hiros_core.errors import ConfigError

HELP = (
    "accuracy of a run's output (tables, --report HTML) or of a calibration file against the "
    "simulator's truth"
)
CALIBRATION_SUFFIXES = (".yaml", ".yml")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros evaluate OUT.mcap --truth DIR [--report DIR]``."""
    parser.add_argument(
        "output",
        type=Path,
        help="the .mcap written by `hiros run`, or a calibration file (.yaml) to judge alone",
    )
    parser.add_argument(
        "--truth",
        type=Path,
        required=True,
        help="simulator folder (truth.npz, calibration.yaml, recording.mcap)",
    )
    parser.add_argument("--report", type=Path, help="folder for report.html and its figures")


def evaluate_output(  # noqa: ANN201 - RunEvaluation
    output: Path, truth_dir: Path, problems: list[str] | None = None
):
    """Read the run and the truth, compute every figure; ``problems``: see ``read_run``."""
    from hiros_core.calibration import load_calibration
    from hiros_eval.run import evaluate_run, read_run
    from hiros_sim import load_truth

    outputs, used = read_run(output, problems)
    true = load_calibration(truth_dir / "calibration.yaml")
    return evaluate_run(outputs, used, true, load_truth(truth_dir), _camera_groups(truth_dir))


def _camera_groups(truth_dir: Path) -> dict:
    """Per camera the simulated recording's frames, if the truth folder holds it, else {}."""
    from hiros_core.recording import iter_groups

    camera_groups: dict = {}
    recording = truth_dir / "recording.mcap"
    if recording.exists():
        for source, group in iter_groups(recording):
            camera_groups.setdefault(source, []).append(group)
    return camera_groups


def evaluate_calibration_file(path: Path, truth_dir: Path) -> list[list[str]]:
    """Rows ``camera, time ms (mean), time ms (max), rotation deg, translation cm``.

    The time error is averaged over the simulated recording's frames (every 15th) when the
    truth folder holds it, so that a wrong drift counts; else it is taken at each camera's
    drift epoch.
    """
    import numpy as np

    from hiros_core.calibration import load_calibration
    from hiros_eval.calibration import compare_calibration

    estimate, true = load_calibration(path), load_calibration(truth_dir / "calibration.yaml")
    times = {
        camera: np.array([group.stamp for group in groups[::15]])
        for camera, groups in _camera_groups(truth_dir).items()
    }
    return [
        [
            camera,
            f"{a.time_error_ms:.2f}",
            f"{a.time_error_max_ms:.2f}",
            f"{a.rotation_error_deg:.3f}",
            f"{a.translation_error_cm:.2f}",
        ]
        for camera, a in compare_calibration(estimate, true, times or None).items()
    ]


def world_line(path: Path, truth_dir: Path) -> str | None:
    """The file's world against the truth's (z up, floor at 0), or None in a camera frame."""
    import numpy as np

    from hiros_core.calibration import load_calibration
    from hiros_eval.calibration import compare_world
    from hiros_sim import load_truth

    estimate, true = load_calibration(path), load_calibration(truth_dir / "calibration.yaml")
    quality = estimate.camera(estimate.reference).quality
    if "floor_up_from" not in quality:
        return None
    people = np.nanmean(load_truth(truth_dir).positions[:, :, 0, :2], axis=(0, 1))
    accuracy = compare_world(estimate, true, people)
    doubt = quality.get("floor_doubtful")
    return (
        f"world: z {accuracy.up_error_deg:.2f} deg from the truth's up; below the people the "
        f"true floor is at z = {accuracy.floor_error_cm:+.1f} cm in it (targets 1 deg, 2 cm); "
        + (
            f"the file calls its floor doubtful: {doubt}"
            if doubt
            else "the file does not call its floor doubtful"
        )
    )


def print_evaluation(console: Console, evaluation) -> None:  # noqa: ANN001 - RunEvaluation
    """The evaluation's tables, then the merged-vs-best-camera ratio."""
    for title, (headers, rows) in evaluation.tables().items():
        if rows:
            console.print(_table(title, headers, rows, console.width))
    if evaluation.cameras:
        for stage in ("merger", "filter"):
            if stage in evaluation.stages:
                ratio = evaluation.to_best_camera(stage)
                console.print(f"{stage} MPJPE / best single camera: {ratio:.2f}")


def _table(title: str, headers: list[str], rows: list[list[str]], width: int) -> Table:
    """A right-aligned table that keeps every word whole in ``width`` columns where it can.

    Too wide for the terminal, rich shrinks columns below their longest word and cuts it
    ("optimi…"); each column then gets the width of its longest word or value instead,
    and the headers wrap between words.
    """
    fits = [max([1, *map(len, header.split()), *(len(row[i]) for row in rows)])
            for i, header in enumerate(headers)]  # fmt: skip
    natural = sum(max(len(h), fit) + 3 for h, fit in zip(headers, fits, strict=True)) + 1
    table = Table(title=title)
    for header, fit in zip(headers, fits, strict=True):
        table.add_column(header, justify="right", width=None if natural <= width else fit)
    for row in rows:
        table.add_row(*row)
    return table


def run(args: argparse.Namespace) -> int:
    """Evaluate, print, and optionally write the HTML report."""
    from hiros_core.outputs import refuse_inputs

    if args.report:
        refuse_inputs(args.report, [args.output, args.truth], "--report")
    console = Console()
    if args.output.suffix.lower() in CALIBRATION_SUFFIXES:
        if args.report:
            msg = "--report needs a run's output (.mcap), not a calibration file"
            raise ConfigError(msg)
        headers = ["camera", "time error ms", "time max ms", "rotation error deg",
                   "translation error cm"]  # fmt: skip
        rows = evaluate_calibration_file(args.output, args.truth)
        title = f"{args.output.name} against the truth (relative to its reference camera)"
        console.print(_table(title, headers, rows, console.width))
        world = world_line(args.output, args.truth)
        if world:
            console.print(world, highlight=False)
        return 0
    problems: list[str] = []
    evaluation = evaluate_output(args.output, args.truth, problems)
    print_warnings(console, problems)  # figures from a damaged output cover only what was read
    print_evaluation(console, evaluation)
    if args.report:
        from hiros_core.outputs import staged_files
        from hiros_eval.report import write_report

        with staged_files(args.report) as staging:  # a cut report never replaces a whole one
            path = write_report(evaluation, staging, f"hiros evaluation of {args.output.name}")
        console.print(f"report: {args.report / path.name}")
    return 0
