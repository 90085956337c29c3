"""Convert other body-tracking files into a recording (single .mcap file or rosbag2 folder).

Formats (guessed from the file when --format is not given):
  k4abt-json      Azure Kinect Body Tracking SDK offline processor JSON (one camera, --camera)
  unipd-csv       UNIPD-BPE <take>KinectPos.csv (+ the KinectQuat.csv beside it; one camera)
  multitrack-csv  KinectMultiTrack CSV: one camera per Kinect_Id, device clock kept (Kinect v2)
  csv             the generic CSV, one row per joint:
                    camera,stamp_ns,body_id,joint,x,y,z[,qx,qy,qz,qw][,confidence]
                  (stamp in integer ns, or a `stamp` column in seconds; joint = layout joint
                  name or index, --layout; metres; empty or NA = unknown)

The recording carries /<camera>/body_tracking_data (visualization_msgs/MarkerArray as the
Azure Kinect ROS driver publishes it), or /<camera>/skeletons (SkeletonGroup) with
--skeleton-groups. Stamps are the file's camera clocks, unchanged.

Examples:
  hiros convert sbj01_bend1KinectPos.csv --out bend.mcap
  hiros convert Study_10_Kinect_1_Time_4_10_14_PM.csv --out study10 --skeleton-groups
  hiros convert body.json --format k4abt-json --camera k02 --out k02.mcap

"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

HELP = "other formats (k4abt JSON, UNIPD / KinectMultiTrack / generic CSV) into a recording"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hiros convert``."""
    from hiros_convert import FORMATS

    parser.add_argument("input", type=Path, metavar="IN", help="file to convert")
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        help="new recording: NAME.mcap or a folder (appears only once it is complete)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out, only if it is a recording hiros wrote (never the input)",
    )
    parser.add_argument("--format", choices=FORMATS, help="input format (default: guessed)")
    parser.add_argument(
        "--skeleton-groups",
        action="store_true",
        help="write SkeletonGroup topics /<cam>/skeletons instead of driver MarkerArrays",
    )
    parser.add_argument("--camera", help="camera name for one-camera formats (default k01)")
    parser.add_argument(
        "--layout", help="layout of the generic CSV: azure_kinect (default), kinect_v2 or a YAML"
    )


def run(args: argparse.Namespace) -> int:
    """Convert and print what was written and what was dropped."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn
    from rich.table import Table

    from hiros_convert import convert
    from hiros_core.outputs import check_output, is_hiros_recording, staged_output

    layout = [Path(args.layout)] if args.layout and Path(args.layout).is_file() else []
    check_output(args.out, inputs=[args.input, *layout], force=args.force,
                 ours=is_hiros_recording, what="recording")  # fmt: skip
    console = Console()
    drops: Counter[str] = Counter()
    with (
        Progress(
            TextColumn("converting"), BarColumn(), MofNCompleteColumn(), console=console
        ) as bar,
        staged_output(args.out, replace=args.force) as staged,
    ):
        task = bar.add_task("convert", total=None)

        def progress(done: int, total: int) -> None:
            if done % 200 == 0 or done == total:
                bar.update(task, completed=done, total=total)

        counts = convert(
            args.input,
            staged,
            fmt=args.format,
            skeleton_groups=args.skeleton_groups,
            camera=args.camera,
            layout=args.layout,
            drops=drops,
            progress=progress,
        )
    table = Table(title=f"{args.out}")
    table.add_column("topic")
    table.add_column("messages", justify="right")
    for topic, count in sorted(counts.items()):
        table.add_row(topic, str(count))
    console.print(table)
    dropped = {reason: n for reason, n in sorted(drops.items()) if n}
    if dropped:
        console.print("dropped: " + ", ".join(f"{reason} {n}" for reason, n in dropped.items()))
    return 0
