"""Run the whole pipeline offline over a recording, at full speed.

Reads the camera topics of REC (a rosbag2 folder, .mcap, .db3 or ROS 1 .bag; Azure-driver
MarkerArray or SkeletonGroup topics), applies the calibration, and writes one MCAP holding every
stage's output (/hiros/tracker, /hiros/merger, /hiros/optimizer, /hiros/filter), coloured
markers for Foxglove or RViz (/hiros/merger/markers, /hiros/filter/markers) and the calibration
used (/hiros/calibration). Every input frame is accounted for in the summary: processed, or
dropped with a reason. `--calibration auto` calibrates from the recording first (with
`--poses-from CAL`, only its clocks: the poses and world are those of CAL).

Parameters are the nodes' own: `--params config/pipeline.yaml` (ROS parameter-file format).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

from hiros_cli.progress import calibrate_with_progress, print_warnings, progress_bar
from hiros_core.calibration import Calibration, load_calibration, save_calibration
from hiros_core.errors import CalibrationError, ConfigError

if TYPE_CHECKING:
    from hiros_visualizer import OverlayParams

HELP = "offline pipeline over a recording -> one MCAP with every stage's output"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros run REC --calibration FILE|auto --out OUT.mcap [--params YAML]``."""
    parser.add_argument("recording", type=Path, help="rosbag2 folder, .mcap, .db3 or .bag")
    parser.add_argument(
        "--calibration",
        required=True,
        help="calibration file (hiros calibrate), or 'auto' to calibrate first",
    )
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        help="output .mcap (or a rosbag2 folder); never one of the inputs. It appears only "
        "when the run ends well (written beside it under a hidden name until then)",
    )
    parser.add_argument(
        "--poses-from",
        type=Path,
        metavar="CAL",
        help="with --calibration auto: keep the camera poses and world of this calibration "
        "(the same cameras, unmoved, calibrated from people walking) and find only the "
        "recording's clocks, as hiros calibrate --poses-from does",
    )
    parser.add_argument("--params", type=Path, help="pipeline parameter file (default: config/)")
    parser.add_argument(
        "--accept-flagged",
        action="store_true",
        help="run even on cameras the calibration flags as doubtful (default: stop, with "
        "the reason; a flagged camera is never used silently)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out, only if it is a recording hiros wrote (anything "
        "else there is refused, --force or not)",
    )
    parser.add_argument(
        "--merge-rate",
        type=_rate,
        help="merger output rate in Hz offline (default 30; 0: on every camera frame, as live)",
    )
    parser.add_argument(
        "--write",
        type=_outputs,
        default=None,
        metavar="WHAT",
        help="what goes into --out beside the calibration, comma-separated among tracker, "
        "merger, optimizer, filter, markers (default: all; e.g. filter,markers for the final "
        "stream and its drawing: about a fifth of the bytes)",
    )
    parser.add_argument(
        "--overlays",
        type=_overlays,
        metavar="WHAT",
        help="draw into the markers beside the skeletons, comma-separated: velocity, "
        "acceleration (arrows), a joint angle's name (knee_left, elbow_right, ...: its value "
        "as text) or angles (all of them); default: none",
    )
    parser.add_argument(
        "--processes",
        type=int,
        choices=(1, 2),
        help="2: read and track in a second process beside the other stages (default where "
        "a second core exists); 1: everything in this process. Same output either way",
    )


def _outputs(text: str) -> frozenset[str]:
    """``--write``: names among ``OUTPUTS``, comma-separated (``chosen_outputs`` checks)."""
    from hiros_pipeline.offline import OUTPUTS, chosen_outputs

    names = [name.strip() for name in text.split(",") if name.strip()]
    try:
        if names:
            return chosen_outputs(names)
    except ConfigError:
        pass
    msg = f"{text!r}: give one or more of {', '.join(OUTPUTS)}, comma-separated"
    raise argparse.ArgumentTypeError(msg)


