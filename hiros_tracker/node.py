"""``tracker`` node: each camera's SkeletonGroups in, tracked world-frame detections out.

    /<cam>/skeletons (raw CDR, camera frame and clock)  ->  Tracker.update  ->  /hiros/tracker

The calibration comes from ``calibration_file`` at start and then, live, from the ``calib``
node's parameters (``cameras.<cam>.time_offset``, ``.translation``, ...) through
``/parameter_events``. A camera without calibration is reported once; its frames are dropped
and counted on ``/diagnostics``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg

from hiros_core.calibration import Calibration, load_calibration
from hiros_core.codec import decode_group, encode_group
from hiros_core.errors import CalibrationError
from hiros_ros import HirosNode, run_node
from hiros_ros.calibration_follower import CalibrationFollower
from hiros_ros.node import camera_qos, pipeline_qos
from hiros_tracker.tracker import Tracker, TrackerParams

__all__ = ["ALIASES", "LIVE", "TrackerNode", "TrackerNodeParams", "main"]

LIVE = (
    "max_delay",
    "gate_distance",
    "gate_growth",
    "min_confidence",
    "body_id_bonus",
    "recent_window",
    "duplicate_distance",
    "min_hits",
    "min_cameras",
    "single_camera_confirm",
    "tentative_timeout",
    "track_timeout",
)
"""Gates, association and track life: applied while the node runs (``Tracker.set_params``)."""

ALIASES = {"fixed_delay": "max_delay"}
"""Hi-ROS's names of our parameters (``input_topics`` is a parameter of its own)."""


@dataclass
class TrackerNodeParams(TrackerParams):
    """The tracker's parameters plus its topics and where the calibration comes from."""

    cameras: list[str] = field(default_factory=lambda: ["k01", "k02", "k03"])
    camera_topic: str = "/{camera}/skeletons"
    input_topics: list[str] = field(default_factory=list)
    """Camera topics in full, as Hi-ROS's tracker takes them; when given, they replace
    ``cameras`` and ``camera_topic``."""
    camera_qos: str = "sensor_data"
    output_topic: str = "/hiros/tracker"
    calibration_file: str = ""
    calib_node: str = "/calib"


class TrackerNode(HirosNode):
    """Camera topics -> ``Tracker.update`` -> ``output_topic``."""

    def __init__(self) -> None:
        super().__init__("tracker")
        self.declare_params(TrackerNodeParams, live=LIVE, apply=self._apply, aliases=ALIASES)
        calibration = self._initial_calibration()
        self.tracker = Tracker(self.params, calibration)
        self.follower = CalibrationFollower(
            self, calibration, self._on_calibration, self.params.calib_node
        )
        self.publisher = self.create_raw_publisher(
            SkeletonGroupMsg, self.params.output_topic, pipeline_qos()
        )
        qos = camera_qos(self.params.camera_qos)
        topics = self.params.input_topics or [
            self.params.camera_topic.format(camera=c) for c in self.params.cameras
        ]
        for topic in topics:
            self.create_raw_subscription(SkeletonGroupMsg, topic, self.on_group, qos)
        self.accounted = self.tracker
        self._reported: set[str] = set()
        self.get_logger().info(f"{topics} -> Tracker -> {self.params.output_topic}")

    def _apply(self, params: TrackerNodeParams) -> None:
        self.tracker.set_params(params)

    def _initial_calibration(self) -> Calibration:
        path = self.params.calibration_file
        if not path:
            self.get_logger().info(f"no calibration_file: waiting for {self.params.calib_node}")
            return Calibration(reference="")
        try:
            return load_calibration(path)
        except CalibrationError as exc:
            self.get_logger().fatal(str(exc))
            raise SystemExit(1) from None

    def _on_calibration(self, calibration: Calibration) -> None:
        known = set(self.tracker.correction.cameras)
        self.tracker.set_calibration(calibration)
        self._reported &= self.tracker.uncalibrated  # (kept a subset: see _report_uncalibrated)
        if set(calibration.cameras) != known:
            self.get_logger().info(f"calibration: cameras {sorted(calibration.cameras)}")

    def on_group(self, data: bytes) -> None:
        """Decode one camera frame, track, publish what the tracker released.

        Frames released with nobody in them go out too, as an empty group: the stages
        downstream learn that nobody is there (a camera's empty frame reaches the tracker
        as an empty group from the bridge). A frame only buffered publishes nothing.
        """
        released = self.tracker.processed
        result = self.tracker.update(decode_group(data))
        self._report_uncalibrated()
        if result.skeletons or self.tracker.processed > released:
            self.publish_raw(self.publisher, encode_group(result))

    def _report_uncalibrated(self) -> None:
        """Name each camera without calibration once, at most one line per log interval.

        Frame ids come from the input: a publisher sending ever-new ones must not get a log
        line per frame (the cameras not named yet are named in later intervals).
        """
        uncalibrated = self.tracker.uncalibrated
        if len(uncalibrated) == len(self._reported):  # the same set: it is kept a subset
            return
        camera = min(uncalibrated - self._reported)

        def message() -> str:  # built only when the line is due
            return (
                f"camera {camera!r} has no calibration ({len(uncalibrated)} camera(s) without "
                f"one so far): its frames are dropped until {self.params.calib_node} or the "
                "calibration file provides one"
            )

        if self.warn_throttled("camera without calibration", message):
            self._reported.add(camera)


def main(args: list[str] | None = None) -> None:
    """``ros2 run hiros tracker``."""
    run_node(TrackerNode, args)
