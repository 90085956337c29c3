"""The optimizer stage: each person keeps their own limb lengths, every frame.

Per track id the stage first learns the limb (link) lengths over the person's first frames:
per link the median of the measured lengths over the last ``number_of_frames_for_calibration``
frames. A link is steady when its robust coefficient of variation (``1.4826 MAD / median``) is
below ``max_calibration_coefficient_of_variation`` (Hi-ROS's acceptance rule, with robust
statistics so a few bad frames do not spoil it). The person calibration is accepted once at
least ``min_calibrated_fraction`` of the layout's links are steady — a steady view of the body —
so that chronically noisy short links (hand tips, thumbs, the 7 cm pelvis-hip links) cannot
block a person forever. Then every link measured in at least ``min_link_presence`` of the
window is constrained to its median: a noisy link's median is still a good length (its
standard error shrinks with the window), only rarely seen links stay free (follow the
measurement). Until acceptance the window slides and the person passes through unchanged.

Once calibrated, each frame's joints are replaced by the positions closest to the measurement,
weighted by confidence, that keep the calibrated lengths exactly
(:func:`hiros_optimizer.kinematics.fit_fixed_lengths`, all people of a layout at once).
Outliers are joints that break the body and the motion at once: a joint at either end of a link
whose measured length is off by more than ``outlier_threshold`` (relative, Hi-ROS's rule) is
down-weighted by ``(outlier_distance / d)^2`` when it lies ``d > outlier_distance`` from the
motion prediction (last output + velocity × dt). Requiring both keeps fast but consistent
motion (a whole arm swinging 25 cm in a frame) at full weight, and tells which end of a broken
link jumped. A small prior towards the prediction (``prior_weight``) keeps unmeasured or
rejected joints where the motion puts them.

Person calibrations can be restarted (:meth:`Optimizer.calibrate`), moved to another id
(:meth:`Optimizer.change_id`) and exported/loaded as plain dicts (YAML on disk, see
``hiros_optimizer.calibration_file``) so a known person keeps their lengths across sessions.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from hiros_core.errors import ConfigError
from hiros_core.layouts import Layout, get_layout
from hiros_core.model import Skeleton, SkeletonGroup, link_rows, ns_to_sec
from hiros_optimizer.kinematics import KinematicTree, fit_fixed_lengths, link_lengths

__all__ = ["Optimizer", "OptimizerParams", "PersonCalibration"]

_MAD_TO_SD = 1.4826  # MAD of a normal distribution times this is its standard deviation
_MIN_VELOCITY_DT = 1e-3  # s; closer frames (duplicates) would turn noise into huge velocities


@dataclass
class OptimizerParams:
    """Parameters of the optimizer node (ROS parameter names and defaults).

    The topics are the node's own parameters (``input_topic``, ``output_topic``), not the
    algorithm's.

    Attributes:
        number_of_frames_for_calibration: frames per person to learn the limb lengths from.
        max_calibration_coefficient_of_variation: a person calibration is accepted when every
            constrained link's robust CV is below this.
        min_link_presence: fraction of the calibration frames a link must be measured in to be
            constrained; rarer links stay free.
        min_calibrated_fraction: fraction of the layout's links whose CV must be below the
            maximum for a person calibration to be accepted.
        outlier_threshold: relative link-length error that makes both ends of a link suspect.
        outlier_distance: metres from the prediction beyond which a suspect joint is
            down-weighted.
        prior_weight: weight of the motion prediction relative to a joint confidence of 1.
        confidence_floor: least weight of a present joint in the fit: the SDK's "none"
            confidence (0) still carries a usable estimate, far better than extrapolation.
        sweeps: block-coordinate sweeps of the fit (its starting point).
        refinements: Gauss-Newton steps of the fit.
        compiled: run the fit as a numba kernel (:mod:`hiros_optimizer.compiled`; the same
            results as the numpy version to ~1e-11 m, ~40x faster; compiled on the first fit
            and cached on disk), else with numpy.
        track_timeout: seconds unseen after which a track's prediction is forgotten (its
            calibration is kept).
        export_calibration: node only: write the person calibrations on each new one.
        load_calibration: node only: read person calibrations at start.
        calibration_file: node only: YAML file of person calibrations.

    """

    number_of_frames_for_calibration: int = 60
    max_calibration_coefficient_of_variation: float = 0.2
    min_link_presence: float = 0.5
    min_calibrated_fraction: float = 0.8
    outlier_threshold: float = 0.2
    outlier_distance: float = 0.15
    prior_weight: float = 0.01
    confidence_floor: float = 0.1
    sweeps: int = 1
    refinements: int = 2
    compiled: bool = True
    track_timeout: float = 1.0
    export_calibration: bool = False
    load_calibration: bool = False
    calibration_file: str = ""

    def __post_init__(self) -> None:
        if self.number_of_frames_for_calibration < 3:
            msg = "number_of_frames_for_calibration must be at least 3 frames"
            raise ConfigError(msg)
        if self.max_calibration_coefficient_of_variation <= 0:
            msg = "max_calibration_coefficient_of_variation must be greater than 0"
            raise ConfigError(msg)
        if not (0 < self.min_link_presence <= 1 and 0 < self.min_calibrated_fraction <= 1):
            msg = "min_link_presence and min_calibrated_fraction must be in (0, 1]"
            raise ConfigError(msg)
        if min(self.outlier_threshold, self.outlier_distance) <= 0 or (
            min(self.prior_weight, self.confidence_floor) < 0
        ):
            msg = "outlier_threshold, outlier_distance must be > 0; prior_weight, floor >= 0"
            raise ConfigError(msg)


@dataclass
class PersonCalibration:
    """One person's limb lengths.

    Attributes:
        layout: the layout the link ids refer to.
        lengths: ``(J,)`` metres by link id (= child joint id); NaN for free links and roots.
        variation: ``(J,)`` robust coefficient of variation seen during calibration (NaN if
            unknown, e.g. loaded without it).
        n_frames: frames the lengths were learnt from.

    """

    layout: Layout
    lengths: np.ndarray
    variation: np.ndarray
    n_frames: int = 0

    def to_dict(self) -> dict[str, Any]:
        """Plain types for YAML: links by name, ``{length, cv}`` in metres and as a fraction."""
        links = {}
        for link_id in np.flatnonzero(np.isfinite(self.lengths)):
            entry = {"length": round(float(self.lengths[link_id]), 6)}
            if np.isfinite(self.variation[link_id]):
                entry["cv"] = round(float(self.variation[link_id]), 6)
            links[self.layout.link_names[link_id]] = entry
        return {"layout": self.layout.name, "n_frames": int(self.n_frames), "links": links}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PersonCalibration:
        """Inverse of :meth:`to_dict`; raises ConfigError naming what is wrong."""
        if not isinstance(data, dict) or not isinstance(data.get("links"), dict):
            msg = "a person calibration must be a mapping with 'layout' and 'links'"
            raise ConfigError(msg)
        layout = get_layout(str(data.get("layout", "azure_kinect")))
        names = {name: i for i, name in enumerate(layout.link_names) if name}
        lengths = np.full(layout.n_joints, np.nan)
        variation = np.full(layout.n_joints, np.nan)
        for name, entry in data["links"].items():
            if name not in names:
                msg = f"link {name!r} is not a link of layout {layout.name!r}"
                raise ConfigError(msg)
            value = entry.get("length") if isinstance(entry, dict) else entry
            try:
                length = float(value)
            except (TypeError, ValueError):
                msg = f"link {name!r} needs a numeric length in metres, got {value!r}"
                raise ConfigError(msg) from None
            if not length > 0:
                msg = f"link {name!r} has a non-positive length {length}"
                raise ConfigError(msg)
            lengths[names[name]] = length
            if isinstance(entry, dict) and entry.get("cv") is not None:
                variation[names[name]] = float(entry["cv"])
        return cls(layout, lengths, variation, int(data.get("n_frames", 0)))


@dataclass
class _Track:
    """What the stage remembers about one track id."""

    layout: Layout
    window: np.ndarray  # (J, N) measured link lengths of the last N frames, NaN where missing
    filled: int = 0  # frames pushed into the window (saturates at N... and beyond)
    calibration: PersonCalibration | None = None
    positions: np.ndarray | None = None  # (J, 3) last output
    velocities: np.ndarray | None = None  # (J, 3) from the last two outputs
    vectors: np.ndarray | None = None  # (J, 3) last link vectors, to start unseen links from
    time_ns: int | None = None

    def forget_motion(self) -> None:
        self.positions = self.velocities = self.vectors = None
        self.time_ns = None


class Optimizer:
    """Limb-length-preserving fit of each tracked person (module docstring).

    Attributes:
        params: the parameters.
        drops: reason -> count of skeletons not optimised (passed through or dropped).
        calibrations: track id -> accepted :class:`PersonCalibration`.

    """

    def __init__(self, params: OptimizerParams | None = None) -> None:
        self.params = params or OptimizerParams()
        self.drops: Counter[str] = Counter()
        self.calibrations: dict[int, PersonCalibration] = {}
        self._tracks: dict[int, _Track] = {}
        self._renames: dict[int, int] = {}
        self._trees: dict[str, KinematicTree] = {}
        self.new_calibrations: list[int] = []
        """Track ids calibrated by the last :meth:`update` (the node exports on these)."""
        if self.params.compiled:
            _warm_up()

    # ----------------------------------------------------------------- person calibrations

    def calibrate(self, track_ids: list[int] | np.ndarray) -> bool:
        """Forget these tracks' lengths and learn them again from their next frames.

        Returns True when every id is known (seen or calibrated); unknown ids are ignored.
        """
        known = True
        for requested in track_ids:
            track_id = self._renames.get(int(requested), int(requested))
            if track_id not in self._tracks and track_id not in self.calibrations:
                known = False
                continue
            self.calibrations.pop(track_id, None)
            track = self._tracks.get(track_id)
            if track is not None:
                track.calibration = None
                track.window[:] = np.nan
                track.filled = 0
        return known

    def change_id(self, from_id: int, to_id: int) -> bool:
        """From now on, track ``from_id`` is person ``to_id``: output id and calibration.

        If ``to_id`` already has a calibration (e.g. loaded for a known person) that one is
        kept; otherwise ``from_id``'s calibration and state move to ``to_id``. Returns False
        (and changes nothing) when ``from_id`` is unknown or ``to_id`` is a live track.
        """
        from_id, to_id = int(from_id), int(to_id)
        source = self._renames.get(from_id, from_id)
        if source not in self._tracks and source not in self.calibrations:
            return False
        if to_id != source and to_id in self._tracks:
            return False
        # Incoming skeletons with from_id (and anything already renamed to it) go to to_id.
        for incoming, target in list(self._renames.items()):
            if target == source:
                self._renames[incoming] = to_id
        self._renames[from_id] = to_id
        if to_id == source:
            return True
        track = self._tracks.pop(source, None)
        calibration = self.calibrations.pop(source, None)
        if to_id in self.calibrations:
            calibration = self.calibrations[to_id]
        if calibration is not None:
            self.calibrations[to_id] = calibration
        if track is not None:
            track.calibration = calibration
            self._tracks[to_id] = track
        return True

    def export_calibrations(self) -> dict[str, Any]:
        """All accepted person calibrations as plain types: ``{"people": {id: {...}}}``."""
        return {
            "people": {
                int(track_id): calibration.to_dict()
                for track_id, calibration in sorted(self.calibrations.items())
            }
        }

    def load_calibrations(self, data: dict[str, Any]) -> list[int]:
        """Adopt person calibrations from :meth:`export_calibrations`' form; returns the ids."""
        people = data.get("people") if isinstance(data, dict) else None
        if not isinstance(people, dict):
            msg = "a person calibration file must hold a mapping 'people: {track_id: ...}'"
            raise ConfigError(msg)
        loaded = {}
        for key, entry in people.items():
            try:
                track_id = int(key)
            except (TypeError, ValueError):
                msg = f"person calibration key {key!r} is not an integer track id"
                raise ConfigError(msg) from None
            loaded[track_id] = PersonCalibration.from_dict(entry)
        for track_id, calibration in loaded.items():
            self.calibrations[track_id] = calibration
            if track_id in self._tracks:
                self._tracks[track_id].calibration = calibration
        return sorted(loaded)

    # ------------------------------------------------------------------------ per frame

    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Fit every calibrated person of ``group``; others pass through (module docstring)."""
        self.new_calibrations = []
        out = SkeletonGroup(group.stamp_ns, group.frame_id, [])
        seen: set[int] = set()
        learning: dict[str, list[tuple[int, Skeleton, _Track]]] = {}
        batches: dict[str, list[tuple[int, Skeleton, _Track]]] = {}
        for skeleton in group.skeletons:
            if skeleton.markers.shape[0] != skeleton.layout.n_joints:
                self.drops["marker rows do not match the layout"] += 1
                continue
            present = skeleton.marker_present
            if not np.isfinite(skeleton.positions[present]).all():
                self.drops["non-finite position of a present joint"] += 1
                continue
            result = skeleton.copy()
            result.id = self._renames.get(skeleton.id, skeleton.id)
            if result.id < 0:
                self.drops["no track id (passed through)"] += 1
                out.skeletons.append(result)
                continue
            if result.id in seen:
                self.drops["track id repeated within a group"] += 1
                continue
            seen.add(result.id)
            out.skeletons.append(result)
            track = self._track(result)
            target = learning if track.calibration is None else batches
            target.setdefault(result.layout.name, []).append((result.id, result, track))
        # Learning and fitting touch disjoint tracks, so their order does not matter.
        for items in learning.values():
            self._learn(items)
        for items in batches.values():
            self._fit(items)
        return out

    def _track(self, skeleton: Skeleton) -> _Track:
        track = self._tracks.get(skeleton.id)
        if track is None or track.layout.name != skeleton.layout.name:
            n = self.params.number_of_frames_for_calibration
            track = _Track(skeleton.layout, np.full((skeleton.layout.n_joints, n), np.nan))
            track.calibration = self._calibration_for(skeleton.id, skeleton.layout)
            self._tracks[skeleton.id] = track
        elif track.time_ns is not None and (
            ns_to_sec(skeleton.src_time_ns - track.time_ns) > self.params.track_timeout
            or skeleton.src_time_ns < track.time_ns
        ):
            track.forget_motion()
        return track

    def _calibration_for(self, track_id: int, layout: Layout) -> PersonCalibration | None:
        calibration = self.calibrations.get(track_id)
        if calibration is not None and calibration.layout.name != layout.name:
            self.drops["person calibration is for another layout (recalibrating)"] += 1
            del self.calibrations[track_id]
            return None
        return calibration

    def _tree(self, layout: Layout) -> KinematicTree:
        tree = self._trees.get(layout.name)
        if tree is None:
            tree = self._trees[layout.name] = KinematicTree.from_layout(layout)
        return tree

    def _learn(self, items: list[tuple[int, Skeleton, _Track]]) -> None:
        """Push this frame's link lengths; accept calibrations whose window is steady.

        All learning people of one layout at once: one link-length computation, and one
        median over the windows of those whose window is full.
        """
        layout = items[0][1].layout
        skeletons = [skeleton for _, skeleton, _ in items]
        present = np.array([skeleton.marker_present for skeleton in skeletons])
        measured = np.array([skeleton.positions for skeleton in skeletons])
        weights = _stacked_weights(skeletons, present)
        positions = np.where((weights > 0)[..., None], measured, np.nan)
        lengths = link_lengths(positions, self._tree(layout).parents)
        full: list[tuple[int, _Track]] = []
        for (track_id, _, track), row_lengths in zip(items, lengths, strict=True):
            size = track.window.shape[1]
            track.window[:, track.filled % size] = row_lengths
            track.filled += 1
            if track.filled >= size:
                full.append((track_id, track))
        self._remember_all(
            [track for _, _, track in items],
            skeletons,
            np.where(present[..., None], measured, np.nan),
        )
        if full:
            self._accept(layout, full)

    def _remember_all(
        self,
        tracks: list[_Track],
        skeletons: list[Skeleton],
        positions: np.ndarray,
        vectors: np.ndarray | None = None,
    ) -> None:
        """:meth:`_remember` of several tracks at once.

        ``positions`` ``(P, J, 3)`` are the skeletons' positions, NaN where absent;
        ``vectors`` ``(P, J, 3)`` their fitted link vectors (None while learning).
        """
        previous = np.full_like(positions, np.nan)
        dt = np.zeros(len(tracks))
        for row, (track, skeleton) in enumerate(zip(tracks, skeletons, strict=True)):
            if track.positions is not None:
                previous[row] = track.positions
            if track.time_ns is not None:
                dt[row] = ns_to_sec(skeleton.src_time_ns - track.time_ns)
        with np.errstate(invalid="ignore", divide="ignore"):
            velocities = (positions - previous) / np.where(dt > 0, dt, 1.0)[:, None, None]
        velocities = np.where(np.isfinite(velocities), velocities, 0.0)
        kept = np.where(np.isfinite(positions), positions, previous)
        for row, (track, skeleton) in enumerate(zip(tracks, skeletons, strict=True)):
            if track.positions is None:
                track.velocities = None
                track.positions = positions[row]
            else:
                if dt[row] >= _MIN_VELOCITY_DT:
                    track.velocities = velocities[row]
                # A joint missing this frame keeps its last position (the prediction survives).
                track.positions = kept[row]
            track.vectors = None if vectors is None else vectors[row]
            track.time_ns = skeleton.src_time_ns

    def _accept(self, layout: Layout, full: list[tuple[int, _Track]]) -> None:
        """Accept the calibration of each full window that is steady enough."""
        params = self.params
        windows = np.array([track.window for _, track in full])  # (R, J, N)
        size = windows.shape[2]
        count = size - np.isnan(windows).sum(axis=2)  # (R, J) frames each link was measured in
        seen = count / size >= params.min_link_presence
        median = _nanmedian_last(windows, count)
        with np.errstate(invalid="ignore", divide="ignore"):
            mad = _nanmedian_last(np.abs(windows - median[..., None]), count)
            variation = np.where(seen, _MAD_TO_SD * mad / median, np.nan)
        median = np.where(seen, median, np.nan)
        with np.errstate(invalid="ignore"):
            steady = (
                seen & (median > 0) & (variation < params.max_calibration_coefficient_of_variation)
            )
        enough = steady.sum(axis=1) >= params.min_calibrated_fraction * layout.link_children.size
        if not enough.any():
            return
        # Noise perpendicular to a link lengthens it on average: |d + n|^2 = L^2 + 3 s^2 with
        # s the per-axis noise of d, of which the radial part shows as the spread s of the
        # lengths; the two perpendicular axes add 2 s^2, which is removed here.
        spread = variation * median
        unbiased = np.sqrt(np.maximum(median**2 - 2 * spread**2, 0.25 * median**2))
        lengths = np.where(seen & (median > 0), unbiased, np.nan)
        for row in np.flatnonzero(enough):
            track_id, track = full[row]
            track.calibration = PersonCalibration(
                layout, lengths[row], variation[row], track.window.shape[1]
            )
            self.calibrations[track_id] = track.calibration
            self.new_calibrations.append(track_id)

    def _fit(self, items: list[tuple[int, Skeleton, _Track]]) -> None:
        """One least-squares fit for all calibrated people of one layout."""
        layout = items[0][1].layout
        tree = self._tree(layout)
        n_people, n_joints = len(items), layout.n_joints
        skeletons = [skeleton for _, skeleton, _ in items]
        tracks = [track for _, _, track in items]
        markers = np.array([skeleton.markers for skeleton in skeletons])  # the output rows
        present = np.array([skeleton.marker_present for skeleton in skeletons])
        measured = markers[..., 1:4].copy()
        weights = _stacked_weights(skeletons, present, self.params.confidence_floor)
        lengths = np.array([track.calibration.lengths for track in tracks])
        prior = np.full((n_people, n_joints, 3), np.nan)
        fallback = np.full((n_people, n_joints, 3), np.nan)
        for row, (skeleton, track) in enumerate(zip(skeletons, tracks, strict=True)):
            if track.positions is not None:
                dt = max(ns_to_sec(skeleton.src_time_ns - track.time_ns), 0.0)
                velocity = 0.0 if track.velocities is None else track.velocities
                prior[row] = track.positions + velocity * dt
                fallback[row] = track.vectors
        weights = weights * self._outlier_factors(tree, measured, lengths, prior)
        positions, vectors = fit_fixed_lengths(
            tree,
            measured,
            weights,
            lengths,
            prior=prior,
            prior_weight=self.params.prior_weight,
            fallback_vectors=fallback,
            sweeps=self.params.sweeps,
            refinements=self.params.refinements,
            compiled=self.params.compiled,
        )
        # Present joints take the fit; links of everyone at once; the skeletons (the stage's
        # own copies) take the new rows.
        np.copyto(markers[..., 1:4], positions, where=present[..., None])
        links, link_present = link_rows(markers, present, layout)
        for row, skeleton in enumerate(skeletons):
            skeleton.markers, skeleton.links = markers[row], links[row]
            skeleton.link_present = link_present[row]
        self._remember_all(
            tracks, skeletons, np.where(present[..., None], markers[..., 1:4], np.nan), vectors
        )

    def _outlier_factors(
        self, tree: KinematicTree, measured: np.ndarray, lengths: np.ndarray, prior: np.ndarray
    ) -> np.ndarray:
        """``(P, J)`` weight factors: < 1 for joints off both the body and the motion."""
        with np.errstate(invalid="ignore", divide="ignore"):
            error = np.abs(link_lengths(measured, tree.parents) - lengths) / lengths
            broken = error > self.params.outlier_threshold  # (P, J) by child joint
            suspect = broken | ((broken.astype(float) @ tree.parent_of) > 0)
            distance = np.linalg.norm(measured - prior, axis=-1)
            factor = np.minimum(1.0, (self.params.outlier_distance / distance) ** 2)
        return np.where(suspect & np.isfinite(factor), factor, 1.0)


@lru_cache(maxsize=1)
def _warm_up() -> None:
    """Compile (or load from numba's disk cache) the fit kernel now, not at the first fit.

    Once per process: a live node would otherwise stall on its first calibrated person (about
    0.5 s from the cache, over 10 s on a machine that never compiled it).
    """
    tree = KinematicTree.from_layout(get_layout("azure_kinect"))
    positions = np.zeros((1, len(tree.parents), 3))
    lengths = np.where(tree.has_parent, 0.1, np.nan)[None]
    fit_fixed_lengths(tree, positions, np.ones(positions.shape[:2]), lengths, compiled=True)


def _nanmedian_last(values: np.ndarray, count: np.ndarray) -> np.ndarray:
    """``np.nanmedian(values, axis=-1)`` of ``(R, J, N)`` with ``count`` non-NaN values each.

    One sort (NaN sorts last) and two gathers give the same numbers as numpy's (mean of the two
    middle values for an even count, NaN where nothing was measured) at a fraction of the
    cost: numpy's small-array path goes through masked arrays, which made the calibration
    check the stage's most expensive step.
    """
    size = values.shape[-1]
    ordered = np.sort(values, axis=-1).reshape(-1)
    base = np.arange(count.size).reshape(count.shape) * size
    low = ordered[base + np.maximum(count - 1, 0) // 2]
    high = ordered[base + count // 2]
    return np.where(count > 0, (low + high) / 2, np.nan)


def _stacked_weights(
    skeletons: list[Skeleton], present: np.ndarray, floor: float = 0.0
) -> np.ndarray:
    """``(P, J)`` :func:`_weights` of several skeletons of one layout."""
    confidence = np.array([skeleton.confidences for skeleton in skeletons])
    confidence = np.where(np.isfinite(confidence), confidence, 1.0)
    return np.where(present, np.clip(confidence, floor, None), 0.0)
