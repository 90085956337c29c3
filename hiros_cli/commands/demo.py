"""The main job on the bundled sample, end to end, in under a minute.

1. simulate: three Azure Kinect cameras watching three people for 60 s, made from the motion
   capture bundled in hiros_data (clocks offset and drifting, realistic noise, flips, ghosts);
2. calibrate: every camera's clock offset and pose, from the people's motion alone;
3. run: tracker -> merger -> optimizer -> filter over the recording;
4. evaluate: every stage and the calibration against the simulator's truth.
Writes sample/ (recording and truth), calib.yaml, out.mcap (open it in Foxglove) and
report/report.html to the output folder, then prints a one-screen summary.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

if TYPE_CHECKING:
    from hiros_eval.run import RunEvaluation
    from hiros_pipeline.offline import RunSummary

HELP = "calibrate, run and evaluate on the bundled sample; writes a report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros demo [--out DIR]``."""
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("hiros_out"),
        help="output folder (default: ./hiros_out); an earlier demo's folder is replaced, "
        "any other existing path is refused",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        help="seconds of the simulated sample (default: the sample's 60 s)",
    )


def run(args: argparse.Namespace) -> int:
    """The four steps with timings, then the summary."""
    from hiros_core.outputs import check_output, only_holds, staged_output
    from hiros_sim import sample_params

    console = Console()
    check_output(args.out, force=True, ours=lambda path: only_holds(path, DEMO_FILES),
                 what="demo folder")  # fmt: skip
    with staged_output(args.out, replace=True) as out:
        out.mkdir()
        evaluation, summary, timings, report = _demo(args, out, console)
    report = args.out / report.relative_to(out)
    seconds = args.duration or sample_params().duration
    _print_summary(console, evaluation, summary, timings, args.out, report, seconds)
    return 0


DEMO_FILES = ("sample", "calib.yaml", "out.mcap", "report")
"""What the demo writes in its folder: all that an earlier demo's folder may hold."""


def _demo(args: argparse.Namespace, out: Path, console: Console) -> tuple:
    """Simulate, calibrate, run and evaluate into ``out``; the figures and the report path."""
    from hiros_cli.progress import calibrate_with_progress, progress_bar
    from hiros_core.calibration import save_calibration
    from hiros_eval.report import write_report
    from hiros_eval.run import evaluate_run
    from hiros_pipeline import load_pipeline_params, run_recording
    from hiros_sim import sample_params, simulate, write_recording

    timings: dict[str, float] = {}

    start = time.perf_counter()
    params = sample_params()
    if args.duration:
        params.duration = args.duration
    with console.status("simulating the sample (3 cameras, 3 people)"):
        result = simulate(params)
        sample = out / "sample"
        write_recording(result, sample)
    recording = sample / "recording.mcap"
    timings["simulate"] = time.perf_counter() - start

    start = time.perf_counter()
    calibration = calibrate_with_progress(recording, console).calibration
    save_calibration(calibration, out / "calib.yaml")
    timings["calibrate"] = time.perf_counter() - start

    start = time.perf_counter()
    demo_params = load_pipeline_params()
    with progress_bar(
        "running the pipeline", sum(map(len, result.camera_groups.values()))
    ) as advance:
        summary = run_recording(
            recording, calibration, out / "out.mcap", demo_params, advance,
            keep_outputs=True,
        )  # fmt: skip
    timings["run"] = time.perf_counter() - start

    start = time.perf_counter()
    evaluation = evaluate_run(
        summary.outputs, calibration, result.calibration, result.truth, result.camera_groups
    )
    facts = [
        ("recording", f"{_scene(params.duration)}, simulated from real motion capture"),
        ("camera frames in / processed / dropped with a reason",
         f"{summary.frames_total} / {summary.processed} / {sum(summary.dropped.values())}"),
        ("pipeline speed (hiros run)", f"{summary.real_time_factor:.1f}x real time"),
    ]  # fmt: skip
    report = write_report(evaluation, out / "report", "hiros demo: the bundled sample", facts)
    timings["evaluate"] = time.perf_counter() - start
    return evaluation, summary, timings, report


def _scene(seconds: float) -> str:
    """The demo's scene in words, with the length it was simulated for."""
    return f"3 cameras, 3 people, {seconds:g} s"


def _add_chain_rows(table: Table, evaluation: RunEvaluation) -> None:
    """What the whole chain gains over the tracker alone and the best camera (issue targets)."""
    if "tracker" not in evaluation.stages or "filter" not in evaluation.stages:
        return
    change = evaluation.angle_change("filter")
    table.add_row("joint-angle RMSE, filter vs tracker", f"{100.0 * change:+.1f} %")
    if evaluation.cameras:
        ratio = evaluation.to_best_camera("filter")
        table.add_row("MPJPE, filter / best single camera", f"{ratio:.2f}")


def _print_summary(  # noqa: PLR0917 - the four results of the demo and where they went
    console: Console,
    evaluation: RunEvaluation,
    summary: RunSummary,
    timings: dict[str, float],
    out: Path,
    report: Path,
    seconds: float,
) -> None:
    table = Table(title=f"hiros demo: {_scene(seconds)}, simulated from real mocap")
    table.add_column("figure")
    table.add_column("value", justify="right")
    for camera, accuracy in evaluation.calibration.items():
        table.add_row(
            f"calibration {camera}: time / rotation / position",
            f"{accuracy.time_error_ms:.1f} ms / {accuracy.rotation_error_deg:.2f}° / "
            f"{accuracy.translation_error_cm:.1f} cm",
        )
    best_camera = evaluation.best_camera
    if best_camera is not None:
        table.add_row(
            f"best single camera ({best_camera}) MPJPE",
            f"{evaluation.cameras[best_camera] * 100:.1f} cm",
        )
    for stage, figures in evaluation.stages.items():
        table.add_row(
            f"{stage}: MPJPE / angles / switches / lag",
            f"{figures.mpjpe * 100:.1f} cm / {figures.angle_rmse.get('mean', float('nan')):.1f}° / "
            f"{figures.identity.id_switches} / {figures.lag * 1000:.0f} ms",
        )
    _add_chain_rows(table, evaluation)
    frames = summary.frames_total
    dropped = sum(summary.dropped.values())
    table.add_row("camera frames in / dropped with a reason", f"{frames} / {dropped}")
    table.add_row("pipeline speed", f"{summary.real_time_factor:.1f}x real time")
    table.add_row(
        "time: simulate / calibrate / run / evaluate",
        " / ".join(f"{v:.1f} s" for v in timings.values()),
    )
    console.print(table)
    console.print(f"outputs in {out}/: calib.yaml, out.mcap (Foxglove), sample/, report: {report}")
