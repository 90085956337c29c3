"""The gravity-aligned world's accuracy: up and the floor against the simulator's truth.

For each simulator condition (``hiros_sim.presets``) and seed, the recording is calibrated as
``hiros calibrate`` does (default settings, the world found from the people) and the world is
compared with the simulator's, which is z up with the floor at z = 0
(``hiros_eval.calibration.compare_world``): the angle between the two z axes, and the height of
the true floor in the estimated world below where the people walked (their mean pelvis
position). Targets: up within 1 deg, the floor within 2 cm.

Every run also says whether the calibration's own figures called its floor doubtful
(``floor_doubtful`` in the reference camera's quality): a run off target that was not called
doubtful is *silently off*.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hiros_bench.seeds import seeds_text
from hiros_calib.calibrator import Calibrator, CalibratorParams
from hiros_core.errors import CalibrationError, ConfigError
from hiros_eval.calibration import compare_world
from hiros_sim import simulate
from hiros_sim.presets import PRESETS, preset_params

__all__ = ["ROWS", "TARGETS", "run"]

ROWS = ("default", "one-person", "15hz", "repeated-motion", "noisy-sdk", "two-cameras-45")
"""The simulator presets measured, in order."""

TARGETS = (1.0, 2.0)
"""Up within this (deg) and the floor within this (cm) of the truth."""


@dataclass
class _Row:
    up_deg: list[float] = field(default_factory=list)
    floor_cm: list[float] = field(default_factory=list)
    seeds: list[int] = field(default_factory=list)
    flags: list[str] = field(default_factory=list)
    """Per run, ``?`` when called doubtful, ``!`` when silently off, else empty."""
    doubtful: int = 0
    silently_off: int = 0
    failures: list[str] = field(default_factory=list)


def one_run(preset: str, seed: int, duration: float, row: _Row) -> None:
    """Simulate one seed of ``preset``, calibrate it with the defaults, judge its world."""
    result = simulate(preset_params(preset, seed=seed, duration=duration))
    try:
        estimate = Calibrator(CalibratorParams(reference="k01")).calibrate(
            result.camera_groups, arrival_ns=result.receive_ns
        )
    except CalibrationError as exc:
        row.failures.append(f"seed {seed}: {exc}")
        return
    quality = estimate.cameras[estimate.reference].quality
    if "floor_up_from" not in quality:
        row.failures.append(f"seed {seed}: no floor found")
        return
    people = np.nanmean(result.truth.positions[:, :, 0, :2], axis=(0, 1))
    accuracy = compare_world(estimate, result.calibration, people)
    row.up_deg.append(accuracy.up_error_deg)
    row.floor_cm.append(accuracy.floor_error_cm)
    doubtful = bool(quality.get("floor_doubtful"))
    off = accuracy.up_error_deg > TARGETS[0] or abs(accuracy.floor_error_cm) > TARGETS[1]
    row.doubtful += doubtful
    row.silently_off += off and not doubtful
    row.seeds.append(seed)
    row.flags.append("?" if doubtful else "!" if off else "")


def _row_line(name: str, row: _Row) -> str:
    if not row.up_deg:
        return f"{name:<16s} no world: {'; '.join(row.failures)}"
    up, floor = np.array(row.up_deg), np.array(row.floor_cm)
    up_cell = f"{np.median(up):.2f}/{up.max():.2f}"
    range_cell = f"{floor.min():+.1f}..{floor.max():+.1f}"
    return (
        f"{name:<16s} {len(up):4d} {up_cell:>11s} {np.median(floor):+8.1f} {range_cell:>12s} "
        f"{row.doubtful:5d} {row.silently_off:7d}   "
        + " ".join(
            f"{seed}:{u:.2f}/{f:+.1f}{flag}"
            for seed, u, f, flag in zip(row.seeds, up, floor, row.flags, strict=True)
        )
    )


def run(
    console,  # noqa: ANN001 - rich Console
    *,
    quick: bool = False,
    seeds: Sequence[int] | None = None,
    duration: float | None = None,
    rows: Sequence[str] = ROWS,
) -> list[str]:
    """Run every row over the seeds; print the table and return its lines."""
    seeds = tuple(seeds) if seeds is not None else tuple(range(2 if quick else 5))
    duration = duration or (30.0 if quick else 60.0)
    lines = [
        f"gravity-aligned world against the simulator's truth: default settings, "
        f"{duration:.0f} s, seeds {seeds_text(seeds)}; targets: up <= {TARGETS[0]:g} deg, "
        f"floor within {TARGETS[1]:g} cm (below the people)",
        f"{'condition':<16s} {'runs':>4s} {'up deg':>11s} {'floor cm':>8s} {'range':>12s} "
        f"{'doubt':>5s} {'silent':>7s}   per run seed:up/floor",
    ]
    for name in rows:
        row = _Row()
        try:
            for seed in seeds:
                with console.status(f"bench world: {name}, seed {seed}"):
                    one_run(name, seed, duration, row)
        except ConfigError as exc:  # a preset whose clips are not on this machine
            lines.append(f"{name:<16s} skipped: {exc}")
            continue
        lines.append(_row_line(name, row))
        lines.extend(f"  failed: {failure}" for failure in row.failures)
    lines.append(
        "up deg: median/max angle between the estimated and the true z; floor cm: median and "
        "range of the true floor's height in the estimated world (negative: estimated floor "
        "too high); doubt: runs whose calibration called its floor doubtful (marked ?); "
        "silent: runs off target and not called doubtful (marked !)"
    )
    lines.append(f"conditions: {', '.join(f'{r} = {PRESETS[r].description}' for r in rows)}")
    for line in lines:
        console.print(line, highlight=False)
    return lines
