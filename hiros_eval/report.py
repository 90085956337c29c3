"""An HTML report of a run's evaluation: tables and matplotlib figures a person wants to read."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from hiros_core.layouts import AZURE_KINECT
from hiros_eval.run import RunEvaluation

__all__ = ["write_report"]


def _figure(path: Path, draw) -> str:  # noqa: ANN001 - callable(ax/fig)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = draw(plt)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return f'<img src="{html.escape(path.name)}" alt="{html.escape(path.stem)}">'


def _error_per_stage(plt, evaluation: RunEvaluation):  # noqa: ANN001, ANN202
    fig, ax = plt.subplots(figsize=(7, 3.5))
    names = [f"camera {c}" for c in evaluation.cameras] + list(evaluation.stages)
    values = [v * 100 for v in evaluation.cameras.values()] + [
        s.mpjpe * 100 for s in evaluation.stages.values()
    ]
    colors = ["#bbbbbb"] * len(evaluation.cameras) + ["#3a7bd5"] * len(evaluation.stages)
    ax.bar(names, values, color=colors)
    ax.set_ylabel("MPJPE (cm)")
    ax.set_title("Joint error: single cameras vs each stage")
    ax.tick_params(axis="x", rotation=30)
    return fig


def _error_per_joint(plt, evaluation: RunEvaluation):  # noqa: ANN001, ANN202
    fig, ax = plt.subplots(figsize=(10, 3.8))
    width = 0.8 / max(len(evaluation.stages), 1)
    for k, (stage, figures) in enumerate(evaluation.stages.items()):
        ax.bar(np.arange(32) + k * width, figures.per_joint * 100, width, label=stage)
    centre = (len(evaluation.stages) - 1) * width / 2
    ax.set_xticks(np.arange(32) + centre, AZURE_KINECT.joint_names, rotation=90, fontsize=7)
    ax.set_ylabel("MPJPE (cm)")
    ax.legend(fontsize=8)
    ax.set_title("Joint error per joint")
    return fig


def _angle_curves(plt, evaluation: RunEvaluation):  # noqa: ANN001, ANN202
    from hiros_eval.body import joint_angles

    fig, axes = plt.subplots(2, 2, figsize=(10, 5.5), sharex=True)
    for ax, angle in zip(
        axes.ravel(), ("knee_left", "hip_left", "elbow_right", "shoulder_right"), strict=True
    ):
        for stage in ("merger", "filter"):
            figures = evaluation.stages.get(stage)
            if not figures or not figures.person_series:
                continue
            person = min(figures.person_series)
            times, estimate, truth = figures.person_series[person]
            order = np.argsort(times)
            elapsed = times[order] - times[order][0]
            ax.plot(elapsed, joint_angles(estimate[order])[angle], lw=0.8, label=stage)
            if stage == "filter":
                ax.plot(elapsed, joint_angles(truth[order])[angle], "k--", lw=0.8, label="truth")
        ax.set_title(f"{angle.replace('_', ' ')} (first person)")
        ax.set_ylabel("degrees")
    axes[0, 0].legend(fontsize=8)
    for ax in axes[1]:
        ax.set_xlabel("time (s)")
    return fig


TIMELINE_BIN = 0.1
"""Seconds per point of the error timeline."""


def _angle_per_stage(plt, evaluation: RunEvaluation):  # noqa: ANN001, ANN202
    fig, ax = plt.subplots(figsize=(10, 3.5))
    stages = list(evaluation.stages.items())
    names = [n for n in (stages[0][1].angle_rmse if stages else {}) if n != "mean"]
    width = 0.8 / max(len(stages), 1)
    for k, (stage, figures) in enumerate(stages):
        values = [figures.angle_rmse.get(name, np.nan) for name in names]
        ax.bar(np.arange(len(names)) + k * width, values, width, label=stage)
    centre = (len(stages) - 1) * width / 2
    ax.set_xticks(np.arange(len(names)) + centre, [n.replace("_", " ") for n in names], fontsize=8)
    ax.set_ylabel("RMSE (degrees)")
    ax.legend(fontsize=8)
    ax.set_title("Joint-angle error per angle and stage")
    return fig


def _error_timeline(plt, evaluation: RunEvaluation):  # noqa: ANN001, ANN202
    """Each true person's joint error over time, per stage: where and when the chain helps."""
    people = sorted({p for figures in evaluation.stages.values() for p in figures.person_series})[
        :4
    ]
    fig, axes = plt.subplots(
        max(len(people), 1), 1, figsize=(10, 1.9 * max(len(people), 1) + 0.6),
        sharex=True, squeeze=False,
    )  # fmt: skip
    start = min(
        (s[0].min() for f in evaluation.stages.values() for s in f.person_series.values()),
        default=0.0,
    )
    for ax, person in zip(axes[:, 0], people, strict=False):
        for stage in ("tracker", "merger", "filter"):
            figures = evaluation.stages.get(stage)
            if not figures or person not in figures.person_series:
                continue
            times, estimate, truth = figures.person_series[person]
            error = np.nanmean(np.linalg.norm(estimate - truth, axis=-1), axis=-1)
            # 0.1 s bins: the tracker has one track per camera, interleaved in time
            bins = np.floor((times - start) / TIMELINE_BIN).astype(np.int64)
            count = np.bincount(bins)
            mean = np.bincount(bins, np.nan_to_num(error)) / np.maximum(count, 1)
            seen = count > 0
            ax.plot(np.flatnonzero(seen) * TIMELINE_BIN, mean[seen] * 100, lw=0.7, label=stage)
        ax.set_ylabel(f"person {person}\nMPJPE (cm)", fontsize=8)
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[0, 0].set_title("Joint error over time (mean over joints, 0.1 s means)")
    axes[-1, 0].set_xlabel("time (s)")
    return fig


def _table(headers: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows
    )
    return f"<table><tr>{head}</tr>{body}</table>"


def write_report(
    evaluation: RunEvaluation, directory: str | Path, title: str = "hiros evaluation"
) -> Path:
    """``directory/report.html`` with its PNG figures beside it."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    images = [
        _figure(directory / "error_per_stage.png", lambda plt: _error_per_stage(plt, evaluation)),
        _figure(directory / "error_per_joint.png", lambda plt: _error_per_joint(plt, evaluation)),
        _figure(directory / "angle_error.png", lambda plt: _angle_per_stage(plt, evaluation)),
        _figure(directory / "joint_angles.png", lambda plt: _angle_curves(plt, evaluation)),
        _figure(directory / "error_timeline.png", lambda plt: _error_timeline(plt, evaluation)),
    ]
    sections = "".join(
        f"<h2>{html.escape(title)}</h2>{_table(headers, rows)}"
        for title, (headers, rows) in evaluation.tables().items()
    )
    style = (
        "body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #ccc;padding:4px 10px;text-align:right}"
        "th{background:#f0f3f8}img{max-width:100%;margin:1em 0}"
    )
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>{style}</style></head><body>
<h1>{html.escape(title)}</h1>
{sections}
<h2>Figures</h2>
{"".join(images)}
</body></html>"""
    path = directory / "report.html"
    path.write_text(page)
    return path
