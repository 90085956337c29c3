"""Soak: the live pipeline and ``calib`` nodes fed a looping recording for many minutes.

``hiros bench soak`` (not in CI, and not among the suites run by default) starts the composed
``pipeline`` node and the ``calib`` node in a loopback-only network namespace and publishes a
simulated minute of three cameras and two people on ``/<cam>/skeletons``, over and over, at
the recorded pace, each loop restamped to the wall clock (so the latency can be measured:
the simulated cameras share one clock; it includes the simulated drivers' own delay between
a frame's stamp and its delivery, which is printed first). Every ``SAMPLE_SECONDS`` it prints
each node's resident memory (``VmRSS``) and the outputs received on ``/hiros/filter``; then the
latency percentiles (receive time minus the output's stamp), the memory growth of each node
after its first two minutes (the issue 21 target: under 5 %) and whether the output ever
stopped (a sampling window without output).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CAMERAS = ("k01", "k02", "k03")
SAMPLE_SECONDS = 10.0
SETTLE_SECONDS = 120.0
"""Memory growth is measured from this time on (start-up and the first calibrations)."""
GROWTH_TARGET = 0.05


def _executable(name: str) -> str:
    return str(Path(sys.prefix) / "bin" / name)


def _rss_mb(pid: int) -> float:
    """Resident memory of a process, MB (0 when it has ended)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def _recording() -> tuple[list[tuple[int, str, object]], Path]:
    """The simulated minute (time-ordered ``(receive ns, camera, group)``) and its calibration."""
    from hiros_core.calibration import save_calibration
    from hiros_sim import SimParams, simulate

    result = simulate(SimParams(n_cameras=len(CAMERAS), n_people=2, duration=60.0, seed=0,
                                max_time_offset=0.0, drift_ppm=0.0))  # fmt: skip
    frames = sorted(
        (int(receive), name, result.camera_groups[name][k])
        for name, groups in result.camera_groups.items()
        for k, receive in enumerate(result.receive_ns[name][: len(groups)])
    )
    path = Path(tempfile.mkdtemp()) / "calibration.yaml"
    save_calibration(result.calibration, path)
    return frames, path


def _start_nodes(calibration: Path) -> dict[str, subprocess.Popen]:
    cameras = "[" + ", ".join(CAMERAS) + "]"
    common = ["--ros-args", "--log-level", "error"]
    commands = {
        "pipeline": [_executable("pipeline"), *common, "-p", "input:=skeletons",
                     "-p", f"cameras:={cameras}", "-p", f"calibration_file:={calibration}"],
        # (it saves its calibration at shutdown: beside the soak's own file, not in the cwd)
        "calib": [_executable("calib"), *common, "-p", f"camera_names:={cameras}",
                  "-p", f"save_file:={calibration.with_name('calib_node.yaml')}"],
    }  # fmt: skip
    return {name: subprocess.Popen(c, stdout=subprocess.DEVNULL) for name, c in commands.items()}


class _Feeder:
    """The rclpy side: camera publishers, the ``/hiros/filter`` subscriber, the figures."""

    def __init__(self) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from hiros_skeleton_msgs.msg import SkeletonGroup as SkeletonGroupMsg
        from rclpy.qos import QoSProfile, qos_profile_sensor_data

        from hiros_ros import make_executor

        rclpy.init()
        self.rclpy = rclpy
        self.node = rclpy.create_node("hiros_soak_feeder")
        self.executor = make_executor()
        self.executor.add_node(self.node)
        self.latencies: list[float] = []
        self.outputs = 0
        self.node.create_subscription(
            SkeletonGroupMsg, "/hiros/filter", self.on_output, QoSProfile(depth=100), raw=True
        )
        self.counts: dict[str, dict[str, str]] = {}  # node -> its last /diagnostics values
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self.on_diagnostics, 10)
        self.publishers = {
            camera: self.node.create_publisher(
                SkeletonGroupMsg, f"/{camera}/skeletons", qos_profile_sensor_data
            )
            for camera in CAMERAS
        }

    def on_output(self, data: bytes) -> None:
        from hiros_core.codec import decode_group

        received = time.time_ns()
        group = decode_group(data)
        if group.skeletons:
            self.outputs += 1
            self.latencies.append((received - group.stamp_ns) * 1e-6)

    def on_diagnostics(self, message: object) -> None:
        for status in message.status:  # type: ignore[attr-defined]
            self.counts[status.name] = {v.key: v.value for v in status.values}

    def dropped(self) -> dict[str, int]:
        """Every node's frames dropped so far, by ``node: reason``."""
        return {
            f"{node.rsplit('/', 1)[-1]}: {key.removeprefix('dropped.')}": int(value)
            for node, values in self.counts.items()
            for key, value in values.items()
            if key.startswith("dropped.") and value.isdigit()
        }

    def discovered(self) -> bool:
        return all(p.get_subscription_count() >= 2 for p in self.publishers.values()) and (
            self.node.count_publishers("/hiros/filter") > 0
        )

    def spin_until(self, deadline: float) -> None:
        while (left := deadline - time.monotonic()) > 0:
            self.executor.spin_once(timeout_sec=left)

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.shutdown()


