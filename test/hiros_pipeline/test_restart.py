"""Issue 21 case 18: a source replayed from its start (hiros play --loop) keeps the output."""

from __future__ import annotations

from hiros_pipeline import Pipeline
from hiros_sim import SimParams, simulate

STAGES = ("tracker", "merger", "optimizer", "filter")


def test_case18_a_replayed_recording_restarts_time_and_the_output_goes_on() -> None:
    result = simulate(SimParams(n_cameras=2, n_people=1, duration=5.0, seed=3))
    frames = sorted(
        (int(receive), name, k)
        for name, groups in result.camera_groups.items()
        for k, receive in enumerate(result.receive_ns[name][: len(groups)])
    )
    pipeline = Pipeline(None, result.calibration)
    published = [dict.fromkeys(STAGES, 0) for _ in range(3)]
    for replay in range(3):
        for _, name, k in frames:
            outputs = pipeline.update(result.camera_groups[name][k])
            for stage in STAGES:
                published[replay][stage] += bool(getattr(outputs, stage).skeletons)
    first = published[0]
    assert first["filter"] > 50
    for again in published[1:]:
        for stage in STAGES:
            assert again[stage] >= 0.9 * first[stage], (stage, published)
    assert pipeline.tracker.restarts == 2
    assert "late frame" not in pipeline.tracker.drops
    assert pipeline.tracker.diagnostics()["restarts"].startswith("2 (last: ")
    assert pipeline.accounted == 3 * len(frames)
