"""Per-track results shared by every camera pair of one synchronisation."""

from __future__ import annotations

import numpy as np
from scipy.fft import rfft

from hiros_calib.signature import PoseSignature, pose_signature, select_joints
from hiros_calib.sync.correlation import GridSignal, grid_signal
from hiros_calib.sync.params import GRID_STEP, REFINE_STEP, SyncParams
from hiros_calib.sync.refine import Spline
from hiros_calib.tracks import BodyTrack

__all__ = ["TrackWork"]


class TrackWork:
    """Per-track results that every camera pair of the track's camera reuses.

    With N cameras each camera is in N - 1 pairs; its tracks' signatures, grid signals,
    spectra and splines are computed once. Keys are object ids of inputs the cache keeps
    alive (tracks are kept with their signature), so an id is never reused for another
    object while the cache exists.
    """

    def __init__(self, params: SyncParams, nfft: int = 0) -> None:
        self.params = params
        self.nfft = nfft
        self._signature: dict[int, tuple[BodyTrack, PoseSignature]] = {}
        self._motion: dict[int, float] = {}
        self._grid: dict[int, GridSignal | None] = {}
        self._spectra: dict[tuple[int, int], tuple[np.ndarray, ...]] = {}
        self._spline: dict[int, Spline] = {}

    def signatures(self, tracks: list[BodyTrack]) -> list[PoseSignature]:
        """Each track's pose signature (computed once per track)."""
        out = []
        for track in tracks:
            if id(track) not in self._signature:
                joints = select_joints(track.layout, self.params.joints)
                signature = pose_signature(track, joints)
                self._signature[id(track)] = (track, signature)
            out.append(self._signature[id(track)][1])
        return out

    def motion(self, signature: PoseSignature) -> float:
        """How much the signature moves (m): still bodies are skipped."""
        if id(signature) not in self._motion:
            self._motion[id(signature)] = signature.motion()
        return self._motion[id(signature)]

    def grid(self, signature: PoseSignature) -> GridSignal | None:
        """The signature on the coarse correlation grid (None: too short)."""
        if id(signature) not in self._grid:
            self._grid[id(signature)] = grid_signal(signature, GRID_STEP)
        return self._grid[id(signature)]

    def spectra(self, signal: GridSignal, nfft: int) -> tuple[np.ndarray, ...]:
        """The signal's, its presence's and its energy's FFT at length ``nfft``."""
        key = (id(signal), nfft)
        if key not in self._spectra:
            # single precision is plenty to find the coarse peak, and twice as fast
            self._spectra[key] = (
                rfft(signal.values, n=nfft, axis=0),
                rfft(signal.present.astype(np.float32), n=nfft),
                rfft(signal.energy.astype(np.float32), n=nfft),
            )
        return self._spectra[key]

    def spline(self, signature: PoseSignature) -> Spline:
        """The signature's spline for the continuous refinement."""
        if id(signature) not in self._spline:
            self._spline[id(signature)] = Spline.build(signature, REFINE_STEP)
        return self._spline[id(signature)]
