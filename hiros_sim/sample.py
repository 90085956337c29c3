"""The bundled sample that ``hiros demo`` runs on: made from the clips in ``hiros_data``."""

from __future__ import annotations

from hiros_sim.params import SimParams

__all__ = ["sample_params"]


def sample_params() -> SimParams:
    """The demo's simulation: 3 cameras (room setup), 3 people, 60 s, seed 7, every realism on.

    Deterministic: the same parameters give the same recording on any machine with the same
    numpy, so the demo generates it on the fly instead of shipping it.
    """
    return SimParams(n_cameras=3, setup="room", n_people=3, duration=60.0, seed=7)
