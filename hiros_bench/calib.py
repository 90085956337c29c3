"""Calibration accuracy on simulator data, beside a Pose2Sim-style baseline run alongside.

For each setup and seed, ``hiros_sim`` makes a recording (3 Azure Kinects in the room setup:
k01 and k02 face each other 180° apart, k03 at the side; 60 s; 1-3 people by seed; every SDK
mistake on) and ``Calibrator`` recovers every camera's clock and pose from the skeletons and
their arrival times. Errors against the simulator's truth (``hiros_eval.calibration``): time
(ms, mean absolute over the recording, so a wrong drift counts), rotation (deg), translation
(cm), all relative to the reference camera k01.

Baseline, measured on the same recordings: the synchronisation of Pose2Sim (Pagnon et al.,
2022), i.e. per camera the summed vertical joint speed per frame, and the integer-frame lag
that best correlates it with the reference camera's, searched in the same window around the
arrival-time lag as ours. Its time error is reported beside ours and as a ratio.

Pose baseline, on the same synchronised joint pairs: Eichler et al. (2022) alone, i.e.
Kabsch inside RANSAC on every joint pair as the SDKs reported them, then Kabsch on the
inliers, each camera against the reference (``hiros_calib.extrinsics.baseline_pair_pose``).
Its median errors are printed beside ours, with our error as a ratio of its.

The simulator's arrival times are exact (capture + a fixed latency), which real receivers are
not: each camera gets a constant extra latency (uniform ±50 ms: USB, body tracking, network)
and every message a jitter (|N(0, 5 ms)|) before either method sees them. The error of the lag
the arrival times alone give is printed too ("arrival").

Translation given the true rotation: on the same synchronised, weighted joint pairs, the
translation that fits them best (weighted mean) once each camera's rotation is the true one.
What is left is how far each camera's SDK places a person's whole body from where the other
does (fixed per-person joint offsets, view-dependent errors, averaged over one to three
people). It shows how much of our translation error a better rotation could remove; the rest is
in the skeletons.

Live: the ``calib`` node's calibrator (:class:`~hiros_calib.live.LiveCalibrator`) is fed a
recording frame by frame in which camera k03 is knocked (turned 5° about the vertical and slid
10 cm, 50 s into 80 s; 2 people; the first three seeds; then again with 2° and 5 cm): how
long after the bump it notices and recalibrates (target: within 10 s), how far k03 is from its
new pose at the end, and how many times a camera was flagged as moved before the bump (false
alarms).

Setups: ``default`` (the simulator's clocks: drifts of ~30 ppm, 0.56 % frame drops) and
``drops+drift`` (1 % frame drops, 200 ppm drift spread), ten seeds each (two with
``quick``). Targets: time median <= 3 ms and 95th percentile <= 10 ms, rotation <= 0.25°,
translation <= 1 cm.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from hiros_calib.calibrator import Calibrator, CalibratorParams
from hiros_calib.extrinsics import baseline_pair_pose, relative_error
from hiros_calib.live import LiveCalibrator, LiveCalibratorParams
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.errors import CalibrationError
from hiros_eval.calibration import compare_calibration
from hiros_sim import SimParams, simulate
from hiros_sim.simulate import bumped_pose

__all__ = ["SETUPS", "run"]

SETUPS: dict[str, dict[str, Any]] = {
    "default": {},
    "drops+drift": {"drop_rate": 0.01, "drift_ppm": 200.0},
}
"""Simulator settings per setup, on top of 3 cameras in the room, 60 s, all realism on."""


@dataclass
class _Errors:
    time_ms: list[float] = field(default_factory=list)
    baseline_ms: list[float] = field(default_factory=list)
    arrival_ms: list[float] = field(default_factory=list)
    rotation_deg: list[float] = field(default_factory=list)
    translation_cm: list[float] = field(default_factory=list)
    baseline_rotation_deg: list[float] = field(default_factory=list)
    baseline_translation_cm: list[float] = field(default_factory=list)
    true_rotation_translation_cm: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)


def _arrival_offsets(groups: Sequence[Any], receive_ns: np.ndarray) -> float:
    stamps = np.array([g.stamp_ns for g in groups], dtype=np.int64)
    return float(np.median(receive_ns[: len(stamps)] - stamps)) * 1e-9


def _vertical_speed(groups: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """Per frame: stamp (s) and summed |vertical joint speed| (camera y axis, m/s)."""
    stamps = np.array([g.stamp for g in groups])
    height = np.array(
        [np.nansum([s.positions[:, 1].sum() for s in g.skeletons]) if g.skeletons else np.nan
         for g in groups]
    )  # fmt: skip
    speed = np.abs(np.gradient(height, stamps))
    return stamps, np.nan_to_num(speed - np.nanmean(speed))


def _baseline_lag(ref: Sequence[Any], cam: Sequence[Any], prior: float, window: float) -> float:
    """Pose2Sim-style lag ``tau = t_ref - t_cam``: best integer frame shift of the speeds."""
    t_ref, s_ref = _vertical_speed(ref)
    t_cam, s_cam = _vertical_speed(cam)
    period = float(np.median(np.diff(t_ref)))
    best, best_lag = -np.inf, 0
    # frame k of cam is compared with frame k + lag of ref; the prior fixes the centre lag
    centre = round((t_cam[0] + prior - t_ref[0]) / period)
    for lag in range(centre - round(window / period), centre + round(window / period) + 1):
        lo, hi = max(0, -lag), min(len(s_cam), len(s_ref) - lag)
        if hi - lo < 10:
            continue
        a, b = s_ref[lo + lag : hi + lag], s_cam[lo:hi]
        score = float(np.corrcoef(a, b)[0, 1])
        if score > best:
            best, best_lag = score, lag
    lo, hi = max(0, -best_lag), min(len(t_cam), len(t_ref) - best_lag)
    return float(np.median(t_ref[lo + best_lag : hi + best_lag] - t_cam[lo:hi]))


def _one_run(setup: dict[str, Any], seed: int, duration: float, errors: _Errors) -> None:
    n_people = 1 + seed % 3
    result = simulate(SimParams(n_cameras=3, setup="room", n_people=n_people,
                                duration=duration, seed=seed, **setup))  # fmt: skip
    truth = result.calibration
    groups = result.camera_groups
    rng = np.random.default_rng(seed)
    receive_ns = {
        camera: (
            arrival
            + round(rng.uniform(-0.05, 0.05) * 1e9)
            + np.abs(rng.normal(0.0, 0.005, len(arrival)) * 1e9).astype(np.int64)
        )
        for camera, arrival in result.receive_ns.items()
    }
    calibrator = Calibrator(CalibratorParams(reference="k01"))
    try:
        estimate = calibrator.calibrate(groups, arrival_ns=receive_ns)
    except CalibrationError as exc:
        errors.failures.append(f"seed {seed}: {exc}")
        return
    times = {c: np.array([g.stamp for g in gs])[::15] for c, gs in groups.items()}
    for acc in compare_calibration(estimate, truth, times).values():
        errors.time_ms.append(acc.time_error_ms)
        errors.rotation_deg.append(acc.rotation_error_deg)
        errors.translation_cm.append(acc.translation_error_cm)
    errors.true_rotation_translation_cm.extend(_true_rotation_translation(calibrator, truth))
    for acc in compare_calibration(_baseline_poses(calibrator, estimate), truth).values():
        errors.baseline_rotation_deg.append(acc.rotation_error_deg)
        errors.baseline_translation_cm.append(acc.translation_error_cm)
    # baseline and arrival times alone: offsets only, poses copied from the truth (only their
    # time errors are used)
    arrival = {c: _arrival_offsets(gs, receive_ns[c]) for c, gs in groups.items()}
    priors = {c: arrival[c] - arrival["k01"] for c in groups}
    lags = {
        c: _baseline_lag(groups["k01"], groups[c], priors[c], 1.0) if c != "k01" else 0.0
        for c in groups
    }
    for offsets, sink in ((lags, errors.baseline_ms), (priors, errors.arrival_ms)):
        for acc in compare_calibration(_offsets_only(truth, offsets), truth, times).values():
            sink.append(acc.time_error_ms)


def _baseline_poses(calibrator: Calibrator, estimate: Calibration) -> Calibration:
    """``estimate`` with each camera's pose replaced by the Eichler-style baseline's.

    The baseline solves each camera against the reference on the calibrator's own joint
    pairs (same clocks, same associations); a camera it cannot solve is left out (NaN).
    """
    out = Calibration(reference=estimate.reference)
    reference = estimate.cameras[estimate.reference]
    out.cameras[estimate.reference] = reference
    result = calibrator.result
    for pair in result.pose_pairs if result is not None else ():
        if pair.camera_a != estimate.reference or pair.reported is None:
            continue
        pose = baseline_pair_pose(pair.reported)
        if pose is None:
            continue
        placed = reference.extrinsics @ pose
        out.cameras[pair.camera_b] = replace(
            estimate.cameras[pair.camera_b],
            translation=placed.translation,
            rotation=placed.quaternion,
        )
    return out


def _true_rotation_translation(calibrator: Calibrator, truth: Calibration) -> list[float]:
    """Per camera paired with the reference: translation error (cm) given its true rotation.

    The translation is the weighted mean of ``p_ref - R_true p_cam`` over the pair's joint
    pairs as the calibrator chose and weighted them (left/right reading, frames kept).
    """
    result = calibrator.result
    if result is None:
        return []
    out = []
    for pair in result.pose_pairs:
        c = pair.correspondences
        if pair.camera_a != result.calibration.reference or not pair.ok or c is None:
            continue
        true_pose = (
            truth.cameras[pair.camera_a].extrinsics.inverse()
            @ truth.cameras[pair.camera_b].extrinsics
        )
        difference = c.points_a - true_pose.rotate(c.points_b)
        translation = np.einsum("fk,fki->i", c.weights, difference) / c.weights.sum()
        out.append(100.0 * float(np.linalg.norm(translation - true_pose.translation)))
    return out


def _offsets_only(truth: Calibration, offsets: dict[str, float]) -> Calibration:
    """The true poses (relative to k01) with the given clock offsets and no drift."""
    out = Calibration(reference="k01")
    for camera, cam in truth.cameras.items():
        relative = truth.cameras["k01"].extrinsics.inverse() @ cam.extrinsics
        out.cameras[camera] = CameraCalibration(
            frame_id=cam.frame_id,
            time_offset=offsets[camera],
            translation=relative.translation,
            rotation=relative.quaternion,
        )
    return out


LIVE_BUMPS = (
    {"bump_camera": "k03", "bump_time": 50.0, "bump_rotation": 5.0, "bump_shift": 0.1},
    {"bump_camera": "k03", "bump_time": 50.0, "bump_rotation": 2.0, "bump_shift": 0.05},
)
"""The live checks' knocked camera, 50 s into 80 s: k03 turns 5° and slides 10 cm (the
target's case), or turns 2° and slides 5 cm (a knock the SDKs' noise nearly hides)."""


@dataclass
class _LiveRun:
    detected_s: float  # after the bump (inf: never)
    recalibrated_s: float
    rotation_deg: float  # k03 against its moved pose, at the end
    translation_cm: float
    false_alarms: int  # cameras flagged as moved before the bump


def _live_run(seed: int, bump: dict[str, Any]) -> _LiveRun:
    """The ``calib`` node's calibrator fed a recording in which k03 is knocked, frame by frame.

    Frames go in in arrival order and the calibrator steps every third frame, as the node
    does on its timer; times are measured on the arrival clock from the bump.
    """
    params = SimParams(n_cameras=3, setup="room", n_people=2, duration=80.0, seed=seed,
                       **bump)  # fmt: skip
    result = simulate(params)
    frames = sorted(
        (int(arrival), camera, group)
        for camera, groups in result.camera_groups.items()
        for group, arrival in zip(groups, result.receive_ns[camera], strict=True)
    )
    live = LiveCalibrator(LiveCalibratorParams(reference="k01"))
    for index, (arrival, _, group) in enumerate(frames):
        live.update(group, arrival)
        if index % 3 == 0:
            live.step(arrival)
    bump_ns = (params.clock_start + params.bump_time + params.latency) * 1e9
    after = [((t - bump_ns) * 1e-9, m) for t, m in live.events if t >= bump_ns]
    false_alarms = sum(" moved " in m for t, m in live.events if t < bump_ns)
    detected = [t for t, m in after if m.startswith("k03: moved")]
    recalibrated = [t for t, m in after if m == "k03: calibrated" and detected and t > detected[0]]
    truth = result.calibration.cameras
    moved = truth["k01"].extrinsics.inverse() @ bumped_pose(truth["k03"], params).extrinsics
    cameras = live.calibration.cameras
    angle, distance = (
        relative_error(cameras["k01"].extrinsics.inverse() @ cameras["k03"].extrinsics, moved)
        if "k01" in cameras and "k03" in cameras
        else (math.nan, math.nan)
    )
    return _LiveRun(
        detected[0] if detected else math.inf,
        recalibrated[0] if recalibrated else math.inf,
        angle,
        100.0 * distance,
        false_alarms,
    )


def _live_line(runs: list[_LiveRun], bump: dict[str, Any]) -> str:
    """Medians over the live runs, and how many never noticed the bump."""
    missed = sum(not math.isfinite(r.detected_s) for r in runs)
    found = [r for r in runs if math.isfinite(r.detected_s)]

    def median(values: list[float]) -> float:
        return float(np.median(values)) if values else math.nan

    return (
        f"live (calib node's calibrator, k03 turned {bump['bump_rotation']:g}° and slid "
        f"{100 * bump['bump_shift']:g} cm at {bump['bump_time']:g} s, "
        f"{len(runs)} runs): detected after {median([r.detected_s for r in found]):.1f} s, "
        f"recalibrated after {median([r.recalibrated_s for r in found]):.1f} s (target <= 10 "
        f"s), {missed} missed, {sum(r.false_alarms for r in runs)} false alarms before it; "
        "30 s after the bump k03 is off by "
        f"{median([r.rotation_deg for r in runs]):.2f} deg, "
        f"{median([r.translation_cm for r in runs]):.1f} cm"
    )


def _baseline_line(errors: _Errors, rotation: float, translation: float) -> str:
    """The pose baseline's median / p95 errors and ours as a ratio of its medians."""
    rot = np.array(errors.baseline_rotation_deg)
    unsolved = int(np.isnan(rot).sum())
    base_rot = _stats(rot[~np.isnan(rot)].tolist())
    tr = np.array(errors.baseline_translation_cm)
    base_tr = _stats(tr[~np.isnan(tr)].tolist())
    return (
        f"  pose baseline (Eichler et al. alone): rotation {base_rot[0]:.3f}/{base_rot[1]:.3f} "
        f"deg, translation {base_tr[0]:.2f}/{base_tr[1]:.2f} cm, {unsolved} unsolved; "
        f"ours as a ratio of it: rotation {rotation / base_rot[0]:.2f}, "
        f"translation {translation / base_tr[0]:.2f}"
    )


