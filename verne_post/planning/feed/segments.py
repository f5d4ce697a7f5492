"""Segmented arrays: many sequences in one array, each element knowing its sequence; the
splines through their waypoints and range operations over them."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np

from .plan import DERIVATIVE_WEIGHTS

# --------------------------------------------------------------------------------------------
# Segmented arrays: many sequences in one array, each element knowing its sequence
# --------------------------------------------------------------------------------------------


def ranges(start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Concatenation of arange(start[i], stop[i]) over i."""
    count = np.maximum(stop - start, 0)
    offset = np.repeat(start - np.r_[0, np.cumsum(count)[:-1]], count)
    return np.arange(int(count.sum())) + offset


def segment_cumsum(values: np.ndarray, start: np.ndarray, dtype: type = float) -> np.ndarray:
    """Per segment, the running sum of ``values`` from 0 (segments begin at ``start``, with a
    last entry = len(values)), each summed on its own: a sequence's plan does not depend, even
    in its last bit, on what it is planned with (the same G-code whether a program is planned
    whole or in parts)."""
    out = np.empty(len(values), dtype=dtype)
    for a, b in zip(start[:-1].tolist(), start[1:].tolist(), strict=True):
        np.cumsum(values[a:b], dtype=dtype, out=out[a:b])
    return out


