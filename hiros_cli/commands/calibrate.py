"""Spatio-temporal calibration of a recording from the people's own motion.

Finds each camera's clock offset (and drift) and pose relative to the reference camera from
the skeletons alone: no cables, no checkerboard. The people should move (walk, swing arms)
for a minute in front of two or more cameras. Writes the calibration file every hiros stage
reads (DESIGN.md format) with quality figures per camera, and prints a one-screen summary.

Every lag the data allow is searched (--max-offset narrows it). The recording's message
arrival (log) times, when they were logged on one receiver's clock, choose among the lags the
motion supports; log times that are each camera's own clock (one recording host per camera),
or that the motion contradicts, are ignored, and the summary says so. People repeating one
motion correlate nearly as well one repetition away: the poses then decide among a few such
lags, since at the true lag both cameras' skeletons should fit one rigid transform best. When
neither can decide, or the motion repeats at more lags than the poses check (a walk looped
for the whole recording), the pair is refused with the candidate lags listed; give
--max-offset when the clocks are known to be close. A lag the poses chose is trusted only
where a third camera closes a loop through it: with two cameras the camera is flagged.

Every camera's quality figures expose a wrong result: the rigid-fit residual at the chosen lag
against the best other lag, and with three or more cameras how far the solved clocks and poses
miss each pair's own measurement (loops that do not close), how far apart two halves of
the recording put each pose, and how far the people's joints moved about where they stood
(lever cm: people who stayed on one spot, exercising or gesturing, leave the rotation to the
body tracker's own errors; under 38 cm RMS on every pair of a camera flags it). A camera that
fails them is flagged: the file is written with
the reason, the exit status is 3, and `hiros run` refuses the file unless given
--accept-flagged.

The world is gravity-aligned (REP-103): z up and the floor at z = 0, found from where the
people's feet rest, x along the reference camera's view, the origin on the floor below it.
--world camera keeps the reference camera's own frame.

People who stay on one spot (exercises, gestures) time the clocks but cannot pin the poses
down. Calibrate once from a recording of people walking across the area, then give that file
as --poses-from for each later recording with the cameras unmoved: its poses and world are
kept, only this recording's clocks are found, and the skeletons judge each candidate lag
against the known poses. A camera the known poses no longer fit (moved since) is flagged.

Examples:
  hiros calibrate sample/recording.mcap --out calib.yaml
  hiros calibrate rec/ --out calib.yaml --reference k02 --plots calib_plots/
  hiros calibrate squats.mcap --poses-from walk_calib.yaml --out squats_calib.yaml

"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console

    from hiros_calib.calibrator import CalibrationResult

FLAGGED_EXIT = 3
"""Exit status of a calibration written with a camera flagged as doubtful."""

HELP = "clock offsets and camera poses from people's motion, written as a calibration file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hiros calibrate``."""
    parser.add_argument("recording", type=Path, metavar="REC", help="recording (.mcap, folder)")
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        help="calibration file to write; it replaces only an earlier calibration file (any "
        "other file there, and the recording itself, are refused)",
    )
    parser.add_argument("--plots", type=Path, metavar="DIR", help="write PNG plots here")
    parser.add_argument(
        "--reference",
        help="camera whose frame and clock are the reference (default: first by name)",
    )
    parser.add_argument(
        "--prior-window",
        type=float,
        help="how far (s) the true lag may lie from the one the arrival times suggest (default 1)",
    )
    parser.add_argument(
        "--no-arrival-times",
        action="store_true",
        help="ignore the recording's log times (search every lag the data allow)",
    )
    parser.add_argument(
        "--max-offset",
        type=float,
        help="search lags within this many seconds (default: every lag; narrow it when "
        "people repeat one motion and the lag is refused as ambiguous)",
    )
    parser.add_argument("--no-drift", action="store_true", help="do not estimate clock drift")
    parser.add_argument(
        "--world",
        choices=("floor", "camera"),
        help="floor (default): z up and the floor at z = 0, found from the people's feet, x "
        "along the reference camera's view (REP-103); camera: the reference camera's own frame",
    )
    parser.add_argument(
        "--poses-from",
        type=Path,
        metavar="CAL",
        help="keep the camera poses and world of this calibration file (the same cameras, "
        "unmoved, calibrated from people walking) and find only this recording's clocks",
    )


