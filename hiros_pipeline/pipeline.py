"""The four stages composed in one process: objects passed directly, no serialisation.

``Pipeline.update(camera_group)`` runs tracker -> merger -> optimizer -> filter and returns what
each stage produced for that input, so the offline runner, the composed node and the tests see
exactly the same data flow as the separate nodes (which call the same ``update`` methods).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from hiros_core.accounting import Accounted, Drops, Merged
from hiros_core.calibration import Calibration
from hiros_core.model import SkeletonGroup
from hiros_filter import Filter, FilterParams
from hiros_merger import Merger, MergerParams
from hiros_optimizer import Optimizer, OptimizerParams
from hiros_tracker import Tracker, TrackerParams

__all__ = ["STAGES", "Pipeline", "PipelineParams", "StageOutputs"]

STAGES = ("tracker", "merger", "optimizer", "filter")


@dataclass
class PipelineParams:
    """Every stage's parameters, under the stage's name (``tracker.max_delay``, ...)."""

    tracker: TrackerParams = field(default_factory=TrackerParams)
    merger: MergerParams = field(default_factory=MergerParams)
    optimizer: OptimizerParams = field(default_factory=OptimizerParams)
    filter: FilterParams = field(default_factory=FilterParams)


class StageOutputs(NamedTuple):
    """What each stage published for one input (in world frame, reference clock)."""

    tracker: SkeletonGroup
    merger: SkeletonGroup
    optimizer: SkeletonGroup
    filter: SkeletonGroup


class Pipeline(Accounted):
    """tracker -> merger -> optimizer -> filter over camera SkeletonGroups.

    Attributes:
        tracker, merger, optimizer, filter: the stage objects (their state is the pipeline's).
        processed, held, drops: the account of its camera frames (``Accounted``).

    """

    def __init__(
        self, params: PipelineParams | None = None, calibration: Calibration | None = None
    ) -> None:
        self.params = params or PipelineParams()
        self.tracker = Tracker(self.params.tracker, calibration)
        self.merger = Merger(self.params.merger, calibration)
        self.optimizer = Optimizer(self.params.optimizer)
        self.filter = Filter(self.params.filter)

    def set_params(self, params: PipelineParams) -> None:
        """New tracker, merger and filter parameters from the next camera frame on.

        The optimizer's are fixed at construction (its fit settings are built once).
        """
        self.params = params
        self.tracker.set_params(params.tracker)
        self.merger.set_params(params.merger)
        self.filter.set_params(params.filter)

    def set_calibration(self, calibration: Calibration) -> None:
        """Apply a new calibration from the next camera frame on."""
        self.tracker.set_calibration(calibration)
        self.merger.set_calibration(calibration)

    def update(self, camera_group: SkeletonGroup) -> StageOutputs:
        """One camera frame (camera frame and clock) through all four stages."""
        return self.downstream(self.tracker.update(camera_group))

    def flush(self) -> StageOutputs:
        """Release what the tracker still buffers (end of a recording)."""
        return self.downstream(self.tracker.flush())

    def downstream(self, tracked: SkeletonGroup) -> StageOutputs:
        """The tracker's output through merger, optimizer and filter.

        The tracker may have run elsewhere, e.g. in the offline runner's reading process.
        """
        merged = self.merger.update(tracked)
        optimized = self.optimizer.update(merged)
        return StageOutputs(tracked, merged, optimized, self.filter.update(optimized))

    @property
    def processed(self) -> int:
        """Camera frames processed: the tracker's (each goes on through the later stages)."""
        return self.tracker.processed

    @property
    def held(self) -> int:
        """Camera frames the tracker holds (its out-of-order buffer)."""
        return self.tracker.held

    @property
    def drops(self) -> Drops:
        """Every stage's drop reasons, prefixed with the stage name, with their kinds.

        Only the tracker drops camera frames whole; the later stages take its outputs and
        leave out detections (see ``Accounted``).
        """
        return Merged(self._parts(STAGES), [self.tracker]).drops

    def diagnostics(self) -> dict[str, str]:
        """Every stage's own figures for ``/diagnostics``, under the stage's name."""
        return Merged(self._parts(STAGES), []).diagnostics()

    @property
    def downstream_drops(self) -> Drops:
        """The drop reasons of the stages after the tracker (see :meth:`downstream`)."""
        return Merged(self._parts(STAGES[1:]), []).drops

    def _parts(self, stages: tuple[str, ...]) -> list[tuple[str, Accounted]]:
        return [(f"{name}: ", getattr(self, name)) for name in stages]
