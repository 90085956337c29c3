"""Speed figures, each against a baseline measured in the same run.

Suites:
  codec      our CDR codec vs rclpy message objects (SkeletonGroup and MarkerArray, 4 x 32)
  io         conversion and bridge throughput (messages per second)
  calib      calibration accuracy over simulator seeds: clocks vs Pose2Sim's lag, poses vs
             Eichler et al.'s RANSAC + Kabsch alone, on the same recordings; with --matrix
             the robustness matrix: one row per simulator condition (host clocks, repeated
             motion, one person, two cameras, noisy SDK, 15 Hz, drops, four people crossing
             and one person walking before the pair on host clocks, exercise on one spot,
             the same timed with a walk's poses, all), default settings
  world      the gravity-aligned world against the simulator's truth: up (deg) and floor
             (cm) per condition (default, one person, 15 Hz, repeated motion, noisy SDK,
             two cameras), default settings, and whether a miss was called doubtful
  tracking   tracker and merger time per frame for 1-4 people vs Hi-ROS's published figures,
             and a norfair tracker on the same detections
  body       optimizer and filter time per frame vs Hi-ROS, filter lag/jitter vs One-Euro
  pipeline   offline throughput and end-to-end DDS latency (separate nodes and composed)
  robust     the stages under the simulator's conditions (noisy SDK, one person, 45 deg pair,
             15 Hz, drops, repeated motion, four crossing, exercise on one spot), with the true
             calibration and with --calibration auto: MPJPE per stage, ratio to the best
             oracle-labelled camera, switches, limb CV, acceptance, mirrored share
  soak       the live pipeline and calib nodes fed a looping recording for --minutes (30):
             each node's memory over time, latency percentiles, whether the output stopped
             (not run without being named, nor in CI)
Without a suite, all of them but soak run in turn. Timings are best-of-N batches; the
machine is shared, so read ratios, not absolute times.

The calib suite also takes simulator settings and a recording length, to see what limits the
accuracy, e.g. ``hiros bench calib --sim oblique_gain=0 --duration 180`` (SimParams names,
as in ``hiros simulate``).
"""

from __future__ import annotations

import argparse
import importlib
import inspect

from rich.console import Console

from hiros_bench import SuiteFailedError
from hiros_bench.seeds import parse_seeds

HELP = "speed and accuracy benchmarks, each beside a baseline run alongside"
SUITES = ("codec", "io", "calib", "world", "tracking", "body", "pipeline", "robust", "soak")
DEFAULT_SUITES = SUITES[:-1]
"""Run when no suite is named: all but the half-hour soak."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros bench [SUITE ...] [--quick]``."""
    parser.add_argument(
        "suites", nargs="*", metavar="SUITE", help=f"any of {', '.join(SUITES)}; default: all"
    )
    parser.add_argument("--quick", action="store_true", help="fewer seeds and repeats")
    parser.add_argument(
        "--sim",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="calib: a simulator setting on top of every setup (SimParams name; repeatable)",
    )
    parser.add_argument(
        "--duration", type=float, help="calib: seconds per simulated recording (default 60)"
    )
    parser.add_argument(
        "--seeds",
        metavar="LIST",
        help="calib, world, robust: the simulator seeds to run, e.g. 0-3,7 (default: each "
        "suite's own; robust with several prints each condition's mean, then each seed)",
    )
    parser.add_argument(
        "--minutes", type=float, help="soak: minutes of feeding the nodes (default 30; quick: 3)"
    )
    parser.add_argument(
        "--matrix",
        action="store_true",
        help="calib: the robustness matrix instead (one row per simulator condition, default "
        "settings: success, refusals, flags, silently wrong results, errors; then the real "
        "KinectMultiTrack sessions)",
    )


def _sim_overrides(pairs: list[str]) -> dict[str, object]:
    """``KEY=VALUE`` strings as SimParams values of each field's own type."""
    import dataclasses

    from hiros_core.errors import ConfigError
    from hiros_sim import SimParams

    names = {f.name for f in dataclasses.fields(SimParams)}
    defaults = SimParams()
    out: dict[str, object] = {}
    for pair in pairs:
        key, _, text = pair.partition("=")
        if key not in names or not text:
            msg = f"--sim {pair!r}: expected KEY=VALUE with KEY one of SimParams' settings"
            raise ConfigError(msg)
        default = getattr(defaults, key)
        if isinstance(default, bool):
            out[key] = text.lower() in ("1", "true", "yes", "on")
        elif isinstance(default, (int, float)):
            try:
                out[key] = type(default)(float(text)) if isinstance(default, float) else int(text)
            except ValueError:
                msg = f"--sim {pair!r}: {key} takes a number"
                raise ConfigError(msg) from None
        else:
            msg = f"--sim {pair!r}: only number and on/off settings can be set here"
            raise ConfigError(msg)
    return out


def run(args: argparse.Namespace) -> int:
    """Run each suite's ``run(console, quick=...)`` and print its table."""
    console = Console(soft_wrap=True)  # table rows stay whole lines when piped to a file
    unknown = sorted(set(args.suites) - set(SUITES))
    if unknown:
        console.print(f"hiros bench: unknown suite(s) {unknown}; choose from {list(SUITES)}")
        return 2
    sim = _sim_overrides(args.sim)  # a mistyped setting fails before anything runs
    seeds = parse_seeds(args.seeds) if args.seeds else None
    failed = []
    for suite in args.suites or DEFAULT_SUITES:
        try:
            module = importlib.import_module(f"hiros_bench.{suite}")
        except ModuleNotFoundError as exc:
            console.print(f"[yellow]bench {suite}: not available ({exc.name} missing)[/]")
            failed.append(suite)
            continue
        console.rule(f"hiros bench {suite}")
        options: dict[str, object] = {"quick": args.quick}
        if seeds is not None:
            options["seeds"] = seeds
        if suite == "calib" and args.matrix:
            module = importlib.import_module("hiros_bench.calib_matrix")
            options.update(duration=args.duration)
        elif suite in ("calib", "world"):
            options.update(sim=sim, duration=args.duration)
        elif suite == "soak":
            options.update(minutes=args.minutes)
        accepted = inspect.signature(module.run).parameters
        try:
            module.run(console, **{k: v for k, v in options.items() if k in accepted})
        except SuiteFailedError as exc:
            console.print(f"[red]bench {suite}: {exc}[/]")
            failed.append(suite)
    return 1 if failed else 0
