"""Fast fixed-decimal number formatting for large outputs (G-code, timed CSV), vectorised.

Text is built as bytes in numpy arrays, a column at a time, instead of one format call per
number; that keeps writing 10^6 blocks or samples to about a second.
"""

from __future__ import annotations

import numpy as np


def scaled_int(values: np.ndarray, decimals: int) -> np.ndarray:
    """``values * 10**decimals`` rounded to int64 (caller has checked the range)."""
    return np.rint(values * (10.0**decimals)).astype(np.int64)


def fixed_field(q: np.ndarray, decimals: int, prefix: bytes) -> np.ndarray:
    """Bytes of ``prefix`` + the decimal number ``q / 10**decimals``, one row per value.

    Returns an (n, W) uint8 array; unused leading positions are 0 bytes, removed when the lines
    are packed. ``q`` is int64 (already scaled and rounded), so no ``-0`` can appear.
    """
    n = q.shape[0]
    neg = q < 0
    a = np.abs(q)
    top = int(a.max()) if n else 0
    nd_max = max(decimals + 1, len(str(top)))
    pow10 = 10 ** np.arange(nd_max - 1, -1, -1, dtype=np.int64)  # most significant first
    digits = ((a[:, None] // pow10) % 10).astype(np.uint8)
    digits += ord("0")
    ndig = np.maximum(np.count_nonzero(a[:, None] >= pow10, axis=1), decimals + 1)
    digits[np.arange(nd_max) < (nd_max - ndig)[:, None]] = 0  # leading zeros
    n_int = nd_max - decimals
    p = len(prefix)
    width = p + 1 + n_int + (1 + decimals if decimals else 0)
    out = np.zeros((n, width), dtype=np.uint8)
    out[:, :p] = np.frombuffer(prefix, dtype=np.uint8)
    out[:, p] = np.where(neg, ord("-"), 0)
    out[:, p + 1 : p + 1 + n_int] = digits[:, :n_int]
    if decimals:
        out[:, p + 1 + n_int] = ord(".")
        out[:, p + 2 + n_int :] = digits[:, n_int:]
    return out


def pack_lines(parts: list[np.ndarray]) -> str:
    """Rows of byte fields (each (n, w) uint8, 0 = nothing) joined into ``\n``-ended lines."""
    n = parts[0].shape[0]
    mat = np.concatenate([*parts, np.full((n, 1), ord("\n"), dtype=np.uint8)], axis=1)
    return mat[mat != 0].tobytes().decode("ascii")


def csv_lines(columns: list[tuple[np.ndarray, int]], text: list[np.ndarray] | None = None) -> str:
    """CSV lines of numeric columns (values, decimals), then text columns (arrays of str)."""
    parts: list[np.ndarray] = []
    for k, (values, decimals) in enumerate(columns):
        parts.append(fixed_field(scaled_int(np.asarray(values, dtype=float), decimals), decimals, b"," if k else b""))
    for column in text or []:
        encoded = np.char.encode(np.char.add(",", column.astype(str)), "ascii")
        width = max(encoded.dtype.itemsize, 1)
        parts.append(np.frombuffer(encoded.astype(f"S{width}").tobytes(), dtype=np.uint8).reshape(-1, width))
    return pack_lines(parts)