def run(args: argparse.Namespace) -> int:
    """Calibrate, write the file (and plots), print the summary."""
    from rich.console import Console

    from hiros_calib.calibrator import CalibratorParams
    from hiros_cli.progress import calibrate_with_progress
    from hiros_core.calibration import load_calibration, save_calibration
    from hiros_core.errors import ConfigError
    from hiros_core.outputs import (
        check_output,
        is_calibration_file,
        refuse_inputs,
        staged_files,
        staged_output,
    )

    console = Console()
    check_output(args.out, inputs=[args.recording], force=True, ours=is_calibration_file,
                 what="calibration file")  # fmt: skip
    if args.plots:
        refuse_inputs(args.plots, [args.recording, args.out], "--plots")
    params = CalibratorParams(reference=args.reference or "")
    if args.prior_window is not None:
        params.prior_window = args.prior_window
    if args.max_offset is not None:
        params.max_offset = args.max_offset
    if args.no_drift:
        params.estimate_drift = False
    if args.poses_from and args.world:
        msg = "--world and --poses-from: the world of the --poses-from calibration is kept"
        raise ConfigError(msg)
    params.world = args.world or "floor"
    known = load_calibration(args.poses_from) if args.poses_from else None
    result = calibrate_with_progress(
        args.recording,
        console,
        params,
        use_arrival=not args.no_arrival_times,
        known_poses=known,
    )
    if args.poses_from:
        result.notes.insert(0, f"poses and world kept from {args.poses_from}; clocks found here")
    calibration = result.calibration
    with staged_output(args.out, replace=True) as staged:
        save_calibration(calibration, staged)
    print_summary(console, result)
    console.print(f"wrote {args.out}")
    if calibration.flagged:
        for camera, why in calibration.flagged.items():
            console.print(f"[bold yellow]{camera} is flagged as doubtful: {why}[/]")
        console.print("[yellow]hiros run refuses flagged cameras unless given --accept-flagged[/]")
        return FLAGGED_EXIT
    if args.plots:
        with staged_files(args.plots) as staging:
            written = write_plots(result, staging)
        console.print(f"wrote {len(written)} plots to {args.plots}")
    return 0


def print_summary(console: Console, result: CalibrationResult) -> None:
    """One screen: per camera offset, drift, pose and quality; per pair the correlation."""
    import numpy as np
    from rich import box
    from rich.table import Table

    from hiros_calib.known import KNOWN_POSE_RESIDUAL, OWN_POSE_RESIDUAL

    calibration = result.calibration
    # long camera names (IP addresses) get short labels so the table fits one screen
    label = {
        name: name if len(name) <= 8 else f"c{k}" for k, name in enumerate(calibration.cameras)
    }
    for name, short in label.items():
        if short != name:
            console.print(f"{short} = {name}", highlight=False)
    table = Table(
        title=(
            f"calibration (reference {label[calibration.reference]}; drift ppm, rot deg; "
            "motion: ms the joints' motion moved the offset)"
        ),
        box=box.SIMPLE,
        pad_edge=False,
        collapse_padding=True,
    )
    columns = (
        "camera",
        "offset s",
        "motion",
        "drift",
        "position m",
        "rot",
        "corr",
        "inl",
        "res cm",
    )
    for column in columns:
        table.add_column(column, justify="right", no_wrap=True, overflow="fold")
    for name, cam in calibration.cameras.items():
        q = cam.quality
        table.add_row(
            label[name],
            f"{cam.time_offset:+.4f}",
            f"{q['time_motion_shift_ms']:+.1f}" if "time_motion_shift_ms" in q else "-",
            f"{cam.drift * 1e6:+.0f}",
            " ".join(f"{v:+.2f}" for v in cam.translation),
            f"{np.degrees(cam.extrinsics.rotation.magnitude()):.1f}",
            f"{q['time_peak']:.2f}" if "time_peak" in q else "-",
            f"{100 * q['inlier_ratio']:.0f}%" if "inlier_ratio" in q else "-",
            f"{100 * q['residual_m']:.1f}" if "residual_m" in q else "-",
        )
    console.print(table)
    pairs = Table(
        title="camera pairs (fit, lever: cm; L/R: frames read swapped)",
        box=box.SIMPLE,
        pad_edge=False,
        collapse_padding=True,
    )
    columns = ("pair", "lag s", "peak", "bodies", "fit", "next lag", "inl", "L/R", "lever")
    for column in columns:
        pairs.add_column(column, justify="right", no_wrap=True)
    poses = {(p.camera_a, p.camera_b): p for p in result.pose_pairs}
    for sync in result.sync_pairs:
        pose = poses.get((sync.camera_a, sync.camera_b))
        pq = pose.quality if pose is not None and pose.ok else {}
        pairs.add_row(
            f"{label.get(sync.camera_a, sync.camera_a)}-{label.get(sync.camera_b, sync.camera_b)}",
            f"{sync.offset:+.4f}" if sync.ok else sync.reason[:40],
            f"{sync.quality.get('peak', np.nan):.2f}",
            str(sync.quality.get("pairs_used", "-")),
            _fit(sync.quality.get("lag_fit_residual_m")),
            _runner_up(sync.quality),
            f"{100 * pq['inlier_ratio']:.0f}%" if "inlier_ratio" in pq else "-",
            f"{100 * pq['mirrored_fraction']:.0f}%" if "mirrored_fraction" in pq else "-",
            f"{100 * pq['motion_lever_m']:.0f}" if "motion_lever_m" in pq else "-",
        )
    console.print(pairs)
    for pose in result.pose_pairs:
        if KNOWN_POSE_RESIDUAL in pose.quality:
            console.print(
                f"known poses: the {pose.camera_a}-{pose.camera_b} joints lie "
                f"{pose.quality[KNOWN_POSE_RESIDUAL]:.1f} cm apart under them, "
                f"{pose.quality[OWN_POSE_RESIDUAL]:.1f} cm under a pose fitted to this "
                "recording alone (a camera moved since fits clearly worse)",
                highlight=False,
            )
    for camera, reason in result.refused.items():
        console.print(f"[yellow]{camera} left out: {reason}[/]")
    for note in result.notes:
        console.print(f"note: {note}", highlight=False)
    floor = calibration.cameras[calibration.reference].quality
    if "floor_up_from" in floor:
        console.print(
            f"world: z up from the {floor['floor_up_from']} ({floor['floor_points']} resting-foot "
            f"samples, {floor['floor_residual_cm']:.1f} cm from their plane), the reference "
            f"camera tilted {floor['floor_tilt_deg']:.1f} deg from level",
            highlight=False,
        )
        if floor.get("floor_doubtful"):
            console.print(f"[yellow]floor doubtful: {floor['floor_doubtful']}[/]", highlight=False)


