"""List the live topics, print a topic's messages, or measure its rate (thin over rclpy).

For an install from PyPI, where there is no ``ros2`` command; with a ROS 2 installation
``ros2 topic`` does the same and more (QoS details, publishing). Messages of the packages
``hiros play`` knows (ours, visualization_msgs, diagnostic_msgs, tf2_msgs, ...) can be echoed;
any topic's rate can be measured (its messages are counted, not decoded). The subscription is
best effort, so it hears every publisher, and transient-local when every publisher is (the
latched /tf_static).

Examples:
  hiros topic list
  hiros topic echo /diagnostics -n 1
  hiros topic hz /hiros/filter --duration 10

"""

from __future__ import annotations

import argparse
import array
import itertools
import math
import statistics
import sys
import time
from collections import deque
from typing import Any

import yaml

from hiros_cli.commands._ros import cli_node
from hiros_core.errors import ConfigError

HELP = "list live topics, echo one, or measure its rate (no ros2 CLI needed)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros topic list | echo TOPIC | hz TOPIC``."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    child = actions.add_parser("list", help="topics and their types", description="topics")
    child.add_argument("--wait", type=float, default=2.0, help="seconds of discovery (default 2)")
    child = actions.add_parser("echo", help="print messages as YAML", description="echo")
    child.add_argument("topic")
    child.add_argument("-n", "--count", type=int, default=0, help="stop after N messages")
    child.add_argument("--timeout", type=float, default=0.0, help="stop after S seconds")
    child = actions.add_parser("hz", help="message rate", description="rate of a topic")
    child.add_argument("topic")
    child.add_argument("--window", type=int, default=100, help="intervals averaged (default 100)")
    child.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")


def run(args: argparse.Namespace) -> int:
    """Do the action until done, Ctrl-C, --count or --duration/--timeout."""
    with cli_node("hiros_topic") as node:
        if args.action == "list":
            return _list(node, args.wait)
        topic_type = _topic_type(node, args.topic)
        if args.action == "echo":
            return _echo(node, args, topic_type)
        return _hz(node, args, topic_type)


def _spin_for(node: Any, seconds: float) -> None:
    import rclpy

    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=min(0.1, max(0.0, end - time.monotonic())))


def _list(node: Any, wait: float) -> int:
    _spin_for(node, wait)
    for topic, types in sorted(node.get_topic_names_and_types()):
        print(f"{topic} [{', '.join(types)}]")
    return 0


def _topic_type(node: Any, topic: str, wait: float = 5.0) -> str:
    """The type the topic's publishers announce (discovery for up to ``wait`` seconds)."""
    end = time.monotonic() + wait
    while True:
        types = dict(node.get_topic_names_and_types()).get(topic)
        if types or time.monotonic() > end:
            break
        _spin_for(node, 0.1)
    if not types:
        msg = f"no publisher of {topic} was found within {wait:g} s"
        raise ConfigError(msg)
    return types[0]


def _subscribe(node: Any, topic: str, cls: type, callback: Any, *, raw: bool) -> Any:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    publishers = node.get_publishers_info_by_topic(topic)
    latched = bool(publishers) and all(
        p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers
    )
    qos = QoSProfile(
        depth=100,
        reliability=ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )
    return node.create_subscription(cls, topic, callback, qos, raw=raw)


def _echo(node: Any, args: argparse.Namespace, topic_type: str) -> int:
    import rclpy

    from hiros_cli.commands.play import message_class

    cls, why = message_class(topic_type)
    if cls is None:
        msg = f"{args.topic} carries {topic_type}, which hiros cannot print ({why})"
        raise ConfigError(msg)
    seen = 0

    def show(message: Any) -> None:
        nonlocal seen
        seen += 1
        sys.stdout.write(yaml.safe_dump(message_fields(message), sort_keys=False) + "---\n")
        sys.stdout.flush()

    _subscribe(node, args.topic, cls, show, raw=False)
    end = time.monotonic() + args.timeout if args.timeout > 0 else math.inf
    while (args.count <= 0 or seen < args.count) and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    return 0


def message_fields(message: Any) -> Any:
    """A ROS message as plain Python (dicts, lists, numbers, strings) for YAML."""
    if hasattr(message, "get_fields_and_field_types"):
        fields = message.get_fields_and_field_types()
        return {name: message_fields(getattr(message, name)) for name in fields}
    if isinstance(message, list | tuple | array.array) or hasattr(message, "tolist"):
        return [message_fields(item) for item in message]
    if isinstance(message, bytes):  # a byte field (a diagnostic level) or a byte array
        return message[0] if len(message) == 1 else list(message)
    return message


class RateMeter:
    """Rate of arrivals over the last ``window`` intervals (what ``ros2 topic hz`` prints)."""

    def __init__(self, window: int) -> None:
        self.arrivals: deque[float] = deque(maxlen=window + 1)
        self.count = 0

    def add(self, t: float) -> None:
        """One message arrived at ``t`` (s, monotonic)."""
        self.arrivals.append(t)
        self.count += 1

    def summary(self) -> str:
        """``average rate: 30.012 Hz`` and the intervals' spread, or why there is none."""
        if len(self.arrivals) < 2:  # one interval needs two arrivals
            return f"{self.count} message(s): no rate yet"
        times = list(self.arrivals)
        intervals = [b - a for a, b in itertools.pairwise(times)]
        mean = statistics.fmean(intervals)
        spread = statistics.pstdev(intervals)
        return (
            f"average rate: {1.0 / mean:.3f} Hz  min: {min(intervals):.4f} s  "
            f"max: {max(intervals):.4f} s  std dev: {spread:.5f} s  window: {len(intervals)}"
        )


def _hz(node: Any, args: argparse.Namespace, topic_type: str) -> int:
    import rclpy

    from hiros_cli.commands.play import message_class

    cls, _ = message_class(topic_type)
    if cls is None:
        msg = f"{args.topic} carries {topic_type}, whose package hiros does not load"
        raise ConfigError(msg)
    meter = RateMeter(args.window)
    _subscribe(node, args.topic, cls, lambda _data: meter.add(time.monotonic()), raw=True)
    end = time.monotonic() + args.duration if args.duration > 0 else math.inf
    next_print = time.monotonic() + 1.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() >= next_print:
            print(meter.summary(), flush=True)
            next_print += 1.0
    print(meter.summary(), flush=True)
    return 0