def _stats(values: list[float]) -> tuple[float, float]:
    if not values:
        return float("nan"), float("nan")
    return float(np.median(values)), float(np.percentile(values, 95))


def run(
    console,  # noqa: ANN001 - rich Console
    seeds: Sequence[int] | None = None,
    quick: bool = False,
    sim: dict[str, Any] | None = None,
    duration: float | None = None,
) -> list[str]:
    """Run every setup over the seeds, print the table and return its lines.

    ``sim`` settings apply on top of every setup and ``duration`` replaces the recording
    length: what-if runs (``hiros bench calib --sim oblique_gain=0``) that show what limits
    the accuracy.
    """
    sim = dict(sim or {})
    # ten seeds (twenty camera poses per setup): pose errors spread about as much as they
    # are large, so five seeds cannot tell a 10 % change from chance
    seeds = tuple(seeds) if seeds is not None else ((0, 1) if quick else tuple(range(10)))
    duration = duration or (30.0 if quick else 60.0)
    changed = ", ".join(f"{k}={v}" for k, v in sim.items())
    lines = [
        f"calibration accuracy: 3 cameras (k01-k02 180° apart), {duration:.0f} s, "
        f"1-3 people, seeds {list(seeds)}; errors relative to k01 (median / p95)"
        + (f"; simulator: {changed}" if changed else ""),
        f"{'setup':<12s} {'time ms':>13s} {'Pose2Sim ms':>13s} {'ratio':>6s} "
        f"{'arrival ms':>13s} {'rotation deg':>13s} {'transl. cm':>11s} {'fails':>5s}",
    ]
    for name, setup in SETUPS.items():
        errors = _Errors()
        for seed in seeds:
            with console.status(f"bench calib: {name}, seed {seed}"):
                _one_run({**setup, **sim}, seed, duration, errors)
        time_med, time_p95 = _stats(errors.time_ms)
        base_med, base_p95 = _stats(errors.baseline_ms)
        arr_med, arr_p95 = _stats(errors.arrival_ms)
        rot_med, rot_p95 = _stats(errors.rotation_deg)
        tr_med, tr_p95 = _stats(errors.translation_cm)
        lines.append(
            f"{name:<12s} {time_med:6.2f}/{time_p95:6.2f} {base_med:6.2f}/{base_p95:6.2f} "
            f"{time_med / base_med:6.3f} {arr_med:6.2f}/{arr_p95:6.2f} "
            f"{rot_med:6.3f}/{rot_p95:6.3f} "
            f"{tr_med:5.2f}/{tr_p95:5.2f} {len(errors.failures):5d}"
        )
        lines.append(_baseline_line(errors, rot_med, tr_med))
        floor_med, floor_p95 = _stats(errors.true_rotation_translation_cm)
        lines.append(
            f"  translation given the true rotation (same joint pairs): {floor_med:.2f}/"
            f"{floor_p95:.2f} cm: how far the cameras' skeletons disagree on where each "
            "person is, which no better rotation removes"
        )
        lines.extend(f"  failed: {failure}" for failure in errors.failures)
    for bump in LIVE_BUMPS:
        live_runs = []
        for seed in seeds[:3]:
            knock = f"{bump['bump_rotation']:g}° knock"
            with console.status(f"bench calib: live, {knock}, seed {seed}"):
                live_runs.append(_live_run(seed, bump))
        lines.append(_live_line(live_runs, bump))
    lines.append("targets: time median <= 3 ms, p95 <= 10 ms; rotation <= 0.25 deg; "
                 "translation <= 1 cm; a moved camera recalibrated within 10 s")  # fmt: skip
    for line in lines:
        console.print(line, highlight=False)
    return lines
