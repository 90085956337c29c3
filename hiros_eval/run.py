"""Accuracy of a whole ``hiros run`` output against the simulator's truth, stage by stage.

The output is in the estimated world (the reference camera's frame and clock); the truth is in
the simulator's world. ``align_to_truth`` moves the output there with the *true* pose and clock
of the reference camera, so every figure includes the calibration's own error, as a user
would see it.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hiros_core.calibration import Calibration
from hiros_core.codec import decode_group
from hiros_core.errors import CalibrationError, RecordingError
from hiros_core.geometry import RigidTransform
from hiros_core.model import Skeleton, SkeletonGroup, camera_from_frame
from hiros_core.recording import RecordingReader
from hiros_core.safe_yaml import parse_yaml
from hiros_eval.body import joint_angle_rmse, limb_length_cv, mpjpe, parabola_vertex
from hiros_eval.calibration import CameraAccuracy, compare_calibration
from hiros_eval.tracking import IdentityMetrics, TruthLike, identity_metrics, match_to_truth

__all__ = [
    "RunEvaluation",
    "StageEvaluation",
    "align_to_truth",
    "evaluate_stage",
    "read_run",
]

STAGES = ("tracker", "merger", "optimizer", "filter")


@dataclass
class StageEvaluation:
    """Figures of one stage's output (distances in m, angles in degrees)."""

    stage: str
    mpjpe: float
    per_joint: np.ndarray
    limb_cv: float
    angle_rmse: dict[str, float]
    identity: IdentityMetrics
    matched: int
    lag: float
    """Seconds the stage's people trail the truth (``series_lag``; ``nan`` when nobody was
    matched): what smoothing costs in time."""
    person_series: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(repr=False)
    """true person -> (times (N,), estimate (N, J, 3), truth (N, J, 3)) for plots."""


@dataclass
class RunEvaluation:
    """Every stage's figures, the single cameras' and the calibration's."""

    stages: dict[str, StageEvaluation]
    cameras: dict[str, float]
    calibration: dict[str, CameraAccuracy]

    @property
    def best_camera(self) -> str | None:
        """The single camera with the smallest MPJPE (None without single-camera figures)."""
        return min(self.cameras, key=self.cameras.__getitem__) if self.cameras else None

    def to_best_camera(self, stage: str) -> float:
        """``stage``'s MPJPE as a fraction of the best single camera's (NaN without either)."""
        best = self.best_camera
        if best is None or stage not in self.stages:
            return float("nan")
        return self.stages[stage].mpjpe / self.cameras[best]

    def angle_change(self, stage: str) -> float:
        """Change of the mean joint-angle RMSE from the tracker's to ``stage``'s (-0.3: 30 % less).

        NaN without either stage.
        """
        if "tracker" not in self.stages or stage not in self.stages:
            return float("nan")
        before = self.stages["tracker"].angle_rmse.get("mean", float("nan"))
        return self.stages[stage].angle_rmse.get("mean", float("nan")) / before - 1.0

    def tables(self) -> dict[str, tuple[list[str], list[list[str]]]]:
        """The figures as text tables (headers, rows), one per kind, for terminal and HTML."""
        stages = [
            [
                stage,
                f"{s.mpjpe * 100:.2f}",
                f"{s.limb_cv * 100:.2f}",
                f"{s.angle_rmse.get('mean', float('nan')):.2f}",
                f"{s.identity.idf1:.3f}",
                str(s.identity.id_switches),
                str(s.identity.fragments),
                f"{s.lag * 1000:.0f}",
            ]
            for stage, s in self.stages.items()
        ]
        cameras = [[camera, f"{value * 100:.2f}"] for camera, value in self.cameras.items()]
        calibration = [
            [
                c,
                f"{a.time_error_ms:.2f}",
                f"{a.rotation_error_deg:.3f}",
                f"{a.translation_error_cm:.2f}",
            ]
            for c, a in self.calibration.items()
        ]
        return {
            "pipeline stages against the truth": (
                [
                    "stage",
                    "MPJPE cm",
                    "limb CV %",
                    "angle RMSE deg",
                    "IDF1",
                    "ID switches",
                    "fragments",
                    "lag ms",
                ],
                stages,
            ),
            "single cameras (true calibration, no tracking)": (["camera", "MPJPE cm"], cameras),
            "calibration used against the truth": (
                ["camera", "time error ms", "rotation error deg", "translation error cm"],
                calibration,
            ),
        }


