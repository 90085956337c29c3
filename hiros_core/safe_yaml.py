"""YAML files read within limits: size, nesting, aliases and the size they expand to.

``yaml.safe_load`` runs no code, but a small file can still take all memory or time: ten
levels of ten aliases each expand to 10^10 nodes as soon as anything walks the result (an
"alias bomb"), and deep nesting ends in a RecursionError in PyYAML's composer. Calibration
files, parameter files and rosbag2 ``metadata.yaml`` are read through ``load_yaml``, which
checks, before anything is built:

* the file's size (``max_bytes``, 1 MiB by default: a calibration file is ~4 KB);
* the nesting depth (``MAX_DEPTH``) and the number of aliases (``MAX_ALIASES``), on the
  parser's event stream, which needs no recursion;
* the number of nodes the document would have with every alias expanded
  (``MAX_NODES``), counted on the composed graph without expanding it.

A file past a limit is refused with one sentence naming it and the limit.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from hiros_core.errors import HirosError

__all__ = ["MAX_ALIASES", "MAX_DEPTH", "MAX_NODES", "MAX_YAML_BYTES", "load_yaml", "parse_yaml"]

MAX_YAML_BYTES = 1 << 20
"""Default largest file read, bytes."""
MAX_DEPTH = 64
"""Largest nesting of mappings and sequences (ROS parameter files nest 3-6 deep)."""
MAX_ALIASES = 100
"""Most aliases (``*name``) in one document; the files hiros writes hold none."""
MAX_NODES = 100_000
"""Most nodes the document may have once every alias is expanded."""


def load_yaml(
    path: Path,
    *,
    what: str,
    error: type[HirosError],
    max_bytes: int = MAX_YAML_BYTES,
) -> Any:
    """The YAML document of ``path`` (safe types only), read within the module's limits.

    Args:
        path: the file.
        what: what the file is, for messages ("calibration file").
        error: the error type raised (``CalibrationError``, ``ConfigError``, ...).
        max_bytes: largest file accepted.

    Raises:
        error: the file cannot be read, is not YAML, or is past a limit.

    """
    try:
        with path.open("rb") as stream:
            raw = stream.read(max_bytes + 1)
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:  # Unicode: a binary file
        msg = f"cannot read {what} {path}: {exc}"
        raise error(msg) from exc
    if len(raw) > max_bytes:
        msg = f"{what} {path} is larger than {max_bytes} bytes: not read"
        raise error(msg)
    return parse_yaml(text, source=f"{what} {path}", error=error, max_chars=max_bytes)


def parse_yaml(
    text: str, *, source: str, error: type[HirosError], max_chars: int = MAX_YAML_BYTES
) -> Any:
    """The YAML document in ``text``, within the limits; ``source`` names it in messages.

    Raises:
        error: ``text`` is not YAML or is past a limit.

    """
    if len(text) > max_chars:
        msg = f"{source} is larger than {max_chars} characters: not read"
        raise error(msg)
    try:
        _check_events(text)
        loader = yaml.SafeLoader(text)
        try:
            node = loader.get_single_node()
            if node is None:
                return None
            if _expanded_size(node) > MAX_NODES:
                msg = f"its aliases expand to more than {MAX_NODES} nodes"
                raise _LimitError(msg)
            return loader.construct_document(node)
        finally:
            loader.dispose()
    except _LimitError as exc:
        msg = f"{source} is refused: {exc}"
        raise error(msg) from None
    except (yaml.YAMLError, RecursionError, ValueError, TypeError) as exc:
        msg = f"cannot read {source}: {_one_line(exc)}"
        raise error(msg) from None


class _LimitError(Exception):
    """A document past one of the limits (internal: turned into the caller's error)."""


def _check_events(text: str) -> None:
    """Depth and alias count from the parser's events (no recursion, nothing built)."""
    depth = aliases = 0
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_DEPTH:
                msg = f"it nests deeper than {MAX_DEPTH} levels"
                raise _LimitError(msg)
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
        elif isinstance(event, yaml.AliasEvent):
            aliases += 1
            if aliases > MAX_ALIASES:
                msg = f"it holds more than {MAX_ALIASES} aliases"
                raise _LimitError(msg)


def _expanded_size(root: yaml.Node) -> int:
    """Nodes of the document with aliases expanded, each shared node counted once per use.

    A depth-first walk with an explicit stack sizes children before their parents and
    memoises each node's size, so it takes time in the number of distinct nodes, not in the
    expanded size. A node met again inside itself (``&a [*a]``) is refused.
    """
    sizes: dict[int, int] = {}
    entered: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, finished = stack.pop()
        key = id(node)
        if key in sizes:
            continue
        children = _children(node)
        if finished:
            sizes[key] = min(1 + sum(sizes[id(c)] for c in children), MAX_NODES + 1)
            continue
        if key in entered:  # popped again before it finished: it is inside itself
            msg = "an alias refers to a node that holds it (a recursive document)"
            raise _LimitError(msg)
        entered.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in children if id(c) not in sizes)
    return sizes[id(root)]


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _one_line(exc: BaseException) -> str:
    """A YAML error's message on one line (PyYAML's span several, with a source excerpt)."""
    if isinstance(exc, RecursionError):
        return f"it nests too deep ({exc})"
    return " ".join(str(exc).split())
