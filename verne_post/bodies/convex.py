"""Distances between convex bodies, N pairs at once: alternating projections with a certificate.

Each body kind gives its closest point to any point (``project``) and its support function
(``support``: the largest d . x over the body for a direction d), both in closed form. The
distance of two disjoint convex bodies A and B is found by alternating projections (y = P_B(x),
x = P_A(y)), which converge to a closest pair; every iterate gives an upper bound |x - y|, and
its direction n = (x - y) / |x - y| a lower bound that holds whatever the iteration did:

    d(A, B) >= min_{a in A} n . a - max_{b in B} n . b = -support_A(-n) - support_B(n)

(a separating slab of that width lies between the bodies). The checks use the lower bound, so
a clearance is never overstated; pairs whose bounds still straddle the margin are iterated
further. Units: mm, in whatever frame both bodies are given.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

#: Iterations before the first certificate, and at most in all.
FIRST_ITERATIONS = 6
MAX_ITERATIONS = 2400
#: mm: bodies whose closest pair found is nearer than this meet.
GAP = 1e-3
#: mm: a positive bound this close to the closest pair found is the clearance (the faces of a
#: tilted cylinder over a box's edge converge slowly; 20 um is below the sampling resolution of
#: :mod:`verne_post.bodies.clearance`, and the bound is never more than the truth).
SETTLED = 0.02


def _norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms of the rows of v (N, 3)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _unit(v: np.ndarray) -> np.ndarray:
    n = _norm(v)[:, None]
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


@dataclass(frozen=True)
class Capsules:
    """N segments p0 -> p1 (mm) swept by spheres of ``radius`` (mm): rods, guideways, the platform."""

    p0: np.ndarray  # (N, 3)
    p1: np.ndarray  # (N, 3)
    radius: np.ndarray  # (N,)

    def _axis(self, x: np.ndarray) -> np.ndarray:
        span = self.p1 - self.p0
        size = np.einsum("ij,ij->i", span, span)
        t = np.clip(np.einsum("ij,ij->i", x - self.p0, span) / np.where(size > 0, size, 1.0), 0.0, 1.0)
        return self.p0 + t[:, None] * span

    def project(self, x: np.ndarray) -> np.ndarray:
        q = self._axis(x)
        off = x - q
        size = _norm(off)
        scale = np.minimum(1.0, self.radius / np.where(size > 0, size, 1.0))
        return q + off * scale[:, None]

    def support(self, d: np.ndarray) -> np.ndarray:
        return (np.maximum(np.einsum("ij,ij->i", self.p0, d), np.einsum("ij,ij->i", self.p1, d))
                + self.radius * _norm(d))

    def support_point(self, d: np.ndarray, near: np.ndarray) -> np.ndarray:
        """A point of each body where ``d`` . x is largest (``near`` breaks ties)."""
        del near
        end = np.where((np.einsum("ij,ij->i", self.p1 - self.p0, d) > 0)[:, None], self.p1, self.p0)
        return end + self.radius[:, None] * _unit(d)

    def normals(self, d: np.ndarray) -> tuple[np.ndarray, ...]:
        """Unit face normals of each body nearest to ``d`` (none: a capsule is smooth)."""
        del d
        return ()

    def centre(self) -> np.ndarray:
        return 0.5 * (self.p0 + self.p1)

    def reach(self) -> np.ndarray:
        """mm: the radius of a sphere about :meth:`centre` holding each body."""
        return 0.5 * np.linalg.norm(self.p1 - self.p0, axis=1) + self.radius


@dataclass(frozen=True)
class Cylinders:
    """N solid circular cylinders, axis c0 -> c1 (mm), of ``radius`` (mm): spindle, holder, tool, table."""

    c0: np.ndarray  # (N, 3)
    c1: np.ndarray  # (N, 3)
    radius: np.ndarray  # (N,)

    @cached_property
    def _axis(self) -> np.ndarray:
        """(N, 3) unit axes (0 for a flat one)."""
        return _unit(self.c1 - self.c0)

    @cached_property
    def _length(self) -> np.ndarray:
        return _norm(self.c1 - self.c0)

    def project(self, x: np.ndarray) -> np.ndarray:
        size, a = self._length, self._axis
        rel = x - self.c0
        along = np.einsum("ij,ij->i", rel, a)
        radial = rel - along[:, None] * a
        r = _norm(radial)
        scale = np.minimum(1.0, self.radius / np.where(r > 0, r, 1.0))
        return self.c0 + np.clip(along, 0.0, size)[:, None] * a + radial * scale[:, None]

    def support(self, d: np.ndarray) -> np.ndarray:
        a = self._axis
        along = np.einsum("ij,ij->i", d, a)
        perp = _norm(d - along[:, None] * a)
        return (np.maximum(np.einsum("ij,ij->i", self.c0, d), np.einsum("ij,ij->i", self.c1, d))
                + self.radius * perp)

    def support_point(self, d: np.ndarray, near: np.ndarray) -> np.ndarray:
        a = self._axis
        along = np.einsum("ij,ij->i", d, a)
        end = np.where((along > 0)[:, None], self.c1, self.c0)
        radial = d - along[:, None] * a
        # d along the axis: the whole end face; its point nearest to ``near``
        flat = _norm(radial) <= 1e-9 * _norm(d)
        rel = near - end
        rel = rel - np.einsum("ij,ij->i", rel, a)[:, None] * a
        size = _norm(rel)
        toward = rel * np.minimum(1.0, self.radius / np.where(size > 0, size, 1.0))[:, None]
        return end + np.where(flat[:, None], toward, self.radius[:, None] * _unit(radial))

    def normals(self, d: np.ndarray) -> tuple[np.ndarray, ...]:
        """The end face's normal and the side's, nearest to ``d``."""
        a = self._axis
        along = np.einsum("ij,ij->i", d, a)
        return np.where((along >= 0)[:, None], a, -a), _unit(d - along[:, None] * a)

    def centre(self) -> np.ndarray:
        return 0.5 * (self.c0 + self.c1)

    def reach(self) -> np.ndarray:
        return np.hypot(0.5 * np.linalg.norm(self.c1 - self.c0, axis=1), self.radius)


@dataclass(frozen=True)
class Boxes:
    """N solid axis-aligned boxes [lo, hi] (mm): stock, fixtures, the cradle (in its own frame)."""

    lo: np.ndarray  # (N, 3)
    hi: np.ndarray  # (N, 3)

    def project(self, x: np.ndarray) -> np.ndarray:
        return np.clip(x, self.lo, self.hi)

    def support(self, d: np.ndarray) -> np.ndarray:
        return np.sum(np.where(d >= 0, self.hi, self.lo) * d, axis=1)

    def support_point(self, d: np.ndarray, near: np.ndarray) -> np.ndarray:
        return np.where(d > 0, self.hi, np.where(d < 0, self.lo, np.clip(near, self.lo, self.hi)))

    def normals(self, d: np.ndarray) -> tuple[np.ndarray, ...]:
        """The face normal nearest to ``d``."""
        normal = np.zeros_like(d)
        k = np.argmax(np.abs(d), axis=1)
        normal[np.arange(len(d)), k] = np.sign(d[np.arange(len(d)), k])
        return (normal,)

    def centre(self) -> np.ndarray:
        return 0.5 * (self.lo + self.hi)

    def reach(self) -> np.ndarray:
        return 0.5 * np.linalg.norm(self.hi - self.lo, axis=1)


Convex = Capsules | Cylinders | Boxes


def rows(body: Convex, index: np.ndarray) -> Convex:
    """The bodies ``index`` of a batch."""
    return type(body)(*(getattr(body, name)[index] for name in body.__dataclass_fields__))


def lower_bound(a: Convex, b: Convex, n: np.ndarray) -> np.ndarray:
    """mm: the width of the slab normal to each unit ``n`` (pointing from B to A) that separates
    them; negative where it does not: a lower bound of the distance for any n."""
    return -a.support(-n) - b.support(n)


def best_slab(a: Convex, b: Convex, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """mm, (N,) and (N, 3): the widest separating slab among the unit direction ``n`` (from B to
    A) and the bodies' face normals nearest to it: a lower bound of the distance, and its normal."""
    slabs = np.stack([n, *b.normals(n), *(-m for m in a.normals(-n))], axis=1)  # (N, S, 3)
    widths = np.stack([lower_bound(a, b, slabs[:, s]) for s in range(slabs.shape[1])], axis=1)
    best = np.argmax(widths, axis=1)
    rows_ = np.arange(len(best))
    return widths[rows_, best], slabs[rows_, best]


