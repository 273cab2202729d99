"""The columns of a CSV recording, read in chunks: header checks, cells to numbers, timestamps.

:func:`read_csv_columns` does the reading for `bayes_fdi.datasets.readers.read_csv`:

- the header's names are taken without spaces around them; a name that appears twice, or twice up
  to spaces around it (``X`` and ``X ``), is refused when the reader would use it, naming both
  spellings and their positions (which one holds the channel is ambiguous);
- a delimiter at the end of every line (an empty field after the last named column) ends the
  row: the named columns keep their values; a line with a value in that field is refused, and so
  is a first data line with a value beyond the named columns (pandas would make the first column
  an index and shift every name by one);
- the file is read as text in chunks of :data:`CHUNK_ROWS` lines, each chunk's used columns turned
  into numbers at once: memory holds the numbers (8 bytes a cell) and one chunk of text, never
  the whole file as text; the memory this needs, estimated from the file's size, is checked
  before reading (`bayes_fdi.datasets.time_grid.check_recording_memory`);
- empty lines are skipped; every message names the file's line;
- the time column holds seconds or ISO date-times (`bayes_fdi.datasets.time_grid.parse_date_times`:
  with UTC offsets they are instants in UTC, the offsets met kept in ``time_offsets``).

Written by hand on pandas' parser: pandas reads CSV text, but it neither refuses duplicate names
(it renames them ``X.1``) nor tells a trailing delimiter from an index column.
"""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

import numpy as np

from bayes_fdi.datasets.format import CHANNELS
from bayes_fdi.datasets.time_grid import (
    check_recording_memory,
    date_time_origin,
    parse_date_times,
)

__all__ = ["BLANK_CELLS", "CHUNK_ROWS", "CsvColumns", "read_csv_columns"]

#: Lines of text parsed at a time.
CHUNK_ROWS = 100_000
#: Cells read as gaps (after stripping spaces).
BLANK_CELLS: tuple[str, ...] = ("", "NaN", "nan", "NA", "N/A")
#: Bytes of text sampled at the start of the file to estimate its number of lines.
_SAMPLE_BYTES = 1 << 20


class CsvColumns(NamedTuple):
    """What :func:`read_csv_columns` read."""

    #: Seconds of each sample (from the first row for date-times); None without a time column.
    time: np.ndarray | None
    #: Channel -> its values as written (floats, NaN for gaps).
    channels: dict[str, np.ndarray]
    #: ``ignored_columns`` and, for date-times, ``time_origin`` (and ``time_offsets``).
    attrs: dict[str, Any]
    #: The file's line of each sample.
    lines: np.ndarray

    def label(self, i: int) -> str:
        """Sample ``i`` in messages: its number, its line and its time."""
        when = "" if self.time is None else f", time {self.time[i]:.10g}"
        if self.time is not None and "time_origin" in self.attrs:
            when = f", {self.time[i]:.10g} s after {self.attrs['time_origin']}"
        return f"sample {i + 1} (line {int(self.lines[i])}{when})"


class _Header(NamedTuple):
    names: list[str]  # as written
    n_lines: int  # physical lines up to and including the header
    first_row: list[str] | None  # the first data row's fields
    first_line: int  # its line


def _read_header(source: str, sep: str) -> _Header:
    try:
        with open(source, newline="", encoding="utf-8-sig") as handle:
            reader = csv.reader(handle, delimiter=sep, skipinitialspace=True)
            rows: Iterator[list[str]] = (row for row in reader if row)
            names = next(rows, None)
            n_lines = reader.line_num
            first = next(rows, None)
            first_line = reader.line_num
    except UnicodeDecodeError as exc:
        raise ValueError(f"{source}: not a readable CSV file (not UTF-8 text: {exc})") from None
    except csv.Error as exc:
        raise ValueError(f"{source}: not a readable CSV file ({exc})") from None
    if names is None:
        raise ValueError(f"{source}: the file is empty")
    return _Header(names, n_lines, first, first_line)


def _duplicates(names: list[str]) -> dict[str, list[int]]:
    """Stripped name -> positions of its columns, for names met more than once."""
    where: dict[str, list[int]] = {}
    for i, name in enumerate(names):
        where.setdefault(name.strip(), []).append(i)
    return {k: v for k, v in where.items() if len(v) > 1 and k}