@dataclass(frozen=True, eq=False)
class Pieces:
    """Piecewise cubics of many sequences: pieces grouped by sequence, in local coordinates.

    ``start`` (P,) local start of each piece; ``first`` (R + 1,) offsets of each sequence's
    pieces; ``coef`` (4, P) or (4, D, P) cubic coefficients (highest first) in (x - start), or
    None for a plain sorted grid. Vector values come out dimension-major, (D, n): each joint's
    row is contiguous.
    """

    start: np.ndarray
    first: np.ndarray
    coef: np.ndarray | None = None

    @cached_property
    def owner(self) -> np.ndarray:
        return np.repeat(np.arange(len(self.first) - 1), np.diff(self.first))

    @cached_property
    def _line(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The sequences laid end to end on one real line, 1 apart beyond their spans: the
        starts there, each sequence's shift, and the bounds (R,) its queries are clipped to."""
        count = np.diff(self.first)
        low, high = np.zeros(len(count)), np.zeros(len(count))
        some = count > 0
        low[some] = self.start[self.first[:-1][some]]
        high[some] = self.start[self.first[1:][some] - 1]
        shift = np.r_[0.0, np.cumsum(high - low + 2.0)[:-1]] - low
        return self.start + shift[self.owner], shift, low - 0.5, high + 0.5

    def search(self, seq: np.ndarray, x: np.ndarray, side: Literal["left", "right"] = "right") -> np.ndarray:
        """np.searchsorted of local positions x among the starts of sequence seq (global index)."""
        line, shift, low, high = self._line
        i = np.searchsorted(line, np.clip(x, low[seq], high[seq]) + shift[seq], side=side)
        # A real search is twice as fast as one of (sequence, position) pairs. Rounding x + shift
        # never reorders (rounding is monotonic), it can only tie a start with x: searching
        # right, i may then be past a start > x; searching left, short of a start < x. Corrected
        # exactly (rarely more than a pass that finds nothing):
        while True:
            if side == "right":
                wrong = np.flatnonzero((i > self.first[seq]) & (self.start[np.maximum(i - 1, 0)] > x))
                step = -1
            else:
                wrong = np.flatnonzero((i < self.first[seq + 1]) & (self.start[np.minimum(i, len(self.start) - 1)] < x))
                step = 1
            if not len(wrong):
                return i
            i[wrong] += step

    def clip(self, seq: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Indices clipped into the pieces of their sequences."""
        return np.clip(index, self.first[seq], self.first[seq + 1] - 1)

    def locate(self, seq: np.ndarray, x: np.ndarray, side: Literal["left", "right"] = "right") -> np.ndarray:
        """Piece holding local position x of sequence seq (its first or last piece outside)."""
        return self.clip(seq, self.search(seq, x, side) - 1)

    def __call__(self, piece: np.ndarray, x: np.ndarray, order: int = 0) -> np.ndarray:
        """Derivative ``order`` (0..3) at local positions x, each in its ``piece``."""
        return self.derivatives(piece, x, (order,))[0]

    def derivatives(self, piece: np.ndarray, x: np.ndarray, orders: tuple[int, ...]) -> list[np.ndarray]:
        """Derivatives of the given orders (0..3) at local positions x, each in its ``piece``."""
        assert self.coef is not None
        tau = x - self.start[piece]
        # c0 is gathered only where the value is wanted; np.take keeps each row contiguous (fancy
        # indexing on the last axis would not, and every reduction over joints would crawl).
        c = np.take(self.coef[: 4 - min(orders)], piece, axis=-1)
        out = []
        for order in orders:
            weights = DERIVATIVE_WEIGHTS[order]
            value = weights[0] * c[0]
            for k, weight in enumerate(weights[1:], start=1):
                value *= tau
                value += c[k] if weight == 1.0 else weight * c[k]
            out.append(value)
        return out


#: d^n/dx^n of c3 x^3 + c2 x^2 + c1 x + c0 as Horner weights on (c3, c2, ...).


def not_a_knot(x: np.ndarray, y: np.ndarray, first: np.ndarray) -> np.ndarray:
    """Cubic coefficients (4, N - R, D) of the not-a-knot splines through (x, y) per sequence.

    x (N,) strictly increasing within each sequence; y (N, D); ``first`` (R + 1,) offsets.
    The same splines as scipy's ``CubicSpline(x, y, bc_type="not-a-knot")`` (a straight line
    through 2 points, a parabola through 3), solved as one tridiagonal system for the slopes.
    """
    n = np.diff(first)
    owner = np.repeat(np.arange(len(n)), n)
    local = np.arange(len(x)) - first[:-1][owner]
    size = n[owner]
    last = local == size - 1
    dx = np.diff(x)
    slope = np.diff(y, axis=0) / dx[:, None]
    # Row i couples slopes i - 1, i, i + 1: dx[i] m[i-1] + 2 (dx[i-1] + dx[i]) m[i] + dx[i-1] m[i+1].
    diag = np.ones(len(x))
    upper = np.zeros(len(x))  # element (i, i + 1)
    lower = np.zeros(len(x))  # element (i, i - 1)
    rhs = np.zeros_like(y, dtype=float)
    inner = np.flatnonzero((local > 0) & ~last & (size >= 4))
    diag[inner] = 2.0 * (dx[inner - 1] + dx[inner])
    upper[inner] = dx[inner - 1]
    lower[inner] = dx[inner]
    rhs[inner] = 3.0 * (dx[inner, None] * slope[inner - 1] + dx[inner - 1, None] * slope[inner])
    # The not-a-knot end rows are not diagonally dominant (dx[1] m[0] + (dx[0] + dx[1]) m[1]).
    # Row 1 minus row 0 (both hold dx[1] m[0]) no longer holds m[0], likewise the row before the
    # last minus the last; m[0] and m[-1] come after from their own rows. What is left is
    # strictly diagonally dominant (dx[0] + dx[1] on the diagonal of row 1 against dx[0]), which
    # a solve without pivoting keeps stable.
    head = np.flatnonzero((local == 0) & (size >= 4))
    d = x[head + 2] - x[head]
    head_rows = dx[head + 1], d, (((dx[head] + 2.0 * d) * dx[head + 1])[:, None] * slope[head]
                                  + (dx[head] ** 2)[:, None] * slope[head + 1]) / d[:, None]
    tail = np.flatnonzero(last & (size >= 4))
    d = x[tail] - x[tail - 2]
    tail_rows = dx[tail - 2], d, ((dx[tail - 1] ** 2)[:, None] * slope[tail - 2]
                                  + ((2.0 * d + dx[tail - 1]) * dx[tail - 2])[:, None] * slope[tail - 1]) / d[:, None]
    lower[head + 1] = upper[tail - 1] = 0.0
    for (_, coupling, value), row in ((head_rows, head + 1), (tail_rows, tail - 1)):
        diag[row] -= coupling
        rhs[row] -= value
    # Two points: the chord. Three: the parabola through them (its slopes at the three nodes).
    two = np.flatnonzero(size == 2)
    rhs[two] = slope[np.where(local[two] == 0, two, two - 1)]
    three = np.flatnonzero((size == 3) & (local == 0))
    for k in range(3):
        node = three + k
        h0, h1 = dx[three], dx[three + 1]
        curvature = (slope[three + 1] - slope[three]) / (h0 + h1)[:, None]
        offset = (-h0, h0, h0 + 2.0 * h1)[k]
        rhs[node] = slope[three] + curvature * offset[:, None]
    m = _tridiagonal(lower, diag, upper, rhs, local)
    for end, (own, coupling, value), row in ((head, head_rows, head + 1), (tail, tail_rows, tail - 1)):
        m[end] = (value - coupling[:, None] * m[row]) / own[:, None]
    block = np.flatnonzero(~last)  # block b starts at node b (global node index)
    h = dx[block][:, None]
    m0, m1, chord = m[block], m[block + 1], slope[block]
    return np.stack([(m0 + m1 - 2.0 * chord) / h ** 2, (3.0 * chord - 2.0 * m0 - m1) / h, m0, y[block]])


def _tridiagonal(lower: np.ndarray, diag: np.ndarray, upper: np.ndarray, rhs: np.ndarray, local: np.ndarray
                 ) -> np.ndarray:
    """x (N, D) with ``lower[i] x[i - 1] + diag[i] x[i] + upper[i] x[i + 1] = rhs[i]`` (N,), for
    a strictly diagonally dominant matrix made of independent systems, one after the other:
    ``local`` (N,) each row's index within its own, whose first row has ``lower`` 0 and last row
    ``upper`` 0.

    Cyclic reduction (Hockney 1965; stable without pivoting for such matrices, Heller 1976): each
    level eliminates each system's odd rows from its even ones, in log2(longest) vectorised
    levels; then the odd unknowns are found back from their rows, level by level. The parity is
    each system's own, so a system gets the same bits whatever comes before it (a zero coupling
    adds exactly nothing). numpy only: scipy's banded solver cost the planning's process 0.3 s
    to import.
    """
    a, b, c, d = lower, diag, upper, rhs
    levels = []
    while np.any(local):
        n = len(b)
        odd = local % 2 == 1
        keep = np.flatnonzero(~odd)
        before, after = np.maximum(keep - 1, 0), np.minimum(keep + 1, n - 1)
        alpha, gamma = -a[keep] / b[before], -c[keep] / b[after]  # 0 at a system's first, last row
        levels.append((a, b, c, d, keep, np.flatnonzero(odd)))
        a, b, c, d = (alpha * a[before], b[keep] + alpha * c[before] + gamma * a[after], gamma * c[after],
                      d[keep] + alpha[:, None] * d[before] + gamma[:, None] * d[after])
        local = local[keep] // 2
    x = d / b[:, None]
    for a, b, c, d, keep, odd in reversed(levels):  # odd: never a system's first row
        n = len(b)
        full = np.zeros((n + 1, d.shape[1]))  # a row of 0 after the last (no coupling to it)
        full[keep] = x
        full[odd] = (d[odd] - a[odd, None] * full[odd - 1] - c[odd, None] * full[odd + 1]) / b[odd, None]
        x = full[:n]
    return x


def range_chmin(n: int, lo: np.ndarray, hi: np.ndarray, values: np.ndarray) -> np.ndarray:
    """out[i] = min(values[m] for every m with lo[m] <= i <= hi[m]) (inf where none), vectorised.

    Each update is written to the two power-of-two blocks covering its range, then the blocks
    are pushed down level by level (a sparse table used in reverse).
    """
    length = hi - lo + 1
    level = np.floor(np.log2(np.maximum(length, 1))).astype(int)
    top = int(level.max()) if len(level) else 0
    table = np.full((top + 1, n), np.inf)
    np.minimum.at(table, (level, lo), values)
    np.minimum.at(table, (level, hi - (1 << level) + 1), values)
    for k in range(top, 0, -1):
        half = 1 << (k - 1)
        np.minimum(table[k - 1], table[k], out=table[k - 1])
        table[k - 1, half:] = np.minimum(table[k - 1, half:], table[k, : n - half])
    return table[0]


def range_max(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """max(values[lo..hi]) for inclusive index arrays lo <= hi (sparse table)."""
    n = len(values)
    levels = [values]
    step = 1
    while 2 * step <= n:
        prev = levels[-1]
        nxt = np.full_like(values, -np.inf)
        nxt[: n - 2 * step + 1] = np.maximum(prev[: n - 2 * step + 1], prev[step: n - step + 1])
        levels.append(nxt)
        step *= 2
    table = np.stack(levels)
    level = np.floor(np.log2(hi - lo + 1)).astype(int)
    return np.maximum(table[level, lo], table[level, hi - (1 << level) + 1])


def sorted_points(seq: np.ndarray, x: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (seq, local x) sorted by sequence then x, exact repeats dropped; with offsets (R + 1,)."""
    # x + 2 seq orders the points as (seq, x) does for x in [0, 1], but for ties by rounding:
    # sorted so (3x faster than a lexsort of the pair, the points being runs already sorted),
    # then checked exactly.
    order = np.argsort(x + 2.0 * seq, kind="stable")
    seq, x = seq[order], x[order]
    if np.any((seq[1:] < seq[:-1]) | ((seq[1:] == seq[:-1]) & (x[1:] < x[:-1]))):
        order = np.lexsort((x, seq))
        seq, x = seq[order], x[order]
    keep = np.r_[True, (seq[1:] != seq[:-1]) | (x[1:] != x[:-1])]
    seq, x = seq[keep], x[keep]
    return seq, x, np.searchsorted(seq, np.arange(count + 1))
