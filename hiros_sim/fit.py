"""Fit the simulator's noise model to a real Azure Kinect stream with an Xsens reference.

The UNIPD-BPE take ``sbj01_bend1`` (bundled in ``hiros_data/unipd_bpe_sample``) holds the
same bending motion seen by Azure Kinect camera k01 (body tracking SDK, ~30 Hz, Unix-ms
stamps, camera frame) and recorded by an Xsens MVN suit (60 Hz BVH, Y up). The two are on
different clocks and in different frames, so the fit first aligns them:

1. map the BVH to the Azure joints (``hiros_sim.mapping``) and keep the joints both skeletons
   define the same way (pelvis, spine, neck, head, shoulders, elbows, wrists, hips, knees,
   ankles);
2. for every time shift on a 1/60 s grid (then a 2 ms grid around the best), interpolate the
   Xsens joints at the Kinect stamps and fit each frame rigidly (Kabsch); keep the shift with
   the smallest median per-frame residual;
3. the global transform is the per-frame one that most frames agree with (RANSAC over frames,
   0.12 m), refined on those frames. The subject faces away from this camera, and the SDK
   reports a front/back flipped body on part of the frames (the residual jumps from ~5 cm
   to ~25 cm): those frames give the flip figure and are left out of the noise figures;
4. the residuals ``kinect - (R xsens + t)`` in the camera frame give the figures below.

Whether the errors are independent per joint or coherent along the skeleton
(``skeleton_errors``, the same code measures the simulator with ``simulated_errors``):

- limb-length CV: SD / mean of each link's length over the unflipped frames;
- whole-body scale: per frame, the median over links of the link's length divided by its
  median length; its CV, spread and correlation time (lag-1 autocorrelation), and the limb CV
  left after dividing each frame's lengths by it (0 for a skeleton that keeps its ratios);
- joint-parent correlation: per camera axis, the correlation of a core joint's residual (bias
  removed) with that of its nearest core ancestor (shoulder with spine chest, elbow with
  shoulder, ...).
- vertical scatter: the robust SD of the error along the vertical (the suit's up; the
  simulator's z) of the foot joints where the reference foot rests (the floor fit's rule),
  and of the pelvis. The floor is found from resting feet (``hiros_calib.world``), so how
  quiet they are is what the floor's accuracy depends on: 1.24 cm on the take (its quietest
  joint; the pelvis 2.3 cm), 4.4 cm on the simulator (docs/world-frame.md).

Figures (``hiros simulate --fit-noise`` prints them; ``SimParams`` defaults use them):

- time shift, rigid-fit RMS, how much the subject faces the camera and the flipped share;
- per-joint bias: the RMS over joints of each joint's mean residual (a fixed offset between
  the SDK's joint centres and the suit's), per axis;
- noise: the standard deviation of the residual after removing each joint's bias, per camera
  axis, and its linear fit against depth ``sigma = base + per_metre * depth`` over depth bins
  (the take spans only ~2.7-4.0 m of depth, so the slope is weakly determined);
- correlation time: from the lag-1 autocorrelation of the residual (``-dt / ln rho``);
- frame timing: median interval, jitter (std of the regular intervals), dropped frames
  (intervals longer than 1.5 frames) and frames with no body.

Fitted on the bundled take (357 Kinect frames, 839 Xsens frames), as printed by the command:

=====================================  ==============================================
time shift Xsens - Kinect              0.073 s
rigid fit RMS, unflipped frames        64.5 mm (17 core joints)
subject facing the camera              median cos +0.96 (facing it)
frames the SDK flipped front/back      37 % (upright frames; bent frames are right)
per-joint bias RMS x, y, z             8.5, 38.0, 21.3 mm (RMS over axes 25.6 mm)
noise std x, y, z (bias removed)       16.9, 31.4, 30.3 mm
noise_base, noise_per_metre            12.0 mm + 4.0 mm/m × depth (lateral sigma)
depth_axis_gain                        1.20
depth range of the take                2.81-3.95 m
noise correlation time                 220 ms
frame interval, stamp jitter           33.0 ms, 0.47 ms
dropped frames, frames with no body    0.56 %, 0.56 %
per-joint RMS error                    median 54 mm; ankles 121 / 85 mm (hidden by the
                                       bending torso), head 78 mm, wrists 73 / 65 mm
limb length CV                         3.5 % on every limb (3.47-3.50 %), thumbs 5.8 / 6.1 %
whole-body scale CV per frame          3.5 % (5-95 %: 0.948-1.065), correlation time 197 ms
limb CV left after the scale           0.0 % (ratios exact), thumbs 4.9 %
error corr. joint-parent x, y, z       0.70, 0.64, 0.53
=====================================  ==============================================

So the SDK reports one rigid body model per frame: the limb lengths keep exact ratios and vary
only with one per-frame body scale, and a joint's error largely follows its parent's. The
simulator's former independent per-joint noise gave 14-44 % limb CV (median 27 %), a
joint-parent correlation of 0.0 and a whole-body "scale" CV of 5.7 %; its rigid model
(``hiros_sim.noise``) gives 3.7-5.0 % (median 3.8 %, thumbs 5.9 %), 0.62 / 0.73 / 0.65 and
3.8 %, with the same per-joint error (noise std 39-48 mm against 42-52 mm, bias RMS 24-29
mm against 24-27 mm; ``simulated_errors`` default, occlusion on).

The residual holds more than the SDK's noise: the Xsens suit's own error, the different joint
definitions of the two skeletons (bias) and the mapping of the spine. The take is a single
subject at 2.8-4 m from one camera, so the depth slope and the side-view (``oblique_gain``)
behaviour are weakly determined or not at all; ``SimParams`` documents which defaults are
fitted and which are guesses.
"""

