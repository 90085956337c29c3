"""The optimizer and filter nodes live: frames through both, the optimizer's services."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HERE = Path(__file__).resolve().parent


def _node(module: str, env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", f"from {module} import main; main()"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def test_optimizer_and_filter_nodes_with_services(ros_env: dict[str, str]) -> None:
    pytest.importorskip("hiros_skeleton_msgs.srv")
    nodes = [_node("hiros_optimizer.node", ros_env), _node("hiros_filter.node", ros_env)]
    try:
        client = subprocess.run(
            [sys.executable, str(HERE / "live_client.py")],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    finally:
        outputs = []
        for node in nodes:
            node.terminate()
            outputs.append(node.communicate(timeout=30)[0])
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