def _fit(residual: float | str | None) -> str:
    """The rigid-fit residual at the chosen lag, in cm."""
    return "-" if residual in (None, "inf") else f"{100 * float(residual):.1f}"


def _runner_up(quality: dict) -> str:
    """The best other lag and how many times worse the skeletons fit there."""
    lag = quality.get("lag_fit_runner_up_lag")
    margin = quality.get("lag_fit_margin")
    if lag is None or margin is None:
        return "-"
    shown = "inf" if margin == "inf" else f"{float(margin):.1f}"
    return f"{lag:+.2f} x{shown}"


def write_plots(result: CalibrationResult, folder: Path) -> list[Path]:
    """Correlation curves per pair, lag over time, residuals per joint (PNG files)."""
    import matplotlib as mpl

    mpl.use("Agg")
    folder.mkdir(parents=True, exist_ok=True)
    return [
        _plot_correlation(result, folder / "correlation.png"),
        _plot_offsets(result, folder / "offset_over_time.png"),
        _plot_joint_residuals(result, folder / "joint_residuals.png"),
    ]


def _plot_correlation(result: CalibrationResult, path: Path) -> Path:
    import matplotlib.pyplot as plt

    usable = [p for p in result.sync_pairs if p.ok and len(p.lags)]
    fig, axes = plt.subplots(len(usable) or 1, 1, figsize=(8, 2.6 * max(1, len(usable))),
                             squeeze=False)  # fmt: skip
    for ax, pair in zip(axes[:, 0], usable, strict=False):
        ax.plot(pair.lags, pair.correlation, lw=1)
        ax.axvline(pair.offset, color="C3", lw=1, label=f"lag {pair.offset:+.4f} s")
        ax.set_title(f"{pair.camera_a}-{pair.camera_b}: pooled signature correlation")
        ax.set_xlabel("lag t_a - t_b (s)")
        ax.set_ylabel("correlation")
        ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_offsets(result: CalibrationResult, path: Path) -> Path:
    import matplotlib.pyplot as plt
    import numpy as np

    clocks = result.clocks
    fig, ax = plt.subplots(figsize=(8, 4))
    for pair in result.sync_pairs:
        a, b = clocks[pair.camera_a], clocks[pair.camera_b]
        if not (pair.ok and len(pair.windows) and a.ok and b.ok):
            continue
        t_b, tau = pair.windows[:, 0], pair.windows[:, 1]
        grid = np.linspace(t_b.min(), t_b.max(), 50)
        model = np.asarray(a.from_reference(b.to_reference(grid))) - grid
        centre, start = float(np.median(tau)), float(t_b.min())
        line = ax.plot(grid - start, 1e3 * (model - centre), lw=1)[0]
        ax.plot(t_b - start, 1e3 * (tau - centre), "o", color=line.get_color(),
                label=f"{pair.camera_a}-{pair.camera_b} (lag {centre:+.4f} s)")  # fmt: skip
    ax.set_xlabel("time in the recording (s)")
    ax.set_ylabel("lag minus its median (ms)")
    ax.set_title("lag per window (dots) and the solved clocks (lines)")
    ax.legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plot_joint_residuals(result: CalibrationResult, path: Path) -> Path:
    import matplotlib.pyplot as plt

    cameras = {
        c: cal.quality["joint_residual_m"]
        for c, cal in result.calibration.cameras.items()
        if cal.quality.get("joint_residual_m")
    }
    fig, axes = plt.subplots(len(cameras) or 1, 1, figsize=(10, 2.8 * max(1, len(cameras))),
                             squeeze=False)  # fmt: skip
    for ax, (camera, per_joint) in zip(axes[:, 0], cameras.items(), strict=False):
        names = list(per_joint)
        ax.bar(range(len(names)), [100 * per_joint[n] for n in names])
        ax.set_xticks(range(len(names)), names, rotation=70, fontsize=7)
        ax.set_ylabel("RMS residual (cm)")
        ax.set_title(f"{camera}: joint residuals of inlier correspondences")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
