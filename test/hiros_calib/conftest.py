"""Fixtures of the calibration tests: synthetic multi-camera scenes with known calibration.

Tests run with ``--import-mode=importlib``, where test modules cannot import siblings, so the
scene builder of ``calib_synthetic.py`` is handed out as a fixture.
"""

import importlib.util
import sys
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location(
    "hiros_calib_test_synthetic", Path(__file__).with_name("calib_synthetic.py")
)
synthetic = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = synthetic  # dataclasses look their module up there
_spec.loader.exec_module(synthetic)


@pytest.fixture(scope="session")
def make_scene():
    """``make_scene(**options) -> Scene`` (see calib_synthetic.make_scene)."""
    return synthetic.make_scene
