"""``pipeline`` node: bridge and all four stages in one process, no serialisation between them.

Camera topics in (Azure-driver ``/<cam>/body_tracking_data`` or ``/<cam>/skeletons``), every
stage's output out on ``/hiros/{tracker,merger,optimizer,filter}``. Stages receive the previous
stage's objects directly; only the published copies are encoded (with the fast codec), and
only for topics someone subscribes to (the topics are volatile: an unheard message reaches
nobody, now or later). The filter's output goes out first: it ends the chain, and its
consumers should not wait while the intermediate stages' outputs are encoded.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from visualization_msgs.msg import MarkerArray

from hiros_core.accounting import Merged
from hiros_core.calibration import Calibration, load_calibration
from hiros_core.codec import decode_group, encode_group
from hiros_filter.node import LIVE as FILTER_LIVE
from hiros_merger.node import LIVE as MERGER_LIVE
from hiros_pipeline.pipeline import STAGES, Pipeline, PipelineParams
from hiros_ros import HirosNode, run_node
from hiros_ros.calibration_follower import CalibrationFollower
from hiros_ros.node import camera_qos, pipeline_qos
from hiros_tracker.node import LIVE as TRACKER_LIVE

LIVE = (
    *(f"tracker.{name}" for name in TRACKER_LIVE),
    *(f"merger.{name}" for name in MERGER_LIVE),
    *(f"filter.{name}" for name in FILTER_LIVE),
)
"""The stage nodes' live parameters, under their stage's name."""


@dataclass
class PipelineNodeParams(PipelineParams):
    """The stages' parameters plus where the cameras and the calibration come from."""

    cameras: list[str] = field(default_factory=lambda: ["k01", "k02", "k03"])
    input: str = "driver"
    """What the cameras publish: ``driver`` (the Azure Kinect driver's MarkerArray on
    /<camera>/body_tracking_data) or ``skeletons`` (SkeletonGroup on /<camera>/skeletons)."""
    camera_qos: str = "sensor_data"
    calibration_file: str = ""
    calib_node: str = "/calib"


class PipelineNode(HirosNode):
    """Composed pipeline: each camera frame goes through ``Pipeline.update``."""

    def __init__(self) -> None:
        super().__init__("pipeline")
        self.declare_params(PipelineNodeParams, live=LIVE, apply=self._apply)
        calibration = (
            load_calibration(self.params.calibration_file)
            if self.params.calibration_file
            else Calibration(reference="")
        )
        self.pipeline = Pipeline(self.params, calibration)
        self.follower = CalibrationFollower(
            self, calibration, self.pipeline.set_calibration, self.params.calib_node
        )
        self.publishers_ = {
            stage: self.create_raw_publisher(SkeletonGroupMsg, f"/hiros/{stage}", pipeline_qos())
            for stage in STAGES
        }
        self._bridges = {}
        for camera in self.params.cameras:
            self._subscribe(camera)
        # A frame the bridge keeps goes on to the tracker: the pipeline counts it.
        parts = [("bridge: ", bridge) for bridge in self._bridges.values()]
        self.accounted = Merged([*parts, ("", self.pipeline)], [self.pipeline])
        self.get_logger().info(
            f"cameras {self.params.cameras} ({self.params.input}) -> "
            + ", ".join(f"/hiros/{s}" for s in STAGES)
        )

    def _apply(self, params: PipelineNodeParams) -> None:
        self.pipeline.set_params(params)

    def _subscribe(self, camera: str) -> None:
        qos = camera_qos(self.params.camera_qos)
        if self.params.input == "driver":
            from hiros_core.driver import DriverBridge, DriverBridgeParams, warm_up

            warm_up()  # the bridge's compiled path, before the first camera message

            bridge = DriverBridge(DriverBridgeParams(), default_frame=f"{camera}_depth_camera_link")
            self._bridges[camera] = bridge
            self.create_raw_subscription(
                MarkerArray,
                f"/{camera}/body_tracking_data",
                lambda data, bridge=bridge: self.on_group(bridge.update_bytes(data, self._now())),
                qos,
            )
        else:
            self.create_raw_subscription(
                SkeletonGroupMsg,
                f"/{camera}/skeletons",
                lambda data: self.on_group(decode_group(data)),
                qos,
            )

    def _now(self) -> int:
        """Arrival time (ns) of a driver message: an empty one is stamped from it."""
        return self.get_clock().now().nanoseconds

    def on_group(self, group) -> None:  # noqa: ANN001 - SkeletonGroup | None from a bridge
        """One camera frame through the stages; publish what each stage produced.

        The counts are taken also when the bridge dropped the frame (``group`` None): a
        camera sending only bad messages must show on /diagnostics at once. When the tracker
        released frames with nobody in them, the empty outputs go out too (as the separate
        nodes publish them): subscribers learn that nobody is there.
        """
        if group is not None:
            processed = self.pipeline.tracker.processed
            outputs = self.pipeline.update(group)
            released = self.pipeline.tracker.processed > processed
            for stage, result in reversed(list(zip(STAGES, outputs, strict=True))):
                publisher = self.publishers_[stage]
                if (result.skeletons or released) and publisher.get_subscription_count():
                    self.publish_raw(publisher, encode_group(result))
        self.absorb_stage()


def main(args: list[str] | None = None) -> None:
    """``ros2 run hiros pipeline``."""
    run_node(PipelineNode, args)
