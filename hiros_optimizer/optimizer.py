"""The optimizer stage: each person keeps their own limb lengths, every frame.

Per track id the stage learns the limb (link) lengths from the person's frames, link by link
(:mod:`hiros_optimizer.learning`): over the last ``number_of_frames_for_calibration`` frames a
link measured in at least ``MIN_LINK_PRESENCE`` of them whose robust coefficient of variation
(``1.4826 MAD / median``) is below ``max_calibration_coefficient_of_variation`` is learnt, and
from then on constrained to its (unbiased) median. Links not learnt yet keep learning from the
raw measurements and follow them meanwhile, so chronically noisy or unseen short links (hand
tips, thumbs, the 7 cm pelvis-hip links) stay free without keeping a thigh free. A limb link
not learnt whose mirror link is borrows that one's length until its own is learnt
(``_borrow_from_mirrors``): a shank below both cameras' views, or a forearm a noisy SDK
jitters, no longer keeps its person unconstrained. A person is accepted once their limb
links are learnt or borrowed; the time that took, or what keeps a person from it past
``acceptance_timeout``, is reported (:meth:`Optimizer.people`, :meth:`Optimizer.report`).
Until a first link is learnt the person passes through unchanged.

Once a link is constrained, each frame's joints are replaced by the positions closest to the
measurement, weighted by confidence, that keep the learnt lengths exactly
(:func:`hiros_optimizer.kinematics.fit_fixed_lengths`, all people of a layout at once).
Outliers are joints that break the body and the motion at once: a joint at either end of a link
whose measured length is off by more than ``OUTLIER_THRESHOLD`` (relative, Hi-ROS's rule) is
down-weighted by ``(OUTLIER_DISTANCE / d)^2`` when it lies ``d > OUTLIER_DISTANCE`` from the
motion prediction (last output + velocity × dt). Requiring both keeps fast but consistent
motion (a whole arm swinging 25 cm in a frame) at full weight, and tells which end of a broken
link jumped. A small prior towards the prediction (``PRIOR_WEIGHT``) keeps unmeasured or
rejected joints where the motion puts them.

Person calibrations can be restarted (:meth:`Optimizer.calibrate`), moved to another id
(:meth:`Optimizer.change_id`) and exported/loaded as plain dicts (YAML on disk, see
``hiros_optimizer.calibration_file``) so a known person keeps their lengths across sessions.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np

from hiros_core.accounting import Accounted, Drops
from hiros_core.errors import ConfigError
from hiros_core.layouts import Layout, get_layout
from hiros_core.model import Skeleton, SkeletonGroup, SkeletonRows
from hiros_core.stacking import LayoutRows, output_skeletons, stack_frame
from hiros_optimizer.learning import PersonProgress, limb_links, window_statistics
from hiros_optimizer.memory import FitSettings, Memory

__all__ = [
    "CONFIDENCE_FLOOR",
    "MIN_LINK_PRESENCE",
    "OUTLIER_DISTANCE",
    "OUTLIER_THRESHOLD",
    "PRIOR_WEIGHT",
    "REFINEMENTS",
    "SWEEPS",
    "Optimizer",
    "OptimizerParams",
    "PersonCalibration",
    "PersonProgress",
]

SWEEPS = 1
"""Block-coordinate sweeps (root to leaves) that start each frame's fixed-length fit."""

REFINEMENTS = 2
"""Gauss-Newton steps on the length spheres that finish it (from the last frame's solution,
a sweep and two steps are enough: a numerical choice, not a setting)."""

MIN_LINK_PRESENCE = 0.5
"""Fraction of a person's calibration frames a link must be measured in to be learnt; rarer
links (a hand tip the SDK rarely sees) stay free."""

OUTLIER_THRESHOLD = 0.2
"""Relative link-length error that makes both ends of a link suspect (Hi-ROS's rule)."""

OUTLIER_DISTANCE = 0.15
"""Metres from the motion prediction beyond which a suspect joint is down-weighted, by
``(OUTLIER_DISTANCE / d)^2``: a whole arm swinging 25 cm in a frame is motion, not an outlier,
as long as its lengths hold."""

PRIOR_WEIGHT = 0.01
"""Weight of the motion prediction in the fit, relative to a joint confidence of 1: a small
pull that keeps an unmeasured or weakly measured joint moving with its track, too small to
override a measurement (0.05 measured no different: docs/ros-citizen.md)."""

