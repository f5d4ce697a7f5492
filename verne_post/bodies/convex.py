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


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
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
        size = np.linalg.norm(off, axis=1)
        scale = np.minimum(1.0, self.radius / np.where(size > 0, size, 1.0))
        return q + off * scale[:, None]

    def support(self, d: np.ndarray) -> np.ndarray:
        return (np.maximum(np.einsum("ij,ij->i", self.p0, d), np.einsum("ij,ij->i", self.p1, d))
                + self.radius * np.linalg.norm(d, axis=1))

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

    def project(self, x: np.ndarray) -> np.ndarray:
        span = self.c1 - self.c0
        size = np.linalg.norm(span, axis=1)
        a = span / np.where(size > 0, size, 1.0)[:, None]
        rel = x - self.c0
        along = np.einsum("ij,ij->i", rel, a)
        radial = rel - along[:, None] * a
        r = np.linalg.norm(radial, axis=1)
        scale = np.minimum(1.0, self.radius / np.where(r > 0, r, 1.0))
        return self.c0 + np.clip(along, 0.0, size)[:, None] * a + radial * scale[:, None]

    def support(self, d: np.ndarray) -> np.ndarray:
        a = _unit(self.c1 - self.c0)
        along = np.einsum("ij,ij->i", d, a)
        perp = np.linalg.norm(d - along[:, None] * a, axis=1)
        return (np.maximum(np.einsum("ij,ij->i", self.c0, d), np.einsum("ij,ij->i", self.c1, d))
                + self.radius * perp)

    def support_point(self, d: np.ndarray, near: np.ndarray) -> np.ndarray:
        a = _unit(self.c1 - self.c0)
        along = np.einsum("ij,ij->i", d, a)
        end = np.where((along > 0)[:, None], self.c1, self.c0)
        radial = d - along[:, None] * a
        # d along the axis: the whole end face; its point nearest to ``near``
        flat = np.linalg.norm(radial, axis=1) <= 1e-9 * np.linalg.norm(d, axis=1)
        rel = near - end
        rel = rel - np.einsum("ij,ij->i", rel, a)[:, None] * a
        size = np.linalg.norm(rel, axis=1)
        toward = rel * np.minimum(1.0, self.radius / np.where(size > 0, size, 1.0))[:, None]
        return end + np.where(flat[:, None], toward, self.radius[:, None] * _unit(radial))

    def normals(self, d: np.ndarray) -> tuple[np.ndarray, ...]:
        """The end face's normal and the side's, nearest to ``d``."""
        a = _unit(self.c1 - self.c0)
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


def distance(a: Convex, b: Convex, need: np.ndarray | float = np.inf) -> np.ndarray:
    """mm, (N,): a certified lower bound of the distance between bodies a[i] and b[i], 0 where they
    meet. Pairs are iterated until the bound is within :data:`SETTLED` of the best pair found
    (within :data:`GAP` of 0: they meet), or,
    where ``need`` (mm, per pair) is given, until the bound is at least ``need`` (clear by that
    much: its exact value is not asked for).

    Alternating projections crawl where two faces are nearly parallel (a cutter's end a degree
    off a face: thousands of steps). So each round also tries the bodies' face normals nearest
    to the iterate's direction as slabs, and restarts from A's point furthest along the best
    slab where that pair is closer: a tilted end face's rim point, which is the closest one."""
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
        upper = np.linalg.norm(gap, axis=1)
        n = _unit(gap)
        slabs = np.stack([n, *bb.normals(n), *(-m for m in aa.normals(-n))], axis=1)  # (K, S, 3)
        widths = np.stack([lower_bound(aa, bb, slabs[:, s]) for s in range(slabs.shape[1])], axis=1)
        best = np.argmax(widths, axis=1)
        low = widths[np.arange(len(best)), best]
        slab = slabs[np.arange(len(best)), best]
        jump = aa.support_point(-slab, xo)
        jumped = np.linalg.norm(jump - bb.project(jump), axis=1)
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
