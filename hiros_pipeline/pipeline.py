"""The four stages composed in one process: objects passed directly, no serialisation.

``Pipeline.update(camera_group)`` runs tracker -> merger -> optimizer -> filter and returns what
each stage produced for that input, so the offline runner, the composed node and the tests see
exactly the same data flow as the separate nodes (which call the same ``update`` methods).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import NamedTuple

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


class Pipeline:
    """tracker -> merger -> optimizer -> filter over camera SkeletonGroups.

    Attributes:
        tracker, merger, optimizer, filter: the stage objects (their state is the pipeline's).

    """

    def __init__(
        self, params: PipelineParams | None = None, calibration: Calibration | None = None
    ) -> None:
        self.params = params or PipelineParams()
        self.tracker = Tracker(self.params.tracker, calibration)
        self.merger = Merger(self.params.merger, calibration)
        self.optimizer = Optimizer(self.params.optimizer)
        self.filter = Filter(self.params.filter)

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
    def drops(self) -> Counter[str]:
        """Every stage's drop reasons, prefixed with the stage name."""
        return self._drops(STAGES)

    @property
    def downstream_drops(self) -> Counter[str]:
        """The drop reasons of the stages after the tracker (see :meth:`downstream`)."""
        return self._drops(STAGES[1:])

    def _drops(self, stages: tuple[str, ...]) -> Counter[str]:
        total: Counter[str] = Counter()
        for name in stages:
            for reason, count in getattr(getattr(self, name), "drops", Counter()).items():
                total[f"{name}: {reason}"] += count
        return total