CONFIDENCE_FLOOR = 0.1
"""Least weight of a present joint in the fit: the SDK's "none" confidence (0) still carries a
usable estimate, far better than extrapolation."""


@dataclass
class OptimizerParams:
    """Parameters of the optimizer node (ROS parameter names and defaults).

    The topics are the node's own parameters (``input_topic``, ``output_topic``), not the
    algorithm's.

    Attributes:
        number_of_frames_for_calibration: frames per person to learn the limb lengths from.
        max_calibration_coefficient_of_variation: a link's length is learnt (and from then
            on constrained) when its robust CV over those frames is below this.
        acceptance_timeout: seconds from a track's first frame within which its limb links
            should be learnt; a person not accepted by then is reported with the reason.
        track_timeout: seconds unseen after which a track's prediction is forgotten (its
            calibration is kept).
        export_calibration: node only: write the person calibrations on each new one.
        load_calibration: node only: read person calibrations at start.
        calibration_file: node only: YAML file of person calibrations.

    """

    number_of_frames_for_calibration: int = 60
    max_calibration_coefficient_of_variation: float = 0.2
    acceptance_timeout: float = 5.0
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
        if not self.acceptance_timeout > 0:
            msg = "acceptance_timeout must be greater than 0 seconds"
            raise ConfigError(msg)


@dataclass
class PersonCalibration:
    """One person's limb lengths.

    Attributes:
        layout: the layout the link ids refer to.
        lengths: ``(J,)`` metres by link id (= child joint id); NaN for free links (not
            learnt yet) and roots.
        variation: ``(J,)`` robust coefficient of variation seen during calibration (NaN if
            unknown, e.g. loaded without it).
        n_frames: frames the lengths were learnt from.
        borrowed: ``(J,)`` limb links whose length is their mirror link's (the other side's),
            until their own is learnt (empty, the default: none).

    """

    layout: Layout
    lengths: np.ndarray
    variation: np.ndarray
    n_frames: int = 0
    borrowed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __post_init__(self) -> None:
        if not len(self.borrowed):
            self.borrowed = np.zeros(len(self.lengths), dtype=bool)

    def to_dict(self) -> dict[str, Any]:
        """Plain types for YAML: links by name, ``{length, cv}`` in metres and as a fraction.

        A borrowed link's entry says so (``borrowed: true``), so that a loaded calibration goes
        on learning it.
        """
        links = {}
        for link_id in np.flatnonzero(np.isfinite(self.lengths)):
            entry: dict[str, Any] = {"length": round(float(self.lengths[link_id]), 6)}
            if np.isfinite(self.variation[link_id]):
                entry["cv"] = round(float(self.variation[link_id]), 6)
            if self.borrowed[link_id]:
                entry["borrowed"] = True
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
        borrowed = np.zeros(layout.n_joints, dtype=bool)
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
            borrowed[names[name]] = isinstance(entry, dict) and entry.get("borrowed") is True
        return cls(layout, lengths, variation, int(data.get("n_frames", 0)), borrowed)


@dataclass
class _Track:
    """One track id: its layout, its row in that layout's :class:`Memory`, its calibration.

    ``learning``: some link of the layout is not learnt yet (its window keeps filling).
    """

    layout: Layout
    row: int
    progress: PersonProgress
    calibration: PersonCalibration | None = None
    learning: bool = True

    def adopt(self, calibration: PersonCalibration | None, stamp_ns: int | None = None) -> None:
        """Take ``calibration`` (None: learn again from scratch); accepted at ``stamp_ns``."""
        self.calibration = calibration
        lengths = None if calibration is None else calibration.lengths
        links = self.layout.link_children
        self.learning = (
            calibration is None
            or bool(np.isnan(calibration.lengths[links]).any())
            or bool(calibration.borrowed[links].any())
        )
        accepted = lengths is not None and bool(np.isfinite(lengths[limb_links(self.layout)]).all())
        if not accepted:
            self.progress.accepted_ns = None
        elif self.progress.accepted_ns is None:
            self.progress.accepted_ns = self.progress.last_ns if stamp_ns is None else stamp_ns


class _Item(NamedTuple):
    """A tracked person of the frame: where their result goes and where their rows are."""

    index: int  # in the output group
    skeleton: Skeleton
    track_id: int  # the output id
    track: _Track
    row: int  # in the frame's stack of the layout