def _loop(feeder: _Feeder, frames: list, seconds: float, on_sample: callable) -> None:
    """Publish ``frames`` over and over for ``seconds``, restamped to the wall clock."""
    from hiros_core.codec import encode_group

    first = frames[0][0]
    start = time.monotonic()
    next_sample = start + SAMPLE_SECONDS
    while time.monotonic() - start < seconds:
        shift = time.time_ns() - first
        loop_start = time.monotonic()
        for receive, camera, group in frames:
            at = loop_start + (receive - first) * 1e-9
            while time.monotonic() >= next_sample:
                on_sample(next_sample - start)
                next_sample += SAMPLE_SECONDS
            feeder.spin_until(at)
            if time.monotonic() - start >= seconds:
                return
            original = group.stamp_ns
            group.stamp_ns = original + shift
            for skeleton in group.skeletons:
                skeleton.src_time_ns += shift
            feeder.publishers[camera].publish(encode_group(group))
            group.stamp_ns = original
            for skeleton in group.skeletons:
                skeleton.src_time_ns -= shift


def soak(minutes: float) -> int:
    """Run the soak; prints one line per sample, then the summary lines."""
    frames, calibration = _recording()
    nodes = _start_nodes(calibration)
    feeder = _Feeder()
    samples: list[tuple[float, dict[str, float], int]] = []
    counted = [0]
    dropped: dict[str, int] = {}

    def on_sample(at: float) -> None:
        rss = {name: _rss_mb(process.pid) for name, process in nodes.items()}
        outputs, counted[0] = feeder.outputs - counted[0], feeder.outputs
        samples.append((at, rss, outputs))
        memory = ", ".join(f"{name} {mb:.0f} MB" for name, mb in rss.items())
        now = feeder.dropped()
        new = {k: n - dropped.get(k, 0) for k, n in now.items() if n > dropped.get(k, 0)}
        dropped.update(now)
        drops = "; dropped " + ", ".join(f"{k} {n}" for k, n in sorted(new.items())) if new else ""
        print(f"soak t={at:6.0f} s: {memory}, {outputs} outputs{drops}", flush=True)

    delay = np.median([receive - group.stamp_ns for receive, _, group in frames]) * 1e-6
    print(f"soak: {len(frames)} camera frames per loop of 60 s; the simulated drivers deliver "
          f"each {delay:.0f} ms after its stamp (median), which the latency includes")  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while not feeder.discovered():
            feeder.spin_until(time.monotonic() + 0.1)
            if time.monotonic() > deadline:
                print("soak: the nodes were not discovered", file=sys.stderr)
                return 2
        _loop(feeder, frames, minutes * 60.0, on_sample)
    finally:
        feeder.close()
        for process in nodes.values():
            process.terminate()
        for process in nodes.values():
            process.wait(timeout=30)
    return _summary(samples, feeder.latencies)


def _summary(samples: list[tuple[float, dict[str, float], int]], latencies: list[float]) -> int:
    """Memory growth after the settling time, stops of the output, latency percentiles."""
    if not samples or not latencies:
        print("soak: no output received from /hiros/filter", file=sys.stderr)
        return 1
    settled = [s for s in samples if s[0] >= SETTLE_SECONDS] or samples[-1:]
    ok = True
    for name in samples[0][1]:
        first, last = settled[0][1][name], samples[-1][1][name]
        growth = (last - first) / first if first else float("inf")
        ok &= growth < GROWTH_TARGET
        print(f"soak rss {name}: {first:.0f} MB at {settled[0][0]:.0f} s -> {last:.0f} MB at "
              f"{samples[-1][0]:.0f} s ({100 * growth:+.1f} %, target < "
              f"{100 * GROWTH_TARGET:.0f} %)")  # fmt: skip
    quiet = sum(outputs == 0 for _, _, outputs in samples)
    ok &= quiet == 0
    values = np.array(latencies)
    p50, p95, p99 = np.percentile(values, [50, 95, 99])
    print(f"soak output: {len(values)} groups, {quiet} of {len(samples)} windows of "
          f"{SAMPLE_SECONDS:.0f} s without output; latency p50 {p50:.1f} ms, p95 {p95:.1f} ms, "
          f"p99 {p99:.1f} ms")  # fmt: skip
    print(f"soak: {'passed' if ok else 'FAILED'}")
    return 0 if ok else 1


def run(console, quick: bool = False, minutes: float | None = None) -> list[str]:  # noqa: ANN001 - rich Console
    """Run the soak in a loopback-only child and print its lines as they come."""
    from hiros_core.isolation import isolated, isolated_env

    minutes = minutes or (3.0 if quick else 30.0)
    command = [sys.executable, "-m", "hiros_bench.soak", "--minutes", str(minutes)]
    lines = []
    with subprocess.Popen(
        isolated(command), env=isolated_env(domain_id=78), stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True,
    ) as child:  # fmt: skip
        assert child.stdout is not None
        for line in child.stdout:
            lines.append(line.rstrip())
            console.print(line.rstrip(), highlight=False)
    return lines


def main() -> int:
    """``python -m hiros_bench.soak --minutes M``."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--minutes", type=float, default=30.0)
    args = parser.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return soak(args.minutes)


if __name__ == "__main__":
    sys.exit(main())
