"""The stages under the simulator's conditions: accuracy, identities, limb lengths, speed.

One row per condition (``hiros_sim.PRESETS``: default, noisier SDK, one person, two cameras
45° apart, 15 Hz, 5 % drops, repeated Bandai-Namco motion, four people crossing, one person
exercising and turning on one spot before two cameras), each a
simulated recording run through tracker -> merger -> optimizer -> filter with default settings,
first with the *true* calibration, so that only the stages are judged, then with the one
``hiros calibrate`` finds in the recording (``--calibration auto``; the output is moved into
the truth's frame with the true pose of the reference camera, so the calibration's own error
counts). The merger outputs at 30 Hz, as in ``hiros run``. Columns:

* MPJPE of each stage's people (``hiros_eval.run.evaluate_run``);
* the filter's MPJPE as a fraction of the best single camera's with its left/right labels
  corrected by an oracle (``camera_mpjpe(oracle_sides=True)``: its noise and bias only);
* identity switches of the filter's output;
* limb-length CV (upper arms, forearms, thighs, shanks) of the filter's output after each
  person's acceptance, and the longest acceptance time (``Optimizer.people``);
* the change of the joint-angle RMSE from the tracker to the filter;
* the share of the filter's skeletons that are mirrored (left for right) against the truth;
* camera frames per second through the four stages (this process, wall clock).

The repeated-motion row needs the shared data (``hiros_sim.shared``); it is left out, with the
reason, where that is absent, as is a row whose recording the calibration refuses.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from hiros_bench.seeds import seeds_text
from hiros_calib.calibrator import Calibrator, CalibratorParams
from hiros_core.errors import CalibrationError, ConfigError
from hiros_core.model import SkeletonGroup
from hiros_eval.body import limb_length_cv
from hiros_eval.run import align_to_truth, evaluate_run
from hiros_eval.tracking import (
    arrival_order,
    camera_mpjpe,
    mirrored_output,
)
from hiros_optimizer import Optimizer
from hiros_optimizer.learning import limb_links
from hiros_pipeline import STAGES, Pipeline, PipelineParams

__all__ = ["CONDITIONS", "Row", "mean_row", "measure", "run"]

CONDITIONS = (
    "default", "noisy-sdk", "one-person", "two-cameras-45", "15hz", "drops-5", "repeated-motion",
    "crossing-4", "exercise-on-spot",
)  # fmt: skip
"""The rows, by ``hiros_sim.PRESETS`` name."""
MERGE_RATE = 30.0
"""Hz, the merger's output rate (``hiros run``'s offline default)."""


@dataclass
class Row:
    """The figures of one condition (distances in m, times in s)."""

    condition: str
    mpjpe: dict[str, float]
    best_camera: float
    switches: int
    limb_cv: float
    accepted: int
    people: int
    acceptance: float
    angle_change: float
    mirrored: float
    fps: float
    flagged: tuple[str, ...] = ()
    """Cameras the calibration flagged (``auto`` only): ``hiros run --calibration auto`` stops
    there; the figures are what ``--accept-flagged`` runs on."""
    mirror_run: float = float("nan")
    """Seconds of the longest unbroken run of one person's mirrored output
    (``MirroredOutput.longest_run_s``): a flicker of a frame, or a person the wrong way round."""

    @property
    def ratio(self) -> float:
        """The filter's MPJPE over the best oracle-labelled camera's."""
        return self.mpjpe.get("filter", float("nan")) / self.best_camera

    def line(self, label: str | None = None, note: str | None = None) -> str:
        """The row as printed under :data:`HEADER`, named ``label`` (default: its condition).

        ``note`` replaces what is said after the figures (default: a flagged calibration).
        """
        stages = " ".join(f"{self.mpjpe.get(stage, float('nan')) * 1e3:6.1f}" for stage in STAGES)
        if note is None:
            note = (
                f"calibration flagged ({', '.join(self.flagged)}): run stops"
                if self.flagged
                else ""
            )
        return (
            f"{label or self.condition:16s} {stages} {self.best_camera * 1e3:6.1f} "
            f"{self.ratio:5.2f} {self.switches:3d} {self.limb_cv * 100:6.2f} "
            f"{self.accepted:2d}/{self.people:<2d} {self.acceptance:6.1f} "
            f"{self.angle_change * 100:+6.1f} {self.mirrored * 100:6.2f} {self.mirror_run:5.1f} "
            f"{self.fps:6.0f}" + (f"  {note}" if note else "")
        )


def mean_row(rows: Sequence[Row]) -> Row:
    """One condition's rows over several seeds as one: means, counts summed, the worst time.

    MPJPEs, the best camera's, limb CV, angle change, mirrored share and speed are means over
    the seeds (the ratio is then that of the means); switches and people are summed and the
    acceptance time is the longest; the cameras any seed's calibration flagged are kept.
    """

    def mean(values: list[float]) -> float:
        finite = [v for v in values if np.isfinite(v)]
        return float(np.mean(finite)) if finite else float("nan")

    stages = {stage for row in rows for stage in row.mpjpe}
    return Row(
        condition=rows[0].condition,
        mpjpe={stage: mean([r.mpjpe.get(stage, np.nan) for r in rows]) for stage in stages},
        best_camera=mean([r.best_camera for r in rows]),
        switches=sum(r.switches for r in rows),
        limb_cv=mean([r.limb_cv for r in rows]),
        accepted=sum(r.accepted for r in rows),
        people=sum(r.people for r in rows),
        acceptance=max((r.acceptance for r in rows if np.isfinite(r.acceptance)), default=np.nan),
        angle_change=mean([r.angle_change for r in rows]),
        mirrored=mean([r.mirrored for r in rows]),
        fps=mean([r.fps for r in rows]),
        flagged=tuple(sorted({c for r in rows for c in r.flagged})),
        mirror_run=max((r.mirror_run for r in rows if np.isfinite(r.mirror_run)), default=np.nan),
    )


HEADER = (
    f"{'condition':16s} {'track':>6s} {'merge':>6s} {'optim':>6s} {'filter':>6s} {'camera':>6s} "
    f"{'ratio':>5s} {'sw':>3s} {'limbCV':>6s} {'acc':>5s} {'accept':>6s} {'angle':>6s} "
    f"{'mirror':>6s} {'m-run':>5s} {'fps':>6s}"
)
UNITS = (
    "(MPJPE mm per stage and of the best single camera with oracle left/right labels; ratio = "
    "filter / that camera; sw: identity switches; limb CV % after acceptance; acc: people "
    "accepted / tracks; accept: longest acceptance time, s; angle: joint-angle RMSE change "
    "tracker -> filter, %; mirror: mirrored filter skeletons, %; m-run: longest unbroken run of a "
    "person's mirrored skeletons, s; fps: camera frames per second; "
    "calibration flagged: hiros run --calibration auto stops there, the figures are what "
    "--accept-flagged runs on)"
)


def measure(condition: str, seed: int = 0, duration: float = 60.0, *, auto: bool = False) -> Row:
    """Simulate ``condition`` and run the stages over it with the true calibration.

    With ``auto``, with the calibration found in the recording instead (as
    ``--calibration auto``: the receiver's arrival times narrow the clock search).

    Raises:
        CalibrationError: with ``auto``, the recording cannot be calibrated.
        ConfigError: the condition's clips are absent.

    """
    from hiros_sim import preset_params, simulate

    result = simulate(preset_params(condition, seed=seed, duration=duration))
    truth, true_calibration = result.truth, result.calibration
    calibration = true_calibration
    if auto:
        calibrator = Calibrator(CalibratorParams(reference=min(result.camera_groups)))
        calibration = calibrator.calibrate(result.camera_groups, arrival_ns=result.receive_ns)
    params = PipelineParams()
    params.merger.output_rate = MERGE_RATE
    pipeline = Pipeline(params, calibration)
    frames = arrival_order(result.camera_groups, calibration)
    outputs: dict[str, list[SkeletonGroup]] = {stage: [] for stage in STAGES}
    start = time.perf_counter()
    for step in [*map(pipeline.update, frames), pipeline.flush()]:
        for stage, group in zip(STAGES, step, strict=True):
            if group.skeletons:
                outputs[stage].append(group)
    seconds = time.perf_counter() - start
    evaluation = evaluate_run(outputs, calibration, true_calibration, truth)
    mirrored = mirrored_output(
        align_to_truth(outputs["filter"], calibration, true_calibration), truth
    )
    cameras = camera_mpjpe(result.camera_groups, true_calibration, truth, oracle_sides=True)
    people = pipeline.optimizer.people()
    accepted = [p.acceptance_time for p in people.values() if p.acceptance_time is not None]
    return Row(
        condition=condition,
        mpjpe={stage: figures.mpjpe for stage, figures in evaluation.stages.items()},
        best_camera=min(cameras.values(), default=float("nan")),
        switches=evaluation.stages["filter"].identity.id_switches,
        limb_cv=limb_cv_after_acceptance(outputs["filter"], pipeline.optimizer),
        accepted=len(accepted),
        people=len(people),
        acceptance=max(accepted, default=float("nan")),
        angle_change=evaluation.angle_change("filter"),
        mirrored=mirrored.share,
        mirror_run=mirrored.longest_run_s,
        fps=len(frames) / seconds,
        flagged=tuple(sorted(calibration.flagged)),
    )


def limb_cv_after_acceptance(groups: list[SkeletonGroup], optimizer: Optimizer) -> float:
    """Mean limb-length CV over the accepted tracks' limb links, from their acceptance on.

    ``groups`` are a stage's output after the optimizer (world frame, one skeleton per track).
    NaN when no track was accepted.
    """
    people = optimizer.people()
    series: dict[int, list[np.ndarray]] = {}
    for group in groups:
        for skeleton in group.skeletons:
            progress = people.get(skeleton.id)
            if progress is None or progress.accepted_ns is None:
                continue
            if skeleton.src_time_ns >= progress.accepted_ns:
                positions = np.where(skeleton.marker_present[:, None], skeleton.positions, np.nan)
                series.setdefault(skeleton.id, []).append(positions)
    cvs = []
    for rows in series.values():
        if len(rows) > 1:
            layout = groups[0].skeletons[0].layout
            cvs.append(np.nanmean(limb_length_cv(np.stack(rows), layout)[limb_links(layout)]))
    return float(np.mean(cvs)) if cvs else float("nan")


def run(
    console,  # noqa: ANN001 - rich Console
    quick: bool = False,
    seeds: Sequence[int] = (0,),
) -> list[str]:
    """Print both matrices (20 s per condition with ``quick``, else 60 s); return their lines.

    With several ``seeds``, each condition's line is its mean over them (:func:`mean_row`),
    followed by each seed's own.
    """
    duration = 20.0 if quick else 60.0
    lines: list[str] = []

    def say(line: str) -> None:
        lines.append(line)
        console.print(line, highlight=False)

    several = len(seeds) > 1
    for auto, what in ((False, "the true calibration"), (True, "--calibration auto")):
        which = (
            f"seeds {seeds_text(seeds)}; each condition's mean, then each seed"
            if several
            else f"seed {seeds_text(seeds)}"
        )
        say(f"stages with {what}, {duration:.0f} s per condition, {which}")
        say(HEADER)
        for condition in CONDITIONS:
            rows: dict[int, Row] = {}
            refused: dict[int, str] = {}
            for seed in seeds:
                try:
                    with console.status(f"bench robust: {condition}, seed {seed}"):
                        rows[seed] = measure(condition, seed, duration, auto=auto)
                except ConfigError as exc:  # clips absent: no seed can run
                    refused = {seed: str(exc)}
                    rows = {}
                    break
                except CalibrationError as exc:  # this seed's recording refused
                    refused[seed] = str(exc)
            _say_rows(say, condition, rows, refused, several)
    say(UNITS)
    return lines


def _say_rows(
    say: Callable[[str], None],
    condition: str,
    rows: dict[int, Row],
    refused: dict[int, str],
    several: bool,
) -> None:
    """One condition's lines: its row, or with ``several`` seeds their mean, then each seed's."""
    if not several:
        for row in rows.values():
            say(row.line())
        for reason in refused.values():
            say(f"{condition:16s} left out: {reason}")
        return
    if not rows:
        say(f"{condition:16s} left out: {next(iter(refused.values()), 'no seed ran')}")
        return
    flagged = sum(bool(row.flagged) for row in rows.values())
    notes = [f"calibration flagged on {flagged} of {len(rows)} seeds"] if flagged else []
    notes += [f"{len(refused)} seed(s) left out"] if refused else []
    say(mean_row(list(rows.values())).line(note="; ".join(notes)))
    for seed in sorted(rows.keys() | refused.keys()):
        if seed in rows:
            say(rows[seed].line(label=f"  seed {seed}"))
        else:
            say(f"{'  seed ' + str(seed):16s} left out: {refused[seed]}")
