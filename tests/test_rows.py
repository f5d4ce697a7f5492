"""kinematics.rows: the row-wise sums written out component by component give numpy's very numbers.

They replace numpy's reductions over a short last axis where results must not change (the posted
program is compared byte for byte), so the test is equality, not closeness: over row lengths 2
to 6, sizes around numpy's buffer and unrolling boundaries, leading axes, and memory layouts
(C, Fortran, strided), with entries spread over 16 decades so that a different order of the sums
would round differently.
"""

from __future__ import annotations

import numpy as np
import pytest

from verne_post.kinematics import rows

SIZES = (1, 2, 3, 7, 8, 9, 100, 4095, 8193, 30_000)


def _layouts(v: np.ndarray) -> list[np.ndarray]:
    wide = np.concatenate([v, v], axis=-1)
    return [v, np.asfortranarray(v), wide[..., ::2], np.swapaxes(np.swapaxes(v, 0, -2).copy(), 0, -2)]


def _spread(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    return rng.normal(size=shape) * 10.0 ** rng.integers(-8, 8, size=shape)


@pytest.mark.parametrize("k", [2, 3, 4, 5, 6])
def test_row_sums_are_numpys_bit_for_bit(k: int) -> None:
    rng = np.random.default_rng(k)
    for n in SIZES:
        for shape in ((n, k), (2, n, k)):
            for a, b in zip(_layouts(_spread(rng, shape)), _layouts(_spread(rng, shape)), strict=True):
                assert np.array_equal(rows.norms(a), np.linalg.norm(a, axis=-1))
                assert np.array_equal(rows.squares(a), np.sum(a * a, axis=-1))
                assert np.array_equal(rows.dots(a, b), np.sum(a * b, axis=-1))
                mask = a > 0.2
                assert np.array_equal(rows.all_of(mask), np.all(mask, axis=-1))
                assert np.array_equal(rows.any_of(mask), np.any(mask, axis=-1))
                with_nan = np.where(rng.random(a.shape) < 0.05, np.nan, np.where(rng.random(a.shape) < 0.05, np.inf, a))
                assert np.array_equal(rows.finite_rows(with_nan), np.all(np.isfinite(with_nan), axis=-1))
                if k == 3:
                    assert np.array_equal(rows.cross(a, b), np.cross(a, b))


def test_a_different_order_of_the_sums_would_be_seen() -> None:
    """The data is spread enough that the order of the sums shows: summing right to left differs."""
    a = _spread(np.random.default_rng(0), (30_000, 3))
    right_to_left = np.sqrt(a[:, 0] * a[:, 0] + (a[:, 1] * a[:, 1] + a[:, 2] * a[:, 2]))
    assert not np.array_equal(right_to_left, np.linalg.norm(a, axis=-1))


def test_the_row_sums_leave_their_inputs_alone() -> None:
    a = _spread(np.random.default_rng(1), (100, 3))
    mask = a > 0
    kept, kept_mask = a.copy(), mask.copy()
    rows.squares(a), rows.all_of(mask), rows.any_of(mask)
    assert np.array_equal(a, kept) and np.array_equal(mask, kept_mask)


def test_take_rows_are_the_rows_numpy_indexes() -> None:
    rng = np.random.default_rng(4)
    for shape in ((0, 3), (1, 3), (50, 3), (1000, 5), (300, 2, 3), (200,)):
        a = _spread(rng, shape)
        n = shape[0]
        for index in (rng.integers(-n, n, 3 * n) if n else np.zeros(0, int), np.zeros(0, int),
                      rng.permutation(n), rng.random(n) < 0.5, np.ones(n, bool), slice(1, None, 2)):
            taken = rows.take_rows(a, index)
            assert taken.shape == a[index].shape and np.array_equal(taken, a[index])
            if isinstance(index, np.ndarray) and taken.size:
                assert not np.shares_memory(taken, a)  # a copy, as a[index] is
