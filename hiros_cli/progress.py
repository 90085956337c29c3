"""One look for long offline work: a progress bar, and the reader's warnings.

The bar counts items and shows the rate; the warnings say what a recording reader could not
read (a truncated file, a damaged chunk), one line each.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager

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
