"""CSV tables: the header and cells of a delimited text file, read fast and refused in one line.

Every refusal names the file, the row (1-based, header = row 1), the column and the fix. Two readers
stand behind `read_table`, and they accept and refuse the same files with the same messages:

- pandas's C parser reads a *plain* file (no quotes, no stray carriage return, every line the
  same number of fields, ...; see `_plain_columns`) straight into float64 columns, with the
  float() of every cell bit for bit. This is the usual file, and it is fast;
- the csv module reads any other file, and gives the text of the cells that a message repeats.

Whenever the fast reader cannot vouch for a file in every respect, the csv module reads it, and
a column whose numbers are refused is converted again from its text for the message, so nothing
the fast reader does shows in a result or a message, only in the time taken.
"""
from __future__ import annotations

import collections

import csv
import io
import math
import sys
from collections.abc import Collection
from pathlib import Path

import numpy as np

from gecgen.model.validation import ModelError, excerpt, read_utf8, require

#: characters in one cell; numbers and names are far shorter
MAX_CELL = 10_000
#: the column separators a table may use, as messages name them (a measurement file is
#: comma-separated, CONTRACTS.md section 3; `gecgen import --sep` reads the others)
SEPARATORS = {",": "','", ";": "';'", "\t": "tabs", "|": "'|'"}


def at(where: str, row: int, col: str) -> str:
    """How messages name a cell: file, row (1-based, header = 1) and column."""
    return f"{where}: row {row}, column {excerpt(col)}"


def parse_float(text: str, decimal: str) -> float:
    """float(text) with `decimal` as the decimal mark. Beside a decimal comma a point is refused,
    not guessed: '1.234' may group thousands."""
    if decimal != ".":
        if "." in text:
            raise ValueError(text)
        text = text.replace(decimal, ".")
    return float(text)


def numbers(cells: np.ndarray, col: str, where: str, fix: str = "fix the value", limit: float = math.inf,
            decimal: str = ".") -> np.ndarray:
    """One column of text cells (R,) as finite floats of magnitude at most `limit`; the first bad
    cell is refused with its row."""
    try:
        values = cells.astype(float) if decimal == "." else np.array([parse_float(c, decimal) for c in cells], float)
    except ValueError:
        mark = "" if decimal == "." else f" with the decimal mark {decimal!r}"
        for r, text in enumerate(cells):
            try:
                parse_float(text, decimal)
            except ValueError:
                raise ModelError(f"{at(where, r + 2, col)}: {excerpt(text)} is not a number{mark}; {fix}") from None
    bad = np.nonzero(~np.isfinite(values))[0]
    require(not len(bad), f"{at(where, bad[0] + 2 if len(bad) else 0, col)}: "
                          f"{excerpt(cells[bad[0]]) if len(bad) else ''} is not finite; fix or remove the row")
    big = np.nonzero(np.abs(values) > limit)[0]
    require(not len(big), f"{at(where, big[0] + 2 if len(big) else 0, col)}: {excerpt(cells[big[0]]) if len(big) else ''} "
                          f"is beyond +-{limit:g}, more than any real reading there; {fix}")
    return values


def _check_separator(header: list[str], where: str, sep: str):
    """Refuse a header of one column that holds another separator."""
    for other, name in SEPARATORS.items():
        if other == sep or len(header) > 1 or other not in header[0]:
            continue
        option = "--sep " + ("tab" if other == "\t" else name)
        if sep == ",":
            hint = option + (" --decimal ','" if other == ";" else "")
            raise ModelError(f"{where}: row 1: the columns are separated by {name}; gecgen reads comma-separated "
                             f"files: convert the file to commas (a wide export converts with gecgen import {hint})")
        raise ModelError(f"{where}: row 1: the columns are separated by {name}, not {SEPARATORS[sep]}; "
                         f"give the file's separator ({option})")


def _check_names(header: list[str], where: str):
    counts = collections.Counter(header)  # linear: a header of 100,000 columns took 26 s by counting each
    twice = [h for h in counts if counts[h] > 1]
    require(not twice, f"{where}: row 1: column {excerpt(twice[0]) if twice else ''} appears twice in the header; "
                       f"rename or remove one")


def _read_cells(text: str, where: str, expect: str, sep: str) -> tuple[list[str], np.ndarray]:
    """Header and cells (rows, columns; text) by the csv module, with every check of `read_table`."""
    # csv's own cap on a cell raises a bare error without the column; lift it for this read and
    # refuse long cells below, by row and column
    cap = csv.field_size_limit()
    csv.field_size_limit(max(cap, len(text) + 1))
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=sep)
    try:
        header = next(reader, None)
        rows = list(reader)
    except csv.Error as exc:
        raise ModelError(f"{where}: row {reader.line_num}: not readable as CSV ({excerpt(str(exc))}); fix the row") from None
    finally:
        csv.field_size_limit(cap)
    require(header, f"{where}: the file is empty; expected a header row with {expect}")
    header = [h.strip() for h in header]
    _check_separator(header, where, sep)
    for r, row in enumerate([header, *rows]):
        if max(map(len, row), default=0) > MAX_CELL:
            c = next(c for c, cell in enumerate(row) if len(cell) > MAX_CELL)
            col = header[c] if r and c < len(header) else f"#{c + 1}"
            raise ModelError(f"{at(where, r + 1, col)}: {len(row[c])} characters ({excerpt(row[c])}); a cell may have "
                             f"at most {MAX_CELL}: fix the file")
    _check_names(header, where)
    require(rows, f"{where}: no data rows after the header")
    lengths = np.fromiter((len(r) for r in rows), int, len(rows))
    bad = np.nonzero(lengths != len(header))[0]
    if len(bad):
        row, n = bad[0] + 2, lengths[bad[0]]
        require(n, f"{where}: row {row}: a blank line between the rows; remove it (blank lines may only end the file)")
        raise ModelError(f"{where}: row {row}: {n} fields, the header has {len(header)}")
    return header, np.array(rows, dtype=object)


