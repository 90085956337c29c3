"""Mocap clips from the developers' shared data folder, which the product never bundles.

The Bandai-Namco Research Motion Dataset 2 (``bandai_motion2``: waving, raising hands, walking
and turning in several styles) is licensed CC BY-NC 4.0: it serves development and tests, so it
is read where it lies and never copied into the repository. The folder holding it is
``$HIROS_SHARED_DATA`` when set, else ``shared/data`` beside the repository checkout.
"""

from __future__ import annotations

import os
from pathlib import Path

from hiros_core.errors import ConfigError

__all__ = ["BANDAI_FOLDER", "bandai_files", "shared_data_dir"]

BANDAI_FOLDER = "bandai_motion2"
_CONTENTS = (
    "wave-both-hands",
    "walk-turn-left",
    "raise-up-both-hands",
    "wave-right-hand",
    "walk-turn-right",
    "wave-left-hand",
)
"""What the people do, in order: the first is the gesture a lone person repeats."""
_STYLES = ("normal", "active", "elderly", "exhausted")
"""Styles every one of ``_CONTENTS`` was recorded in."""


def shared_data_dir() -> Path:
    """``$HIROS_SHARED_DATA``, else ``../shared/data`` relative to the repository."""
    configured = os.environ.get("HIROS_SHARED_DATA")
    if configured:
        return Path(configured)
    return Path(__file__).resolve().parents[2] / "shared" / "data"


def bandai_files(n_people: int, seed: int) -> tuple[str, ...]:
    """One Bandai-Namco clip per person: gestures and walks in turn, styles varying by seed.

    Raises:
        ConfigError: the dataset is not where ``shared_data_dir`` points.

    """
    folder = shared_data_dir() / BANDAI_FOLDER
    files = tuple(
        folder
        / f"dataset-2_{_CONTENTS[p % len(_CONTENTS)]}_{_STYLES[(seed + p) % len(_STYLES)]}_001.bvh"
        for p in range(n_people)
    )
    missing = [path.name for path in files if not path.is_file()]
    if missing:
        msg = (
            f"the Bandai-Namco motion needs {', '.join(missing)} in {folder}: set "
            f"HIROS_SHARED_DATA to the folder that holds {BANDAI_FOLDER}/ (the clips are CC BY-NC "
            "and not bundled)"
        )
        raise ConfigError(msg)
    return tuple(str(path) for path in files)
