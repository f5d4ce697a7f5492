"""Numeric CSV tables with a header: read with file/line errors, write atomically."""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from .atomic import atomic_write


def read_table(path: str | os.PathLike[str], required: Sequence[str], optional: Sequence[str] = (),
               notes: list[str] | None = None) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Columns (name -> float array) and the 1-based file line of each row.

    The header names every ``required`` column and any of the ``optional`` ones, in any order;
    case and surrounding spaces are ignored. Every cell is a finite number; an optional
    column's cell may be empty (NaN). Blank lines and lines starting with ``#`` are skipped.
    As spreadsheets write CSV: a UTF-8 byte-order mark is skipped, and a header separated by
    ``;`` makes the file ``;``-separated with ``,`` as the decimal point (said in ``notes``).
    """
    source = str(path)
    try:
        with open(path, encoding="utf-8-sig", newline="") as handle:
            text = handle.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", source) from None
    lines_of_text = text.splitlines()
    header_text = next((t for t in lines_of_text if t.strip() and not t.lstrip().startswith("#")), "")
    semicolons = ";" in header_text
    rows = list(csv.reader(lines_of_text, delimiter=";" if semicolons else ","))
    if semicolons:
        rows = [[cell.replace(",", ".") for cell in row] for row in rows]
        if notes is not None:
            notes.append(f"{source}: read as ';'-separated with ',' as the decimal point (a spreadsheet's CSV)")
    expected = ",".join(required) + "".join(f"[,{c}]" for c in optional)
    numbered = [(k + 1, [cell.strip() for cell in row]) for k, row in enumerate(rows)
                if any(cell.strip() for cell in row) and not row[0].lstrip().startswith("#")]
    if not numbered:
        raise InputError(f"empty file: expected a header line {expected}", source)
    header_line, header = numbered[0]
    names = [cell.lower() for cell in header]
    for k, name in enumerate(names):
        if name not in required and name not in optional:
            raise InputError(f"unknown column '{header[k]}' (header must be {expected})", source, header_line)
        if name in names[:k]:
            raise InputError(f"column '{name}' appears twice", source, header_line)
    missing = [c for c in required if c not in names]
    if missing:
        raise InputError(f"header lacks column(s) {','.join(missing)} (need {expected})", source, header_line)
    values = np.empty((len(numbered) - 1, len(names)))
    lines = np.empty(len(numbered) - 1, dtype=np.int64)
    for r, (line, row) in enumerate(numbered[1:]):
        if len(row) != len(names):
            raise InputError(f"row has {len(row)} fields, header (line {header_line}) has {len(names)}", source, line)
        for c, cell in enumerate(row):
            if cell == "" and names[c] in optional:
                values[r, c] = math.nan
                continue
            try:
                value = float(cell)
            except ValueError:
                raise InputError(f"'{cell}' is not a number (column {names[c]})", source, line) from None
            if not math.isfinite(value):
                raise InputError(f"'{cell}' is not a finite number (column {names[c]})", source, line)
            values[r, c] = value
        lines[r] = line
    return {name: values[:, c] for c, name in enumerate(names)}, lines


def write_table(path: str | os.PathLike[str], columns: dict[str, np.ndarray], formats: dict[str, str]) -> None:
    """Write columns as CSV with a header, atomically; ``formats`` maps a column to e.g. '%.6f'."""
    names = list(columns)
    with atomic_write(Path(path), newline="") as handle:
        handle.write(",".join(names) + "\n")
        n = len(next(iter(columns.values()))) if columns else 0
        if n == 0:
            return
        text = [np.char.mod(formats.get(name, "%.9g"), np.asarray(columns[name])) for name in names]
        rows = text[0]
        for column in text[1:]:
            rows = np.char.add(np.char.add(rows, ","), column)
        handle.write("\n".join(rows.tolist()) + "\n")


def write_json(path: str | os.PathLike[str], data: object) -> None:
    """Write ``data`` as indented JSON, atomically; undefined numbers (NaN, inf) as null."""
    import json

    with atomic_write(Path(path)) as handle:
        json.dump(_json_ready(data), handle, indent=2, allow_nan=False)
        handle.write("\n")


def _json_ready(data: object) -> object:
    """``data`` with every non-finite float replaced by None (JSON has no NaN) and numpy
    scalars as Python numbers."""
    if isinstance(data, dict):
        return {key: _json_ready(value) for key, value in data.items()}
    if isinstance(data, (list, tuple)):
        return [_json_ready(value) for value in data]
    if isinstance(data, np.generic):
        data = data.item()
    if isinstance(data, float) and not math.isfinite(data):
        return None
    return data
