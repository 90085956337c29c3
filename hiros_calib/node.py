"""``calib`` node: camera skeleton topics in, a live calibration out as parameters and TF.

    /<cam>/skeletons (raw CDR, camera frame and clock) -> LiveCalibrator -> parameters
        cameras.<cam>.{frame_id, time_offset, drift, drift_epoch, translation, rotation,
        quality.*} and /tf_static (world -> each camera's <prefix>camera_base, the root of
        its driver's TF tree: hiros_core.frames)

Other nodes follow the parameters through ``/parameter_events`` (``ros2 param get /calib
cameras.k02.time_offset`` reads one). A calibration file (``calibration_file``) is loaded at
start and published at once; ``~/save`` (std_srvs/Trigger) writes the current calibration to
``save_file`` (default: ``calibration_file``), and so does shutdown. The estimates run on a
worker thread so that frames keep arriving while a window is being solved.
"""

from __future__ import annotations

import copy
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_srvs.srv import Trigger
from tf2_msgs.msg import TFMessage

from hiros_calib.live import LiveCalibrator, LiveCalibratorParams
from hiros_core.calibration import Calibration, load_calibration, save_calibration
from hiros_core.codec import decode_group
from hiros_core.errors import CalibrationError
from hiros_core.frames import AZURE_KINECT_MOUNT, CameraMount, camera_transforms
from hiros_ros import HirosNode, run_node
from hiros_ros.memory import release_freed_memory
from hiros_ros.node import camera_qos
from hiros_ros.tf import tf_message

__all__ = ["LIVE", "STEP_PERIOD", "CalibNode", "CalibNodeParams", "main"]

LIVE = (
    "buffer_length",
    "first_estimate_after",
    "update_period",
    "blend",
    "check_period",
    "moved_floor",
    "moved_shift",
    "recalibrate_after",
    "silent_after",
    "save_file",
    "publish_tf",
)
"""The live schedule, windows and outputs: applied while the node runs (the calibrator reads
its parameters at every step)."""

STEP_PERIOD = 0.2
"""Seconds between the worker's looks at whether a check or an estimate is due."""


@dataclass
class CalibNodeParams(LiveCalibratorParams):
    """The live calibration's parameters plus the node's topics and files."""

    camera_names: list[str] = field(default_factory=lambda: ["k01", "k02", "k03"])
    """Cameras to listen to (not ``cameras``: that prefix holds the results)."""
    camera_topic: str = "/{camera}/skeletons"
    """Topic of each camera; {camera} is replaced by each name of camera_names."""
    camera_qos: str = "sensor_data"
    calibration_file: str = ""
    """Loaded at start when it exists; the default place ``~/save`` writes to."""
    save_file: str = ""
    """Where ``~/save`` and shutdown write; empty: ``calibration_file`` or calibration.yaml."""
    publish_tf: bool = True
    """Publish world -> camera transforms on /tf_static."""
    tf_frame_suffix: str = AZURE_KINECT_MOUNT.frame_suffix
    """A skeleton frame with this suffix hangs in its driver's tree below tf_base_suffix."""
    tf_base_suffix: str = AZURE_KINECT_MOUNT.base_suffix
    """Root of each camera's driver tree, which /tf_static attaches to the world (world ->
    <prefix>camera_base, so that no frame has two parents); empty: world -> skeleton frame."""
    tf_base_to_frame: list[float] = field(
        default_factory=lambda: list(AZURE_KINECT_MOUNT.base_to_frame)
    )
    """The driver's fixed base -> skeleton frame transform: x, y, z (m), qx, qy, qz, qw
    (default: the Azure Kinect ROS driver's camera_base -> depth_camera_link)."""


def _flat_quality(quality: dict[str, Any], prefix: str) -> dict[str, Any]:
    """``quality.*`` parameters: numbers as doubles, nested mappings one level deep."""
    out: dict[str, Any] = {}
    for key, value in quality.items():
        name = f"{prefix}.{key}"
        if isinstance(value, dict):
            out.update(_flat_quality(value, name))
        elif isinstance(value, bool | str):
            out[name] = value
        elif isinstance(value, int | float):
            out[name] = float(value)
    return out


def calibration_parameters(calibration: Calibration) -> dict[str, Any]:
    """The node's result parameters, ``cameras.<cam>.*``, as plain values."""
    out: dict[str, Any] = {}
    for name, cam in calibration.cameras.items():
        prefix = f"cameras.{name}"
        out[f"{prefix}.frame_id"] = cam.frame_id
        out[f"{prefix}.time_offset"] = float(cam.time_offset)
        out[f"{prefix}.drift"] = float(cam.drift)
        out[f"{prefix}.drift_epoch"] = float(cam.drift_epoch)
        out[f"{prefix}.translation"] = [float(v) for v in cam.translation]
        out[f"{prefix}.rotation"] = [float(v) for v in cam.rotation]
        out.update(_flat_quality(cam.quality, f"{prefix}.quality"))
    return out


