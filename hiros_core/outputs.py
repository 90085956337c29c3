"""Outputs that never destroy an input or a user's file, and never appear half-written.

Every command that writes does so in two steps:

1. ``check_output`` before any work: the output may not be an input, nor a folder holding
   one (compared by resolved path and by ``samefile``, so a symbolic or hard link counts);
   an existing output is replaced only with ``force`` and only when it is what the command
   itself makes (``ours``: a hiros recording, a calibration file, a simulation folder).
2. ``staged_output`` around the work: the command writes under the final name inside a
   hidden folder beside the target (same file system, so the final step is a rename); on
   success the earlier output goes and the new one is renamed into place; on an error, an
   interrupt or SIGTERM the hidden folder is removed. Nothing is ever left under the final
   name that the command did not finish.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import struct
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from hiros_core.errors import OutputError

__all__ = [
    "BAG_METADATA",
    "STAGING_PREFIX",
    "check_output",
    "is_calibration_file",
    "is_hiros_recording",
    "only_holds",
    "refuse_inputs",
    "staged_files",
    "staged_output",
]

STAGING_PREFIX = ".hiros-partial-"
"""Name start of the hidden folder an output is written in before it is renamed into place."""
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_HEADER_OPCODE = 0x01
_MAX_CALIBRATION_BYTES = 1 << 20
"""A calibration file larger than this is not one ``hiros calibrate`` wrote (they are ~4 KB)."""

BAG_METADATA = "metadata.yaml"
"""The file rosbag2 describes a bag folder in, beside its MCAP files."""


def _resolved(path: Path) -> Path:
    return Path(os.path.realpath(path))


def _holds(folder: Path, path: Path) -> bool:
    """Whether ``path`` is ``folder`` or lies inside it (resolved paths)."""
    return folder == path or folder in path.parents


def check_output(
    out: Path,
    *,
    inputs: Iterable[Path | str] = (),
    force: bool = False,
    ours: Callable[[Path], bool] | None = None,
    what: str = "output",
    option: str = "--out",
) -> None:
    """Refuse, before any work, an output that would destroy an input or a user's file.

    Args:
        out: the output path the user gave.
        inputs: every file or folder the command reads.
        force: the user allows replacing an earlier output.
        ours: whether an existing ``out`` is what this command makes (only that is
            replaced); None: nothing existing is replaced.
        what: what the command writes, for the message ("recording", "calibration file").
        option: the option that named ``out``, for the message.

    Raises:
        OutputError: ``out`` is or holds an input, or exists and may not be replaced.

    """
    refuse_inputs(out, inputs, option)
    if not (out.exists() or out.is_symlink()):
        return
    if ours is None or not ours(out):
        msg = f"{option} {out} exists and is not a {what} this command made; not replaced"
        raise OutputError(msg)
    if not force:
        msg = f"{option} {out} exists already; --force replaces it (only a {what} hiros made)"
        raise OutputError(msg)


def refuse_inputs(out: Path, inputs: Iterable[Path | str], option: str = "--out") -> None:
    """Refuse an output path that is one of ``inputs`` or a folder holding one.

    Raises:
        OutputError: naming the option and the input.

    """
    target = _resolved(out)
    for given in inputs:
        source = Path(given)
        if not source.exists() and not source.is_symlink():
            continue
        resolved = _resolved(source)
        same = target == resolved
        with contextlib.suppress(OSError):
            same = same or (out.exists() and os.path.samefile(out, source))
        if same or _holds(target, resolved):
            relation = "is the input" if same else "is a folder holding the input"
            msg = (
                f"{option} {out} {relation} {source}: an output never replaces an input "
                "(--force or not); choose another path"
            )
            raise OutputError(msg)


@contextmanager
def staged_output(final: Path, *, replace: bool = False) -> Iterator[Path]:
    """The path to write ``final`` at; it becomes ``final`` only if the block succeeds.

    The yielded path has ``final``'s name inside a new hidden folder beside it, so a rosbag2
    folder's file names and a recording's suffix are those of the final output. On success
    an existing ``final`` is removed when ``replace`` (``check_output`` has vetted it) and
    the new output renamed into place; on any exception, Ctrl-C or SIGTERM (turned into an
    exception by the command line) the hidden folder and all in it are removed.

    Raises:
        OutputError: ``final`` appeared meanwhile and ``replace`` is False.

    """
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(_make_staging(final))
    try:
        staged = staging / final.name
        yield staged
        if final.exists() or final.is_symlink():
            if not replace:
                msg = f"{final} appeared while it was being written; the new output is not kept"
                raise OutputError(msg)
            if staged.is_dir() or final.is_dir():  # a file replaces a file in one step
                _remove(final)
        if staged.exists():
            staged.replace(final)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@contextmanager
def staged_files(folder: Path) -> Iterator[Path]:
    """A new hidden folder to write files meant for ``folder`` in; on success they move in.

    For outputs that go into a folder which may hold other things (``--plots``, ``--report``,
    ``hiros export``): each file written replaces its namesake in ``folder`` in one rename,
    the rest of ``folder`` is left alone; on an error or interrupt nothing reaches it.
    """
    folder.mkdir(parents=True, exist_ok=True)
    staging = Path(_make_staging(folder / "files"))
    try:
        yield staging
        for path in sorted(staging.iterdir()):
            path.replace(folder / path.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _make_staging(final: Path) -> str:
    import tempfile

    return tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{final.name}-", dir=final.parent)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


def only_holds(folder: Path, names: Iterable[str]) -> bool:
    """Whether ``folder`` is a folder holding nothing but entries named among ``names``."""
    if not folder.is_dir() or folder.is_symlink():
        return False
    allowed = set(names)
    return all(entry.name in allowed for entry in folder.iterdir())


def is_hiros_recording(path: Path) -> bool:
    """Whether ``path`` is a recording hiros wrote.

    That is an MCAP file whose header names hiros as its library, or a rosbag2 folder
    holding only ``<name>_0.mcap`` (such a file) and ``metadata.yaml``.
    """
    if path.is_dir():
        mcap = path / f"{path.name}_0.mcap"
        return only_holds(path, {mcap.name, BAG_METADATA}) and is_hiros_recording(mcap)
    if not path.is_file() or path.is_symlink():
        return False
    try:
        with path.open("rb") as stream:
            head = stream.read(8 + 9 + 4 + 256 + 4 + 256)
    except OSError:
        return False
    return _header_library(head).startswith("hiros")


def _header_library(head: bytes) -> str:
    """The ``library`` string of the MCAP header record in ``head`` ("" when there is none)."""
    if not head.startswith(_MCAP_MAGIC) or len(head) < 17 or head[8] != _HEADER_OPCODE:
        return ""
    try:
        at = 17
        (profile_length,) = struct.unpack_from("<I", head, at)
        at += 4 + profile_length
        (library_length,) = struct.unpack_from("<I", head, at)
        return head[at + 4 : at + 4 + library_length].decode("utf-8", "replace")
    except struct.error:
        return ""


def is_calibration_file(path: Path) -> bool:
    """Whether ``path`` is a small YAML file that loads as a calibration file."""
    from hiros_core.calibration import load_calibration
    from hiros_core.errors import CalibrationError

    if not path.is_file() or path.is_symlink() or path.stat().st_size > _MAX_CALIBRATION_BYTES:
        return False
    try:
        load_calibration(path)
    except CalibrationError:
        return False
    return True