def _pandas_options() -> dict:
    import pandas as pd

    # before 3.1 pandas's default converter is not correctly rounded; its round-trip one is float()'s.
    # 3.1 has one, correctly rounded, converter and deprecates the option
    version = tuple(int(v) for v in pd.__version__.split(".")[:2])
    return {"float_precision": "round_trip"} if version < (3, 1) else {}


def _plain_columns(data: bytes, sep: str, decimal: str, text: Collection[str]) -> tuple[list[str], dict] | None:
    """The header (names stripped) and every column (float64, or the cells' text for the columns
    named in `text`) of a file that the csv module and pandas split into the same fields and that
    passes every check of `_read_cells` but the one for repeated names; else None.

    The fast reader declines: quotes (a quoted cell may hold separators and line breaks), NUL, a
    carriage return outside a CRLF line end, fewer than two columns, a cell longer than MAX_CELL
    bytes, a blank line, a row whose field count differs from the header's, a cell of a number
    column that pandas cannot read as a float, and the words true and false in any case (pandas
    reads a column of them as 1 and 0, float() refuses them)."""
    if b'"' in data or b"\0" in data:
        return None
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n")
        if b"\r" in data:
            return None
    if not data.endswith(b"\n"):
        data += b"\n"
    raw = np.frombuffer(data, np.uint8)
    if any(letter in data for letter in (b"u", b"U", b"l", b"L")):  # one of 'true', one of 'false'
        lower = (raw | 0x20).tobytes()  # ASCII letters in lower case; no other byte becomes a letter
        if b"true" in lower or b"false" in lower:
            return None
    ends = np.flatnonzero(raw == ord("\n"))
    lengths = np.diff(ends, prepend=-1) - 1
    if len(ends) < 2 or lengths.min() == 0:
        return None
    # a cell is what lies between separators and line ends: a wide table's lines are long, its cells not
    if (np.diff(np.flatnonzero((raw == ord(sep)) | (raw == ord("\n"))), prepend=-1) - 1).max() > MAX_CELL:
        return None
    header = [h.strip() for h in data[:ends[0]].decode().split(sep)]
    separators = np.diff(np.searchsorted(np.flatnonzero(raw == ord(sep)), ends), prepend=0)
    if len(header) < 2 or (separators != len(header) - 1).any():
        return None
    import pandas as pd

    try:
        frame = pd.read_csv(io.BytesIO(data), sep=sep, decimal=decimal, header=None, skiprows=1, names=range(len(header)),
                            index_col=False, dtype={k: object if h in text else np.float64 for k, h in enumerate(header)},
                            na_filter=False, skip_blank_lines=False, engine="c", **_pandas_options())
    except (ValueError, OverflowError):
        return None
    if len(frame) != len(ends) - 1:
        return None
    # the number columns as one block: a Series per column costs a wide table (40,000 columns) 16 s
    numeric = [k for k, h in enumerate(header) if h not in text]
    block = frame.iloc[:, numeric].to_numpy(np.float64) if numeric else np.zeros((len(frame), 0))
    at_block = {k: j for j, k in enumerate(numeric)}
    return header, {h: block[:, at_block[k]].copy() if k in at_block else frame[k].to_numpy(copy=True)
                    for k, h in enumerate(header)}


