"""Shared by the pipeline tests: simulated scenes written as recordings with their truth."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from hiros_sim import SimParams, simulate, write_recording


@pytest.fixture(scope="session")
def simulated_scene(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    """``simulated_scene(name, **SimParams)``: a folder with the recording and its truth."""

    def make(name: str, **settings: object) -> Path:
        folder = tmp_path_factory.mktemp(name)
        write_recording(simulate(SimParams(**settings)), folder)
        return folder

    return make