def _refuse_duplicate(source: str, names: list[str], positions: list[int], channel: str) -> None:
    spellings = [names[i] for i in positions]
    where = " and ".join(str(i + 1) for i in positions)
    if len(set(spellings)) == 1:
        problem = f"column {spellings[0]!r} appears {len(positions)} times (columns {where})"
    else:
        quoted = " and ".join(repr(s) for s in dict.fromkeys(spellings))
        problem = f"columns {quoted} (columns {where}) differ only by spaces around the name"
    raise ValueError(
        f"{source}: {problem}: which one holds {channel} is ambiguous; rename or remove one"
    )


def _check_memory(source: str, n_used: int) -> None:
    """Numbers of the used columns (concatenated, then normalised) for the estimated rows."""
    size = os.path.getsize(source)
    with open(source, "rb") as handle:
        sample = handle.read(_SAMPLE_BYTES)
    whole = sample[: sample.rfind(b"\n") + 1]  # the lines read whole
    rows = size / max(len(whole), 1) * max(whole.count(b"\n"), 1)
    check_recording_memory(rows * (n_used + 1) * 8 * 3, f"reading {source} (about {rows:.3g} rows)")


def _numbers(text: Any, name: str, source: str, lines: np.ndarray) -> np.ndarray:
    """Stripped cells as floats: blank cells (:data:`BLANK_CELLS`) are NaN; the rest numbers."""
    import pandas as pd

    blank = text.isin(BLANK_CELLS).to_numpy()
    parsed = pd.to_numeric(text.where(~blank), errors="coerce").to_numpy(dtype=np.float64)
    bad = np.isnan(parsed) & ~blank
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{source}: line {int(lines[row])}, column {name!r}: {text.iloc[row]!r} is not a "
            "number (write gaps as an empty cell or NaN)"
        )
    # blank cells are NaN already (masked before the conversion)
    return parsed


