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
=====================================  ==============================================

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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hiros_core.errors import RecordingError
from hiros_core.layouts import AZURE_KINECT
from hiros_data import DATA_DIR
from hiros_sim.bvh import read_bvh
from hiros_sim.mapping import map_to_azure

__all__ = ["NoiseFit", "align", "fit_noise", "read_kinect_csv"]

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


def _kabsch(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Rotation, translation and RMS of ``target ≈ R source + t`` for ``(M, 3)`` points."""
    mean_s, mean_t = source.mean(axis=0), target.mean(axis=0)
    h = (source - mean_s).T @ (target - mean_t)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    translation = mean_t - rotation @ mean_s
    residual = target - (source @ rotation.T + translation)
    return rotation, translation, float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))


def _interpolate(times: np.ndarray, rate: float, positions: np.ndarray) -> np.ndarray:
    frame = times * rate
    valid = (frame >= 0) & (frame <= positions.shape[0] - 1)
    lower = np.clip(np.floor(frame).astype(int), 0, positions.shape[0] - 2)
    w = (frame - lower)[:, None, None]
    out = (1.0 - w) * positions[lower] + w * positions[lower + 1]
    out[~valid] = np.nan
    return out


def _kabsch_batch(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame Kabsch for ``(F, M, 3)`` point sets: rotations ``(F, 3, 3)``, RMS ``(F,)``."""
    src = source - source.mean(axis=1, keepdims=True)
    dst = target - target.mean(axis=1, keepdims=True)
    u, _, vt = np.linalg.svd(np.einsum("fmi,fmj->fij", src, dst))
    d = np.sign(np.linalg.det(np.einsum("fji,fkj->fik", vt, u)))
    fix = np.ones((len(d), 3))
    fix[:, 2] = d
    rotation = np.einsum("fji,fj,fkj->fik", vt, fix, u)
    residual = dst - np.einsum("fij,fmj->fmi", rotation, src)
    return rotation, np.sqrt(np.mean(np.sum(residual**2, axis=2), axis=1))


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
        _, rms = _kabsch_batch(moved[ok][:, _CORE], kinect[ok][:, _CORE])
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
    rotations, _ = _kabsch_batch(src, dst)
    translations = dst.mean(axis=1) - np.einsum("fij,fj->fi", rotations, src.mean(axis=1))
    candidates = np.einsum("cij,fmj->cfmi", rotations, src) + translations[:, None, None]
    frame_rms = np.sqrt(np.mean(np.sum((candidates - dst[None]) ** 2, axis=3), axis=2))
    best_candidate = int(np.argmax((frame_rms < flip_threshold).sum(axis=1)))
    inliers = frame_rms[best_candidate] < flip_threshold
    rotation, translation, _ = _kabsch(src[inliers].reshape(-1, 3), dst[inliers].reshape(-1, 3))
    residual = dst - (src @ rotation.T + translation)
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
    )