def capsule_distance(a: Capsules, b: Capsules) -> np.ndarray:
    """mm, (N,): the distance of two capsules in closed form (0 where they meet): their axes'
    closest points, clamped to the segments (Ericson, Real-Time Collision Detection, 5.1.9),
    less both radii."""
    d1, d2, r = a.p1 - a.p0, b.p1 - b.p0, a.p0 - b.p0
    aa, ee = np.einsum("ij,ij->i", d1, d1), np.einsum("ij,ij->i", d2, d2)
    bb, cc, ff = np.einsum("ij,ij->i", d1, d2), np.einsum("ij,ij->i", d1, r), np.einsum("ij,ij->i", d2, r)
    tiny = 1e-12
    safe_a, safe_e = np.where(aa > tiny, aa, 1.0), np.where(ee > tiny, ee, 1.0)
    denom = aa * ee - bb * bb
    s = np.where(denom > tiny * np.maximum(aa * ee, 1.0), np.clip((bb * ff - cc * ee) / np.where(denom > 0, denom, 1.0),
                                                               0.0, 1.0), 0.0)
    s = np.where(aa > tiny, s, 0.0)
    t = np.where(ee > tiny, (bb * s + ff) / safe_e, 0.0)
    # t outside the second segment: clamp it and recompute s for it
    t_clamped = np.clip(t, 0.0, 1.0)
    again = (t != t_clamped) | (ee <= tiny)  # the second segment a point: s for its one point too
    s = np.where(again, np.where(aa > tiny, np.clip((bb * t_clamped - cc) / safe_a, 0.0, 1.0), 0.0), s)
    gap = (a.p0 + s[:, None] * d1) - (b.p0 + t_clamped[:, None] * d2)
    return np.maximum(_norm(gap) - a.radius - b.radius, 0.0)


