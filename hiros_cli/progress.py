"""One look for long offline work: a progress bar, a calibration's stages, the reader's warnings.

The bar counts items and shows the rate; a calibration shows its stage; the warnings say what
a recording reader could not read (a truncated file, a damaged chunk), one line each.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

if TYPE_CHECKING:
    from hiros_calib.calibrator import CalibrationResult, CalibratorParams
    from hiros_core.calibration import Calibration


@contextmanager
def progress_bar(
    description: str, total: int | None, console: Console | None = None
) -> Iterator[Callable[[int], None]]:
    """Yield ``advance(n)``; the bar is transient and disappears when the work is done."""
    columns = [SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn(), TimeRemainingColumn()]  # fmt: skip
    with Progress(*columns, console=console or Console(stderr=True), transient=True) as bar:
        task = bar.add_task(description, total=total)
        yield lambda n=1: bar.advance(task, n)


def print_warnings(console: Console, problems: Iterable[str]) -> None:
    """One ``warning:`` line per problem (a truncated file, a damaged chunk), as written."""
    for problem in problems:
        console.print(f"warning: {problem}", markup=False, highlight=False)


def calibrate_with_progress(
    recording: Path,
    console: Console,
    params: CalibratorParams | None = None,
    *,
    use_arrival: bool = True,
    known_poses: Calibration | None = None,
) -> CalibrationResult:
    """``hiros_calib.calibrate_recording`` behind a transient bar of its stages.

    The reader's warnings are printed when it returns, before its result, or when it fails
    (a damaged recording can be why). Raises what ``calibrate_recording`` raises.
    """
    from hiros_calib.offline import READING, calibrate_recording

    problems: list[str] = []
    columns = (TextColumn("{task.description:<24}"), BarColumn(), TimeElapsedColumn())
    try:
        with Progress(*columns, console=console, transient=True) as bar:
            task = bar.add_task(READING, total=1.0)
            return calibrate_recording(
                recording,
                params,
                use_arrival=use_arrival,
                progress=lambda stage, done: bar.update(task, description=stage, completed=done),
                problems=problems,
                known_poses=known_poses,
            )
    finally:
        print_warnings(console, problems)
