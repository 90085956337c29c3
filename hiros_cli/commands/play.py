"""Replay a recording onto live ROS 2 topics at the recorded speed.

Every message is published exactly as recorded (raw CDR: header stamps untouched) at its log
time relative to the first message played, divided by --rate. /clock (rosgraph_msgs/Clock)
carries the recording's log time, so nodes started with use_sim_time:=true run on the
recording's clock. Needs the ROS 2 environment (make setup). Only types of known message
packages are played (``KNOWN_PACKAGES``: ours, the Azure driver's and standard ROS ones); a
type name in a recording is never imported as such, other topics are skipped and counted.
Topics a live hiros graph latches (``/tf_static``, ``/hiros/calibration``: offered
transient-local, as hiros's recordings also say in their channels' QoS) are published latched,
so that a node started after the replay began still gets the camera transforms and the
calibration.

Examples:
  hiros play sample.mcap                           # everything, real time, /clock
  hiros play take.mcap --rate 2 --loop             # twice as fast, over and over
  hiros play take.mcap --start 30 --topics /k01/body_tracking_data /k02/body_tracking_data
  hiros play take.mcap --remap /k01/body_tracking_data:=/cam_a/body_tracking_data

"""

from __future__ import annotations

import argparse
import importlib
import re
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from hiros_core.errors import ConfigError, RecordingError
from hiros_core.recording import RecordedMessage, RecordingReader
from hiros_core.recording.writer import offered_qos

T = TypeVar("T")

HELP = "replay a recording onto live ROS topics at recorded speed (with /clock)"

CLOCK_PERIOD = 0.01
"""Seconds of wall time between /clock messages (100 Hz, as ``ros2 bag play --clock``)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hiros play``."""
    parser.add_argument("recording", type=Path, metavar="REC", help=".mcap/.db3/.bag or folder")
    parser.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1)")
    parser.add_argument("--loop", action="store_true", help="start over at the end")
    parser.add_argument(
        "--start", type=float, default=0.0, help="skip the first START seconds (default 0)"
    )
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics")
    parser.add_argument(
        "--remap", nargs="+", default=[], metavar="FROM:=TO", help="publish FROM on TO"
    )
    parser.add_argument("--no-clock", action="store_true", help="do not publish /clock")
    parser.add_argument(
        "--delay",
        type=float,
        default=1.0,
        help="wait up to this many seconds for every topic's subscribers before playing "
        "(default 1)",
    )


def parse_remaps(pairs: Iterable[str]) -> dict[str, str]:
    """``["/a:=/b"]`` -> ``{"/a": "/b"}``; raises ConfigError on a malformed pair."""
    remaps = {}
    for pair in pairs:
        source, sep, target = pair.partition(":=")
        if not sep or not source or not target:
            msg = f"--remap {pair!r} must look like /from/topic:=/to/topic"
            raise ConfigError(msg)
        remaps[source] = target
    return remaps


def playback_schedule(
    items: Iterable[T],
    *,
    rate: float = 1.0,
    start: float = 0.0,
    log_time: Callable[[T], int] = int,  # type: ignore[assignment]
) -> Iterator[tuple[T, float]]:
    """``(item, wall seconds after the start of play)`` for each item that is played.

    Items logged before ``start`` seconds after the first one are skipped; the first played
    item goes out at 0, later ones at their log-time distance from it divided by ``rate``.
    """
    if rate <= 0:
        msg = f"--rate must be positive, not {rate}"
        raise ConfigError(msg)
    first = origin = None
    for item in items:
        stamp = log_time(item)
        if first is None:
            first = stamp
        if stamp < first + start * 1e9:
            continue
        if origin is None:
            origin = stamp
        yield item, (stamp - origin) / 1e9 / rate


KNOWN_PACKAGES = (
    "hiros_skeleton_msgs",
    "visualization_msgs",
    "tf2_msgs",
    "geometry_msgs",
    "sensor_msgs",
    "std_msgs",
    "diagnostic_msgs",
    "rosgraph_msgs",
    "builtin_interfaces",
)
"""Message packages whose types ``hiros play`` publishes: ours and the ROS 2 packages that
camera drivers and hiros record. A recording's type names are looked up among these, never
imported by name: a schema naming any other module (``os/msg/X``) is skipped, not run."""
_TYPE_NAME = re.compile(r"[A-Z][A-Za-z0-9]*")


def message_class(msgtype: str) -> tuple[type | None, str]:
    """The rclpy class of ``package/msg/Type`` and, when there is none, why it is skipped.

    Only a package of ``KNOWN_PACKAGES`` is imported (by its name from that table); the
    type is then an attribute of its ``msg`` module that is a ROS message class.
    """
    package, _, name = msgtype.partition("/msg/")
    if package not in KNOWN_PACKAGES or not _TYPE_NAME.fullmatch(name):
        return None, "unknown_type"
    try:
        module = importlib.import_module(f"{package}.msg")  # a name of the table only
    except ImportError:
        return None, "package_not_installed"
    cls = getattr(module, name, None)
    if not (isinstance(cls, type) and hasattr(cls, "_TYPE_SUPPORT")):
        return None, "unknown_type"
    return cls, ""


