"""Numeric column tables from text files (CSV and whitespace tables): measured C(q), DMA curves.

Rules, shared by every table vecontact reads:

* ``#`` starts a comment (whole line or the rest of a line); blank lines are skipped;
* fields are separated by commas, semicolons, tabs or runs of spaces (the first of ``,``, ``;``,
  tab found on a line decides; otherwise whitespace);
* one header line of column names is allowed before the first data row (a line with a field that
  is not a number); columns can then be picked by name as well as by 0-based index;
* every data row has the same number of fields, all finite numbers.

Every problem raises :class:`vecontact.errors.InputError` under the job key given by the caller,
naming the file and the line.
"""
import math

import numpy as np

from vecontact.errors import InputError

__all__ = ["read_columns"]


def _split(line):
    for sep in (",", ";", "\t"):
        if sep in line:
            return [f.strip() for f in line.split(sep)]
    return line.split()


def _is_number(text):
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_columns(path, key, names, columns=None):
    """Read the columns ``names`` (their meaning, for messages, e.g. ("q", "C")) from a text table.

    ``columns``: None (the file has exactly ``len(names)`` columns, in that order) or a list of
    ``len(names)`` entries, each a 0-based column index or a header name. Returns a float array of
    shape (rows, len(names)). ``key`` is the job key errors are reported under.
    """
    try:
        with open(path, "r", encoding="utf-8-sig") as fh:
            lines = fh.readlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(key, f"cannot read {path}: {exc}") from None
    header, rows, width = None, [], None
    for lineno, line in enumerate(lines, start=1):
        fields = _split(line.split("#", 1)[0].strip())
        if not fields or fields == [""]:
            continue
        if not all(_is_number(f) for f in fields):
            if header is None and not rows:
                header = fields
                continue
            bad = next(f for f in fields if not _is_number(f))
            raise InputError(key, f"{path} line {lineno}: {bad!r} is not a number")
        if width is None:
            width = len(fields)
        elif len(fields) != width:
            raise InputError(key, f"{path} line {lineno}: expected {width} columns (as the rows above), "
                                  f"got {len(fields)}")
        values = [float(f) for f in fields]
        if not all(math.isfinite(v) for v in values):
            raise InputError(key, f"{path} line {lineno}: non-finite value")
        rows.append((lineno, values))
    if not rows:
        raise InputError(key, f"{path}: no data rows")
    pick = _pick(path, key, names, columns, header, width)
    data = np.array([values for _, values in rows], dtype=float)[:, pick]
    return data


def _pick(path, key, names, columns, header, width):
    """Column indices for ``names`` from the ``columns`` choice (indices or header names)."""
    want = len(names)
    if header is not None and len(header) != width:
        raise InputError(key, f"{path}: the header names {len(header)} columns, the rows have {width}")
    if columns is None:
        if width != want:
            raise InputError(key, f"{path}: expected {want} columns ({', '.join(names)}), got {width} "
                                  f"(pick them with the columns option)")
        return list(range(want))
    if not isinstance(columns, (list, tuple)) or len(columns) != want:
        raise InputError(key, f"columns must list {want} columns ({', '.join(names)}), got {columns!r}")
    pick = []
    for name, c in zip(names, columns):
        if isinstance(c, bool):
            raise InputError(key, f"column for {name}: {c!r} is not an index or a header name")
        if isinstance(c, int):
            if not 0 <= c < width:
                raise InputError(key, f"column {c} for {name}: {path} has columns 0..{width - 1}")
            pick.append(c)
        elif isinstance(c, str):
            if header is None or c not in header:
                known = ", ".join(header) if header else "none: the file has no header line"
                raise InputError(key, f"column {c!r} for {name}: not in the header of {path} ({known})")
            pick.append(header.index(c))
        else:
            raise InputError(key, f"column for {name}: {c!r} is not an index or a header name")
    return pick