def _overlays(text: str) -> OverlayParams:
    """``--overlays``: names for ``overlays_from_names``, comma-separated."""
    from hiros_visualizer import overlays_from_names

    try:
        return overlays_from_names(name.strip() for name in text.split(",") if name.strip())
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _rate(text: str) -> float:
    """``--merge-rate``: Hz, finite and 0 or more (NaN or a negative rate has no period)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        msg = f"{text!r} is not a rate in Hz (a number, 0 or more)"
        raise argparse.ArgumentTypeError(msg)
    return value


def resolve_calibration(
    spec: str,
    recording: Path,
    out: Path,
    console: Console,
    *,
    accept_flagged: bool = False,
    poses_from: Path | None = None,
) -> Calibration:
    """A calibration file, or ``auto``: calibrate the recording and save beside the output.

    The file written for ``auto`` (``OUT.calib.yaml``) replaces only an earlier calibration
    file and never an input. It is written even when a camera is flagged, so the user can
    read why; the run then stops unless ``accept_flagged``. ``poses_from`` (only with
    ``auto``) keeps that calibration's poses and world, and finds only the clocks.

    Raises:
        CalibrationError: a camera is flagged as doubtful (and not ``accept_flagged``).
        ConfigError: ``poses_from`` with a calibration file.

    """
    if spec != "auto":
        if poses_from is not None:
            msg = "--poses-from goes with --calibration auto (a calibration file has its poses)"
            raise ConfigError(msg)
        return refuse_flagged(load_calibration(spec), spec, console, accept=accept_flagged)
    from hiros_core.outputs import check_output, is_calibration_file, staged_output

    path = out.with_suffix(".calib.yaml")
    check_output(path, inputs=[recording], force=True, ours=is_calibration_file,
                 what="calibration file", option="--calibration auto: its file")  # fmt: skip
    console.print(f"calibrating {recording} first (--calibration auto)")
    known = load_calibration(poses_from) if poses_from is not None else None
    if poses_from is not None:
        console.print(f"keeping the camera poses and world of {poses_from}; finding the clocks")
    calibration = calibrate_with_progress(recording, console, known_poses=known).calibration
    with staged_output(path, replace=True) as staged:
        save_calibration(calibration, staged)
    console.print(f"calibration written to {path}")
    return refuse_flagged(calibration, str(path), console, accept=accept_flagged)


def refuse_flagged(
    calibration: Calibration, source: str, console: Console, *, accept: bool
) -> Calibration:
    """The calibration, unless a camera is flagged: then an error (or, accepted, a warning).

    Raises:
        CalibrationError: naming each flagged camera and why.

    """
    flagged = calibration.flagged
    if not flagged:
        return calibration
    reasons = "; ".join(f"{camera}: {why}" for camera, why in flagged.items())
    if accept:
        console.print(f"[yellow]warning: using flagged cameras (--accept-flagged): {reasons}[/]")
        return calibration
    msg = (
        f"{source}: the calibration flags {', '.join(flagged)} as doubtful ({reasons}). "
        "Record more varied motion and calibrate again, or pass --accept-flagged to run anyway"
    )
    raise CalibrationError(msg)


def run(args: argparse.Namespace) -> int:
    """Run, then print the accounting table."""
    from hiros_core.outputs import check_output, is_hiros_recording, staged_output
    from hiros_core.recording import require_camera_topics
    from hiros_pipeline import load_pipeline_params, run_recording
    from hiros_pipeline.offline import OUTPUTS, message_count

    console = Console()
    calibration_file = None if args.calibration == "auto" else args.calibration
    inputs = [args.recording, args.params, calibration_file, args.poses_from]
    check_output(args.out, inputs=[p for p in inputs if p is not None], force=args.force,
                 ours=is_hiros_recording, what="recording")  # fmt: skip
    params = load_pipeline_params(args.params, merge_rate=args.merge_rate)
    require_camera_topics(args.recording)
    calibration = resolve_calibration(
        args.calibration,
        args.recording,
        args.out,
        console,
        accept_flagged=args.accept_flagged,
        poses_from=args.poses_from,
    )
    with (
        staged_output(args.out, replace=args.force) as staged,
        progress_bar(f"hiros run {args.recording.name}", message_count(args.recording)) as advance,
    ):
        summary = run_recording(
            args.recording, calibration, staged, params, advance, processes=args.processes,
            write=args.write or OUTPUTS, overlays=args.overlays,
        )  # fmt: skip
    print_summary(console, summary, args.out)
    return 0


def print_summary(console: Console, summary, out: Path) -> None:  # noqa: ANN001 - RunSummary
    """Frames in = processed + dropped frames by reason; then detections dropped, speed.

    The frames read per camera come first; ``frames in`` adds what the reader lost, so
    that the rows under it add up to it.
    """
    table = Table(title=f"hiros run -> {out}", show_header=True)
    table.add_column("what")
    table.add_column("count", justify="right")
    for camera, frames in sorted(summary.frames_in.items()):
        table.add_row(f"frames read: {camera}", str(frames))
    table.add_row("frames in", str(summary.frames_total))
    table.add_row("  processed", str(summary.processed))
    for reason, count in sorted(summary.dropped.items()):
        table.add_row(f"  dropped: {reason}", str(count))
    if not summary.dropped:
        table.add_row("  dropped", "0")
    for stage, groups in summary.published.items():
        what = f"published /hiros/{stage}" if stage in summary.written else f"{stage} (not written)"
        table.add_row(what, f"{groups} ({len(summary.people[stage])} ids)")
    for reason, count in sorted(summary.dropped_detections.items()):
        table.add_row(f"detections dropped: {reason}", str(count))
    for track, text in summary.acceptance.items():
        table.add_row(f"limb lengths: person {track}", text)
    console.print(table)
    print_warnings(console, summary.problems)
    console.print(
        f"{summary.duration:.1f} s of recording in {summary.wall_time:.2f} s "
        f"({summary.real_time_factor:.0f}x real time)"
    )
