"""Shared fixtures: real data paths and a fresh ROS_DOMAIN_ID per ROS test."""

from __future__ import annotations

import itertools
import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED_DATA = REPO.parent / "shared" / "data"
_domains = itertools.count(int(os.environ.get("HIROS_TEST_DOMAIN_BASE", "40")) + os.getpid() % 40)


def shared_data(*parts: str) -> Path:
    """A file of ../shared/data; skips the test where the folder is absent (a user's checkout)."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} is not available")
    return path


@pytest.fixture
def ros_env(monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """Environment for ROS 2 child processes: own domain id, localhost-only discovery."""
    domain = str(next(_domains) % 100 + 100)
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return dict(os.environ)
