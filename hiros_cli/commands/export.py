"""Export a stage's people for biomechanics: joint positions (CSV and OpenSim .trc) and angles.

For each person (skeleton id) of the chosen stage in a `hiros run` output, writes
person_<id>_positions.csv (metres), person_<id>.trc (OpenSim marker file, Y up) and
person_<id>_angles.csv (knee, hip, elbow, shoulder flexion in degrees).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from hiros_cli.progress import print_warnings
from hiros_core.errors import RecordingError

HELP = "per-person joint positions (CSV, OpenSim .trc) and joint angles (CSV)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros export OUT.mcap --out DIR [--stage filter]``."""
    parser.add_argument("output", type=Path, help="the .mcap written by `hiros run`")
    parser.add_argument("--out", type=Path, required=True, help="folder for the exported files")
    parser.add_argument(
        "--stage", default="filter", choices=["tracker", "merger", "optimizer", "filter"]
    )
    parser.add_argument(
        "--min-frames", type=int, default=30, help="skip people seen in fewer frames"
    )


def run(args: argparse.Namespace) -> int:
    """Read the stage, write three files per person."""
    from hiros_core.outputs import refuse_inputs, staged_files
    from hiros_eval.export import person_series, write_angles_csv, write_positions_csv, write_trc
    from hiros_eval.run import read_run

    refuse_inputs(args.out, [args.output])
    console = Console()
    problems: list[str] = []
    outputs, _ = read_run(args.output, problems)
    print_warnings(console, problems)
    if not outputs[args.stage]:
        held = [stage for stage, groups in outputs.items() if groups]
        msg = (
            f"{args.output} holds no /hiros/{args.stage} output"
            + (f"; it holds {', '.join(held)}: choose one with --stage" if held else "")
            + " (`hiros run --write` picks what a run writes)"
        )
        raise RecordingError(msg)
    people = person_series(outputs[args.stage])
    args.out.mkdir(parents=True, exist_ok=True)
    written = 0
    for person, (times, positions) in sorted(people.items()):
        if len(times) < args.min_frames:
            continue
        with staged_files(args.out) as staging:  # each file whole in args.out, or absent
            write_positions_csv(staging / f"person_{person}_positions.csv", times, positions)
            write_trc(staging / f"person_{person}.trc", times, positions)
            write_angles_csv(staging / f"person_{person}_angles.csv", times, positions)
        console.print(f"person {person}: {len(times)} frames, {times[-1]:.1f} s")
        written += 1
    console.print(f"{written} people exported from /hiros/{args.stage} to {args.out}")
    return 0