def read_run(
    path: str | Path, problems: list[str] | None = None
) -> tuple[dict[str, list[SkeletonGroup]], Calibration]:
    """Each stage's groups and the calibration used, from a ``hiros run`` MCAP.

    ``problems`` receives the reader's sentences on what it could not read (a damaged chunk).
    """
    outputs: dict[str, list[SkeletonGroup]] = {stage: [] for stage in STAGES}
    calibration = None
    wanted = {f"/hiros/{stage}" for stage in STAGES} | {"/hiros/calibration"}
    with RecordingReader(path) as reader:
        for message in reader.messages(wanted & set(reader.topics)):
            if message.topic == "/hiros/calibration":
                source = f"{path} /hiros/calibration"
                text = bytes(message.data[8:]).split(b"\x00", 1)[0].decode("utf-8", "replace")
                data = parse_yaml(text, source=source, error=CalibrationError)
                calibration = Calibration.from_dict(data, source)
            else:
                outputs[message.topic.rsplit("/", 1)[1]].append(decode_group(message.data))
        if problems is not None:
            problems.extend(reader.problems)
    if calibration is None:
        msg = f"{path} has no /hiros/calibration topic: is it the output of `hiros run`?"
        raise RecordingError(msg)
    return outputs, calibration


def align_to_truth(
    groups: Sequence[SkeletonGroup], used: Calibration, true: Calibration
) -> list[SkeletonGroup]:
    """Groups moved from the estimated world and clock into the truth's.

    Only what the figures read is moved: joint positions and stamps (orientations and
    velocities are left out, NaN), so a whole run aligns in one matrix product per group.
    """
    reference = used.reference
    used_ref, true_ref = used.camera(reference), true.camera(reference)
    space: RigidTransform = true_ref.extrinsics @ used_ref.extrinsics.inverse()
    rotation, translation = space.rotation.as_matrix(), space.translation

    def clock(stamp_ns: int) -> int:
        camera_time = (
            stamp_ns * 1e-9 - used_ref.time_offset + used_ref.drift * used_ref.drift_epoch
        ) / (1.0 + used_ref.drift)
        return round(float(true_ref.to_reference_time(camera_time)) * 1e9)

    aligned = []
    for group in groups:
        skeletons = []
        for skeleton in group.skeletons:
            moved = Skeleton.empty(
                skeleton.layout, skeleton_id=skeleton.id, src_frame=skeleton.src_frame
            )
            moved.src_time_ns = clock(skeleton.src_time_ns)
            moved.marker_present[:] = skeleton.marker_present
            moved.positions[:] = skeleton.positions @ rotation.T + translation
            skeletons.append(moved)
        aligned.append(SkeletonGroup(clock(group.stamp_ns), true.world_frame, skeletons))
    return aligned


def evaluate_stage(
    stage: str, groups: Sequence[SkeletonGroup], truth: TruthLike
) -> StageEvaluation:
    """MPJPE (overall, per joint), limb-length CV, joint-angle RMSE and identity figures."""
    frames, at, matches, _ = match_to_truth(groups, truth)
    series: dict[int, list[tuple[float, np.ndarray, np.ndarray]]] = defaultdict(list)
    for frame, people, match in zip(frames, at, matches, strict=True):
        for hypothesis, person in enumerate(match):
            if person >= 0:
                series[int(person)].append(
                    (frame.stamp_ns * 1e-9, frame.positions[hypothesis], people[person])
                )
    person_series = {
        person: (
            np.array([t for t, _, _ in rows]),
            np.stack([e for _, e, _ in rows]),
            np.stack([g for _, _, g in rows]),
        )
        for person, rows in series.items()
    }
    if person_series:
        estimate = np.concatenate([s[1] for s in person_series.values()])
        target = np.concatenate([s[2] for s in person_series.values()])
        overall, per_joint = mpjpe(estimate, target)
        angles = joint_angle_rmse(estimate, target)
        cvs = [np.nanmedian(limb_length_cv(s[1])) for s in person_series.values() if len(s[1]) > 1]
        limb_cv = float(np.nanmean(cvs)) if cvs else float("nan")
    else:
        overall, per_joint, angles, limb_cv = float("nan"), np.full(32, np.nan), {}, float("nan")
    return StageEvaluation(
        stage=stage,
        mpjpe=overall,
        per_joint=per_joint,
        limb_cv=limb_cv,
        angle_rmse=angles,
        identity=identity_metrics(groups, truth),
        matched=sum(len(s[0]) for s in person_series.values()),
        lag=series_lag(person_series, truth),
        person_series=person_series,
    )


