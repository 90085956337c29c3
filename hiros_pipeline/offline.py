"""``hiros run``: the composed pipeline over a recording, at full speed, every frame accounted for.

Reads camera topics (Azure-driver MarkerArray or SkeletonGroup) in log-time order, feeds each
camera frame to ``Pipeline.update`` and writes every stage's output, the visualisation markers
of the merged and filtered people, the calibration used and the cameras' static TF tree
(``/tf_static``: ``hiros_core.frames.recording_transforms``) into one MCAP. Deterministic: the
same recording and parameters give the same bytes.
"""

from __future__ import annotations

import gc
import itertools
import multiprocessing as mp
import os
import resource
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path

import yaml

from hiros_core.accounting import Drops
from hiros_core.calibration import Calibration
from hiros_core.cdr import PlanBuilder
from hiros_core.codec import warm_up as codec_warm_up
from hiros_core.driver import warm_up as bridge_warm_up
from hiros_core.errors import ConfigError, RecordingError
from hiros_core.frames import encode_tf_message, recording_transforms
from hiros_core.model import SkeletonGroup
from hiros_core.recording import MARKER_ARRAY, RecordingWriter, iter_groups
from hiros_pipeline.pipeline import STAGES, Pipeline, PipelineParams, StageOutputs
from hiros_tracker import Tracker
from hiros_visualizer import Drawing, OverlayParams
from hiros_visualizer.markers import warm_up as markers_warm_up

__all__ = [
    "OUTPUTS",
    "RunSummary",
    "chosen_outputs",
    "default_processes",
    "message_count",
    "run_recording",
]

DRAWN_STAGES = ("merger", "filter")
OUTPUTS = (*STAGES, "markers")
"""What ``run_recording`` can write: each stage's output, and the markers of the drawn stages
written (``/hiros/<stage>/markers``). All of them by default."""


@dataclass
class RunSummary:
    """What ``run_recording`` did, for the user and for tests.

    Every camera frame is accounted for: ``frames_total`` (the frames read plus those the
    reader lost) == ``processed`` + ``sum(dropped.values())``; the tracker holds none at
    the end. What processed frames left out is counted apart, in ``dropped_detections``.

    Attributes:
        frames_in: camera frames read, per camera.
        processed: camera frames the tracker processed (each went on through every stage).
        dropped: reason -> camera frames dropped whole, by the reader (``reader: ...``,
            messages lost or rejected) or the tracker (``tracker: ...``).
        dropped_detections: reason -> detections (or parts of one, e.g. a bridge's
            ``nan_position``) left out of processed frames, reader and stages together.
        problems: the reader's sentences on what it met (a truncated file, a damaged chunk).
        published: stage -> output groups it gave (not empty); in ``out`` if written.
        people: stage -> distinct skeleton ids seen.
        duration: seconds of recording (reference clock) covered by the tracker output.
        wall_time: seconds the run took.

    """

    frames_in: Counter[str] = field(default_factory=Counter)
    processed: int = 0
    dropped: Counter[str] = field(default_factory=Counter)
    dropped_detections: Counter[str] = field(default_factory=Counter)
    problems: list[str] = field(default_factory=list)
    published: Counter[str] = field(default_factory=Counter)
    written: frozenset[str] = frozenset(OUTPUTS)
    """What ``out`` holds beside the calibration (``run_recording``'s ``write``)."""
    people: dict[str, set[int]] = field(default_factory=lambda: {s: set() for s in STAGES})
    first_ns: int | None = None
    last_ns: int | None = None
    wall_time: float = 0.0
    seconds: dict[str, float] = field(default_factory=dict)
    """Wall seconds by part: ``read`` (reading, decoding, bridging) and ``tracker`` (in the
    child process when there are two), ``stages`` (merger, optimizer, filter), ``write``
    (encoding, drawing, writing; compression runs in a helper thread and shows here only when
    it holds the run up), ``finish`` (the last chunks and the index), and with two processes
    ``waiting`` (this process idle, waiting for the child's frames)."""
    outputs: dict[str, list] | None = None
    acceptance: dict[int, str] = field(default_factory=dict)
    """Optimizer: track id -> when its limb lengths were accepted, or why not
    (``Optimizer.report``)."""
    """stage -> its output groups, when ``run_recording(keep_outputs=True)``."""
    cpu: dict[str, float] = field(default_factory=dict)
    """CPU seconds over the same span as ``wall_time``: ``main`` (the calling thread),
    ``writer`` (this process's other threads: the MCAP writer's compression) and, with two
    processes, ``child`` (reading and tracking). Unlike wall time, CPU time leaves out the
    waits for a busy core, so it stays readable on a shared machine (it still follows the
    host's speed)."""

    @property
    def frames_total(self) -> int:
        """Camera frames in: read, or lost by the reader (``processed`` + dropped ones)."""
        lost = sum(n for reason, n in self.dropped.items() if reason.startswith("reader: "))
        return sum(self.frames_in.values()) + lost

    def add_drops(self, drops: Drops, prefix: str = "") -> None:
        """Count a stage's (or the reader's) drops, frames and detections apart."""
        self.dropped.update({prefix + r: n for r, n in drops.of_frames().items()})
        self.dropped_detections.update({prefix + r: n for r, n in drops.of_detections().items()})

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
    """The calibration file's YAML as a ``std_msgs/msg/String`` (CDR).

    Written with the codec's own CDR writer: building a rosbags type store for it took
    ~0.1 s of a run's clock.
    """
    message = PlanBuilder()
    message.string(yaml.safe_dump(calibration.to_dict(), sort_keys=False))
    return bytes(message.buf)


