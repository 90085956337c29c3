"""Speed figures, each against a baseline measured in the same run.

Suites:
  codec      our CDR codec vs rclpy message objects (SkeletonGroup and MarkerArray, 4 x 32)
  io         conversion and bridge throughput (messages per second)
  calib      calibration accuracy over simulator seeds vs the Pose2Sim-style baseline
  tracking   tracker and merger time per frame for 1-4 people vs Hi-ROS's published figures,
             and a norfair tracker on the same detections
  body       optimizer and filter time per frame vs Hi-ROS, filter lag/jitter vs One-Euro
  pipeline   offline throughput and end-to-end DDS latency (separate nodes and composed)
Without a suite, all of them run in turn. Timings are best-of-N batches; the machine is shared,
so read ratios, not absolute times.
"""

from __future__ import annotations

import argparse
import importlib
import inspect

from rich.console import Console

HELP = "speed and accuracy benchmarks, each beside a baseline run alongside"
SUITES = ("codec", "io", "calib", "tracking", "body", "pipeline")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros bench [SUITE ...] [--quick]``."""
    parser.add_argument(
        "suites", nargs="*", metavar="SUITE", help=f"any of {', '.join(SUITES)}; default: all"
    )
    parser.add_argument("--quick", action="store_true", help="fewer seeds and repeats")


def run(args: argparse.Namespace) -> int:
    """Run each suite's ``run(console, quick=...)`` and print its table."""
    console = Console()
    unknown = sorted(set(args.suites) - set(SUITES))
    if unknown:
        console.print(f"hiros bench: unknown suite(s) {unknown}; choose from {list(SUITES)}")
        return 2
    failed = []
    for suite in args.suites or SUITES:
        try:
            module = importlib.import_module(f"hiros_bench.{suite}")
        except ModuleNotFoundError as exc:
            console.print(f"[yellow]bench {suite}: not available ({exc.name} missing)[/]")
            failed.append(suite)
            continue
        console.rule(f"hiros bench {suite}")
        takes_quick = "quick" in inspect.signature(module.run).parameters
        module.run(console, quick=args.quick) if takes_quick else module.run(console)
    return 1 if failed else 0
