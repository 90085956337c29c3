"""HirosNode: what every hiros node shares — parameters, raw topics, QoS, counters, diagnostics.

A node built on it reads as its data flow: declare parameters from the stage's dataclass,
subscribe raw CDR bytes, decode with the fast codec, call the stage, encode, publish bytes.
Bad input never raises out of a callback: ``drop(reason)`` counts it, logs once per reason and
interval, and the counts go out on ``/diagnostics`` every second. Every frame a node receives
is accounted for there, at any moment:

    received == processed + sum(dropped.*) + held

``dropped.<reason>`` counts whole frames (the node's own drops, an exception in a callback, and
the frame reasons of its stage); ``dropped_detections.<reason>`` counts what was left out of
processed frames; ``errors.<reason>`` counts failures that lost no input frame (an output not
published, a calibration step, a file not written). ``processed`` and ``held`` are the stage's
own counts (``hiros_core.accounting``) when the node names it in ``accounted``.
"""

from __future__ import annotations

import gc
import os
import signal
import threading
import time
from collections import Counter
from collections.abc import Callable, Collection
from typing import Any, TypeVar

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data

from hiros_core.accounting import Accounted
from hiros_core.codec import warm_up as codec_warm_up
from hiros_core.errors import ConfigError
from hiros_ros.diagnostics import NodeHealth
from hiros_ros.params import NodeParameters, declare_params

T = TypeVar("T")

__all__ = ["HirosNode", "camera_qos", "pipeline_qos", "run_node"]


def camera_qos(kind: str = "sensor_data", depth: int = 10) -> QoSProfile:
    """QoS for camera topics: best-effort sensor data by default (what drivers publish)."""
    if kind == "sensor_data":
        profile = QoSProfile(depth=depth)
        profile.reliability = qos_profile_sensor_data.reliability
        profile.durability = qos_profile_sensor_data.durability
        profile.history = qos_profile_sensor_data.history
        return profile
    return pipeline_qos(depth)


def pipeline_qos(depth: int = 10) -> QoSProfile:
    """QoS between pipeline stages: reliable, volatile, keep last ``depth``."""
    return QoSProfile(depth=depth)


