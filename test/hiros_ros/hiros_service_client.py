"""Client side of the Hi-ROS drop-in test: call the optimizer where Hi-ROS's clients call it."""

from __future__ import annotations

import sys
import time

import rclpy

from hiros_optimizer.node import service_types


def main() -> int:
    rclpy.init()
    node = rclpy.create_node("hiros_service_client")
    calibrate_type, change_id_type = service_types()
    change_id = node.create_client(change_id_type, "/hiros/change_id")
    calibrate = node.create_client(calibrate_type, "/hiros/calibrate")
    deadline = time.monotonic() + 60
    while not (change_id.service_is_ready() and calibrate.service_is_ready()):
        rclpy.spin_once(node, timeout_sec=0.1)
        if time.monotonic() > deadline:
            print("no /hiros services", file=sys.stderr)
            return 2
    results = []
    for client, request in (
        (change_id, change_id_type.Request(from_id=3, to_id=0)),
        (calibrate, calibrate_type.Request(track_ids=[7])),
    ):
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=10)
        results.append(future.result().ok)
    names = dict(node.get_service_names_and_types())
    print("answers", *results)
    print("types", names["/hiros/change_id"][0], names["/hiros/calibrate"][0])
    print("private", "/hiros/skeleton_optimizer/change_id" in names)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
