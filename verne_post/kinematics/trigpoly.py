"""Batched trigonometric polynomials in tan-half-angle form, for the exact eliminations.

A polynomial in (cos a, sin a) of degree k equals num(t) / (1 + t^2)^k with t = tan(a/2),
cos a = (1 - t^2) / (1 + t^2), sin a = 2t / (1 + t^2). The closure formulas are written once
as ordinary arithmetic on ``c`` and ``s``; called with arrays they evaluate, called with
:class:`TrigPoly` they build the numerator polynomial whose real roots are the solutions.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

_ONE_PLUS_T2 = np.array([1.0, 0.0, 1.0])


def _convolve_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros((a.shape[0], a.shape[1] + b.shape[1] - 1))
    for i in range(a.shape[1]):
        out[:, i : i + b.shape[1]] += a[:, i : i + 1] * b
    return out


class TrigPoly:
    """``num`` (N, 2k+1): ascending coefficients in t of N numerators; ``degree`` k."""

    __array_priority__ = 1000  # ndarray * TrigPoly must defer to TrigPoly.__rmul__

    def __init__(self, num: np.ndarray, degree: int) -> None:
        self.num = num
        self.degree = degree

    @classmethod
    def cos_sin(cls, n: int) -> tuple[TrigPoly, TrigPoly]:
        ones = np.ones((n, 1))
        return cls(ones * [1.0, 0.0, -1.0], 1), cls(ones * [0.0, 2.0, 0.0], 1)

    def _lift(self, degree: int) -> np.ndarray:
        num = self.num
        for _ in range(degree - self.degree):
            num = _convolve_rows(num, _ONE_PLUS_T2[None, :])
        return num

    @staticmethod
    def _coerce(other: object, n: int) -> TrigPoly:
        if isinstance(other, TrigPoly):
            return other
        value = np.broadcast_to(np.asarray(other, dtype=float), (n,))
        return TrigPoly(value[:, None].copy(), 0)

    def __add__(self, other: object) -> TrigPoly:
        other = self._coerce(other, self.num.shape[0])
        degree = max(self.degree, other.degree)
        return TrigPoly(self._lift(degree) + other._lift(degree), degree)

    __radd__ = __add__

    def __neg__(self) -> TrigPoly:
        return TrigPoly(-self.num, self.degree)

    def __sub__(self, other: object) -> TrigPoly:
        return self + (-self._coerce(other, self.num.shape[0]))

    def __rsub__(self, other: object) -> TrigPoly:
        return (-self) + other

    def __mul__(self, other: object) -> TrigPoly:
        if isinstance(other, TrigPoly):
            return TrigPoly(_convolve_rows(self.num, other.num), self.degree + other.degree)
        value = np.asarray(other, dtype=float)
        return TrigPoly(self.num * (value[:, None] if value.ndim else value), self.degree)

    __rmul__ = __mul__

    def __pow__(self, exponent: int) -> TrigPoly:
        result = self
        for _ in range(exponent - 1):
            result = result * self
        return result


def real_half_angle_roots(num: np.ndarray, imag_tol: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Real roots of each row's numerator as angles: (row index (K,), angle (K,) rad in (-pi, pi]).

    Every row also gets pi itself (t = infinity), because a vanishing leading coefficient
    hides it; callers verify every candidate against the closure equations. Rows of full
    degree are solved together (eigenvalues of stacked companion matrices); the rare row
    whose leading coefficient vanishes goes through ``np.roots``. Rows come out in order.
    """
    n = len(num)
    coefficients = num[:, ::-1]  # highest power first
    scale = np.max(np.abs(coefficients), axis=1)
    usable = (scale > 0) & np.isfinite(scale)
    coefficients = coefficients / np.where(usable, scale, 1.0)[:, None]
    full = usable & (np.abs(coefficients[:, 0]) > 1e-13)
    degree = num.shape[1] - 1
    rows = np.flatnonzero(full) if degree > 0 else np.empty(0, int)
    companion = np.zeros((rows.size, degree, degree))
    companion[:, 0, :] = -coefficients[rows, 1:] / coefficients[rows, :1]
    companion[:, np.arange(1, degree), np.arange(degree - 1)] = 1.0
    values = np.linalg.eigvals(companion) if rows.size else np.empty((0, degree), complex)
    index, column = np.nonzero(np.abs(values.imag) <= imag_tol * (1.0 + np.abs(values)))
    parts_index, parts_t = [rows[index]], [values[index, column].real]
    for k in np.flatnonzero(usable & ~full):
        nonzero = np.flatnonzero(np.abs(coefficients[k]) > 1e-13)
        trimmed = coefficients[k, nonzero[0]:]
        found = np.roots(trimmed) if trimmed.size > 1 else np.empty(0, complex)
        found = found[np.abs(found.imag) <= imag_tol * (1.0 + np.abs(found))].real
        parts_index.append(np.full(found.size, k))
        parts_t.append(found)
    index = np.concatenate([*parts_index, np.arange(n)])
    angle = np.concatenate([2.0 * np.arctan(np.concatenate(parts_t)), np.full(n, np.pi)])
    order = np.argsort(index, kind="stable")
    return index[order], angle[order]


@lru_cache(maxsize=64)
def _vincent(d: int, lo: float, hi: float) -> np.ndarray:
    """(d + 1, d + 1): ascending coefficients of q(x) = (1 + x)^d p((lo + hi x) / (1 + x)) from p's,
    so that q's positive roots are p's roots in (lo, hi) (the same few intervals on every call:
    cached, not to be written to)."""
    transform = np.zeros((d + 1, d + 1))
    for j in range(d + 1):
        term = np.polynomial.polynomial.polypow([lo, hi], j)
        product = np.polynomial.polynomial.polymul(term, np.polynomial.polynomial.polypow([1.0, 1.0], d - j))
        transform[:len(product), j] = product  # (hi = 0 lowers the degree)
    return transform


def roots_within(num: np.ndarray, lo: float, hi: float, unsure: float = 1e-9) -> np.ndarray:
    """(N,) int: how many real roots (with multiplicity) the polynomial of each row (ascending
    coefficients in t, (N, d + 1)) has in (lo, hi), where that is sure: 0 or 1; else -1.
    Descartes' rule of signs on q(x) = (1 + x)^d p((lo + hi x) / (1 + x)), whose positive roots
    are p's roots in (lo, hi) (Vincent's transform): no sign variation in q's coefficients means
    no such root, one means exactly one. A coefficient within ``unsure`` (relative to the largest)
    of 0 could have either sign (a zero hides how many variations it stands for): not sure."""
    q = num @ _vincent(num.shape[1] - 1, lo, hi).T
    size = np.max(np.abs(q), axis=1, keepdims=True)
    sure = np.all(np.abs(q) > unsure * size, axis=1) & np.isfinite(size[:, 0])
    sign = np.sign(q)
    variations = np.count_nonzero(sign[:, 1:] != sign[:, :-1], axis=1)
    return np.where(sure & (variations <= 1), variations, -1)
