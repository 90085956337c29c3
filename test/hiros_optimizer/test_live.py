"""The optimizer and filter nodes live: frames through both, the optimizer's services."""

from __future__ import annotations

from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HERE = Path(__file__).resolve().parent


def test_optimizer_and_filter_nodes_with_services(ros_processes) -> None:
    pytest.importorskip("hiros_skeleton_msgs.srv")
    ros_processes.node("hiros_optimizer.node")
    ros_processes.node("hiros_filter.node")
    client = ros_processes.client(HERE / "live_client.py")
    outputs = [ros_processes.stop()]
    log = client.stdout + client.stderr + "".join(outputs)
    assert client.returncode == 0, log
    words = client.stdout.split()
    figures = dict(zip(words[::2], words[1::2], strict=True))
    assert int(figures["received"]) == 95, log
    assert figures["change_id"] == "True", log
    assert figures["unknown"] == "False", log
    assert figures["calibrate"] == "True", log
    assert figures["last_id"] == "0", log
    assert float(figures["vx"]) == pytest.approx(0.5, abs=0.02), log
    assert "Traceback" not in log
