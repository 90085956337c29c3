"""``hiros run``: the composed pipeline over a recording, at full speed, every frame accounted for.

Reads camera topics (Azure-driver MarkerArray or SkeletonGroup) in log-time order, feeds each
camera frame to ``Pipeline.update`` and writes every stage's output, the visualisation markers
of the merged and filtered people, and the calibration used into one MCAP. Deterministic: the
same recording and parameters give the same bytes.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from hiros_azure_bridge.driver_format import warm_up
from hiros_core.calibration import Calibration
from hiros_core.recording import MARKER_ARRAY, RecordingWriter, iter_groups
from hiros_pipeline.pipeline import STAGES, Pipeline, PipelineParams, StageOutputs
from hiros_visualizer.markers import encode_skeleton_markers

__all__ = ["RunSummary", "message_count", "run_recording"]

DRAWN_STAGES = ("merger", "filter")


@dataclass
class RunSummary:
    """What ``run_recording`` did, for the user and for tests.

    Attributes:
        frames_in: camera frames read, per camera.
        dropped: reason -> frames (or detections) left out, reader and stages together.
        published: stage -> output groups written.
        people: stage -> distinct skeleton ids seen.
        duration: seconds of recording (reference clock) covered by the tracker output.
        wall_time: seconds the run took.

    """

    frames_in: Counter[str] = field(default_factory=Counter)
    dropped: Counter[str] = field(default_factory=Counter)
    published: Counter[str] = field(default_factory=Counter)
    people: dict[str, set[int]] = field(default_factory=lambda: {s: set() for s in STAGES})
    first_ns: int | None = None
    last_ns: int | None = None
    wall_time: float = 0.0
    seconds: dict[str, float] = field(default_factory=dict)
    """Wall seconds by part: ``read`` (reading, decoding, bridging), ``stages`` (the four
    stages), ``write`` (encoding, drawing, writing; compression runs in a helper thread and
    shows here only when it holds the run up), ``finish`` (the last chunks and the index)."""
    outputs: dict[str, list] | None = None
    """stage -> its output groups, when ``run_recording(keep_outputs=True)``."""

    @property
    def duration(self) -> float:
        """Reference-clock seconds between the first and last tracker output."""
        if self.first_ns is None or self.last_ns is None:
            return 0.0
        return (self.last_ns - self.first_ns) * 1e-9

    @property
    def real_time_factor(self) -> float:
        """Recording seconds processed per wall-clock second."""
        return self.duration / self.wall_time if self.wall_time > 0 else 0.0


def message_count(path: str | Path) -> int | None:
    """Messages in a recording when its index says so cheaply (MCAP summary), else None."""
    path = Path(path)
    if path.suffix != ".mcap" or not path.is_file():
        return None
    try:
        from mcap.reader import make_reader

        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()
        return summary.statistics.message_count if summary and summary.statistics else None
    except Exception:
        return None


def _calibration_message(calibration: Calibration) -> bytes:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    text = yaml.safe_dump(calibration.to_dict(), sort_keys=False)
    string = store.types["std_msgs/msg/String"](data=text)
    return bytes(store.serialize_cdr(string, "std_msgs/msg/String"))


def run_recording(
    recording: str | Path,
    calibration: Calibration,
    out: str | Path,
    params: PipelineParams | None = None,
    progress: Callable[[int], None] | None = None,
    *,
    keep_outputs: bool = False,
) -> RunSummary:
    """Run the pipeline over ``recording``; write ``out`` (MCAP); return the summary.

    ``keep_outputs`` also keeps every stage's groups in ``summary.outputs`` (what the demo
    evaluates, without reading the MCAP back).
    """
    summary = RunSummary(outputs={stage: [] for stage in STAGES} if keep_outputs else None)
    pipeline = Pipeline(params, calibration)
    warm_up()  # like the stages' kernels, loaded before the clock starts (~20 ms)
    started = time.perf_counter()
    reader_drops: Counter[str] = Counter()
    clock, parts = time.perf_counter, [0.0, 0.0, 0.0]  # read, stages, write
    with RecordingWriter(out) as writer:
        first_stamp: int | None = None
        mark = clock()
        for source, group in iter_groups(recording, drops=reader_drops):
            summary.frames_in[source] += 1
            if first_stamp is None:
                first_stamp = group.stamp_ns
                writer.write("/hiros/calibration", "std_msgs/msg/String",
                             _calibration_message(calibration), 0)  # fmt: skip
            read = clock()
            outputs = pipeline.update(group)
            computed = clock()
            _write(writer, outputs, summary)
            if progress is not None:
                progress(1)
            done = clock()
            parts[0] += read - mark
            parts[1] += computed - read
            parts[2] += done - computed
            mark = done
        finishing = clock()
        _write(writer, pipeline.flush(), summary)
    summary.seconds = dict(zip(("read", "stages", "write"), parts, strict=True))
    summary.seconds["finish"] = clock() - finishing
    summary.dropped.update({f"reader: {k}": v for k, v in reader_drops.items()})
    summary.dropped.update(pipeline.drops)
    summary.wall_time = time.perf_counter() - started
    return summary


def _write(writer: RecordingWriter, outputs: StageOutputs, summary: RunSummary) -> None:
    for stage, group in zip(STAGES, outputs, strict=True):
        if not group.skeletons:
            continue
        writer.write_group(f"/hiros/{stage}", group)
        summary.published[stage] += 1
        if summary.outputs is not None:
            summary.outputs[stage].append(group)
        summary.people[stage].update([int(s.id) for s in group.skeletons])
        if stage == "tracker":
            summary.first_ns = group.stamp_ns if summary.first_ns is None else summary.first_ns
            summary.last_ns = group.stamp_ns
        if stage in DRAWN_STAGES:
            writer.write(
                f"/hiros/{stage}/markers",
                MARKER_ARRAY,
                encode_skeleton_markers(group, stage),
                group.stamp_ns,
            )