def latched(topic: str) -> bool:
    """Whether a live hiros graph offers ``topic`` transient-local (kept for late subscribers).

    The same table gives the offered QoS the recordings' channels carry.
    """
    return any(profile["durability"] == "transient_local" for profile in offered_qos(topic))


class Player:
    """Publishes a recording's messages on time, and /clock in between."""

    def __init__(self, node: Any, topics: dict[str, str], args: argparse.Namespace) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile
        from rosgraph_msgs.msg import Clock

        self.args = args
        self.remaps = parse_remaps(args.remap)
        self.publishers = {}
        self.skipped: Counter[str] = Counter()
        for topic, msgtype in topics.items():
            cls, reason = message_class(msgtype)
            if cls is None:
                self.skipped[reason] += 1
                node.get_logger().warning(f"skipping {topic}: {msgtype} ({_SKIPPED[reason]})")
                continue
            qos = QoSProfile(depth=100)
            if latched(topic):
                qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
            self.publishers[topic] = node.create_publisher(cls, self.remaps.get(topic, topic), qos)
        self.clock = None if args.no_clock else node.create_publisher(Clock, "/clock", 10)
        self.clock_msg = Clock()
        self.counts: Counter[str] = Counter()

    def wait_for_subscribers(self, timeout: float) -> None:
        """Give DDS discovery up to ``timeout`` s, less when every topic has a subscriber.

        Volatile topics deliver nothing to subscribers that have not been discovered yet, so
        without this pause the first messages of a replay would be lost.
        """
        deadline = time.monotonic() + max(timeout, 0.0)
        while time.monotonic() < deadline and not all(
            p.get_subscription_count() for p in self.publishers.values()
        ):
            time.sleep(0.05)

    def publish_clock(self, log_time_ns: int) -> None:
        """/clock at a recording log time."""
        if self.clock is not None:
            sec, nanosec = divmod(int(log_time_ns), 1_000_000_000)
            self.clock_msg.clock.sec, self.clock_msg.clock.nanosec = sec, nanosec
            self.clock.publish(self.clock_msg)

    def play(self, messages: Iterable[RecordedMessage]) -> int:
        """Publish every message at its time; returns how many were published."""
        played = 0
        wall_start = time.monotonic()
        origin = None
        for message, offset in playback_schedule(
            messages, rate=self.args.rate, start=self.args.start, log_time=_log_time
        ):
            origin = message.log_time_ns if origin is None else origin
            while (remaining := wall_start + offset - time.monotonic()) > 0:
                elapsed = time.monotonic() - wall_start
                self.publish_clock(origin + int(elapsed * self.args.rate * 1e9))
                time.sleep(min(remaining, CLOCK_PERIOD))
            self.publish_clock(message.log_time_ns)
            self.publishers[message.topic].publish(message.data)
            self.counts[self.remaps.get(message.topic, message.topic)] += 1
            played += 1
        return played

    def flush(self, timeout: float = 2.0) -> None:
        """Wait until every subscriber acknowledged what was published (reliable QoS).

        Without this the process may tear its writers down while the last samples are still
        in flight, and a subscriber would miss the end of the replay.
        """
        from rclpy.duration import Duration

        for publisher in self.publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=timeout))


_SKIPPED = {
    "unknown_type": f"not a message type of {', '.join(KNOWN_PACKAGES)}",
    "package_not_installed": "its package is not installed here",
}


def _log_time(message: RecordedMessage) -> int:
    return message.log_time_ns


def run(args: argparse.Namespace) -> int:
    """Play until the end (or forever with --loop, until Ctrl-C)."""
    from hiros_ros import prepare_ros_environment

    prepare_ros_environment()
    import rclpy

    list(playback_schedule([], rate=args.rate))  # a bad --rate fails before ROS starts
    parse_remaps(args.remap)
    with RecordingReader(args.recording) as reader:
        topics = dict(reader.topics)
    if args.topics:
        missing = sorted(set(args.topics) - set(topics))
        if missing:
            msg = f"{args.recording} has no topic {', '.join(missing)} (it has {sorted(topics)})"
            raise RecordingError(msg)
        topics = {t: topics[t] for t in args.topics}
    rclpy.init()
    node = rclpy.create_node("hiros_play")
    player = Player(node, topics, args)
    try:
        player.wait_for_subscribers(args.delay)
        while True:
            with RecordingReader(args.recording) as reader:
                played = player.play(reader.messages(player.publishers))
                for problem in reader.problems:
                    node.get_logger().warning(problem)
            if not args.loop or played == 0:
                break
        player.flush()
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    for topic, count in sorted(player.counts.items()):
        print(f"{topic}: {count} messages")
    for reason, count in sorted(player.skipped.items()):
        print(f"topics skipped: {reason}: {count}")
    return 0
