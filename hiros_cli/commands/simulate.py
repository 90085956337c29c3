"""Make a semi-synthetic multi-camera recording from real motion capture, with its truth.

People from BVH mocap clips (by default the CMU and Xsens clips bundled in hiros_data) walk in a
room watched by simulated Azure Kinect cameras, each with its own pose, clock offset, drift and
frame rate. Each camera reports what its body-tracking SDK would: noisy joints (fitted to a real
Azure Kinect vs Xsens take), occluded joints with low confidence, front/back flips, left/right
swaps, ghost bodies and changing body ids.

DIR receives recording.mcap (Azure-driver topics /<cam>/body_tracking_data) with rosbag2's
metadata.yaml (DIR itself opens as a bag: hiros calibrate DIR, ros2 bag info DIR), truth.npz
(world joints of each person at the mocap rate) and calibration.yaml (true camera poses and
clocks).

Examples:
  hiros simulate --out sim                      # 3 cameras, 2 people, 60 s
  hiros simulate --out sim --setup facing --people 1 --duration 20 --no-noise
  hiros simulate --out sim --bvh my_take.bvh --cameras 4 --setup ring --rate 15
  hiros simulate --sample --out sample          # the demo's recording
  hiros simulate --preset noisy-sdk --seed 3 --out sim   # a robustness condition (see --preset)
  hiros simulate --fit-noise                    # fit the noise model to the real take and
                                                # compare the simulator's errors with it

"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from hiros_core.errors import ConfigError
from hiros_core.outputs import check_output, only_holds, staged_output

HELP = "semi-synthetic multi-camera recording from real mocap, with the truth"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hiros simulate``."""
    parser.add_argument(
        "--out",
        type=Path,
        help="output folder: new or empty (it appears only when the simulation is written)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out, only if it holds nothing but an earlier simulation's "
        "files (recording.mcap, metadata.yaml, truth.npz, calibration.yaml)",
    )
    from hiros_sim.presets import PRESETS

    width = max(map(len, PRESETS))
    parser.epilog = "presets (--preset NAME, hiros_sim.PRESETS):\n" + "\n".join(
        f"  {name:<{width}}  {preset.description}" for name, preset in PRESETS.items()
    )
    parser.add_argument(
        "--preset",
        choices=list(PRESETS),
        metavar="NAME",
        help="a robustness condition, listed below; the options given apply on top of it",
    )
    parser.add_argument("--cameras", type=int, help="number of cameras (default 3)")
    parser.add_argument(
        "--setup",
        help="room (default; a facing pair plus others), facing, ring, pair (two cameras "
        "40-50 deg apart, 1.3-1.5 m baseline), or a calibration YAML",
    )
    parser.add_argument("--people", type=int, help="1..6 people (default 2)")
    parser.add_argument("--duration", type=float, help="seconds (default 60)")
    parser.add_argument("--seed", type=int, help="random seed (default 0)")
    parser.add_argument(
        "--rate", type=float, help="camera frame rate in Hz: 30, 15, 5 (default 30)"
    )
    parser.add_argument("--bvh", nargs="+", type=Path, help="BVH clips (default: hiros_data)")
    parser.add_argument(
        "--no-noise", action="store_true", help="perfect cameras (clocks and poses still differ)"
    )
    parser.add_argument(
        "--max-offset", type=float, help="largest camera clock offset in seconds (default 3)"
    )
    parser.add_argument("--drift-ppm", type=float, help="clock drift spread, ppm (default 30)")
    parser.add_argument("--ghost-rate", type=float, help="ghost bodies per camera per minute")
    parser.add_argument("--swap-rate", type=float, help="left/right swaps per person per minute")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KNOB=VALUE",
        help="any SimParams field, e.g. --set flip_rate=10 --set fov=90,70 (repeatable)",
    )
    parser.add_argument(
        "--sample", action="store_true", help="use the demo's parameters (hiros_sim.sample_params)"
    )
    parser.add_argument(
        "--truth-only", action="store_true", help="write truth.npz and calibration.yaml only"
    )
    parser.add_argument(
        "--fit-noise",
        action="store_true",
        help="fit the noise model to the real Azure Kinect vs Xsens take and print the figures",
    )


def _params(args: argparse.Namespace):  # noqa: ANN202 - SimParams, imported lazily
    """The preset (or the demo's parameters, or the defaults), then each option given."""
    from hiros_sim import SimParams, preset_params, sample_params

    if args.sample and args.preset:
        msg = "give --sample or --preset, not both"
        raise ConfigError(msg)
    params = sample_params() if args.sample else SimParams()
    overrides = {
        "n_cameras": args.cameras,
        "setup": args.setup,
        "n_people": args.people,
        "duration": args.duration,
        "seed": args.seed,
        "rate": args.rate,
        "bvh_files": tuple(str(p) for p in args.bvh) if args.bvh else None,
        "noise": False if args.no_noise else None,
        "max_time_offset": args.max_offset,
        "drift_ppm": args.drift_ppm,
        "ghost_rate": args.ghost_rate,
        "swap_rate": args.swap_rate,
    }
    overrides = {k: v for k, v in overrides.items() if v is not None}
    overrides.update(_knobs(params, args.set))
    if args.preset:
        return preset_params(args.preset, **overrides)
    return replace(params, **overrides)


