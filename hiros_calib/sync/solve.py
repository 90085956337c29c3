"""Every camera's clock from all pairwise lags at once (robust weighted least squares)."""

from __future__ import annotations

import numpy as np

from hiros_calib.sync.clock import CameraClock, PairOffset
from hiros_calib.sync.params import MIN_DRIFT_SPAN, SyncParams
from hiros_calib.tracks import BodyTrack

__all__ = ["clock_epochs", "solve_clocks"]


def solve_clocks(
    cameras: list[str],
    reference: str,
    pairs: list[PairOffset],
    epochs: dict[str, float],
    params: SyncParams,
) -> dict[str, CameraClock]:
    """Globally consistent clocks from all pairwise lags (robust weighted least squares).

    Each window measurement of pair (a, b) at b-time ``t_b`` with lag ``tau`` says
    ``tau + o_a + d_a (t_b + tau - e_a) - o_b - d_b (t_b - e_b) = 0`` (offsets ``o``, drifts
    ``d``, epochs ``e``); the reference has ``o = d = 0``. Cameras not linked to the
    reference through usable pairs are refused with the pairs' reasons.
    """
    clocks = {c: CameraClock(c, drift_epoch=epochs.get(c, 0.0)) for c in cameras}
    clocks[reference] = CameraClock(
        reference, "ok", time_offset=0.0, drift_epoch=epochs.get(reference, 0.0)
    )
    usable = [p for p in pairs if p.ok and len(p.windows)]
    linked = _linked(reference, usable)
    for camera in cameras:
        if camera not in linked:
            reasons = [
                f"{p.camera_a}-{p.camera_b}: {p.reason or 'no window measurement'}"
                for p in pairs
                if camera in (p.camera_a, p.camera_b)
            ]
            clocks[camera].reason = f"cannot link {camera} to the reference {reference}: " + (
                "; ".join(reasons) if reasons else "no camera pair includes it"
            )
    unknown = [c for c in cameras if c in linked and c != reference]
    if not unknown:
        return clocks
    usable = [p for p in usable if p.camera_a in linked and p.camera_b in linked]
    spans = _drift_spans(usable)
    with_drift = [
        c for c in unknown if params.estimate_drift and spans.get(c, 0.0) >= MIN_DRIFT_SPAN
    ]
    column = {("o", c): k for k, c in enumerate(unknown)}
    column.update({("d", c): len(unknown) + k for k, c in enumerate(with_drift)})
    rows, rhs, weights = [], [], []
    for pair in usable:
        for t_b, tau, weight, _ in pair.windows:
            row = np.zeros(len(column))
            for camera, sign, at in ((pair.camera_a, 1.0, t_b + tau), (pair.camera_b, -1.0, t_b)):
                if ("o", camera) in column:
                    row[column["o", camera]] = sign
                if ("d", camera) in column:
                    row[column["d", camera]] = sign * (at - clocks[camera].drift_epoch)
            rows.append(row)
            rhs.append(-tau)
            weights.append(weight)
    for camera in with_drift:
        row = np.zeros(len(column))
        row[column["d", camera]] = 1.0
        rows.append(row)
        rhs.append(0.0)
        weights.append(0.0)
    prior = np.zeros(len(rows), dtype=bool)
    prior[len(rows) - len(with_drift) :] = True
    design, target, weight = np.array(rows), np.array(rhs), np.array(weights)
    solution, residual = _robust_lstsq(
        design, target, weight, prior, prior_sigma=params.drift_prior
    )
    for camera in unknown:
        clock = clocks[camera]
        clock.status = "ok"
        clock.time_offset = float(solution[column["o", camera]])
        if ("d", camera) in column:
            clock.drift = float(solution[column["d", camera]])
        mine = np.array(
            [camera in (p.camera_a, p.camera_b) for p in usable for _ in range(len(p.windows))]
        )
        clock.quality = {
            "window_residual_ms": round(1e3 * float(np.sqrt(np.mean(residual[mine] ** 2))), 3),
            "windows": int(mine.sum()),
            "drift_estimated": ("d", camera) in column,
        }
    return clocks


def _linked(reference: str, pairs: list[PairOffset]) -> set[str]:
    linked, frontier = {reference}, [reference]
    while frontier:
        camera = frontier.pop()
        for p in pairs:
            for here, there in ((p.camera_a, p.camera_b), (p.camera_b, p.camera_a)):
                if here == camera and there not in linked:
                    linked.add(there)
                    frontier.append(there)
    return linked


def _drift_spans(pairs: list[PairOffset]) -> dict[str, float]:
    """Per camera, the time span its window measurements cover (drift is only defined then)."""
    times: dict[str, list[float]] = {}
    for p in pairs:
        if len(p.windows) < 3:
            continue
        for camera in (p.camera_a, p.camera_b):
            times.setdefault(camera, []).extend(p.windows[:, 0].tolist())
    return {c: max(t) - min(t) for c, t in times.items()}


def _robust_lstsq(
    design: np.ndarray,
    target: np.ndarray,
    weight: np.ndarray,
    prior: np.ndarray,
    *,
    prior_sigma: float,
    iterations: int = 6,
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least squares, Huber-reweighted, with ridge rows for the drift prior.

    Measurement weights are relative, so their scale (the variance per unit weight) is
    estimated from the residuals at each pass; a prior row ``d = 0`` then gets the weight
    that makes its standard deviation ``prior_sigma``. Returns the solution and the
    measurement rows' residuals.
    """
    robust = np.ones_like(weight)
    measured = ~prior
    variance = 1e-6  # (1 ms)^2 per unit weight until the residuals say otherwise
    solution = np.zeros(design.shape[1])
    for _ in range(iterations):
        w = weight * robust
        w[prior] = variance / prior_sigma**2
        root = np.sqrt(w)[:, None]
        solution = np.linalg.lstsq(design * root, target * root[:, 0], rcond=None)[0]
        residual = (design @ solution - target)[measured]
        scaled = residual * np.sqrt(weight[measured])
        sigma = max(1.4826 * float(np.median(np.abs(scaled))), 1e-9)
        ratio = np.abs(scaled) / (1.5 * sigma)
        robust[measured] = np.where(ratio <= 1, 1.0, 1.0 / np.maximum(ratio, 1e-12))
        dof = max(1, int(measured.sum()) - design.shape[1])
        variance = max(float((robust[measured] * scaled**2).sum()) / dof, 1e-12)
    return solution, (design @ solution - target)[measured]


def clock_epochs(tracks: dict[str, list[BodyTrack]]) -> dict[str, float]:
    """Per camera the middle of its tracks (camera clock), used as the drift epoch.

    There an offset and a drift estimated from the same data are least correlated.
    """
    return {
        c: 0.5 * (min(t.start for t in ts) + max(t.end for t in ts)) if ts else 0.0
        for c, ts in tracks.items()
    }
