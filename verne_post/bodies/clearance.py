"""The clearance of every checked pair of bodies along a joint-space motion, with a sampling bound.

A motion is a chain of block ends (joints mm, rad); the controller runs each block on its
straight joint-space line. For a pair of bodies and a stretch of a block between two samples
s_a and s_b, let m be an upper bound of how far any point of the moving body travels relative
to the other between them. Then at every point of the stretch the clearance d satisfies

    d >= (d(s_a) + d(s_b) - m) / 2

(a point reached after travelling p from s_a is within p of where it was, and within m - p of
where it will be). m is taken as KAPPA times the largest displacement of the body's axis end
points between the samples plus its radius times the turn of its axis (a rigid body of
revolution: every point is an affine mix of the end points plus a radial offset); KAPPA covers
the path's bend between two samples, which bisection makes small. A stretch whose bound is
under the near-miss margin is bisected (forward kinematics at its middle) until the bound
clears the margin, or is no lower than the block's least sampled clearance less RESOLUTION
(branch and bound: it cannot hold a smaller one; a collision found ends the block's search), or
the stretch moves less than RESOLUTION mm; the clearance reported is then the least bound.
Distances are certified lower bounds (:mod:`verne_post.bodies.convex`); far pairs are first
judged by bounding spheres. Units: mm, rad.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .convex import Boxes, Capsules, Convex, Cylinders, distance, quick_bound, rows

#: The path of a body point between two samples is at most this many times the chord.
KAPPA = 1.25
#: mm: a stretch that moves less is not bisected further.
RESOLUTION = 0.05
MAX_LEVELS = 18


@dataclass(frozen=True)
class Samples:
    """The moving bodies at S samples of the motion (see :func:`clear_motion`)."""

    bodies: dict[str, np.ndarray]  # name -> (S, 2, 3) axis end points in the pair's frame
    radius: dict[str, np.ndarray]  # name -> (S,) mm


@dataclass(frozen=True)
class Pair:
    """A checked pair: a moving body (a capsule or cylinder of :class:`Samples`) and a fixed one
    (in the same frame), or two moving capsules. ``active``: (M,) bool per block, where it is
    checked (None: everywhere)."""

    moving: str
    other: str
    kind: type  # Capsules or Cylinders: the moving body
    fixed: Convex | None  # one row; None: ``other`` moves too (capsules)
    active: np.ndarray | None = None


@dataclass(frozen=True)
class Contact:
    """The least clearance of one pair on one block: the bound (mm, 0 where they meet), where."""

    block: int
    fraction: float  # along the block, 0 at its start, 1 at its end
    moving: str
    other: str
    clearance: float


@dataclass(frozen=True)
class ClearanceResult:
    """Every pair's least clearance per block under the margin (``contacts``), and per block the
    least certified clearance over all pairs (mm, capped at ``cap``: far is far)."""

    contacts: tuple[Contact, ...]
    smallest: np.ndarray  # (M,)
    cap: float


def _body(kind: type, ends: np.ndarray, radius: np.ndarray) -> Convex:
    return kind(ends[:, 0], ends[:, 1], radius)


def _norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms of the rows of v (..., 3)."""
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def _motion(ends_a: np.ndarray, ends_b: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """mm: the bound of how far a point of the body moves between two placements (see module)."""
    shift = np.maximum(_norm(ends_b[:, 0] - ends_a[:, 0]), _norm(ends_b[:, 1] - ends_a[:, 1]))

    def direction(ends: np.ndarray) -> np.ndarray:
        span = ends[:, 1] - ends[:, 0]
        size = _norm(span)[:, None]
        return span / np.where(size > 0, size, 1.0)

    turn = _norm(direction(ends_b) - direction(ends_a))
    return KAPPA * (shift + radius * 1.1 * turn)


def clear_motion(joints: np.ndarray, place: Callable[[np.ndarray, np.ndarray, np.ndarray], Samples],
                 tool: np.ndarray, pairs: list[Pair], margin: float, cap: float = 100.0,
                 first_collision: bool = False) -> ClearanceResult:
    """The clearance along the motion through block ends ``joints`` (M, 5) (mm, rad; block k runs
    from end k-1 to end k, block 0 is the positioning before the program and is only sampled at
    its end). ``place(joints, tool, alpha_guess)`` gives the bodies at joint sets (NaN where out of
    reach) with tool ``tool`` (per joint set: an index of the tools' stacks). Pairs in
    ``pairs``; a clearance under ``margin`` (mm) is a contact. With ``first_collision`` it stops
    after the first pair that meets (the motion fails: how else is not asked)."""
    m = len(joints)
    known = np.all(np.isfinite(joints), axis=1)
    ends = place(joints, tool, None)
    smallest = np.full(m, cap)
    contacts: list[Contact] = []
    left, right = np.arange(m - 1), np.arange(1, m)
    usable = known[:-1] & known[1:]
    shapes: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def shape(name: str, kind: type) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A moving body's centres, bounding radii and motion bound per block (each body once)."""
        if name not in shapes:
            body_ends, r = ends.bodies[name], ends.radius[name]
            half = 0.5 * _norm(body_ends[:, 1] - body_ends[:, 0])
            reach = half + r if kind is Capsules else np.hypot(half, r)
            shapes[name] = (0.5 * (body_ends[:, 0] + body_ends[:, 1]), reach,
                            _motion(body_ends[:-1], body_ends[1:], np.maximum(r[:-1], r[1:])))
        return shapes[name]

    for pair in pairs:
        centre_a, reach_a, move = shape(pair.moving, pair.kind)
        if pair.fixed is not None:
            reach_b = pair.fixed.reach()[0]
            centre_b = pair.fixed.centre()[0]
        else:
            centre_b, reach_b, b_move = shape(pair.other, Capsules)
            move = move + b_move
        sphere = np.maximum(_norm(centre_a - centre_b) - reach_a - reach_b, 0.0)
        # the slabs about the centres' direction and the bodies' faces: most pairs settle here
        rows_ = np.flatnonzero(known & (sphere < margin + 1.0))
        if rows_.size:
            sphere[rows_] = np.maximum(sphere[rows_], quick_bound(*_pair_bodies(pair, ends, rows_)))
        sphere = np.where(known, sphere, np.inf)
        active = np.ones(m, bool) if pair.active is None else pair.active
        # block k (ends k-1 -> k) is checked where the pair is active on it; block 0 at its end
        check_end = known & active
        lb = np.where(usable & active[1:], 0.5 * (sphere[:-1] + sphere[1:] - move), np.inf)
        near = np.flatnonzero((lb < margin) | (check_end[1:] & (sphere[1:] < margin)))
        at0 = check_end[0] and sphere[0] < margin
        if not near.size and not at0:
            np.minimum(smallest[1:], np.where(active[1:], np.maximum(lb, 0.0), cap), out=smallest[1:])
            continue
        # exact distances at the ends of the near stretches
        need = np.unique(np.r_[left[near], right[near], [0] if at0 else []]).astype(int)
        need = need[known[need]]
        exact = sphere.copy()
        exact[need] = _distance(pair, ends, need, margin)
        lb = np.where(usable & active[1:], 0.5 * (exact[:-1] + exact[1:] - move), np.inf)
        # a block whose bound clears the margin has at least that bound; the others get their
        # ends' clearances here and the bisection's least bound below
        value = np.where(lb >= margin, np.minimum(lb, exact[1:]), exact[1:])
        np.minimum(smallest[1:], np.where(active[1:], value, cap), out=smallest[1:])
        if at0 and exact[0] < margin:
            smallest[0] = min(smallest[0], exact[0])
            contacts.append(Contact(0, 1.0, pair.moving, pair.other, float(exact[0])))
        open_ = np.flatnonzero(lb < margin)
        if open_.size:
            contacts += _bisect(joints, place, tool, pair, open_, exact, margin, smallest)
        if first_collision and any(c.clearance <= 0.0 for c in contacts):
            break
    return ClearanceResult(tuple(contacts), smallest, cap)


def _pair_bodies(pair: Pair, ends: Samples, index: np.ndarray) -> tuple[Convex, Convex]:
    a = _body(pair.kind, ends.bodies[pair.moving][index], ends.radius[pair.moving][index])
    if pair.fixed is None:
        b = _body(Capsules, ends.bodies[pair.other][index], ends.radius[pair.other][index])
    else:
        b = rows(pair.fixed, np.zeros(len(index), int))
    return a, b


def _distance(pair: Pair, ends: Samples, index: np.ndarray, need: float) -> np.ndarray:
    return distance(*_pair_bodies(pair, ends, index), need + 1.0)


def _bisect(joints: np.ndarray, place: Callable[[np.ndarray, np.ndarray, np.ndarray], Samples], tool: np.ndarray,
            pair: Pair, blocks: np.ndarray, exact: np.ndarray, margin: float, smallest: np.ndarray
            ) -> list[Contact]:
    """Bisect the stretches of ``blocks`` (block k + 1 runs from end k to end k + 1) whose bound is
    under the margin: the least bound per block under the margin, as contacts."""
    q0, q1 = joints[blocks], joints[blocks + 1]
    t0, t1 = np.zeros(len(blocks)), np.ones(len(blocks))
    d0, d1 = exact[blocks], exact[blocks + 1]
    owner = np.arange(len(blocks))
    e0 = place(q0, tool[blocks + 1], None)
    e1 = place(q1, tool[blocks + 1], None)
    a0, a1 = e0.bodies[pair.moving], e1.bodies[pair.moving]
    r = e0.radius[pair.moving]
    b0 = e0.bodies.get(pair.other) if pair.fixed is None else None
    b1 = e1.bodies.get(pair.other) if pair.fixed is None else None
    rb = e0.radius.get(pair.other) if pair.fixed is None else None
    best = np.minimum(d0, d1)  # sampled clearances are true lower bounds where they were taken
    where = np.where(d0 <= d1, 0.0, 1.0)
    for level in range(MAX_LEVELS + 1):
        move = _motion(a0, a1, r) + (0.0 if b0 is None else _motion(b0, b1, rb))
        lb = 0.5 * (d0 + d1 - move)
        # Branch and bound on the block's least clearance: a stretch whose bound is not below the
        # least sampled clearance so far (a collision found: 0) cannot hold a smaller one.
        # A block whose bodies were found to meet (0, the least there is) is settled.
        split = ((lb < margin) & (lb < best[owner] - RESOLUTION) & (best[owner] > 0.0) & (move > RESOLUTION)
                 & (level < MAX_LEVELS))
        stop = np.flatnonzero((lb < margin) & ~split)  # resolved: its bound is the clearance there
        low = np.maximum(lb[stop], 0.0)
        better = low < best[owner[stop]]
        best[owner[stop[better]]] = low[better]
        where[owner[stop[better]]] = 0.5 * (t0[stop[better]] + t1[stop[better]])
        s = np.flatnonzero(split)
        if not s.size:
            break
        tm = 0.5 * (t0[s] + t1[s])
        qm = q0[owner[s]] + tm[:, None] * (q1[owner[s]] - q0[owner[s]])
        em = place(qm, tool[blocks[owner[s]] + 1], None)
        am, ram = em.bodies[pair.moving], em.radius[pair.moving]
        if pair.fixed is None:
            bm, rbm = em.bodies[pair.other], em.radius[pair.other]
            dm = distance(_body(Capsules, am, ram), _body(Capsules, bm, rbm), margin + 1.0)
        else:
            dm = distance(_body(pair.kind, am, ram), rows(pair.fixed, np.zeros(len(s), int)), margin + 1.0)
        dm = np.where(np.isfinite(am).all(axis=(1, 2)), dm, np.inf)
        upd = dm < best[owner[s]]
        best[owner[s][upd]] = dm[upd]
        where[owner[s][upd]] = tm[upd]
        owner = np.r_[owner[s], owner[s]]
        t0, t1 = np.r_[t0[s], tm], np.r_[tm, t1[s]]
        d0, d1 = np.r_[d0[s], dm], np.r_[dm, d1[s]]
        a0, a1 = np.r_[a0[s], am], np.r_[am, a1[s]]
        r = np.r_[r[s], ram]
        if b0 is not None:
            b0, b1 = np.r_[b0[s], bm], np.r_[bm, b1[s]]
            rb = np.r_[rb[s], rbm]
    np.minimum.at(smallest, blocks + 1, best)
    return [Contact(int(blocks[k] + 1), float(where[k]), pair.moving, pair.other, float(best[k]))
            for k in np.flatnonzero(best < margin)]


__all__ = ["Boxes", "ClearanceResult", "Contact", "Cylinders", "Pair", "Samples", "clear_motion"]