from __future__ import annotations

import gzip
import io
import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hiros_calib.world import RESTING_SPEED, SPEED_BASELINE
from hiros_core.errors import RecordingError
from hiros_core.geometry import kabsch, kabsch_batch
from hiros_core.layouts import AZURE_KINECT
from hiros_data import DATA_DIR
from hiros_eval.body import limb_length_cv
from hiros_sim.bvh import read_bvh
from hiros_sim.mapping import map_to_azure

if TYPE_CHECKING:
    from hiros_sim.params import SimParams

__all__ = [
    "NoiseFit",
    "SkeletonErrors",
    "align",
    "fit_noise",
    "read_kinect_csv",
    "simulated_errors",
    "skeleton_errors",
    "take_scene",
]

_DATA = DATA_DIR / "unipd_bpe_sample"
DEFAULT_BVH = _DATA / "sbj01_bend1.bvh.gz"
DEFAULT_CSV = _DATA / "sbj01_bend1KinectPos.csv.gz"

_CORE = np.array(
    [
        AZURE_KINECT.index(n)
        for n in (
            "Pelvis", "SpineNaval", "SpineChest", "Neck", "Head",
            "ShoulderLeft", "ElbowLeft", "WristLeft", "ShoulderRight", "ElbowRight", "WristRight",
            "HipLeft", "KneeLeft", "AnkleLeft", "HipRight", "KneeRight", "AnkleRight",
        )
    ]
)  # fmt: skip


def read_kinect_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (s, Unix) and ``(N, 32, 3)`` positions of a UNIPD-BPE ``*KinectPos.csv``.

    Frames where every joint is zero (the SDK found nobody) are NaN.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
        text = gzip.decompress(raw).decode() if path.suffix == ".gz" else raw.decode()
        table = np.genfromtxt(io.StringIO(text), delimiter=",", names=True)
        columns = [
            [table[f"{joint}Pos{axis}"] for axis in "XYZ"] for joint in AZURE_KINECT.joint_names
        ]
        stamps = np.asarray(table["time"], dtype=float) * 1e-3
    except (OSError, ValueError, EOFError) as exc:
        msg = f"cannot read Kinect CSV {path}: {exc}"
        raise RecordingError(msg) from exc
    positions = np.transpose(np.asarray(columns, dtype=float), (2, 0, 1))
    positions[(positions == 0.0).all(axis=(1, 2))] = np.nan
    return stamps, positions


def _interpolate(times: np.ndarray, rate: float, positions: np.ndarray) -> np.ndarray:
    frame = times * rate
    valid = (frame >= 0) & (frame <= positions.shape[0] - 1)
    lower = np.clip(np.floor(frame).astype(int), 0, positions.shape[0] - 2)
    w = (frame - lower)[:, None, None]
    out = (1.0 - w) * positions[lower] + w * positions[lower + 1]
    out[~valid] = np.nan
    return out