class _TimeColumn:
    """The time cells of successive chunks: seconds, or date-times (the first chunk decides)."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.parts: list[np.ndarray] = []
        self.kind = ""  # "seconds" or "date-times"
        self.offsets: dict[str, None] = {}
        self.first = ""  # the first date-time, as written, and its line
        self.first_line = 0

    def add(self, text: Any, lines: np.ndarray) -> None:
        import pandas as pd

        empty = (text == "").to_numpy()
        if empty.any():
            line = int(lines[np.flatnonzero(empty)[0]])
            raise ValueError(f"{self.source}: line {line}: the time cell is empty")
        if not self.kind:
            numeric = pd.to_numeric(text, errors="coerce").notna().all()
            self.kind = "seconds" if numeric else "date-times"
        if self.kind == "seconds":
            self.parts.append(_numbers(text, "time", self.source, lines))
            return
        parsed = parse_date_times(text, self.source, lambda i: f"line {int(lines[i])}")
        if not self.parts:
            self.first, self.first_line = str(text.iloc[0]), int(lines[0])
        elif bool(parsed.offsets) != bool(self.offsets):  # a chunk unlike the first ones
            with_offset, without = (
                (f"line {int(lines[0])} ({text.iloc[0]!r})", f"line {self.first_line} "
                 f"({self.first!r})") if parsed.offsets else
                (f"line {self.first_line} ({self.first!r})", f"line {int(lines[0])} "
                 f"({text.iloc[0]!r})")
            )  # fmt: skip
            raise ValueError(
                f"{self.source}: {with_offset} has a UTC offset but {without} has none; write "
                "every timestamp with its offset, or none"
            )
        self.offsets.update(dict.fromkeys(parsed.offsets))
        self.parts.append(parsed.instants)

    def seconds(self) -> tuple[np.ndarray, dict[str, str]]:
        values = np.concatenate(self.parts)
        if self.kind == "seconds":
            return values, {}
        first = values[0]
        seconds = ((values - first) / np.timedelta64(1, "ns") * 1e-9).astype(np.float64)
        offsets = list(self.offsets)
        attrs = {"time_origin": date_time_origin(first, offsets[0] if offsets else "")}
        if offsets:
            attrs["time_offsets"] = json.dumps(offsets)
        return seconds, attrs


def read_csv_columns(
    source: str,
    sep: str,
    choose: Callable[[list[str]], tuple[dict[str, str], list[str]]],
) -> CsvColumns:
    """Read the columns of a CSV recording (the rules are in the module's docstring).

    Parameters
    ----------
    source
        The file.
    sep
        The delimiter.
    choose
        Column names (stripped, each once) -> (channel or ``time`` -> column name, unused
        names): `bayes_fdi.datasets.readers` picks the columns.

    Returns
    -------
    CsvColumns
    """
    import pandas as pd

    header = _read_header(source, sep)
    names = header.names
    width = len(names)
    if header.first_row is not None and len(header.first_row) == width + 1:
        if header.first_row[-1].strip():
            raise ValueError(
                f"{source}: line {header.first_line} has {width + 1} fields but the header names "
                f"{width} columns; the last field {header.first_row[-1]!r} has no column name "
                "(every column would shift by one): name it in the header"
            )
        names = [*names, ""]  # a delimiter ends every line: an unnamed, empty last field
    elif header.first_row is not None and len(header.first_row) != width:
        raise ValueError(
            f"{source}: line {header.first_line} has {len(header.first_row)} fields but the "
            f"header names {width} columns"
        )
    stripped = [n.strip() for n in names]
    chosen, _ = choose([n for n in dict.fromkeys(stripped) if n])
    ignored = [n for n in stripped if n and n not in chosen.values()]  # each column once
    for positions in _duplicates(names).values():
        used = [c for c, column in chosen.items() if column == stripped[positions[0]]]
        if used:
            _refuse_duplicate(source, names, positions, used[0])
    position = {channel: stripped.index(column) for channel, column in chosen.items()}
    unnamed = [i for i, n in enumerate(stripped) if not n]
    _check_memory(source, len(position))
    try:
        chunks = pd.read_csv(
            source, sep=sep, header=None, skiprows=header.n_lines, dtype=str,
            keep_default_na=False, na_filter=False, skipinitialspace=True,
            skip_blank_lines=False, index_col=False, chunksize=CHUNK_ROWS, encoding="utf-8-sig",
        )  # fmt: skip
        columns, time, lines = _read_chunks(
            chunks, source, header.n_lines, len(names), position, unnamed
        )
    except pd.errors.EmptyDataError:
        columns, time, lines = {c: np.empty(0) for c in position}, None, np.empty(0, np.int64)
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise ValueError(f"{source}: not a readable CSV file ({exc})") from None
    attrs: dict[str, Any] = {"ignored_columns": json.dumps(ignored)}
    seconds = None
    if "time" in position:
        seconds, time_attrs = time.seconds() if time is not None else (np.empty(0), {})
        attrs.update(time_attrs)
    return CsvColumns(seconds, {c: columns[c] for c in CHANNELS}, attrs, lines)


def _read_chunks(
    chunks: Iterator[Any],
    source: str,
    header_lines: int,
    width: int,
    position: dict[str, int],
    unnamed: list[int],
) -> tuple[dict[str, np.ndarray], _TimeColumn | None, np.ndarray]:
    """Numbers of the chosen columns, the time column and the line of each sample."""
    parts: dict[str, list[np.ndarray]] = {c: [] for c in position if c != "time"}
    time = _TimeColumn(source) if "time" in position else None
    line_parts = []
    for chunk in chunks:
        if chunk.shape[1] != width:  # pandas takes the width from the first data line
            raise ValueError(
                f"{source}: line {int(chunk.index[0]) + header_lines + 1} has "
                f"{chunk.shape[1]} fields where {width} were expected from the header"
            )
        blank = (chunk == "").all(axis=1).to_numpy()
        chunk = chunk[~blank]
        lines = chunk.index.to_numpy() + header_lines + 1
        for i in unnamed:  # a column without a name holds nothing (a trailing delimiter)
            cells = chunk[i].str.strip()
            full = (cells != "").to_numpy()
            if full.any():
                row = int(np.flatnonzero(full)[0])
                raise ValueError(
                    f"{source}: line {int(lines[row])} holds {cells.iloc[row]!r} in column "
                    f"{i + 1}, which has no name in the header: name it"
                )
        for channel, i in position.items():
            text = chunk[i].str.strip()
            if channel == "time":
                time.add(text, lines)
            else:
                parts[channel].append(_numbers(text, channel, source, lines))
        line_parts.append(lines)
    columns = {c: np.concatenate(p) if p else np.empty(0) for c, p in parts.items()}
    return (
        columns,
        time if time is not None and time.parts else None,
        (np.concatenate(line_parts) if line_parts else np.empty(0, np.int64)),
    )
