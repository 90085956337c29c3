"""Small CSV helpers: read a header and rows, find columns by loose names, parse numbers.

Every CSV format we read spells its columns a little differently (``Person_Id`` or
``Person#``, ``PelvisPosX`` or ``Pelvis_X``), so columns are matched on a key with case and
punctuation removed.
"""

from __future__ import annotations

import csv
import re
from collections import Counter
from pathlib import Path

import numpy as np

from hiros_core.errors import RecordingError

__all__ = ["Table", "column_key", "read_table"]

_PUNCTUATION = re.compile(r"[^a-z0-9]")
_MISSING = {"", "na", "nan", "null", "none", "-"}


def column_key(name: str) -> str:
    """``Person_Id`` -> ``personid``, ``Kinect#`` -> ``kinect``: the loose name of a column."""
    return _PUNCTUATION.sub("", name.strip().lower())


class Table:
    """A CSV file's rows as strings, with columns found by loose name.

    Attributes:
        path: the file, for error messages.
        header: column names as written.
        rows: ``(N, C)`` array of strings (rows with the wrong width are dropped).

    """

    def __init__(self, path: Path, header: list[str], rows: np.ndarray) -> None:
        self.path = path
        self.header = header
        self.rows = rows
        self._keys = {column_key(name): i for i, name in reversed(list(enumerate(header)))}

    def find(self, *aliases: str) -> int | None:
        """Index of the first column whose loose name is one of ``aliases``, else None."""
        for alias in aliases:
            if (index := self._keys.get(column_key(alias))) is not None:
                return index
        return None

    def require(self, what: str, *aliases: str) -> int:
        """Like ``find`` but raises RecordingError naming the file and the missing column."""
        index = self.find(*aliases)
        if index is None:
            msg = f"{self.path}: no {what} column (looked for {', '.join(aliases)})"
            raise RecordingError(msg)
        return index

    def numbers(self, columns: list[int | None] | np.ndarray) -> np.ndarray:
        """``(N, len(columns))`` float64; missing values (NA, empty) and absent columns NaN."""
        out = np.full((len(self.rows), len(columns)), np.nan)
        present = [i for i, c in enumerate(columns) if c is not None]
        if not present or not len(self.rows):
            return out
        cells = np.char.strip(self.rows[:, [columns[i] for i in present]])
        missing = np.isin(np.char.lower(cells), list(_MISSING))
        cells[missing] = "nan"
        try:
            out[:, present] = cells.astype(np.float64)
        except ValueError as exc:
            msg = f"{self.path}: a value is not a number ({exc})"
            raise RecordingError(msg) from None
        return out

    def readable(self, column: int, *, integer: bool = False) -> np.ndarray:
        """``(N,)`` bool: which cells of ``column`` ``numbers`` (or ``integers``) can read.

        For formats where one bad row should cost that row, not the file: the caller drops
        the others with ``keep``.
        """
        unique, inverse = np.unique(np.char.strip(self.rows[:, column]), return_inverse=True)
        check = _is_integer if integer else _is_number
        return np.array([check(cell) for cell in unique.tolist()], dtype=bool)[inverse.ravel()]

    def keep(self, rows: np.ndarray, drops: Counter[str]) -> None:
        """Keep the rows where ``rows`` is True; the others are counted ``bad_row``."""
        drops["bad_row"] += int((~rows).sum())
        self.rows = self.rows[rows]

    def integers(self, column: int) -> np.ndarray:
        """``(N,)`` int64 of one column, exact for large stamps; raises RecordingError if bad."""
        try:
            return np.array([int(v) for v in np.char.strip(self.rows[:, column])], dtype=np.int64)
        except ValueError as exc:
            msg = f"{self.path}: column {self.header[column]!r} must hold integers ({exc})"
            raise RecordingError(msg) from None


def _is_integer(cell: str) -> bool:
    try:
        return -(1 << 63) <= int(cell) < 1 << 63
    except ValueError:
        return False


def _is_number(cell: str) -> bool:
    if cell.lower() in _MISSING:
        return True
    try:
        float(cell)
    except ValueError:
        return False
    return True


MAX_CSV_BYTES = 256 << 20
"""Largest CSV file read (half an hour of three cameras and two people, one row per joint);
the rows are held as text while read, about ten times the file's size."""


def read_table(path: str | Path, drops: Counter[str] | None = None) -> Table:
    """Read a CSV file with a header row; rows of the wrong width are counted ``bad_row``.

    Raises:
        RecordingError: the file cannot be read, is empty or larger than ``MAX_CSV_BYTES``.

    """
    path = Path(path)
    drops = drops if drops is not None else Counter()
    try:
        if path.stat().st_size > MAX_CSV_BYTES:
            msg = f"CSV file {path} is larger than {MAX_CSV_BYTES} bytes: not read (split it)"
            raise RecordingError(msg)
        with path.open(newline="") as stream:
            reader = csv.reader(stream, skipinitialspace=True)
            header = next(reader, None)
            body = [row for row in reader if row]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        msg = f"cannot read CSV file {path}: {exc}"
        raise RecordingError(msg) from exc
    if not header:
        msg = f"CSV file {path} is empty (expected a header row)"
        raise RecordingError(msg)
    header = [name.strip() for name in header]
    good = [row for row in body if len(row) == len(header)]
    drops["bad_row"] += len(body) - len(good)
    rows = np.array(good, dtype=str) if good else np.empty((0, len(header)), dtype=str)
    return Table(path, header, rows)
