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
from dataclasses import dataclass

import numpy as np

from hiros_calib.calibrator import Calibrator, CalibratorParams
from hiros_core.errors import CalibrationError, ConfigError
from hiros_core.model import SkeletonGroup
from hiros_eval.body import limb_length_cv
from hiros_eval.run import align_to_truth, evaluate_run
from hiros_eval.tracking import arrival_order, camera_mpjpe, mirrored_share
from hiros_optimizer import Optimizer
from hiros_optimizer.learning import limb_links
from hiros_pipeline import STAGES, Pipeline, PipelineParams

__all__ = ["CONDITIONS", "Row", "measure", "run"]

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

    @property
    def ratio(self) -> float:
        """The filter's MPJPE over the best oracle-labelled camera's."""
        return self.mpjpe.get("filter", float("nan")) / self.best_camera

    def line(self) -> str:
        """The row as printed under :data:`HEADER`."""
        stages = " ".join(f"{self.mpjpe.get(stage, float('nan')) * 1e3:6.1f}" for stage in STAGES)
        return (
            f"{self.condition:16s} {stages} {self.best_camera * 1e3:6.1f} {self.ratio:5.2f} "
            f"{self.switches:3d} {self.limb_cv * 100:6.2f} {self.accepted:2d}/{self.people:<2d} "
            f"{self.acceptance:6.1f} {self.angle_change * 100:+6.1f} {self.mirrored * 100:6.2f} "
            f"{self.fps:6.0f}"
            + (
                f"  calibration flagged ({', '.join(self.flagged)}): run stops"
                if self.flagged
                else ""
            )
        )


HEADER = (
    f"{'condition':16s} {'track':>6s} {'merge':>6s} {'optim':>6s} {'filter':>6s} {'camera':>6s} "
    f"{'ratio':>5s} {'sw':>3s} {'limbCV':>6s} {'acc':>5s} {'accept':>6s} {'angle':>6s} "
    f"{'mirror':>6s} {'fps':>6s}"
)
UNITS = (
    "(MPJPE mm per stage and of the best single camera with oracle left/right labels; ratio = "
    "filter / that camera; sw: identity switches; limb CV % after acceptance; acc: people "
    "accepted / tracks; accept: longest acceptance time, s; angle: joint-angle RMSE change "
    "tracker -> filter, %; mirror: mirrored filter skeletons, %; fps: camera frames per second; "
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
        mirrored=mirrored_share(
            align_to_truth(outputs["filter"], calibration, true_calibration), truth
        ),
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


def run(console, quick: bool = False) -> list[str]:  # noqa: ANN001 - rich Console
    """Print both matrices (20 s per condition with ``quick``, else 60 s); return their lines."""
    duration = 20.0 if quick else 60.0
    lines: list[str] = []

    def say(line: str) -> None:
        lines.append(line)
        console.print(line, highlight=False)

    for auto, what in ((False, "the true calibration"), (True, "--calibration auto")):
        say(f"stages with {what}, {duration:.0f} s per condition, seed 0")
        say(HEADER)
        for condition in CONDITIONS:
            try:
                say(measure(condition, duration=duration, auto=auto).line())
            except (ConfigError, CalibrationError) as exc:  # clips absent, or refused
                say(f"{condition:16s} left out: {exc}")
    say(UNITS)
    return lines
