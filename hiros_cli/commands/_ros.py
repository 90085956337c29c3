"""What ``hiros topic`` and ``hiros param`` share: one short-lived rclpy node, and waiting."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from hiros_core.errors import ConfigError


@contextmanager
def cli_node(name: str) -> Iterator[Any]:
    """An rclpy node for one command, shut down however the command ends."""
    from hiros_ros import prepare_ros_environment

    prepare_ros_environment()
    import rclpy

    rclpy.init()
    node = rclpy.create_node(name)
    try:
        yield node
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


def answer(node: Any, future: Any, timeout: float, what: str) -> Any:
    """Spin ``node`` until ``future`` is done; its result, or ConfigError naming ``what``."""
    import rclpy

    rclpy.spin_until_future_complete(node, future, timeout_sec=timeout)
    if not future.done():
        msg = f"{what}: no answer within {timeout:g} s"
        raise ConfigError(msg)
    return future.result()