class HirosNode(Node):
    """Base class of every hiros node.

    Attributes:
        counters: ``received``, ``processed``, ``held``, ``published``, ``dropped.<reason>``,
            ``dropped_detections.<reason>`` and ``errors.<reason>`` counts (module docstring).
        accounted: the stage (or ``Merged`` stages) the received frames go to, whose
            ``processed``, ``held`` and drops become the node's after every callback; None:
            a frame whose callback returns is processed.

    """

    def __init__(self, node_name: str, *, log_interval: float = 5.0, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.counters: Counter[str] = Counter()
        self.accounted: Accounted | None = None
        self._frames_dropped = 0  # sum of dropped.*, kept as it goes (checked every frame)
        self._seen_drops: Counter[str] = Counter()  # the stage's drops already counted
        self._log_interval = log_interval
        self._last_log: dict[str, float] = {}
        self.parameters: NodeParameters[Any]
        self.health = NodeHealth()
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(1.0, self.publish_diagnostics)

    # -- parameters
    def declare_params(
        self,
        params_type: type[T],
        *,
        live: Collection[str] = (),
        apply: Callable[[T], None] | None = None,
        aliases: dict[str, str] | None = None,
        fixed: dict[str, Any] | None = None,
    ) -> T:
        """Declare the dataclass fields as parameters (``hiros_ros.params``); ``params`` follows.

        Defaults are the dataclass's, ``-p`` and ``--params-file`` override them; ``live``
        names are applied while running (``apply`` gets the new dataclass first), the rest are
        read-only.
        """
        self.parameters = declare_params(
            self, params_type, live=live, apply=apply, aliases=aliases, fixed=fixed
        )
        return self.parameters.params

    @property
    def params(self) -> Any:
        """The node's parameters dataclass as it is now (live changes included)."""
        return self.parameters.params

    # -- raw topics through the fast codec
    def create_raw_subscription(
        self, msg_type: type, topic: str, callback: Callable[[bytes], None], qos: QoSProfile
    ) -> Any:
        """Subscribe to CDR bytes; every frame is accounted for (module docstring).

        An exception in ``callback`` drops the frames it left unaccounted for (the one
        received, or one the stage was processing) under the exception's name; raised
        after the stage accounted for them (e.g. while publishing), it counts as an error.
        """

        def guarded(data: bytes) -> None:
            self.counters["received"] += 1
            start = time.perf_counter()
            try:
                callback(data)
            except Exception as exc:
                self._count_exception(exc, topic)
            else:
                if self.accounted is None:
                    self.counters["processed"] += 1
                else:
                    self.absorb_stage()
            self.health.add_duration(time.perf_counter() - start)

        return self.create_subscription(msg_type, topic, guarded, qos, raw=True)

    def create_raw_publisher(self, msg_type: type, topic: str, qos: QoSProfile) -> Any:
        """A publisher whose ``publish`` takes CDR bytes (rclpy publishes them as they are).

        For SkeletonGroups, loads the compiled group encoder now, so that the first message
        does not wait for it (``codec.warm_up``); a node publishing only other messages (the
        visualizer's MarkerArrays) never loads it.
        """
        if msg_type.__name__ == "SkeletonGroup":
            codec_warm_up()
        return self.create_publisher(msg_type, topic, qos)

    def publish_raw(self, publisher: Any, data: bytes) -> None:
        """Publish bytes and count them."""
        publisher.publish(data)
        self.counters["published"] += 1

    # -- accounting
    def count(self, name: str, amount: int = 1) -> None:
        """Add to a named counter (shown on /diagnostics)."""
        self.counters[name] += amount

    def drop(self, reason: str, detail: str = "", amount: int = 1) -> None:
        """Count ``amount`` input frames dropped whole for ``reason``; log once per interval."""
        self._frames_dropped += amount
        self._count_logged("dropped", reason, detail, amount, "dropped input")

    def drop_detections(self, reason: str, detail: str = "", amount: int = 1) -> None:
        """Count detections (or parts of one) left out of processed frames, logged likewise."""
        self._count_logged("dropped_detections", reason, detail, amount, "dropped detections")

    def error(self, reason: str, detail: str = "", amount: int = 1) -> None:
        """Count a failure that lost no input frame (see the module docstring), logged likewise."""
        self._count_logged("errors", reason, detail, amount, "error")

    def _count_logged(self, kind: str, reason: str, detail: str, amount: int, what: str) -> None:
        key = f"{kind}.{reason}"
        self.counters[key] += amount
        total = self.counters[key]
        self.warn_throttled(key, lambda: f"{what} ({reason}, {total} so far): {detail}")

    @property
    def frames_accounted(self) -> int:
        """Frames processed, dropped whole or held (``received`` once every callback ended)."""
        return self.counters["processed"] + self._frames_dropped + self.counters["held"]

    def _count_exception(self, exc: Exception, topic: str) -> None:
        """Drop the frames the failed callback left unaccounted for; else count an error."""
        if self.accounted is not None:
            self.absorb_stage()
        lost = self.counters["received"] - self.frames_accounted
        reason, detail = type(exc).__name__, f"{topic}: {exc}"
        if lost > 0:
            self.drop(reason, detail, amount=lost)
        else:
            self.error(reason, detail)

    def warn_throttled(self, key: str, message: Callable[[], str]) -> bool:
        """Log ``message()`` unless ``key`` was logged within the interval; True if logged.

        Whatever input can vary (a camera name, an id) must reach the log through here, so
        that a stream of ever-new values cannot flood it.
        """
        now = time.monotonic()
        if now - self._last_log.get(key, -1e9) < self._log_interval:
            return False
        self._last_log[key] = now
        self.get_logger().warning(message())
        return True

    def absorb_stage(self) -> None:
        """Make ``accounted``'s counts the node's: ``processed``, ``held`` and new drops.

        Called after every callback (and for each diagnostics message): a stage may drop
        or release frames it held at any call.
        """
        stage = self.accounted
        if stage is None:
            return
        drops = stage.drops
        for reason, total in tuple(drops.items()):
            new = total - self._seen_drops[reason]
            if new > 0:
                count = self.drop if drops.is_frame(reason) else self.drop_detections
                count(reason, f"{new} more from the stage", amount=new)
                self._seen_drops[reason] = total
        self.counters["processed"] = stage.processed
        self.counters["held"] = stage.held

    def publish_diagnostics(self) -> None:
        """One DiagnosticStatus: the level and message of the last minute, every counter.

        WARN while a frame was dropped or something failed within ``health.window`` seconds;
        OK again after a clean window (the counters keep the totals since start). What
        processed frames left out (a skeleton without joints, a duplicate track) is normal in
        a crowded scene: it shows in the counts and the message, at level OK. The values add
        the stage's own figures (``Accounted.diagnostics``: the tracker's restarts, frames a
        bridge lost before reception), the input and output rates (messages per second over
        ``health.rate_window``) and the callbacks' processing time percentiles
        (``latency_ms.*``).
        """
        self.absorb_stage()
        totals = self._totals()
        self.health.sample(time.monotonic(), totals)
        status = DiagnosticStatus(name=self.get_fully_qualified_name(), hardware_id="hiros")
        status.level, status.message = self._status(totals)
        values = {k: str(v) for k, v in self.counters.items()}
        if self.accounted is not None:  # the stages' own figures (tracker restarts, ...)
            values.update(self.accounted.diagnostics())
        values["input_rate_hz"] = f"{self.health.rate('received'):.2f}"
        values["output_rate_hz"] = f"{self.health.rate('published'):.2f}"
        for name, value in self.health.latency_ms().items():
            values[f"latency_ms.{name}"] = f"{value:.3f}"
        status.values = [KeyValue(key=k, value=v) for k, v in sorted(values.items())]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(array)

    def _totals(self) -> Counter[str]:
        """Counters summed by kind (``dropped``, ``errors``, ...), ``dropped`` in frames."""
        totals: Counter[str] = Counter()
        for key, value in self.counters.items():
            totals[key.partition(".")[0]] += value
        totals["dropped"] = self._frames_dropped
        return totals

    def status_notes(self) -> list[str]:
        """What the node says of its input besides the counts (e.g. "nobody in view: k03")."""
        return []

    def _status(self, totals: Counter[str]) -> tuple[bytes, str]:
        """Diagnostic level and message: the window's drops and errors, the notes, the rest."""
        window = f"in the last {self.health.window:g} s"
        parts = []
        dropped, errors = self.health.recent("dropped"), self.health.recent("errors")
        if dropped:
            received = self.health.recent("received")
            parts.append(f"{dropped} of {received} frame(s) dropped {window}")
        if errors:
            parts.append(f"{errors} error(s) {window}")
        level = DiagnosticStatus.WARN if parts else DiagnosticStatus.OK
        parts += self.status_notes()
        earlier = totals["dropped"] - dropped
        if earlier:
            parts.append(f"{earlier} frame(s) dropped before")
        if totals["dropped_detections"]:
            parts.append(f"{totals['dropped_detections']} detection(s) left out")
        return level, "; ".join(parts) or "ok"


_STOP = threading.Event()
"""Set by SIGINT/SIGTERM; the spin loop of ``run_node`` checks it between waits."""


def _request_stop(signum: int, frame: object) -> None:
    _STOP.set()


def make_executor() -> Executor:
    """The C++ events executor of rclpy where available, else its single-threaded one.

    The events executor dispatches a callback in a few microseconds where the Python one
    spends a few hundred (it rebuilds its wait set in Python every time), which is most of a
    stage's latency at 90 camera frames per second. ``HIROS_EXECUTOR=single`` forces the
    Python executor.
    """
    if os.environ.get("HIROS_EXECUTOR", "events") != "single":
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:  # rclpy before Jazzy's backport
            pass
        else:
            return EventsExecutor()
    return SingleThreadedExecutor()


def run_node(node_factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """``rclpy.init``, spin until Ctrl-C or SIGTERM, clean up without a traceback.

    rclpy's own signal handler would shut the context down before we could run the node's
    ``on_shutdown`` (the calib node saves its file there, and logs it); so SIGINT and SIGTERM
    only ask the loop to stop, which it does after the callback under way (an exception
    raised inside a callback would reach the C++ executor and be logged as a fatal error),
    and the context is shut down last.
    """
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, _request_stop)
    signal.signal(signal.SIGTERM, _request_stop)
    node = None
    try:
        try:
            node = node_factory()
        except ConfigError as exc:  # a parameter out of range, of the wrong type, ...
            get_logger("hiros").fatal(str(exc))
            raise SystemExit(1) from None
        executor = make_executor()
        executor.add_node(node)
        gc.freeze()  # start-up's objects out of the collector: a full pass over them is a
        # pause of ~50 ms inside some frame's callback; what the node makes later is collected
        while rclpy.ok() and not _STOP.is_set():
            executor.spin_once(timeout_sec=0.2)  # short waits: a stop request is seen promptly
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            shutdown_hook = getattr(node, "on_shutdown", None)
            if callable(shutdown_hook):
                shutdown_hook()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