class Optimizer(Accounted):
    """Limb-length-preserving fit of each tracked person (module docstring).

    Attributes:
        params: the parameters.
        drops: reason -> count of skeletons not optimised (passed through or dropped; a
            frame is never dropped whole: each ``update`` is processed, see ``Accounted``).
        calibrations: track id -> :class:`PersonCalibration` (its learnt links, also while
            others are still being learnt).

    """

    def __init__(self, params: OptimizerParams | None = None) -> None:
        self.params = params or OptimizerParams()
        self.drops = Drops()
        self.calibrations: dict[int, PersonCalibration] = {}
        self._tracks: dict[int, _Track] = {}
        self._renames: dict[int, int] = {}
        self._memories: dict[str, Memory] = {}
        params = self.params
        self._settings = FitSettings(
            confidence_floor=CONFIDENCE_FLOOR,
            outlier_threshold=OUTLIER_THRESHOLD,
            outlier_distance=OUTLIER_DISTANCE,
            prior_weight=PRIOR_WEIGHT,
            track_timeout=params.track_timeout,
            sweeps=SWEEPS,
            refinements=REFINEMENTS,
        )
        self.new_calibrations: list[int] = []
        """Track ids with links learnt by the last :meth:`update` (the node exports on these)."""
        self.new_overdue: list[int] = []
        """Track ids the last :meth:`update` found not accepted within ``acceptance_timeout``."""
        _warm_up()

    # ----------------------------------------------------------------- person calibrations

    def calibrate(self, track_ids: list[int] | np.ndarray) -> bool:
        """Forget these tracks' lengths and learn them again from their next frames.

        Returns True when every id is known (seen or calibrated); unknown ids are ignored.
        An empty list asks for nothing: False.
        """
        if len(track_ids) == 0:
            return False
        known = True
        for requested in track_ids:
            track_id = self._renames.get(int(requested), int(requested))
            if track_id not in self._tracks and track_id not in self.calibrations:
                known = False
                continue
            self.calibrations.pop(track_id, None)
            track = self._tracks.get(track_id)
            if track is not None:
                track.adopt(None)
                track.progress = PersonProgress(track.progress.last_ns, track.progress.last_ns)
                self._memories[track.layout.name].restart_window(track.row)
        return known

    def change_id(self, from_id: int, to_id: int) -> bool:
        """From now on, track ``from_id`` is person ``to_id``: output id and calibration.

        If ``to_id`` already has a calibration (e.g. loaded for a known person) that one is
        kept; otherwise ``from_id``'s calibration and state move to ``to_id``. Returns False
        (and changes nothing) when ``from_id`` is unknown, ``to_id`` is a live track, the two
        are equal (nothing to change) or ``to_id`` is negative (-1 means "no id").
        """
        from_id, to_id = int(from_id), int(to_id)
        if from_id == to_id or to_id < 0:
            return False
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
            track.adopt(calibration)
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
            track = self._tracks.get(track_id)
            if track is not None and track.layout.name == calibration.layout.name:
                track.adopt(calibration)
        return sorted(loaded)

    # ----------------------------------------------------------------------------- progress

    def people(self) -> dict[int, PersonProgress]:
        """Track id -> how far its limb lengths are learnt (every track seen)."""
        return {track_id: track.progress for track_id, track in sorted(self._tracks.items())}

    def report(self) -> dict[int, str]:
        """Track id -> one sentence: acceptance time, or why the person is not accepted."""
        limit = self.params.max_calibration_coefficient_of_variation
        return {
            track_id: track.progress.summary(track.layout, limit)
            for track_id, track in sorted(self._tracks.items())
        }

    def diagnostics(self) -> dict[str, str]:
        """Key-values for ``/diagnostics``: acceptance time per person, or the reason."""
        return {f"person.{track_id}": text for track_id, text in self.report().items()}

    # ------------------------------------------------------------------------ per frame

    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Fit every calibrated person of ``group``; others pass through (module docstring)."""
        self.new_calibrations = []
        self.new_overdue = []
        out = self._fitted(group)
        self.processed += 1  # (once it went through: a frame whose fit raised is not)
        return out

    def _fitted(self, group: SkeletonGroup) -> SkeletonGroup:
        out = SkeletonGroup(group.stamp_ns, group.frame_id, [])
        if not group.skeletons:
            return out
        seen: set[int] = set()
        batches: dict[int, tuple[LayoutRows, list[_Item]]] = {}
        for skeleton, place in zip(
            group.skeletons, stack_frame(group.skeletons, self.drops), strict=True
        ):
            if place is None:
                continue
            track_id = self._renames.get(skeleton.id, skeleton.id)
            if track_id < 0:
                self.drops.detections("no track id (passed through)")
                result = skeleton.copy()
                result.id = track_id
                out.skeletons.append(result)
                continue
            if track_id in seen:
                self.drops.detections("track id repeated within a group")
                continue
            seen.add(track_id)
            stack, row = place
            track = self._track(track_id, skeleton.layout, skeleton.src_time_ns)
            item = _Item(len(out.skeletons), skeleton, track_id, track, row)
            batches.setdefault(id(stack), (stack, []))[1].append(item)
            out.skeletons.append(skeleton)  # replaced by its result below
        for stack, items in batches.values():
            self._update_layout(stack, items, out.skeletons)
        return out

    def _track(self, track_id: int, layout: Layout, stamp_ns: int) -> _Track:
        track = self._tracks.get(track_id)
        if track is None or track.layout.name != layout.name:
            if track is not None:
                self._memories[track.layout.name].release(track.row)
            memory = self._memories.get(layout.name)
            if memory is None:
                n = self.params.number_of_frames_for_calibration
                memory = self._memories[layout.name] = Memory(layout, n)
            track = _Track(layout, memory.allocate(), PersonProgress(stamp_ns, stamp_ns))
            track.adopt(self._calibration_for(track_id, layout), stamp_ns)
            self._tracks[track_id] = track
        track.progress.last_ns = max(track.progress.last_ns, stamp_ns)
        return track

    def _calibration_for(self, track_id: int, layout: Layout) -> PersonCalibration | None:
        calibration = self.calibrations.get(track_id)
        if calibration is not None and calibration.layout.name != layout.name:
            self.drops.detections("person calibration is for another layout (recalibrating)")
            del self.calibrations[track_id]
            return None
        return calibration

    def _update_layout(
        self, stack: LayoutRows, items: list[_Item], results: list[Skeleton]
    ) -> None:
        """Learn or fit the tracked people of one layout; their results into ``results``.

        The people with learnt links (fitted) and those without (learning) each take one
        :class:`Memory` call on their stacked rows (they touch disjoint tracks, so the order
        does not matter), and the links of the fitted people are rebuilt at once. Fitted
        people still learning some link first push their raw lengths into their window.
        """
        memory = self._memories[stack.layout.name]
        indices = [item.row for item in items]
        markers, present = stack.take(indices)
        rows = np.array([item.track.row for item in items])
        stamps = np.array([item.skeleton.src_time_ns for item in items], dtype=np.int64)
        calibrations = [item.track.calibration for item in items]
        fitting = [calibration is not None for calibration in calibrations]
        everyone = all(fitting)
        recording = np.flatnonzero(
            [
                calibration is not None and item.track.learning
                for calibration, item in zip(calibrations, items, strict=True)
            ]
        )
        if recording.size:
            memory.record(rows[recording], markers[recording], present[recording])
        if everyone:
            lengths = np.array([calibration.lengths for calibration in calibrations])
            links, link_present = memory.fit(
                rows, stamps, markers, present, lengths, settings=self._settings
            )
        else:
            links, link_present = stack.input_links(indices)  # the learning people's as they came
        if any(fitting) and not everyone:
            fit = np.flatnonzero(fitting)
            lengths = np.array([c.lengths for c in calibrations if c is not None])
            fit_markers = markers[fit]
            links[fit], link_present[fit] = memory.fit(
                rows[fit], stamps[fit], fit_markers, present[fit], lengths, settings=self._settings
            )
            markers[fit] = fit_markers
        if not everyone:
            learn = np.flatnonzero(np.logical_not(fitting))
            memory.learn(
                rows[learn], stamps[learn], markers[learn], present[learn], settings=self._settings
            )
        learning = [item for item in items if item.track.learning]
        if learning:
            self._check(memory, learning)
        output = SkeletonRows(markers, present, links, link_present, stack.input_boxes(indices))
        ids = [item.track_id for item in items]
        made = output_skeletons([item.skeleton for item in items], ids, output)
        for item, result in zip(items, made, strict=True):
            results[item.index] = result

    def _check(self, memory: Memory, items: list[_Item]) -> None:
        """Learn links from the full windows that are due; report people past the timeout.

        A window is checked on every frame until its person is accepted, then once per window
        length: what is left are extremities that may never be learnt, and checking them on
        every (overlapping) window would both cost the stage a sort per person and frame for
        good and, tested again and again, let a noisy link pass once by chance.
        """
        size = memory.window.shape[2]
        due = []
        timeout = self.params.acceptance_timeout
        for item in items:
            progress = item.track.progress
            filled = int(memory.filled[item.track.row])
            step = 1 if progress.accepted_ns is None else size
            if filled >= size and (filled - size) % step == 0:
                due.append(item)
        if due:
            self._learn_links(memory, due)
        for item in items:
            progress = item.track.progress
            if (
                progress.accepted_ns is None
                and not progress.overdue
                and (progress.seen_for > timeout)
            ):
                progress.overdue = True
                self.new_overdue.append(item.track_id)

    def _learn_links(self, memory: Memory, due: list[_Item]) -> None:
        """Lock the links each due window has learnt; a person's learnt links stay locked."""
        params = self.params
        layout = memory.layout
        statistics = window_statistics(
            memory.window[[item.track.row for item in due]],
            MIN_LINK_PRESENCE,
            params.max_calibration_coefficient_of_variation,
        )
        links, limbs = layout.link_children, limb_links(layout)
        for row, item in enumerate(due):
            track = item.track
            old = track.calibration
            none = np.zeros(layout.n_joints, dtype=bool)
            known = none if old is None else np.isfinite(old.lengths)
            was_borrowed = none if old is None else old.borrowed
            own = known & ~was_borrowed
            kept = np.full(layout.n_joints, np.nan) if old is None else old.lengths
            steady = np.where(statistics.learnt[row], statistics.lengths[row], np.nan)
            lengths = np.where(own, kept, steady)  # a borrowed link's own length replaces it
            lengths, borrowed = _borrow_from_mirrors(lengths, layout)
            if np.isfinite(lengths[limbs]).all():  # accepted: every link seen often enough
                lengths = np.where(np.isfinite(lengths), lengths, statistics.lengths[row])
            variation = statistics.variation[row]
            if old is not None:
                variation = np.where(own, old.variation, variation)
            free = np.zeros(layout.n_joints, dtype=bool)
            free[links] = np.isnan(lengths[links])
            track.progress.observe(statistics, row, free, borrowed)
            if np.array_equal(np.isfinite(lengths), known) and np.array_equal(
                borrowed, was_borrowed
            ):
                continue  # nothing new learnt
            calibration = PersonCalibration(
                layout, lengths, variation, memory.window.shape[2], borrowed
            )
            track.adopt(calibration, item.skeleton.src_time_ns)
            self.calibrations[item.track_id] = calibration
            self.new_calibrations.append(item.track_id)