def _knobs(params: object, settings: list[str]) -> dict[str, object]:
    """``KNOB=VALUE`` strings to typed SimParams overrides (type of the field's default)."""
    out: dict[str, object] = {}
    for setting in settings:
        name, sep, text = setting.partition("=")
        name = name.strip().replace("-", "_")
        if not sep or not hasattr(params, name):
            msg = f"--set {setting!r}: expected KNOB=VALUE with a SimParams field as KNOB"
            raise ConfigError(msg)
        default = getattr(params, name)
        try:
            if isinstance(default, bool):
                value: object = text.strip().lower() in {"1", "true", "yes", "on"}
            elif isinstance(default, tuple):
                value = tuple(type(d)(v) for d, v in zip(default, text.split(","), strict=True))
            else:
                value = type(default)(text)
        except (TypeError, ValueError) as exc:
            msg = f"--set {setting!r}: {exc}"
            raise ConfigError(msg) from exc
        out[name] = value
    return out


def _fit_noise() -> int:
    from rich.console import Console
    from rich.table import Table

    from hiros_sim.fit import fit_noise, simulated_errors

    fit = fit_noise()
    console = Console()
    table = Table(title="Azure Kinect vs Xsens (UNIPD-BPE sbj01_bend1, camera k01)")
    table.add_column("figure")
    table.add_column("value", justify="right")
    for name, value in fit.figures():
        table.add_row(name, value)
    console.print(table)
    # the same figures on the simulator, in the take's situation (hiros_sim.fit.simulated_errors)
    simulated = simulated_errors()
    table = Table(title="Coherence of the errors: the take vs the simulator (one camera, 3.3 m)")
    for column in ("figure", "real take", "simulator"):
        table.add_column(column, justify="left" if column == "figure" else "right")
    for (name, real), (_, sim) in zip(fit.skeleton.figures(), simulated.figures(), strict=True):
        table.add_row(name, real, sim)
    console.print(table)
    return 0


def _check_out(args: argparse.Namespace) -> bool:
    """Refuse an --out holding anything but an earlier simulation, or one without --force.

    An empty folder is used as it is; a folder that holds an input (--bvh, --setup) never.
    Returns whether an existing --out is to be replaced.
    """
    from hiros_sim.output import SIMULATION_FILES

    out: Path = args.out
    setup = Path(args.setup) if args.setup else None
    inputs = [*(args.bvh or ()), *([setup] if setup and setup.is_file() else [])]
    empty = out.is_dir() and not out.is_symlink() and not any(out.iterdir())
    check_output(
        out,
        inputs=inputs,
        force=args.force or empty,
        ours=lambda path: only_holds(path, SIMULATION_FILES),
        what="simulation folder",
    )
    return args.force or empty


def run(args: argparse.Namespace) -> int:
    """Simulate and write the folder; prints a summary."""
    if args.fit_noise:
        return _fit_noise()
    if args.out is None:
        msg = "give an output folder with --out DIR (or use --fit-noise)"
        raise ConfigError(msg)
    import numpy as np
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Table

    from hiros_sim import save_truth, simulate, write_recording

    replacing = _check_out(args)
    params = _params(args)
    console = Console(stderr=True)
    with Progress(
        TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(), console=console
    ) as bar:
        task = bar.add_task("simulating", total=1)

        def progress(step: str, done: int, total: int) -> None:
            bar.update(task, description=f"simulating: {step}", completed=done, total=total)

        result = simulate(params, progress=progress)
        bar.update(task, description="writing")
        with staged_output(args.out, replace=replacing) as staged:
            if args.truth_only:
                save_truth(result, staged)
            else:
                write_recording(result, staged)
        bar.update(task, description="done")

    table = Table(title=f"hiros simulate -> {args.out}")
    for column in ("camera", "messages", "bodies/frame", "SDK ids", "offset s", "drift ppm"):
        table.add_column(column, justify="right")
    for name, groups in result.camera_groups.items():
        cam = result.calibration.cameras[name]
        bodies = np.mean([len(g.skeletons) for g in groups]) if groups else 0.0
        ids = len({s.id for g in groups for s in g.skeletons})
        table.add_row(
            name,
            str(len(groups)),
            f"{bodies:.2f}",
            str(ids),
            f"{cam.time_offset:+.3f}",
            f"{cam.drift * 1e6:+.1f}",
        )
    out = Console()
    out.print(table)
    truth = result.truth
    out.print(
        f"{len(truth.person_ids)} people ({', '.join(truth.clip_names)}), "
        f"{truth.times[-1] - truth.times[0]:.1f} s of truth at {truth.rate:.0f} Hz, seed "
        f"{params.seed}, noise {'on' if params.noise else 'off'}"
    )
    for path in sorted(Path(args.out).iterdir()):
        out.print(f"  {path}  {path.stat().st_size / 1e6:.2f} MB")
    return 0
