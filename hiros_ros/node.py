"""HirosNode: what every hiros node shares — parameters, raw topics, QoS, counters, diagnostics.

A node built on it reads as its data flow: declare parameters from the stage's dataclass,
subscribe raw CDR bytes, decode with the fast codec, call the stage, encode, publish bytes.
Bad input never raises out of a callback: ``drop(reason)`` counts it, logs once per reason and
interval, and the counts go out on ``/diagnostics`` every second.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any, TypeVar

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data

from hiros_ros.params import declare_params

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
        counters: ``received``, ``published`` and ``dropped.<reason>`` counts.

    """

    def __init__(self, node_name: str, *, log_interval: float = 5.0, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.counters: Counter[str] = Counter()
        self._log_interval = log_interval
        self._last_log: dict[str, float] = {}
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(1.0, self.publish_diagnostics)

    # -- parameters
    def declare_params(self, params_type: type[T]) -> T:
        """Declare the dataclass fields as parameters (YAML defaults, ``-p`` overrides)."""
        return declare_params(self, params_type)

    # -- raw topics through the fast codec
    def create_raw_subscription(
        self, msg_type: type, topic: str, callback: Callable[[bytes], None], qos: QoSProfile
    ) -> Any:
        """Subscribe to CDR bytes; exceptions in ``callback`` become counted drops."""

        def guarded(data: bytes) -> None:
            self.counters["received"] += 1
            try:
                callback(data)
            except Exception as exc:
                self.drop(type(exc).__name__, f"{topic}: {exc}")

        return self.create_subscription(msg_type, topic, guarded, qos, raw=True)

    def create_raw_publisher(self, msg_type: type, topic: str, qos: QoSProfile) -> Any:
        """A publisher whose ``publish`` takes CDR bytes (rclpy publishes them as they are)."""
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
        """Count dropped input under ``reason`` and log it at most once per interval."""
        self.counters[f"dropped.{reason}"] += amount
        total = self.counters[f"dropped.{reason}"]
        self.warn_throttled(reason, lambda: f"dropped input ({reason}, {total} so far): {detail}")

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

    def absorb_drops(self, drops: Counter[str], seen: Counter[str]) -> None:
        """Report the increase of a stage's own ``drops`` counter since the last call."""
        for reason, total in drops.items():
            new = total - seen[reason]
            if new > 0:
                self.drop(reason, f"{new} more from the stage", amount=new)
                seen[reason] = total

    def publish_diagnostics(self) -> None:
        """One DiagnosticStatus with every counter; WARN when anything was dropped."""
        status = DiagnosticStatus(name=self.get_fully_qualified_name(), hardware_id="hiros")
        dropped = sum(v for k, v in self.counters.items() if k.startswith("dropped."))
        status.level = DiagnosticStatus.WARN if dropped else DiagnosticStatus.OK
        status.message = f"{dropped} input(s) dropped" if dropped else "ok"
        status.values = [KeyValue(key=k, value=str(v)) for k, v in sorted(self.counters.items())]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(array)


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
        node = node_factory()
        executor = make_executor()
        executor.add_node(node)
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
