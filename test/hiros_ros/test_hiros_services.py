"""Hi-ROS's clients call the optimizer at /hiros/change_id and /hiros/calibrate."""

from __future__ import annotations

from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
HERE = Path(__file__).resolve().parent


def test_the_optimizer_answers_at_hiros_s_service_names(ros_processes) -> None:
    ros_processes.node(
        "hiros_optimizer.node", "-r", "__node:=skeleton_optimizer", "-r", "__ns:=/hiros"
    )
    client = ros_processes.client(HERE / "hiros_service_client.py", timeout=90)
    output = ros_processes.stop()
    assert client.returncode == 0, client.stderr + output
    lines = client.stdout.splitlines()
    assert lines[0] == "answers False False"  # no track 3 to move, no track 7 to calibrate
    # ours without Hi-ROS's hiros_skeleton_optimizer installed (the same fields)
    assert lines[1] == "types hiros_skeleton_msgs/srv/ChangeId hiros_skeleton_msgs/srv/Calibrate"
    assert lines[2] == "private True"  # and still at ~/change_id
    assert "Traceback" not in output


def test_hiros_s_service_types_are_taken_when_installed(monkeypatch) -> None:
    import sys
    import types

    from hiros_skeleton_msgs import srv as ours

    from hiros_optimizer.node import service_types

    assert service_types() == (ours.Calibrate, ours.ChangeId)
    hiros_package = types.ModuleType("hiros_skeleton_optimizer")
    hiros_srv = types.ModuleType("hiros_skeleton_optimizer.srv")
    hiros_srv.Calibrate, hiros_srv.ChangeId = type("Calibrate", (), {}), type("ChangeId", (), {})
    monkeypatch.setitem(sys.modules, "hiros_skeleton_optimizer", hiros_package)
    monkeypatch.setitem(sys.modules, "hiros_skeleton_optimizer.srv", hiros_srv)
    assert service_types() == (hiros_srv.Calibrate, hiros_srv.ChangeId)