class CalibNode(HirosNode):
    """Camera topics -> ``LiveCalibrator`` -> parameters, /tf_static, calibration file."""

    def __init__(self) -> None:
        super().__init__("calib")
        self.declare_params(CalibNodeParams, live=LIVE, apply=self._apply)
        self._setting_results = False  # True while publish_result sets cameras.*
        self.add_on_set_parameters_callback(self._on_set_results)
        self.live = LiveCalibrator(self.params, self._initial_calibration())
        # snapshots handed from the worker thread: the newest result, and the one to publish
        self._current = copy.deepcopy(self.live.calibration)
        self._latest: Calibration | None = self._current
        self._published: dict[str, Any] = {}
        self.accounted = self.live
        self._logged_events = 0
        qos = camera_qos(self.params.camera_qos)
        topics = [self.params.camera_topic.format(camera=c) for c in self.params.camera_names]
        self._topic_cameras: dict[str, str] = {}
        for camera, topic in zip(self.params.camera_names, topics, strict=True):
            self.create_raw_subscription(
                SkeletonGroupMsg, topic, lambda data, c=camera: self.on_group(c, data), qos
            )
        tf_qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._tf = self.create_publisher(TFMessage, "/tf_static", tf_qos)
        self.create_service(Trigger, "~/save", self.on_save)
        self.create_timer(0.5, self.publish_result)
        self._stop = threading.Event()
        self._worker = threading.Thread(target=self._work, name="calib-worker", daemon=True)
        self._worker.start()
        self.get_logger().info(f"{topics} -> LiveCalibrator -> parameters cameras.*, /tf_static")

    def _apply(self, params: CalibNodeParams) -> None:
        self.live.params = params

    def _on_set_results(self, parameters: list[Parameter]) -> SetParametersResult:
        """Refuse a change of the results (``cameras.*``) from outside.

        The calibration makes them: a value set by hand would be followed by the stages but
        unknown to the calibration.
        """
        if self._setting_results:
            return SetParametersResult(successful=True)
        for parameter in parameters:
            if parameter.name.startswith("cameras."):
                reason = (
                    f"{parameter.name} is a result of the calibration; to start from other "
                    "values give calibration_file, to keep these call ~/save"
                )
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _initial_calibration(self) -> Calibration | None:
        path = self.params.calibration_file
        if not path or not Path(path).exists():
            return None
        try:
            calibration = load_calibration(path)
        except CalibrationError as exc:
            self.get_logger().error(f"{exc}; starting without it")
            return None
        self.get_logger().info(f"loaded {path}: cameras {sorted(calibration.cameras)}")
        return calibration

    def on_group(self, topic_camera: str, data: bytes) -> None:
        """Buffer one frame of ``topic_camera``'s topic with its arrival time on our clock.

        The calibrated camera is named by the frame id; a topic's frames name the topic's
        camera, or else (drivers with other frame names) the first camera seen on it. Frames
        naming any other camera are dropped: every new name would become a camera to buffer
        and to pair with all the others in each estimate (a stream of ever-new frame ids
        made the estimates crawl and log a line per camera).
        """
        group = decode_group(data)
        camera = group.camera
        if camera and camera != topic_camera:
            bound = self._topic_cameras.setdefault(
                topic_camera, camera if camera not in self.params.camera_names else topic_camera
            )
            if camera != bound:
                self.drop(
                    "frame_id of another camera",
                    f"{group.frame_id!r} on the topic of {topic_camera!r}, which carries {bound!r}",
                )
                return
        elif camera:
            self._topic_cameras[topic_camera] = camera
        self.live.update(group, self.get_clock().now().nanoseconds)

    def _work(self) -> None:
        while not self._stop.wait(STEP_PERIOD):
            try:
                estimates = self.live.estimates
                if self.live.step(self.get_clock().now().nanoseconds):
                    self._current = copy.deepcopy(self.live.calibration)
                    self._latest = self._current
                if self.live.estimates != estimates:
                    release_freed_memory()  # an estimate's arrays would otherwise stay mapped
            except Exception as exc:  # the worker must survive a bad window
                self.error(type(exc).__name__, f"calibration step: {exc}")

    def publish_result(self) -> None:
        """Apply a new result (parameters, TF) and log what happened since the last call."""
        events, count = self.live.events_since(self._logged_events)
        if count - self._logged_events > len(events):
            missed = count - self._logged_events - len(events)
            self.get_logger().info(f"{missed} older events not logged (only the newest are kept)")
        for _, message in events:
            self.get_logger().info(message)
        self._logged_events = count
        latest, self._latest = self._latest, None
        if latest is None or not latest.cameras:
            return
        values = calibration_parameters(latest)
        changed = [
            Parameter(name, value=value)
            for name, value in values.items()
            if self._published.get(name) != value
        ]
        self._setting_results = True
        try:
            for parameter in changed:
                if not self.has_parameter(parameter.name):
                    self.declare_parameter(parameter.name, parameter.value)
            self.set_parameters(changed)
        finally:
            self._setting_results = False
        self._published.update(values)
        if self.params.publish_tf:
            mount = CameraMount(self.params.tf_frame_suffix, self.params.tf_base_suffix,
                                tuple(self.params.tf_base_to_frame))  # fmt: skip
            stamp = self.get_clock().now().to_msg()
            self._tf.publish(tf_message(camera_transforms(latest, mount), stamp))
        self.count("results_published")

    def _save_path(self) -> Path:
        return Path(self.params.save_file or self.params.calibration_file or "calibration.yaml")

    def save(self) -> str:
        """Write the current calibration; returns what happened, for the service and logs."""
        calibration = self._current
        if not calibration.cameras:
            return "nothing to save: no camera is calibrated yet"
        path = self._save_path()
        save_calibration(calibration, path)
        return f"saved {sorted(calibration.cameras)} to {path}"

    def on_save(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/save``: write the calibration file."""
        try:
            response.message = self.save()
            response.success = not response.message.startswith("nothing")
        except OSError as exc:
            response.success, response.message = False, f"cannot save: {exc}"
        self.get_logger().info(response.message)
        return response

    def on_shutdown(self) -> None:
        """Stop the worker and save what was found (called by ``run_node``)."""
        self._stop.set()
        self._worker.join(timeout=5.0)
        try:
            self.get_logger().info(self.save())
        except OSError as exc:
            self.get_logger().error(f"cannot save at shutdown: {exc}")


def main(args: list[str] | None = None) -> None:
    """``ros2 run hiros calib``."""
    run_node(CalibNode, args)
