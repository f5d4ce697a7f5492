"""Row-wise vector arithmetic over arrays of short rows (..., k), k from 2 to 6, a component at a time.

numpy reduces a short last axis slowly: ``np.linalg.norm(v, axis=-1)`` of (N, 3) rows costs about
six times the same sum written out component by component (655 against 110 us at 30,000 rows, one
core), ``np.sum(a * b, axis=-1)`` and ``np.all(m, axis=-1)`` likewise, and ``np.cross`` several
times its three products. numpy sums such an axis left to right, so written out in that order
these give the very same numbers (tests/test_rows.py compares them bit for bit with numpy's over
sizes, shapes and memory layouts): a drop-in where the results must not change.
"""

from __future__ import annotations

import numpy as np


def squares(v: np.ndarray) -> np.ndarray:
    """(...,): the sum of the squares of each row of ``v`` (..., k); ``np.sum(v * v, axis=-1)``."""
    total = v[..., 0] * v[..., 0]
    for k in range(1, v.shape[-1]):
        total += v[..., k] * v[..., k]
    return total


def norms(v: np.ndarray) -> np.ndarray:
    """(...,): the Euclidean norm of each row of ``v`` (..., k); ``np.linalg.norm(v, axis=-1)``."""
    return np.sqrt(squares(v))


def dots(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...,): the dot products of the rows of ``a`` and ``b`` (..., k), broadcast;
    ``np.sum(a * b, axis=-1)``."""
    total = a[..., 0] * b[..., 0]
    for k in range(1, a.shape[-1]):
        total = total + a[..., k] * b[..., k]
    return total


def all_of(mask: np.ndarray) -> np.ndarray:
    """(...,) bool: where every entry of a row of ``mask`` (..., k) holds; ``np.all(mask, axis=-1)``."""
    out = mask[..., 0].copy()
    for k in range(1, mask.shape[-1]):
        out &= mask[..., k]
    return out


def any_of(mask: np.ndarray) -> np.ndarray:
    """(...,) bool: where some entry of a row of ``mask`` (..., k) holds; ``np.any(mask, axis=-1)``."""
    out = mask[..., 0].copy()
    for k in range(1, mask.shape[-1]):
        out |= mask[..., k]
    return out


def finite_rows(v: np.ndarray) -> np.ndarray:
    """(...,) bool: rows of ``v`` (..., k) with every entry finite; ``np.all(np.isfinite(v), axis=-1)``."""
    out = np.isfinite(v[..., 0])
    for k in range(1, v.shape[-1]):
        out &= np.isfinite(v[..., k])
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3): the cross products of the rows of ``a`` and ``b`` (..., 3); ``np.cross(a, b)``."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def take_rows(a: np.ndarray, index: np.ndarray | slice) -> np.ndarray:
    """``a[index]`` along the first axis: by ``np.take`` for an index array and ``np.compress`` for a
    mask, the same rows (copies, as ``a[index]`` makes them) without numpy's slow gather of short
    rows (an (N, 3) array's rows: 4 to 5 times the time); a slice as a view."""
    if isinstance(index, np.ndarray) and index.ndim == 1 and a.ndim > 1:
        return np.compress(index, a, axis=0) if index.dtype == bool else np.take(a, index, axis=0)
    return a[index]