LAG_RANGE = (-0.1, 0.2)
"""Delays (s) searched for a stage's lag: from its output leading the truth by 0.1 s to it
trailing by 0.2 s (first every 20 ms, then every 5 ms around the best)."""
LAG_SAMPLES = 3000
"""Estimates (evenly spread) the lag is fitted on: plenty for one delay, and it stays fast."""


def series_lag(
    person_series: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]], truth: TruthLike
) -> float:
    """Delay (s) of the estimates behind the truth: the shift of the truth that fits best.

    The mean joint error of every person's estimates against their truth ``delay`` earlier
    is smallest at the stage's delay; a parabola through the best shift and its neighbours
    refines it. Positive: the output trails the truth (smoothing); negative: it runs ahead
    (content newer than its stamp). NaN when nobody is seen. (Correlating frame-to-frame
    changes, as ``body.lag`` does for clean signals, is thrown off by the frame-to-frame
    noise of fused skeletons.)
    """
    if not person_series:
        return float("nan")
    people = np.array(list(person_series))
    times = np.concatenate([person_series[p][0] for p in people])
    owner = np.concatenate([np.full(len(person_series[p][0]), k) for k, p in enumerate(people)])
    estimate = np.concatenate([person_series[p][1] for p in people])
    pick = np.unique(np.linspace(0, len(times) - 1, min(len(times), LAG_SAMPLES)).astype(int))
    times, person, estimate = times[pick], people[owner[pick]], estimate[pick]

    def error(delay: float) -> float:
        earlier = truth.at(times - delay)[person, np.arange(len(times))]  # (N, J, 3)
        with np.errstate(invalid="ignore"):
            return float(np.nanmean(np.linalg.norm(estimate - earlier, axis=-1)))

    coarse = np.arange(LAG_RANGE[0], LAG_RANGE[1] + 1e-9, 0.02)
    errors = np.array([error(d) for d in coarse])
    if not np.isfinite(errors).any():  # no estimate beside a finite truth
        return float("nan")
    first = coarse[int(np.nanargmin(errors))]
    shifts = np.arange(first - 0.02, first + 0.02 + 1e-9, 0.005)
    mean = np.array([error(d) for d in shifts])
    best = int(np.nanargmin(mean))  # (finite: ``first`` is among the shifts)
    offset = parabola_vertex(*mean[best - 1 : best + 2]) if 0 < best < len(mean) - 1 else 0.0
    return float(shifts[best] + offset * 0.005)


def evaluate_run(
    outputs: dict[str, list[SkeletonGroup]],
    used: Calibration,
    true: Calibration,
    truth: TruthLike,
    camera_groups: dict[str, list[SkeletonGroup]] | None = None,
) -> RunEvaluation:
    """All figures of one run; ``camera_groups`` adds each single camera's MPJPE."""
    from hiros_eval.tracking import camera_mpjpe

    stages = {
        stage: evaluate_stage(stage, align_to_truth(groups, used, true), truth)
        for stage, groups in outputs.items()
        if groups
    }
    per_frame = camera_mpjpe(camera_groups, true, truth) if camera_groups else {}
    cameras = {camera_from_frame(frame): value for frame, value in sorted(per_frame.items())}
    return RunEvaluation(stages, cameras, compare_calibration(used, true))