def default_processes() -> int:
    """2 (reading and tracking beside the other stages) where a second core and fork exist."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return 2 if (cores or 1) >= 2 and "fork" in mp.get_all_start_methods() else 1


def run_recording(
    recording: str | Path,
    calibration: Calibration,
    out: str | Path,
    params: PipelineParams | None = None,
    progress: Callable[[int], None] | None = None,
    *,
    keep_outputs: bool = False,
    processes: int | None = None,
    write: Iterable[str] = OUTPUTS,
    overlays: OverlayParams | None = None,
) -> RunSummary:
    """Run the pipeline over ``recording``; write ``out`` (MCAP); return the summary.

    ``write`` picks what goes into ``out`` beside the calibration (``OUTPUTS``; e.g. only
    ``filter``: a fifth of the bytes); the summary counts every stage whatever is written.
    ``overlays`` are drawn into the markers beside the skeletons (none by default).

    ``keep_outputs`` also keeps every stage's groups in ``summary.outputs`` (what the demo
    evaluates, without reading the MCAP back). ``processes`` 2 reads and tracks in a child
    process while this one merges, optimises, filters and writes (the stages are sequential
    per frame, so the pipeline splits across cores like an assembly line); 1 runs all here.
    Both give the same bytes. Default: :func:`default_processes`.
    """
    summary = RunSummary(
        outputs={stage: [] for stage in STAGES} if keep_outputs else None,
        written=chosen_outputs(write),
    )
    pipeline = Pipeline(params, calibration)
    _warm_up()
    started = time.perf_counter()
    cpu_started = time.thread_time(), time.process_time(), _children_cpu()
    processes = default_processes() if processes is None else processes
    clock, parts = time.perf_counter, {"stages": 0.0, "write": 0.0}
    drawings = {stage: Drawing(stage, overlays=overlays) for stage in DRAWN_STAGES}
    with (
        _frozen_heap(),
        _tracking(recording, pipeline.tracker, processes) as tracked,
        RecordingWriter(out, discard_on_error=True) as writer,  # no half-written output
    ):
        writer.write_initial(
            "/hiros/calibration", "std_msgs/msg/String", _calibration_message(calibration)
        )
        tree = encode_tf_message(recording_transforms(calibration), 0)  # static: any time
        writer.write_initial("/tf_static", "tf2_msgs/msg/TFMessage", tree)
        for item in tracked:
            if isinstance(item, _TrackingEnd):
                break
            source, group = item
            summary.frames_in[source] += 1
            computed = clock()
            outputs = pipeline.downstream(group)
            written = clock()
            _write(writer, outputs, summary, drawings)
            if progress is not None:
                progress(1)
            parts["stages"] += written - computed
            parts["write"] += clock() - written
        finishing = clock()
        _write(writer, pipeline.downstream(item.flushed), summary, drawings)
        for stage, drawing in drawings.items():  # the end: nobody is left to draw
            for message in drawing.finish(writer.end_ns or 0, calibration.world_frame):
                writer.write(f"/hiros/{stage}/markers", MARKER_ARRAY, message, writer.end_ns or 0)
    summary.seconds = {**item.seconds, **parts, "finish": clock() - finishing}
    summary.add_drops(item.reader_drops, "reader: ")
    summary.problems.extend(item.reader_problems)
    summary.add_drops(item.tracker_drops, "tracker: ")
    summary.add_drops(pipeline.downstream_drops)
    summary.processed = item.tracker_processed
    summary.acceptance = pipeline.optimizer.report()
    summary.wall_time = time.perf_counter() - started
    main = time.thread_time() - cpu_started[0]
    summary.cpu = {"main": main, "writer": time.process_time() - cpu_started[1] - main}
    if processes > 1:
        summary.cpu["child"] = _children_cpu() - cpu_started[2]
    return summary


def _warm_up() -> None:
    """Load the compiled paths a run takes beside the stages' before the clock starts.

    The bridge's, the encoder's and the drawing's kernels, as the stages load theirs when
    made: ~0.1 s from numba's cache, which a process's first run would count otherwise, and
    the forked reading child on every run (it loses what it loads when it ends).
    """
    bridge_warm_up()
    codec_warm_up()
    markers_warm_up()


@contextmanager
def _frozen_heap() -> Iterator[None]:
    """Leave the objects that exist now out of the cyclic garbage collector during the run.

    They are long-lived (modules, kernels, caches: ~150 000 objects), and a full collection
    walks them all: the first run of a process made one, ~0.1 s of a 20 s recording's
    0.8 s. Frozen before the fork, they also stay out of the child's collections, which
    would write to the pages it shares with this process (copy on write). The run's own
    objects are collected as usual; the frozen ones are handed back at the end, unless the
    caller had frozen objects of its own (``gc`` cannot hand back only some).
    """
    callers = gc.get_freeze_count()
    gc.freeze()
    try:
        yield
    finally:
        if not callers:
            gc.unfreeze()


def _children_cpu() -> float:
    """CPU seconds of this process's ended (waited-for) children so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