def _borrow_from_mirrors(lengths: np.ndarray, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """Limb links not learnt take their mirror link's own length; ``(J,)`` and which did.

    A person's left and right limbs are alike in length (long bones differ by about a
    centimetre in healthy adults), whereas a limb a camera pair never sees whole (a shank
    below both views), or sees only through a noisy SDK's jitter, may not be learnt for many
    seconds. Borrowed, it is constrained at once and its person accepted; its own length
    replaces the borrowed one once learnt, so a real difference between the sides shows.
    """
    limbs = limb_links(layout)
    mirrors = np.asarray(layout.mirror)[limbs]
    take = np.isnan(lengths[limbs]) & np.isfinite(lengths[mirrors])
    out = lengths.copy()
    out[limbs[take]] = lengths[mirrors[take]]
    borrowed = np.zeros(len(lengths), dtype=bool)
    borrowed[limbs[take]] = True
    return out, borrowed


@lru_cache(maxsize=1)
def _warm_up() -> None:
    """Compile (or load from numba's disk cache) the frame kernels now, not at the first frame.

    Once per process: a live node would otherwise stall on its first people (about 0.5 s from
    the cache, over 10 s on a machine that never compiled them).
    """
    layout = get_layout("azure_kinect")
    memory = Memory(layout, 3)
    rows = np.array([memory.allocate()])
    markers = np.zeros((1, layout.n_joints, 20))
    present = np.ones((1, layout.n_joints), dtype=bool)
    settings = FitSettings(0.1, 0.2, 0.15, 0.01, 1.0, 1, 2)
    memory.learn(rows, np.zeros(1, dtype=np.int64), markers, present, settings=settings)
    lengths = np.where(memory.tree.has_parent, 0.1, np.nan)[None]
    memory.fit(rows, np.ones(1, dtype=np.int64), markers, present, lengths, settings=settings)
