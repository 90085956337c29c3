"""Frame accounting shared by every stage: each input frame is processed, dropped or held.

A stage's ``drops`` counts what it left out by reason, as before, but a reason is of one of
two kinds: a *frame* reason drops the whole input frame (a late or duplicate frame, an
uncalibrated camera), any other reason leaves out part of a frame that is still processed
(a detection, a joint of one, an estimate). Only the first kind may enter a frame balance,

    frames in == processed + frames dropped + held,

which a node's ``/diagnostics`` and ``hiros run``'s summary show; mixing the two made the sums
meaningless. A stage says which kind a reason is where it counts it (``drops.frame(reason)``
or ``drops.detections(reason, n)``), and carries ``processed`` and ``held`` beside ``drops``
(the ``Accounted`` base class). ROS-free: the stages import it, the nodes read it.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["Accounted", "Drops", "Merged"]


class Drops(Counter[str]):
    """reason -> count of what a stage left out; knows which reasons drop whole frames.

    A ``Counter`` (``drops[reason]`` reads a count, ``drops == {...}`` compares) whose reasons
    counted through ``frame`` are frame reasons; every other reason, whether counted through
    ``detections`` or by a helper handed the counter (``drops[reason] += n``), leaves out part
    of a processed frame. A reason is of one kind only.

    Attributes:
        frame_reasons: the reasons that dropped whole frames.
        frame_total: frames dropped, all frame reasons together (kept as it goes: a node
            checks its balance after every frame).

    """

    def __init__(
        self, counts: Mapping[str, int] | None = None, frame_reasons: Iterable[str] = ()
    ) -> None:
        super().__init__(counts or {})
        self.frame_reasons: set[str] = set(frame_reasons)
        self.frame_total = sum(self[reason] for reason in self.frame_reasons)

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled with the kinds (``Counter`` would keep the counts alone)."""
        return type(self), (dict(self), self.frame_reasons)

    def copy(self) -> Drops:
        """A copy with the kinds."""
        return type(self)(self, self.frame_reasons)

    def frame(self, reason: str, amount: int = 1) -> None:
        """Count ``amount`` whole input frames dropped for ``reason``."""
        self[reason] += amount
        self.frame_total += amount
        self.frame_reasons.add(reason)

    def detections(self, reason: str, amount: int = 1) -> None:
        """Count ``amount`` detections (or parts of one) left out of a processed frame."""
        self[reason] += amount

    def is_frame(self, reason: str) -> bool:
        """Whether ``reason`` drops whole frames."""
        return reason in self.frame_reasons

    def of_frames(self) -> Counter[str]:
        """Frames dropped, by reason (reasons with a zero count left out)."""
        return Counter({r: n for r, n in self.items() if n and r in self.frame_reasons})

    def of_detections(self) -> Counter[str]:
        """Detections (or parts) left out of processed frames, by reason (zeros left out)."""
        return Counter({r: n for r, n in self.items() if n and r not in self.frame_reasons})

    def add(self, other: Mapping[str, int], prefix: str = "", *, frames: bool = False) -> None:
        """Add ``other``'s counts, each reason under ``prefix``, keeping their kinds.

        The kinds are ``other``'s when it is a ``Drops``; a plain counter's reasons are frame
        reasons when ``frames`` (e.g. the messages a recording reader lost), else not.
        """
        kinds = other.frame_reasons if isinstance(other, Drops) else None
        for reason, count in tuple(other.items()):  # (a tuple: another thread may count)
            if not count:
                continue
            if (reason in kinds) if kinds is not None else frames:
                self.frame(prefix + reason, count)
            else:
                self[prefix + reason] += count


class Accounted:
    """Base of a stage that accounts for every input frame (mixed into each stage class).

    After every ``update``, each frame it was given is in exactly one of ``processed``,
    ``drops.frame_total`` or ``held``; so one ``update`` raises their sum by one.

    Attributes:
        processed: frames the stage worked through (an empty output included).
        drops: what it left out, by reason and kind (see ``Drops``).
        held: frames it holds, to be processed or dropped later (0 unless it buffers).

    """

    processed: int = 0
    held: int = 0
    drops: Drops

    @property
    def accounted(self) -> int:
        """Frames accounted for: processed, dropped whole, or held."""
        return self.processed + self.drops.frame_total + self.held

    def diagnostics(self) -> dict[str, str]:
        """The stage's own figures for ``/diagnostics`` beside the counts: key -> text.

        None by default; e.g. the optimizer's time to accept each person.
        """
        return {}


class Merged(Accounted):
    """Several stages' accounts as one, for a node or a pipeline that runs more than one.

    Frames are those of the ``counting`` stages (the ones the node's input frames end in:
    all of them side by side, or the last of a chain); the drops are every stage's, each
    under its prefix, so that a frame a first stage drops is not looked for in the next.
    """

    def __init__(
        self, parts: Iterable[tuple[str, Accounted]], counting: Iterable[Accounted]
    ) -> None:
        self.parts = list(parts)
        self.counting = list(counting)

    @property
    def processed(self) -> int:  # type: ignore[override]
        """Frames the counting stages processed."""
        return sum(stage.processed for stage in self.counting)

    @property
    def held(self) -> int:  # type: ignore[override]
        """Frames held by any stage."""
        return sum(stage.held for _, stage in self.parts)

    @property
    def drops(self) -> Drops:  # type: ignore[override]
        """Every stage's drops, each reason under the stage's prefix."""
        total = Drops()
        for prefix, stage in self.parts:
            total.add(stage.drops, prefix)
        return total

    def diagnostics(self) -> dict[str, str]:
        """Every stage's figures, each key under the stage's prefix."""
        return {
            prefix + key: text
            for prefix, stage in self.parts
            for key, text in stage.diagnostics().items()
        }