@dataclass
class _TrackingEnd:
    """Last item of a tracked stream: what the tracker still held, and the accounting."""

    flushed: SkeletonGroup
    reader_drops: Drops
    reader_problems: list[str]
    tracker_drops: Drops
    tracker_processed: int
    seconds: dict[str, float]


def _tracked_frames(
    recording: str | Path, tracker: Tracker
) -> Iterator[tuple[str, SkeletonGroup] | _TrackingEnd]:
    """``(camera, tracker output)`` per camera frame read, then a ``_TrackingEnd``."""
    reader_drops = Drops()
    reader_problems: list[str] = []
    clock, read, tracking = time.perf_counter, 0.0, 0.0
    mark = clock()
    for source, group in iter_groups(recording, drops=reader_drops, problems=reader_problems):
        tracked_at = clock()
        tracked = tracker.update(group)
        done = clock()
        read += tracked_at - mark
        tracking += done - tracked_at
        yield source, tracked
        mark = clock()
    flushed = tracker.flush()
    seconds = {"read": read, "tracker": tracking}
    yield _TrackingEnd(
        flushed, reader_drops, reader_problems, tracker.drops, tracker.processed, seconds
    )


_BATCH = 8
"""Camera frames per message from the reading process (~330 kB for 4 people)."""
_PIPE_BYTES = 1 << 20
"""Pipe buffer asked for (Linux's largest by default): a few batches fit in it, so the
child can track ahead while this process is busy instead of waiting in lockstep. With the
64 kB default not one batch fitted, and each side waited for the other's slow batches (0.2-0.3
s each per 20 s of 4 people; 8 frames in 1 MB: 14 % faster, 11 alternating rounds)."""
_PIPES = 4
"""Pipes the batches take in turn, for ~4 MB of them in flight (one pipe holds 1 MB at
most): the two processes take turns being the slower one, and the child's lead over a
fast stretch now covers the next slow one, where one pipe's three batches did not. 4 pipes
were 2-7 % faster than 1 (two series of 5 and 10 alternating rounds), 16 no faster than 4."""


@contextmanager
def _tracking(
    recording: str | Path, tracker: Tracker, processes: int
) -> Iterator[Iterator[tuple[str, SkeletonGroup] | _TrackingEnd]]:
    """The tracked stream: ``_tracked_frames`` here, or in a forked child process.

    With ``processes`` 2 the child owns the tracker from the fork on (this process's copy
    stays unused) and passes its items back in batches, through ``_PIPES`` pipes in turn;
    groups cross as stacked arrays (``SkeletonGroup.__reduce__``). The child starts on
    entry, before the caller starts any thread, and is stopped on an early exit.
    """
    if processes < 2:
        yield _tracked_frames(recording, tracker)
        return
    context = mp.get_context("fork")
    receivers, senders = zip(*(context.Pipe(duplex=False) for _ in range(_PIPES)), strict=True)
    for sender in senders:
        _enlarge(sender)
    child = context.Process(target=_track_and_send, args=(recording, tracker, senders, receivers))
    child.daemon = True
    child.start()
    for sender in senders:
        sender.close()
    try:
        yield _received(receivers, child)
    except BaseException:
        child.terminate()
        raise
    finally:
        for receiver in receivers:
            receiver.close()
        child.join()


