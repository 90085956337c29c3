"""Any supported file -> a recording with Azure-driver MarkerArray or SkeletonGroup topics.

``convert`` is what ``hiros convert`` runs: read the input into per-camera streams, then write
every camera's groups, merged in receive order, as ``/<camera>/body_tracking_data``
(visualization_msgs/MarkerArray exactly as the Azure Kinect ROS driver publishes, the
default, so the recording exercises the bridge like a live camera) or ``/<camera>/skeletons``
(hiros_skeleton_msgs/SkeletonGroup, what the bridge would publish).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path

from hiros_convert._frames import CameraStream
from hiros_convert._table import column_key
from hiros_convert.generic_csv import read_generic_streams
from hiros_convert.k4abt_json import read_k4abt_streams
from hiros_convert.multitrack import read_multitrack_streams
from hiros_convert.unipd import read_unipd_streams
from hiros_core.errors import RecordingError
from hiros_core.layouts import get_layout

__all__ = ["FORMATS", "convert", "detect_format", "read_streams"]

FORMATS = ("k4abt-json", "unipd-csv", "multitrack-csv", "csv")
"""Input formats ``hiros convert --format`` accepts."""


def detect_format(path: str | Path) -> str:
    """Guess an input file's format from its extension and CSV header.

    Raises:
        RecordingError: the file is missing or looks like none of ``FORMATS``.

    """
    path = Path(path)
    if not path.is_file():
        problem = "is a folder, not a file" if path.is_dir() else "does not exist"
        msg = f"input file {path} {problem}"
        raise RecordingError(msg)
    if path.suffix.lower() == ".json":
        return "k4abt-json"
    if path.suffix.lower() == ".csv":
        try:
            with path.open() as stream:
                header = {column_key(c) for c in stream.readline().split(",")}
        except (OSError, UnicodeDecodeError) as exc:
            msg = f"cannot read input file {path}: {exc}"
            raise RecordingError(msg) from exc
        if "skeletontime" in header:
            return "multitrack-csv"
        if "pelvisposx" in header or "pelvisquatx" in header:
            return "unipd-csv"
        if "joint" in header:
            return "csv"
    msg = f"cannot tell the format of {path}; give --format (one of {', '.join(FORMATS)})"
    raise RecordingError(msg)


def read_streams(
    path: str | Path,
    fmt: str | None = None,
    *,
    camera: str | None = None,
    layout: str | None = None,
    drops: Counter[str] | None = None,
) -> dict[str, CameraStream]:
    """Per-camera streams of an input file in any of ``FORMATS`` (guessed when None).

    ``camera`` names the one camera of single-camera formats (k4abt JSON, UNIPD CSV; default
    ``k01``); ``layout`` is the generic CSV's layout (default ``azure_kinect``).
    """
    fmt = fmt or detect_format(path)
    drops = drops if drops is not None else Counter()
    if fmt == "k4abt-json":
        return read_k4abt_streams(path, camera=camera or "k01", drops=drops)
    if fmt == "unipd-csv":
        return read_unipd_streams(path, camera=camera or "k01", drops=drops)
    if fmt == "multitrack-csv":
        return read_multitrack_streams(path, drops=drops)
    if fmt == "csv":
        return read_generic_streams(path, layout=get_layout(layout or "azure_kinect"), drops=drops)
    msg = f"unknown input format {fmt!r}; use one of {', '.join(FORMATS)}"
    raise RecordingError(msg)


def convert(
    in_path: str | Path,
    out_path: str | Path,
    *,
    fmt: str | None = None,
    skeleton_groups: bool = False,
    camera: str | None = None,
    layout: str | None = None,
    drops: Counter[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Counter[str]:
    """Convert ``in_path`` into the recording ``out_path`` (``.mcap`` file or rosbag2 folder).

    Args:
        in_path: input file.
        out_path: new recording path.
        fmt: input format, guessed from the file when None.
        skeleton_groups: write SkeletonGroup topics instead of Azure-driver MarkerArrays.
        camera: camera name for single-camera formats.
        layout: layout of the generic CSV.
        drops: receives the parser's drop reasons.
        progress: called with (messages written, total) as the writing goes.

    Returns:
        Messages written per topic.

    Raises:
        RecordingError: unreadable input or unwritable output.

    """
    from hiros_core.driver import group_to_driver_markers
    from hiros_core.recording import RecordingWriter

    drops = drops if drops is not None else Counter()
    streams = read_streams(in_path, fmt, camera=camera, layout=layout, drops=drops)
    order = sorted(
        (int(stream.receive_ns[i]), name, i)
        for name, stream in streams.items()
        for i in range(len(stream.groups))
    )
    if not order:
        dropped = ", ".join(f"{reason} {n}" for reason, n in sorted(drops.items()) if n)
        msg = f"{in_path} holds no skeletons to convert" + (
            f" (dropped: {dropped})" if dropped else ""
        )
        raise RecordingError(msg)
    counts: Counter[str] = Counter()
    with RecordingWriter(out_path, discard_on_error=True) as writer:  # no half-written output
        for done, (receive_ns, name, i) in enumerate(order, start=1):
            group = streams[name].groups[i]
            if skeleton_groups:
                topic = f"/{name}/skeletons"
                writer.write_group(topic, group, receive_ns)
            else:
                topic = f"/{name}/body_tracking_data"
                writer.write_marker_array(topic, group_to_driver_markers(group), receive_ns)
            counts[topic] += 1
            if progress is not None:
                progress(done, len(order))
    return counts
