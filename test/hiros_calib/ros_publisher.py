"""Camera side of the calib node test: replays a synthetic two-camera scene at 3x speed.

Publishes raw SkeletonGroup bytes on /cam0/skeletons and /cam1/skeletons in reference-time
order, then waits for the calib node's result parameters on /parameter_events and /tf_static,
calls ~/save and prints one summary line the test reads.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

import rclpy
from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
from rcl_interfaces.msg import ParameterEvent
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_srvs.srv import Trigger
from tf2_msgs.msg import TFMessage

from hiros_core.codec import encode_group

SPEED = 3.0
_spec = importlib.util.spec_from_file_location(
    "calib_synthetic", Path(__file__).with_name("calib_synthetic.py")
)
synthetic = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = synthetic
_spec.loader.exec_module(synthetic)


def main() -> int:
    scene = synthetic.make_scene(angles_deg=(0.0, 120.0), duration=30.0, noise=0.005, seed=1)
    frames = sorted(
        (scene.truth.cameras[name].to_reference_time(g.stamp), name, g)
        for name, groups in scene.camera_groups.items()
        for g in groups
    )
    rclpy.init()
    node = rclpy.create_node("hiros_test_calib_cameras")
    offsets: dict[str, float] = {}
    frames_seen: list[str] = []

    def on_event(event: ParameterEvent) -> None:
        if event.node == "/calib":
            for p in (*event.new_parameters, *event.changed_parameters):
                if p.name.endswith(".time_offset"):
                    offsets[p.name.split(".")[1]] = p.value.double_value

    node.create_subscription(ParameterEvent, "/parameter_events", on_event, 100)
    tf_qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(
        TFMessage,
        "/tf_static",
        lambda m: frames_seen.extend(t.child_frame_id for t in m.transforms),
        tf_qos,
    )
    publishers = {
        name: node.create_publisher(SkeletonGroupMsg, f"/{name}/skeletons", QoSProfile(depth=50))
        for name in scene.camera_groups
    }
    time.sleep(2.0)  # discovery
    start, first = time.monotonic(), frames[0][0]
    for t_ref, name, group in frames:
        delay = (t_ref - first) / SPEED - (time.monotonic() - start)
        if delay > 0:
            rclpy.spin_once(node, timeout_sec=min(delay, 0.01))
            time.sleep(max(0.0, (t_ref - first) / SPEED - (time.monotonic() - start)))
        publishers[name].publish(encode_group(group))
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and "cam1" not in offsets:
        rclpy.spin_once(node, timeout_sec=0.1)
    client = node.create_client(Trigger, "/calib/save")
    client.wait_for_service(timeout_sec=10.0)
    future = client.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
    for _ in range(20):
        rclpy.spin_once(node, timeout_sec=0.05)
    saved = future.result().message if future.result() else "no answer"
    truth = scene.truth.cameras["cam1"].time_offset
    print(
        f"offset {offsets.get('cam1', float('nan')):.4f} truth {truth:.4f} "
        f"tf {sorted(set(frames_seen))} save: {saved}",
        flush=True,
    )
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