def _enlarge(pipe: Connection) -> None:
    """Ask for a ``_PIPE_BYTES`` pipe buffer where the system allows (Linux ``F_SETPIPE_SZ``)."""
    try:
        import fcntl

        fcntl.fcntl(pipe.fileno(), getattr(fcntl, "F_SETPIPE_SZ", 1031), _PIPE_BYTES)
    except (ImportError, OSError):  # not Linux, or a lower pipe-max-size: the default stays
        pass


def _received(
    receivers: Sequence[Connection], child: mp.process.BaseProcess
) -> Iterator[tuple[str, SkeletonGroup] | _TrackingEnd]:
    """The child's items, read from its pipes in turn.

    The child's exception is raised here, and its unexpected end reported.
    """
    waiting, clock = 0.0, time.perf_counter
    for receiver in itertools.cycle(receivers):
        asked = clock()
        try:
            batch = receiver.recv()
        except EOFError:
            child.join(5.0)
            code = child.exitcode
            msg = f"the reading and tracking process ended unexpectedly (exit code {code})"
            raise RecordingError(msg) from None
        waiting += clock() - asked
        if isinstance(batch, BaseException):
            raise batch
        if isinstance(batch[-1], _TrackingEnd):
            batch[-1].seconds["waiting"] = waiting
            yield from batch
            return
        yield from batch


def _track_and_send(
    recording: str | Path,
    tracker: Tracker,
    senders: Sequence[Connection],
    receivers: Sequence[Connection],
) -> None:
    """Child process: read and track ``recording``, send the items in batches.

    The batches, and an error, go through ``senders`` in turn: the parent reads them so.
    The child first closes its copies of the parent's ``receivers``: a parent killed
    outright then leaves it a broken pipe, and it ends, instead of a full pipe that no one
    reads, where it would wait forever.
    """
    for receiver in receivers:
        receiver.close()
    batch: list = []
    turns = itertools.cycle(senders)
    try:
        for item in _tracked_frames(recording, tracker):
            batch.append(item)
            if len(batch) >= _BATCH or isinstance(item, _TrackingEnd):
                next(turns).send(batch)
                batch = []
    except (BrokenPipeError, EOFError):
        pass  # the parent stopped reading (its own error or an interrupt): nothing to report
    except Exception as error:  # raised again in the parent, which reports it
        next(turns).send(error)
    finally:
        for sender in senders:
            sender.close()


def chosen_outputs(write: Iterable[str]) -> frozenset[str]:
    """The outputs to write, checked against ``OUTPUTS`` (``ConfigError`` names the others)."""
    chosen = frozenset(write)
    unknown = sorted(chosen - set(OUTPUTS))
    if unknown:
        msg = f"cannot write {', '.join(unknown)}: choose among {', '.join(OUTPUTS)}"
        raise ConfigError(msg)
    return chosen


def _write(
    writer: RecordingWriter,
    outputs: StageOutputs,
    summary: RunSummary,
    drawings: dict[str, Drawing],
) -> None:
    for stage, group in zip(STAGES, outputs, strict=True):
        if not group.skeletons:
            continue
        summary.published[stage] += 1
        if summary.outputs is not None:
            summary.outputs[stage].append(group)
        summary.people[stage].update([int(s.id) for s in group.skeletons])
        if stage == "tracker":
            summary.first_ns = group.stamp_ns if summary.first_ns is None else summary.first_ns
            summary.last_ns = group.stamp_ns
        if stage not in summary.written:
            continue
        writer.write_group(f"/hiros/{stage}", group)
        if stage in DRAWN_STAGES and "markers" in summary.written:
            _write_markers(writer, stage, drawings[stage], group)


def _write_markers(
    writer: RecordingWriter, stage: str, drawing: Drawing, group: SkeletonGroup
) -> None:
    for message in drawing.draw(group):
        writer.write(f"/hiros/{stage}/markers", MARKER_ARRAY, message, group.stamp_ns)
