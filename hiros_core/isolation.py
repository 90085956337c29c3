"""Keep DDS on this machine when a command starts ROS 2 processes.

They run in a private network namespace holding only loopback, or, where the kernel refuses
that, with discovery limited to localhost. ``hiros bench`` and the tests use this; nothing here
imports ROS.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess

__all__ = ["isolated", "isolated_env"]

_IN_NAMESPACE = "HIROS_IN_NETNS"


@functools.cache
def _can_unshare() -> bool:
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return False
    probe = subprocess.run(["unshare", "-rn", "true"], capture_output=True, check=False)
    return probe.returncode == 0


def isolated_env(domain_id: int | None = None) -> dict[str, str]:
    """The environment for ROS 2 children: localhost-only discovery, optional domain id."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(domain_id)
    return env


def isolated(command: list[str]) -> list[str]:
    """``command`` wrapped to run in a loopback-only network namespace when possible."""
    if os.environ.get(_IN_NAMESPACE) == "1" or not _can_unshare():
        return command
    script = f'ip link set lo up && {_IN_NAMESPACE}=1 exec "$@"'
    return ["unshare", "-rn", "sh", "-c", script, "sh", *command]
