"""Pipeline speed: offline throughput (multiple of real time) and end-to-end DDS latency.

Offline: a simulated recording of 3 cameras x 30 Hz x 4 people through ``hiros run``'s runner
(reading, bridging, all four stages, writing), as recording seconds per wall-clock second, in
one process and in two (reading and tracking in a child, the default where two cores exist),
writing every output (the default, what the target is for), and in two writing only the
final stream and its markers (``--write filter,markers``, for long recordings).
Latency: camera message published -> filter output received, over real DDS, for the composed
``pipeline`` node and for the four stages as separate nodes (see ``hiros_bench.latency``); the
processes run in a loopback-only network namespace.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from hiros_core.calibration import load_calibration
from hiros_core.isolation import isolated, isolated_env

TARGET_REAL_TIME = 100.0


FINAL_ONLY = ("filter", "markers")
"""``hiros run --write filter,markers``: the final stream and its drawing only."""
RUNS = ((1, None), (2, None), (2, FINAL_ONLY))
"""(processes, what is written; None: everything, the default) of each throughput run."""


def offline_throughput(
    duration: float, runs: tuple[tuple[int, tuple[str, ...] | None], ...] = RUNS
) -> list[tuple[float, float, float, dict[str, float]]]:
    """``run_recording`` on 3 cameras x 30 Hz x 4 people, simulated, per entry of ``runs``.

    Returns, for each entry of ``runs`` (process count, outputs written): recording seconds,
    wall seconds, the real-time factor and the wall seconds by part (``RunSummary.seconds``)
    followed by the CPU seconds of ``RunSummary.cpu`` as ``cpu main``, ``cpu writer`` and
    ``cpu child``.
    """
    from hiros_pipeline import load_pipeline_params, run_recording
    from hiros_pipeline.offline import OUTPUTS
    from hiros_sim import SimParams, simulate, write_recording

    params = load_pipeline_params()  # what `hiros run` uses: config/ and its defaults
    results = []
    with tempfile.TemporaryDirectory() as folder:
        sim = Path(folder) / "sim"
        write_recording(
            simulate(SimParams(n_cameras=3, n_people=4, duration=duration, seed=11)), sim
        )
        calibration = load_calibration(sim / "calibration.yaml")
        for k, (count, write) in enumerate(runs):
            summary = run_recording(
                sim / "recording.mcap", calibration, Path(folder) / f"out{k}.mcap", params,
                processes=count, write=write or OUTPUTS,
            )  # fmt: skip
            cpu = {f"cpu {part}": seconds for part, seconds in summary.cpu.items()}
            results.append((
                summary.duration, summary.wall_time, summary.real_time_factor,
                {**summary.seconds, **cpu},
            ))  # fmt: skip
    return results


def latency(mode: str, seconds: float) -> str:
    """One line of p50/p95 latency for ``mode`` (composed or nodes), measured in a child."""
    command = [
        sys.executable,
        "-m",
        "hiros_bench.latency",
        "--mode",
        mode,
        "--seconds",
        str(seconds),
    ]
    result = subprocess.run(
        isolated(command), env=isolated_env(domain_id=77), capture_output=True, text=True,
        timeout=300, check=False,
    )  # fmt: skip
    lines = [line for line in result.stdout.splitlines() if line.startswith("latency")]
    if result.returncode != 0 or not lines:
        return f"latency {mode}: failed ({(result.stderr or result.stdout).strip()[-300:]})"
    return lines[-1]


def run(console, quick: bool = False) -> list[str]:  # noqa: ANN001 - rich Console
    """Print the offline throughput and both latencies."""
    duration = 20.0 if quick else 60.0
    lines = []
    measured = offline_throughput(duration)
    for (count, write), (recorded, wall, factor, parts) in zip(RUNS, measured, strict=True):
        cpu = {part: parts.pop(part) for part in list(parts) if part.startswith("cpu")}
        busiest = max(cpu.values())
        what = "its default parameters" if write is None else f"--write {','.join(write)}"
        lines += [
            f"offline hiros run ({what}), "
            f"3 cameras x 30 Hz x 4 people, {count} process"
            f"{'es' if count > 1 else ''}: {recorded:.1f} s of recording in {wall:.2f} s = "
            f"{factor:.1f}x real time (target {TARGET_REAL_TIME:.0f}x)",
            "  of which " + ", ".join(f"{part} {seconds:.2f} s" for part, seconds in parts.items()),
            "  "
            + ", ".join(f"{part} {seconds:.2f} s" for part, seconds in cpu.items())
            + f": {recorded / busiest:.1f}x real time where each has a free core",
        ]
    for mode in ("composed", "nodes"):
        lines.append(latency(mode, 10.0 if quick else 20.0))
    for line in lines:
        console.print(line, highlight=False)
    return lines