class Table:
    """A CSV read by `read_table`: `header` (names stripped), len() data rows, and per column its
    numbers (`numbers`) or its cells' text (`cells`; `rows` for all of them). Row r of a column is
    line r + 2 of the file."""

    def __init__(self, data: bytes, where: str, expect: str, sep: str, decimal: str, header: list[str],
                 columns: dict | None, cells: np.ndarray | None):
        self.header, self.where, self.decimal = header, where, decimal
        self._data, self._expect, self._sep = data, expect, sep
        self._columns = columns  # the fast reader's, or None
        self._index = {}  # column name -> its first position: a wide table is read column by column
        for k, h in enumerate(header):
            self._index.setdefault(h, k)
        self._cells = cells  # the csv module's (rows, columns), read when first needed
        self._rows = len(next(iter(columns.values()))) if columns else len(cells)

    def __len__(self) -> int:
        return self._rows

    def _text(self) -> np.ndarray:
        if self._cells is None:
            _, self._cells = _read_cells(self._data.decode(), self.where, self._expect, self._sep)
        return self._cells

    def cells(self, col: str) -> np.ndarray:
        """The text of a column's cells (R,), as the file has them."""
        fast = self._columns.get(col) if self._columns else None
        return fast if fast is not None and fast.dtype == object else self._text()[:, self._index[col]]

    def rows(self) -> list[list[str]]:
        """Every row's cells as text, as the file has them."""
        return self._text().tolist()

    def numbers(self, col: str, fix: str = "fix the value", limit: float = math.inf) -> np.ndarray:
        """A column as finite floats (R,) of magnitude at most `limit`, or the first bad cell refused
        with its row, its text and `fix`."""
        fast = self._columns.get(col) if self._columns else None
        if (fast is not None and fast.dtype == np.float64 and np.isfinite(fast).all()
                and (not len(fast) or np.abs(fast).max() <= limit)):
            return fast
        return numbers(self.cells(col), col, self.where, fix, limit, self.decimal)


#: how messages name a table given as a pandas DataFrame: its rows are numbered as in the CSV that
#: `DataFrame.to_csv(index=False)` writes (header = row 1, so iloc[i] is row i + 2)
DATAFRAME = "DataFrame"


def _source(path, what: str) -> tuple[bytes, str]:
    """The bytes and name of a table: a file, or a pandas DataFrame as the CSV it writes (its
    index left out, missing values as empty cells) so that one reader checks both alike."""
    if hasattr(path, "to_csv") and hasattr(path, "columns"):
        require(not any(isinstance(c, tuple) for c in path.columns),
                f"{DATAFRAME}: the columns are a MultiIndex; give one level of column names (the {what}'s header)")
        return path.to_csv(index=False, lineterminator="\n").encode(), DATAFRAME
    return read_utf8(Path(path), what), str(path)


def _without_blank_end(data: bytes) -> bytes:
    """data with the blank lines that end it (line ends, spaces, tabs, carriage returns after the last
    line end that follows a cell) made one line end, found from the end: a regular expression for it
    scans every byte of a 50 MB file, 13 s."""
    end = len(data.rstrip(b" \t\r\n"))
    i = data.find(b"\n", end)
    if i < 0:
        return data
    return data[:i - 1 if i > end and data[i - 1] == ord("\r") else i] + b"\n"
#: files smaller than this (bytes) are read by the csv module unless pandas is already loaded
SMALL_BYTES = 1_000_000


def _check_line_lengths(data: bytes, where: str, sep: str):
    """Refuse, before any parsing, a line longer than a valid row can be (every field of the header's
    count at MAX_CELL characters): a 700 MB cell once took 7 GB to refuse."""
    raw = np.frombuffer(data, np.uint8)
    ends = np.flatnonzero(raw == ord("\n"))
    if not len(ends):
        return
    lengths = np.diff(np.append(ends, len(raw)), prepend=-1) - 1
    fields = data[:ends[0]].count(sep.encode()) + 1
    longest = (MAX_CELL + 1) * fields * 4  # a character is at most 4 bytes of UTF-8
    over = np.flatnonzero(lengths > longest)
    require(not len(over), f"{where}: row {over[0] + 1 if len(over) else 0}: "
                           f"{lengths[over[0]] if len(over) else 0} bytes, more than {fields} cells of at most "
                           f"{MAX_CELL} characters can hold: fix the file")


def read_table(path, what: str, expect: str, text: Collection[str] = (), verbatim: bool = False,
               sep: str = ",", decimal: str = ".") -> Table:
    """Read a CSV, given by its path or as a pandas DataFrame with the file's columns (`_source`).
    Refuses a missing, empty or non-UTF-8 file, a header that shows another separator
    or repeats a name, a cell over MAX_CELL characters, no data rows and rows whose field count
    differs from the header's; `what` names the file kind in messages ("measurement file") and
    `expect` says what the header should hold.

    `text` names the columns that hold text (a target's name); every other column is read as numbers
    by the fast reader, and a file where that fails is read by the csv module. `verbatim`: the caller
    wants the text of every cell (it writes them back), so the csv module reads the file.
    `sep` separates the columns, `decimal` marks the decimals of numbers ("." or ",")."""
    data, where = _source(path, what)
    # blank lines after the last row end the file (spreadsheets and tracker software write them);
    # a blank line between rows is refused below
    data = _without_blank_end(data)
    _check_line_lengths(data, where, sep)
    # below SMALL_BYTES the csv module is done before pandas would even be imported (0.25 s): the
    # two readers give the same arrays and messages, so the choice is speed alone
    small = len(data) < SMALL_BYTES and "pandas" not in sys.modules
    plain = None if verbatim or small else _plain_columns(data, sep, decimal, text)
    if plain is None:
        header, cells = _read_cells(data.decode(), where, expect, sep)
        return Table(data, where, expect, sep, decimal, header, None, cells)
    header, columns = plain
    _check_names(header, where)  # two columns or more: the separator is right
    return Table(data, where, expect, sep, decimal, header, columns, None)