def _kabsch_rms(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame ``target ≈ R source + t`` for ``(F, M, 3)`` point sets: ``R (F, 3, 3)``, RMS."""
    rotations, translations = kabsch_batch(target, source)
    residual = target - (np.einsum("fij,fmj->fmi", rotations, source) + translations[:, None])
    return rotations, np.sqrt(np.mean(np.sum(residual**2, axis=2), axis=1))


def _core_parents() -> np.ndarray:
    """Each core joint's nearest core ancestor in the Azure tree (-1 for the pelvis)."""
    parents = np.asarray(AZURE_KINECT.parents)
    core = set(_CORE.tolist())
    nearest = []
    for joint in _CORE:
        parent = parents[joint]
        while parent >= 0 and parent not in core:
            parent = parents[parent]
        nearest.append(parent)
    return np.array(nearest)


_CORE_PARENT = _core_parents()
_THUMBS = np.array([AZURE_KINECT.index("ThumbLeft"), AZURE_KINECT.index("ThumbRight")])


@dataclass
class SkeletonErrors:
    """Whether a stream's errors are independent per joint or coherent along the skeleton.

    Attributes:
        limb_cv: ``(32,)`` coefficient of variation (SD / mean) of each link's length over
            time, by link id (the child joint); NaN for the root.
        scale_cv: CV of the per-frame whole-body scale, the median over links of the link's
            length divided by its median length.
        unscaled_limb_cv: ``(32,)`` the limb-length CV left after dividing each frame's
            lengths by that scale: 0 for a skeleton whose limbs keep their ratios.
        scale_span: 5th and 95th percentile of that scale.
        scale_correlation_time: seconds, from the scale's lag-1 autocorrelation.
        parent_correlation: ``(3,)`` per camera axis, the correlation of a core joint's error
            (its bias removed) with its nearest core ancestor's.
        noise_std: ``(3,)`` per axis, the error's standard deviation, each joint's bias removed.
        bias_rms: ``(3,)`` per axis, the RMS over joints of each joint's mean error.
        joint_error: mean per-joint position error, metres.
        frames: frames the figures come from (over all streams).
        vertical_scatter: ``(2,)`` robust SD (1.4826 MAD, metres) of the error along the
            vertical of the foot joints where the reference foot rests, and of the pelvis;
            each stream's and joint's median removed. NaN without a vertical.

    The error figures are over the 17 core joints (``_CORE``) that the SDK and a mocap
    reference define alike; the limb and scale figures over every link.

    """

    limb_cv: np.ndarray
    scale_cv: float
    unscaled_limb_cv: np.ndarray
    scale_span: tuple[float, float]
    scale_correlation_time: float
    parent_correlation: np.ndarray
    noise_std: np.ndarray
    bias_rms: np.ndarray
    joint_error: float
    frames: int
    vertical_scatter: np.ndarray

    @property
    def body_limb_cv(self) -> float:
        """Median limb-length CV over the links other than the thumbs."""
        cv = np.delete(self.limb_cv, _THUMBS)
        return float(np.nanmedian(cv))

    def figures(self) -> list[tuple[str, str]]:
        """Named, formatted figures for a table or a report."""
        thumbs = np.nanmean(self.limb_cv[_THUMBS])
        return [
            ("limb length CV, median (not thumbs)", f"{self.body_limb_cv * 100:.1f} %"),
            (
                "limb length CV, range (not thumbs)",
                _range_percent(np.delete(self.limb_cv, _THUMBS)),
            ),
            ("limb length CV, thumbs", f"{thumbs * 100:.1f} %"),
            ("whole-body scale CV per frame", f"{self.scale_cv * 100:.1f} %"),
            (
                "limb CV beyond the scale, body, thumbs",
                f"{np.nanmedian(np.delete(self.unscaled_limb_cv, _THUMBS)) * 100:.1f} %, "
                f"{np.nanmean(self.unscaled_limb_cv[_THUMBS]) * 100:.1f} %",
            ),
            ("whole-body scale 5-95 %", f"{self.scale_span[0]:.3f}-{self.scale_span[1]:.3f}"),
            ("scale correlation time", f"{self.scale_correlation_time * 1000:.0f} ms"),
            (
                "error corr. joint-parent x, y, z",
                ", ".join(f"{c:.2f}" for c in self.parent_correlation),
            ),
            ("noise std x, y, z (bias removed)", _mm(self.noise_std)),
            ("per-joint bias RMS x, y, z", _mm(self.bias_rms)),
            ("mean per-joint error", f"{self.joint_error * 1000:.1f} mm"),
            (
                "vertical scatter, resting foot / pelvis",
                f"{self.vertical_scatter[0] * 100:.2f} / {self.vertical_scatter[1] * 100:.2f} cm",
            ),
        ]


def _range_percent(values: np.ndarray) -> str:
    return f"{np.nanmin(values) * 100:.1f}-{np.nanmax(values) * 100:.1f} %"


def _lag1(series: list[np.ndarray], follows: list[np.ndarray]) -> float:
    """Lag-1 autocorrelation pooled over series (each centred), only over consecutive pairs."""
    num = den_a = den_b = 0.0
    for values, consecutive in zip(series, follows, strict=True):
        centred = values - np.nanmean(values)
        pair = consecutive[1:] & np.isfinite(centred[1:]) & np.isfinite(centred[:-1])
        a, b = centred[:-1][pair], centred[1:][pair]
        num, den_a, den_b = num + a @ b, den_a + a @ a, den_b + b @ b
    return float(num / np.sqrt(den_a * den_b)) if den_a > 0 and den_b > 0 else float("nan")


def _limb_figures(observed: np.ndarray) -> tuple[np.ndarray, ...]:
    """Limb-length figures of one ``(F, 32, 3)`` stream.

    Returns per link the frames measured, the length CV and the CV left after the whole-body
    scale, and the ``(F,)`` scale itself (NaN where fewer than 8 links are measured).
    """
    parents = np.asarray(AZURE_KINECT.parents)
    lengths = np.linalg.norm(observed - observed[:, np.maximum(parents, 0)], axis=-1)
    lengths[:, parents < 0] = np.nan
    counts = np.isfinite(lengths).sum(axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN links and frames
        cv = limb_length_cv(observed)
        ratio = lengths / np.nanmedian(lengths, axis=0)
        scale = np.nanmedian(ratio, axis=1)
        scale[np.isfinite(ratio).sum(axis=1) < 8] = np.nan
        unscaled = ratio / scale[:, None]
        unscaled_cv = np.nanstd(unscaled, axis=0) / np.nanmean(unscaled, axis=0)
    return counts, cv, unscaled_cv, scale


def skeleton_errors(
    streams: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    interval: float,
    ups: Sequence[np.ndarray] | None = None,
) -> SkeletonErrors:
    """The ``SkeletonErrors`` figures pooled over streams (one per camera and person).

    Args:
        streams: ``(observed, reference, consecutive)`` per stream: ``(F, 32, 3)`` reported
            and true joints in the same frame (NaN where not reported) and ``(F,)`` True where
            a frame follows the previous one by one regular interval.
        interval: the frame interval, seconds.
        ups: per stream, ``(3,)`` the vertical in its frame (for ``vertical_scatter``).

    """
    cv2_sum = np.zeros(AZURE_KINECT.n_joints)
    unscaled2_sum = np.zeros(AZURE_KINECT.n_joints)
    cv_count = np.zeros(AZURE_KINECT.n_joints)
    scales, follows, noises, biases, errors = [], [], [], [], []
    vertical: list[list[np.ndarray]] = [[], []]
    for k, (observed, reference, consecutive) in enumerate(streams):
        counts, cv, unscaled, scale = _limb_figures(observed)
        if counts.max(initial=0) < 10:
            continue
        use = np.isfinite(cv) & (counts >= 10)
        cv2_sum[use] += counts[use] * cv[use] ** 2
        unscaled2_sum[use] += counts[use] * unscaled[use] ** 2
        cv_count[use] += counts[use]
        scales.append(scale)
        follows.append(np.asarray(consecutive, dtype=bool))
        residual = observed[:, _CORE] - reference[:, _CORE]  # (F, 17, 3)
        seen = np.isfinite(residual[..., 0]).sum(axis=0)  # (17,)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            bias = np.nanmean(residual, axis=0)
        bias[seen < 10] = np.nan
        noises.append(residual - bias)
        biases.append(bias)
        errors.append(np.linalg.norm(residual, axis=-1).ravel())
        if ups is not None:
            feet, pelvis = _vertical_errors(observed, reference, consecutive, interval, ups[k])
            vertical[0].extend(feet)
            vertical[1].extend(pelvis)
    if not noises:
        msg = "no stream has ten frames with the joints to measure"
        raise RecordingError(msg)
    all_scales = np.concatenate(scales)
    all_scales = all_scales[np.isfinite(all_scales)]
    rho = _lag1(scales, follows)
    noise = np.concatenate(noises)  # (F, 17, 3)
    child = np.flatnonzero(_CORE_PARENT >= 0)
    parent = np.searchsorted(_CORE, _CORE_PARENT[child])
    a, b = noise[:, child].reshape(-1, 3), noise[:, parent].reshape(-1, 3)
    pair = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    a, b = a[pair], b[pair]
    with np.errstate(invalid="ignore", divide="ignore"):
        limb_cv = np.sqrt(cv2_sum / cv_count)
        unscaled_limb_cv = np.sqrt(unscaled2_sum / cv_count)
    return SkeletonErrors(
        limb_cv=limb_cv,
        scale_cv=float(np.std(all_scales) / np.mean(all_scales)),
        unscaled_limb_cv=unscaled_limb_cv,
        scale_span=(float(np.percentile(all_scales, 5)), float(np.percentile(all_scales, 95))),
        scale_correlation_time=float(-interval / np.log(np.clip(rho, 1e-6, 0.999))),
        parent_correlation=np.sum(a * b, axis=0)
        / np.sqrt(np.sum(a * a, axis=0) * np.sum(b * b, axis=0)),
        noise_std=np.sqrt(np.nanmean(noise.reshape(-1, 3) ** 2, axis=0)),
        bias_rms=np.sqrt(np.nanmean(np.concatenate(biases) ** 2, axis=0)),
        joint_error=float(np.nanmean(np.concatenate(errors))),
        frames=int(sum(len(s) for s in scales)),
        vertical_scatter=np.array([_robust_sd(values) for values in vertical]),
    )


def _robust_sd(values: list[np.ndarray]) -> float:
    """1.4826 times the median absolute value of the pooled (each already centred) values."""
    pooled = np.concatenate(values) if values else np.zeros(0)
    return float(1.4826 * np.median(np.abs(pooled))) if len(pooled) else float("nan")


def _vertical_errors(
    observed: np.ndarray,
    reference: np.ndarray,
    consecutive: np.ndarray,
    interval: float,
    up: np.ndarray,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Vertical errors, each joint's median removed: the resting feet's, then the pelvis's.

    A foot rests where its reference joint moves slower than ``RESTING_SPEED`` over
    ``SPEED_BASELINE`` (the floor fit's rule), over frames that follow each other regularly.
    """
    half = max(1, round(0.5 * SPEED_BASELINE / interval))
    error = (observed - reference) @ up  # (F, 32)
    broken = np.concatenate([[0], np.cumsum(~np.asarray(consecutive, dtype=bool)[1:])])
    feet, pelvis = [], []
    if len(error) > 2 * half:
        regular = broken[2 * half :] == broken[: -2 * half]
        for joint in (AZURE_KINECT.index("FootLeft"), AZURE_KINECT.index("FootRight")):
            moved = np.linalg.norm(
                reference[2 * half :, joint] - reference[: -2 * half, joint], axis=-1
            )
            rests = np.zeros(len(error), dtype=bool)
            with np.errstate(invalid="ignore"):
                rests[half:-half] = regular & (moved / (2 * half * interval) < RESTING_SPEED)
            values = error[rests, joint]
            values = values[np.isfinite(values)]
            if len(values) >= 10:
                feet.append(values - np.median(values))
    values = error[:, AZURE_KINECT.index("Pelvis")]
    values = values[np.isfinite(values)]
    if len(values) >= 10:
        pelvis.append(values - np.median(values))
    return feet, pelvis


@dataclass
class Alignment:
    """Xsens -> camera: ``camera ≈ R xsens(t + shift) + t``.

    Attributes:
        shift: seconds to add to Kinect times (from its first frame) to get Xsens times.
        rotation: ``(3, 3)``.
        translation: ``(3,)``.
        rms: RMS residual over the frames the SDK did not flip, metres.
        flipped: ``(N,)`` frames whose residual exceeds ``flip_threshold``: the SDK reported a
            front/back flipped body there (the subject faces away from this camera).
        facing_cos: median cosine between the body's facing and the direction to the camera.

    """

    shift: float
    rotation: np.ndarray
    translation: np.ndarray
    rms: float
    flipped: np.ndarray
    facing_cos: float


def align(
    kinect_times: np.ndarray,
    kinect: np.ndarray,
    reference_rate: float,
    reference: np.ndarray,
    flip_threshold: float = 0.12,
) -> Alignment:
    """Time shift and rigid transform that best put ``reference`` onto ``kinect``.

    The time shift minimises the median per-frame rigid-fit residual, which ignores both the
    unknown global pose and the frames where the SDK flipped the body. The global transform is
    the per-frame transform most frames agree with (within ``flip_threshold``), refined on
    those frames.

    Args:
        kinect_times: ``(N,)`` seconds from the first Kinect frame.
        kinect: ``(N, 32, 3)`` camera frame, NaN frames allowed.
        reference_rate: the reference's frame rate.
        reference: ``(T, 32, 3)`` reference joints (any frame).
        flip_threshold: RMS (m) above which a frame counts as flipped.

    """
    seen = np.isfinite(kinect[:, 0, 0])

    def cost(shift: float) -> float:
        moved = _interpolate(kinect_times + shift, reference_rate, reference)
        ok = np.isfinite(moved[:, 0, 0]) & seen
        if ok.sum() < 0.6 * len(kinect_times):
            return np.inf
        _, rms = _kabsch_rms(moved[ok][:, _CORE], kinect[ok][:, _CORE])
        return float(np.median(rms))

    span = reference.shape[0] / reference_rate
    coarse = np.arange(-kinect_times[-1], span, 1.0 / reference_rate)
    best = coarse[int(np.argmin([cost(s) for s in coarse]))]
    fine = np.arange(best - 1.0 / reference_rate, best + 1.0 / reference_rate, 0.002)
    shift = float(fine[int(np.argmin([cost(s) for s in fine]))])

    moved = _interpolate(kinect_times + shift, reference_rate, reference)
    ok = np.flatnonzero(np.isfinite(moved[:, 0, 0]) & seen)
    src, dst = moved[ok][:, _CORE], kinect[ok][:, _CORE]
    # each frame's own transform, scored by how many frames it explains
    rotations, translations = kabsch_batch(dst, src)
    candidates = np.einsum("cij,fmj->cfmi", rotations, src) + translations[:, None, None]
    frame_rms = np.sqrt(np.mean(np.sum((candidates - dst[None]) ** 2, axis=3), axis=2))
    best_candidate = int(np.argmax((frame_rms < flip_threshold).sum(axis=1)))
    inliers = frame_rms[best_candidate] < flip_threshold
    pose = kabsch(dst[inliers].reshape(-1, 3), src[inliers].reshape(-1, 3))
    rotation, translation = pose.rotation.as_matrix(), pose.translation
    residual = dst - pose.apply(src)
    rms_all = np.sqrt(np.mean(np.sum(residual**2, axis=2), axis=1))
    flipped = np.zeros(len(kinect_times), dtype=bool)
    flipped[ok] = rms_all > flip_threshold
    good = ~flipped[ok]
    rms = float(np.sqrt(np.mean(np.sum(residual[good] ** 2, axis=2))))

    from hiros_sim.people import body_forward

    in_camera = moved[ok] @ rotation.T + translation
    facing = body_forward(in_camera @ _Y_DOWN_TO_Z_UP.T) @ _Y_DOWN_TO_Z_UP
    pelvis = in_camera[:, AZURE_KINECT.index("Pelvis")]
    to_camera = -pelvis / np.linalg.norm(pelvis, axis=1, keepdims=True)
    facing_cos = float(np.median(np.einsum("fc,fc->f", facing, to_camera)))
    return Alignment(shift, rotation, translation, rms, flipped, facing_cos)


_Y_DOWN_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""Camera axes (y down) to a Z-up frame for ``body_forward``, which wants Z up."""


@dataclass
class NoiseFit:
    """Figures of the fit; see the module docstring for how each is measured."""

    alignment: Alignment
    bias_rms: np.ndarray  # (3,) per camera axis, m
    noise_std: np.ndarray  # (3,) per camera axis, m
    noise_base: float  # m, lateral (x, y) sigma at depth 0
    noise_per_metre: float  # m per m of depth
    depth_axis_gain: float
    correlation_time: float  # s
    depth_range: tuple[float, float]
    frame_interval: float  # s
    jitter: float  # s
    drop_rate: float
    empty_rate: float
    per_joint_error: dict[str, float]  # RMS error per joint (bias + noise), m
    skeleton: SkeletonErrors  # limb lengths, body scale, joint-parent correlation

    def figures(self) -> list[tuple[str, str]]:
        """Named, formatted figures for a table or a report."""
        a = self.alignment
        worst = sorted(self.per_joint_error.items(), key=lambda kv: -kv[1])[:3]
        return [
            ("time shift Xsens - Kinect", f"{a.shift:.3f} s"),
            ("rigid fit RMS, unflipped frames", f"{a.rms * 1000:.1f} mm"),
            ("subject facing the camera (median cos)", f"{a.facing_cos:+.2f}"),
            ("frames the SDK flipped front/back", f"{np.mean(a.flipped) * 100:.0f} %"),
            ("per-joint bias RMS x, y, z", _mm(self.bias_rms)),
            ("noise std x, y, z (bias removed)", _mm(self.noise_std)),
            ("noise_base (x, y)", f"{self.noise_base * 1000:.1f} mm"),
            ("noise_per_metre", f"{self.noise_per_metre * 1000:.1f} mm/m"),
            ("depth_axis_gain (z / x, y)", f"{self.depth_axis_gain:.2f}"),
            ("depth range of the take", f"{self.depth_range[0]:.2f}-{self.depth_range[1]:.2f} m"),
            ("noise correlation time", f"{self.correlation_time * 1000:.0f} ms"),
            ("frame interval", f"{self.frame_interval * 1000:.1f} ms"),
            ("stamp jitter", f"{self.jitter * 1000:.2f} ms"),
            ("dropped frames", f"{self.drop_rate * 100:.2f} %"),
            ("frames with no body", f"{self.empty_rate * 100:.2f} %"),
            ("worst joints (RMS)", ", ".join(f"{n} {v * 1000:.0f} mm" for n, v in worst)),
            *self.skeleton.figures()[:8],
        ]


def _mm(values: np.ndarray) -> str:
    return ", ".join(f"{v * 1000:.1f}" for v in values) + " mm"


def fit_noise(bvh: str | Path = DEFAULT_BVH, csv: str | Path = DEFAULT_CSV) -> NoiseFit:
    """Align the Xsens take with the Kinect stream and measure the Kinect's errors."""
    motion = read_bvh(bvh)
    reference = map_to_azure(motion)
    stamps, kinect = read_kinect_csv(csv)
    times = stamps - stamps[0]
    alignment = align(times, kinect, motion.rate, reference)
    observed = kinect
    moved = _interpolate(times + alignment.shift, motion.rate, reference)
    moved = moved @ alignment.rotation.T + alignment.translation
    ok = np.isfinite(moved[:, 0, 0]) & np.isfinite(observed[:, 0, 0]) & ~alignment.flipped
    residual = (observed - moved)[ok][:, _CORE]  # (F, J, 3)
    bias = residual.mean(axis=0)  # (J, 3)
    noise = residual - bias
    depth = observed[ok][:, _CORE, 2]

    # sigma against depth: RMS of the lateral (x, y) noise in depth bins, then a line
    edges = np.quantile(depth, np.linspace(0.0, 1.0, 9))
    centres, sigmas, weights = [], [], []
    for lo, hi in itertools.pairwise(edges):
        sel = (depth >= lo) & (depth <= hi)
        if sel.sum() > 30:
            centres.append(depth[sel].mean())
            sigmas.append(np.sqrt(np.mean(noise[sel][:, :2] ** 2)))
            weights.append(sel.sum())
    slope, intercept = np.polyfit(centres, sigmas, 1, w=np.sqrt(weights))
    noise_std = noise.reshape(-1, 3).std(axis=0)

    # lag-1 autocorrelation over consecutive regular frames
    dt = np.diff(stamps)
    interval = float(np.median(dt))
    regular = np.abs(dt - interval) < 0.5 * interval
    index = np.flatnonzero(ok)
    consecutive = np.flatnonzero(np.diff(index) == 1)
    consecutive = consecutive[regular[index[consecutive]]]
    a, b = noise[consecutive], noise[consecutive + 1]
    rho = float(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)))
    correlation_time = -interval / np.log(np.clip(rho, 1e-6, 0.999))

    per_joint = np.sqrt(np.mean(np.sum(residual**2, axis=2), axis=0))
    follows = np.zeros(len(index), dtype=bool)
    follows[consecutive + 1] = True
    up = alignment.rotation[:, 2]  # the suit's vertical in the camera frame
    skeleton = skeleton_errors([(observed[ok], moved[ok], follows)], interval, [up])
    return NoiseFit(
        alignment=alignment,
        bias_rms=np.sqrt(np.mean(bias**2, axis=0)),
        noise_std=noise_std,
        noise_base=float(intercept),
        noise_per_metre=float(slope),
        depth_axis_gain=float(noise_std[2] / np.sqrt(np.mean(noise_std[:2] ** 2))),
        correlation_time=float(correlation_time),
        depth_range=(float(depth.min()), float(depth.max())),
        frame_interval=interval,
        jitter=float(np.std(dt[regular])),
        drop_rate=float(np.sum(np.round(dt[~regular] / interval) - 1) / len(stamps)),
        empty_rate=float(np.mean(~np.isfinite(kinect[:, 0, 0]))),
        per_joint_error={
            AZURE_KINECT.joint_names[j]: float(e) for j, e in zip(_CORE, per_joint, strict=True)
        },
        skeleton=skeleton,
    )


def take_scene(**changes: Any) -> SimParams:
    """The real take's situation as simulator settings, with ``changes`` to other fields.

    One camera 3.3 m from one person playing the take's own Xsens motion on the spot.
    """
    from hiros_sim.params import SimParams

    scene = SimParams(
        n_cameras=1,
        setup="room",
        n_people=1,
        duration=40.0,
        camera_radius=3.3,
        walk_area=0.0,
        bvh_files=(str(DEFAULT_BVH),),
    )
    return replace(scene, **changes)


def simulated_errors(
    params: SimParams | None = None, *, facing_only: bool = False
) -> SkeletonErrors:
    """The ``SkeletonErrors`` figures of the simulator's camera streams, to compare with the take.

    Simulates ``params`` with the SDK's discrete mistakes off (flips, swaps, ghosts, misses,
    dropped frames), so that only the joint noise model is measured. Joints outside the field
    of view (confidence 0) count as not reported. The default, with ``facing_only`` (frames
    where the body faces the camera within 60°), is the take's situation: one camera 3.3 m
    from one person playing the take's own Xsens motion.
    """
    from hiros_sim.simulate import simulate

    if params is None:
        params = take_scene()
        facing_only = True
    params = replace(
        params,
        flip_rate=0.0,
        flip_probability=0.0,
        swap_rate=0.0,
        ghost_rate=0.0,
        miss_rate=0.0,
        id_change_rate=0.0,
        drop_rate=0.0,
    )
    result = simulate(params)
    streams, ups = [], []
    for name, groups in result.camera_groups.items():
        cam = result.calibration.camera(name)
        stamps = np.array([group.stamp_ns for group in groups], dtype=np.int64)
        world = result.truth.at(cam.to_reference_time(stamps * 1e-9))  # (P, N, 32, 3)
        reference = cam.extrinsics.inverse().apply(world.reshape(-1, 3)).reshape(world.shape)
        observed = np.full(world.shape, np.nan)
        for n, (group, persons) in enumerate(zip(groups, result.labels[name], strict=True)):
            for skeleton, person in zip(group.skeletons, persons, strict=True):
                if person >= 0:
                    observed[person, n] = np.where(
                        skeleton.confidences[:, None] > 0.0, skeleton.positions, np.nan
                    )
        if facing_only:  # like the take, whose subject faces the camera
            from hiros_sim.people import body_forward

            to_camera = cam.translation - world[:, :, AZURE_KINECT.index("Pelvis")]
            facing = np.einsum("pnc,pnc->pn", body_forward(world), to_camera)
            observed[~(facing > 0.5 * np.linalg.norm(to_camera, axis=-1))] = np.nan
        follows = np.concatenate([[False], np.diff(stamps) < 1.5e9 / params.rate])
        streams.extend((observed[p], reference[p], follows) for p in range(world.shape[0]))
        ups.extend([cam.extrinsics.inverse().rotate(np.array([0.0, 0.0, 1.0]))] * world.shape[0])
    return skeleton_errors(streams, 1.0 / params.rate, ups)