def quick_bound(a: Convex, b: Convex) -> np.ndarray:
    """mm, (N,): a cheap lower bound of each pair's distance (no iteration): the best slab about
    the direction between the bodies' centres (never less than their bounding spheres' gap)."""
    return np.maximum(best_slab(a, b, _unit(a.centre() - b.centre()))[0], 0.0)


def distance(a: Convex, b: Convex, need: np.ndarray | float = np.inf) -> np.ndarray:
    """mm, (N,): a certified lower bound of the distance between bodies a[i] and b[i], 0 where they
    meet. Pairs are iterated until the bound is within :data:`SETTLED` of the best pair found
    (within :data:`GAP` of 0: they meet), or,
    where ``need`` (mm, per pair) is given, until the bound is at least ``need`` (clear by that
    much: its exact value is not asked for).

    Alternating projections crawl where two faces are nearly parallel (a cutter's end a degree
    off a face: thousands of steps). So each round also tries the bodies' face normals nearest
    to the iterate's direction as slabs, and restarts from A's point furthest along the best
    slab where that pair is closer: a tilted end face's rim point, which is the closest one. Two
    capsules need none of it: their distance is closed-form (:func:`capsule_distance`)."""
    if isinstance(a, Capsules) and isinstance(b, Capsules):
        return capsule_distance(a, b)
    count = len(a.centre())
    need = np.broadcast_to(np.asarray(need, dtype=float), (count,))
    x = a.project(b.project(a.centre()))
    lower = np.full(count, -np.inf)
    open_ = np.arange(count)
    done = 0
    while open_.size and done < MAX_ITERATIONS:
        aa, bb = rows(a, open_), rows(b, open_)
        xo = x[open_]
        for _ in range(FIRST_ITERATIONS if done == 0 else 2 * FIRST_ITERATIONS):
            y = bb.project(xo)
            xo = aa.project(y)
        done += FIRST_ITERATIONS if done == 0 else 2 * FIRST_ITERATIONS
        y = bb.project(xo)
        gap = xo - y
        upper = _norm(gap)
        low, slab = best_slab(aa, bb, _unit(gap))
        jump = aa.support_point(-slab, xo)
        jumped = _norm(jump - bb.project(jump))
        closer = jumped < upper
        xo = np.where(closer[:, None], jump, xo)
        upper = np.minimum(upper, jumped)
        low = np.where(upper > 0, low, 0.0)
        low = np.where(upper <= GAP, 0.0, low)  # within GAP of meeting: 0 is the bound, and it is settled
        lower[open_] = np.maximum(lower[open_], np.minimum(low, upper))
        x[open_] = xo
        settled = ((upper <= GAP) | (lower[open_] >= need[open_])
                   | ((lower[open_] > 0) & (upper - lower[open_] <= SETTLED)))
        open_ = open_[~settled]
    return np.maximum(lower, 0.0)
