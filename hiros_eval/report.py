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


FIGURES = (
    ("error_per_stage", _error_per_stage,
     "Mean joint error (MPJPE) of each camera alone (grey: its own skeletons put in the world "
     "with the true calibration, no tracking) and of each stage of the chain (blue). Lower is "
     "better; the merger is where the cameras' views are combined."),
    ("error_per_joint", _error_per_joint,
     "The same error joint by joint, per stage: small, fast or often hidden joints (hand "
     "tips, thumbs) usually err most."),
    ("angle_error", _angle_per_stage,
     "Error of the joint angles biomechanics reads (knee, hip, elbow, shoulder), per stage."),
    ("joint_angles", _angle_curves,
     "Four joint angles of the first person over time: the merger's and the filter's against "
     "the truth (dashed)."),
    ("error_timeline", _error_timeline,
     "Each person's joint error over time, per stage: where and when the chain helps (the "
     "tracker's line jumps where a camera flips or loses the person)."),
)  # fmt: skip
"""Each figure's file name, drawing function and caption, in page order."""

GLOSSARY = (
    ("MPJPE", "mean per-joint position error: the mean distance from each joint to the "
     "truth, over every joint of every matched person and frame"),
    ("limb CV", "how much each limb's length varies over time (coefficient of variation, "
     "median over limbs): a real limb does not change length"),
    ("angle RMSE", "root-mean-square error of the knee, hip, elbow and shoulder angles"),
    ("IDF1", "share of frames where each person keeps one identity (1 = perfect)"),
    ("ID switches", "times a true person changes output id"),
    ("fragments", "times a person's output track breaks; the tracker keeps one track per "
     "camera, so its count is high by design and only the merged stages' matter"),
    ("lag", "how far the output trails the truth (the delay of the truth that fits it "
     "best); negative: it runs slightly ahead"),
)  # fmt: skip
"""Terms of the stage table, explained under it."""


def _headline(evaluation: RunEvaluation) -> str:
    """One paragraph with the figures a reader looks for first."""
    stages = evaluation.stages
    final = stages.get("filter") or (list(stages.values())[-1] if stages else None)
    if final is None:
        return "<p>No output stage could be matched to the truth.</p>"
    parts = [
        f"The final stage ({final.stage}) puts joints {final.mpjpe * 100:.1f} cm from the truth "
        f"on average, with joint angles {final.angle_rmse.get('mean', float('nan')):.1f}° off "
        f"(RMSE) and {final.identity.id_switches} identity switches."
    ]
    camera = evaluation.best_camera
    if camera is not None:
        parts.append(
            f"The best single camera ({camera}) alone errs {evaluation.cameras[camera] * 100:.1f}"
            f" cm: the chain gives {evaluation.to_best_camera(final.stage):.2f} of that."
        )
    if "tracker" in stages and final.stage != "tracker":
        change = evaluation.angle_change(final.stage)
        parts.append(f"Joint-angle error changes by {100 * change:+.0f} % from the "
                     "tracker (each camera's skeletons) to the final output.")  # fmt: skip
    if evaluation.calibration:
        worst = [
            max(getattr(a, name) for a in evaluation.calibration.values())
            for name in ("time_error_ms", "rotation_error_deg", "translation_error_cm")
        ]
        parts.append(
            f"The calibration used is within {worst[0]:.1f} ms, {worst[1]:.2f}° and "
            f"{worst[2]:.1f} cm of the truth for every camera."
        )
    return f"<p class=lead>{html.escape(' '.join(parts))}</p>"


def _glossary() -> str:
    items = "".join(
        f"<dt>{html.escape(term)}</dt><dd>{html.escape(text)}</dd>" for term, text in GLOSSARY
    )
    return f"<dl>{items}</dl>"


def write_report(
    evaluation: RunEvaluation,
    directory: str | Path,
    title: str = "hiros evaluation",
    facts: list[tuple[str, str]] | None = None,
) -> Path:
    """``directory/report.html`` with its PNG figures beside it.

    ``facts``: (what, value) rows about the run itself (frames, speed), shown first.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    figures = "".join(
        f"<figure>{_figure(directory / f'{name}.png', lambda plt, d=draw: d(plt, evaluation))}"
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        for name, draw, caption in FIGURES
    )
    tables = list(evaluation.tables().items())
    sections = "".join(
        f"<h2>{html.escape(heading)}</h2>{_table(headers, rows)}" + (_glossary() if k == 0 else "")
        for k, (heading, (headers, rows)) in enumerate(tables)
    )
    run = (
        "<h2>the run</h2>" + _table(["what", "value"], [list(row) for row in facts])
        if facts
        else ""
    )
    style = (
        "body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #ccc;padding:4px 10px;text-align:right}"
        "th{background:#f0f3f8}img{max-width:100%;margin:0.5em 0 0}"
        ".lead{font-size:1.1em;line-height:1.5}figure{margin:1.5em 0}"
        "figcaption{color:#555;font-size:0.9em}dl{font-size:0.9em;color:#444}"
        "dt{font-weight:bold;float:left;clear:left;width:8em}dd{margin-left:9em}"
    )
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>{style}</style></head><body>
<h1>{html.escape(title)}</h1>
{_headline(evaluation)}
{run}
{sections}
<h2>Figures</h2>
{figures}
</body></html>"""
    path = directory / "report.html"
    path.write_text(page)
    return path
