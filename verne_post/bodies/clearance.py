"""The clearance of every checked pair of bodies along a joint-space motion, with a sampling bound.

A motion is a chain of block ends (joints mm, rad); the controller runs each block on its
straight joint-space line q(t) = q_a + t (q_b - q_a), t in [0, 1]. For a pair of bodies and a
stretch between two samples s_a and s_b, let m bound the SPEED (mm per unit t) of every point of
the moving body relative to the other, everywhere on the stretch. A point is then within m t of
where it was at s_a and within m (1 - t) of where it will be at s_b, so at every t the clearance is

    d(t) >= max(d(s_a) - m t, d(s_b) - m (1 - t)) >= (d(s_a) + d(s_b) - m) / 2.

m is a sum over the joints, never a chord (a chord hides motions that cancel: a slider moving a
point one way while the table turns it back; measured, a chord-based bound was exceeded 2 to 6
times on long stretches). The bodies are rigid bodies of revolution, so take their points without
spin about their axes. With s = |rho_b - rho_a| (mm) and dtheta1, dtheta2 (rad) the stretch's
steps, every point of a body on the platform (the head's bodies, the platform) moves in the base
frame at most

    m_base = (G + A l) s,   G = K_J max ||dP/drho||_F,   A = K_J max |d alpha/drho|,

the norms of the module's Jacobian (:func:`verne_post.kinematics.module_jacobian`) at the two
samples, l the point's distance from the platform's tilt axis (x through P), constant on the
rigid platform. K_J = 1.25 covers the Jacobian between the samples: over 6,000 random stretches
of up to 100 mm its norms never exceeded the larger end's by more than 0.8 % (1.03 at 200 mm);
a stretch of more than MAX_SLIDER_STEP (100 mm) is split before any bound is taken. A rod's
points mix its slider end (speed at most s) and its platform end, plus its radius times the turn
of its axis (at most the ends' speeds over its length). Seen from the table side the base turns:
in the cradle frame add dtheta1 times the point's distance from the cradle axis, in the table
frame also dtheta2 times its distance from the table axis. Those distances are taken at the
samples (the larger), grown by m / 2, the most a point can move away from both samples:
m = (m_base + dtheta1 (c1 + m_base / 2) + dtheta2 c2) / (1 - dtheta2 / 2). A stretch turning
more than MAX_TURN (0.5 rad) is split first, too. :class:`Samples` carries each body's levers
(G + A l, c1, c2) at each sample.

A stretch whose bound is under the near-miss margin is cut into as many equal pieces as its
bound asks for (forward kinematics at the cuts) until the bound clears the margin, or is no
lower than the block's least sampled clearance less RESOLUTION (branch and bound: it cannot hold
a smaller one; a collision found ends the block's search), or the stretch moves less than
RESOLUTION mm; the clearance reported is then the least bound over the block's stretches.
Distances are certified lower bounds (:mod:`verne_post.bodies.convex`).

Most pairs are far on most blocks, so they are first judged a WINDOW of blocks at a time. Every
point of the body swept over a window's blocks lies within R = r + D + M / 2 of the body's axis
at the window's first end: r its largest radius there, D the largest displacement of an axis end
point from that first end over the window's ends (a point of the axis is an affine mix of its end
points), M the largest bound m of a block in it (by the above, a point between two samples is
within m / 2 of where it was at one of them). The window's capsule (the first end's axis, radius
R) is judged against the other body (its own window capsule, or the fixed body) by the certified
bounds; where that clears the margin, it is the clearance of every block of the window. Only the
other windows go through the blocks' ends, spheres first, as above. Units: mm, rad.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .convex import Boxes, Capsules, Convex, Cylinders, distance, quick_bound, rows

#: The module Jacobian's norms between two samples are at most this many times the larger end's.
K_J = 1.25
#: mm, rad: a longer stretch (slider steps' norm, both turns together) is split before a bound is taken.
MAX_SLIDER_STEP = 100.0
MAX_TURN = 0.5
#: A block that would need more stretches is not checked (:class:`MotionTooLongError`): 1 km of slider
#: or 800 turns of the table in one block.
MAX_BLOCK_PIECES = 10_000
#: mm: a stretch whose bound is less is not cut further; rounds of cutting at most.
RESOLUTION = 0.05
MAX_LEVELS = 18
#: A stretch is cut into at most this many pieces at a time.
MAX_PIECES = 64
#: Blocks judged together first (module docstring).
WINDOW = 16


@dataclass(frozen=True)
class Samples:
    """The moving bodies at S samples of the motion (see :func:`clear_motion`)."""

    bodies: dict[str, np.ndarray]  # name -> (S, 2, 3) axis end points in the pair's frame
    radius: dict[str, np.ndarray]  # name -> (S,) mm
    alpha: np.ndarray  # (S,) rad: the platform's tilt, a warm start for samples between them
    #: name -> (S, 3) the body's levers (module docstring): mm of its fastest point's motion per
    #: mm of slider travel (K_J included), and its distances (mm) from the cradle's axis and the
    #: table's, each 0 where the body's frame does not turn with that axis
    levers: dict[str, np.ndarray]


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


def _motion(q_a: np.ndarray, q_b: np.ndarray, levers_a: np.ndarray, levers_b: np.ndarray) -> np.ndarray:
    """mm: the bound m of every point's speed (per unit of the line's parameter) on the stretches
    from joints ``q_a`` to ``q_b`` (N, 5) (mm, rad), the body's levers (N, 3) at both (module
    docstring); inf where the stretch is too long to be bounded (it is split), NaN where an end is
    unknown."""
    step = q_b - q_a
    slider = np.sqrt(np.einsum("ij,ij->i", step[:, :3], step[:, :3]))
    turn1, turn2 = np.abs(step[:, 3]), np.abs(step[:, 4])
    lever = np.maximum(levers_a, levers_b)
    base = lever[:, 0] * slider
    bound = (base + turn1 * np.where(lever[:, 1] > 0, lever[:, 1] + 0.5 * base, 0.0)
             + turn2 * lever[:, 2]) / np.where(lever[:, 2] > 0, 1.0 - 0.5 * turn2, 1.0)
    return np.where((slider <= MAX_SLIDER_STEP) & (turn1 + turn2 <= MAX_TURN), bound, np.inf)


Place = Callable[[np.ndarray, np.ndarray, np.ndarray | None, frozenset[str] | None], Samples]


def clear_motion(joints: np.ndarray, place: Place,
                 tool: np.ndarray, pairs: list[Pair], margin: float, cap: float = 100.0,
                 first_collision: bool = False, alpha_guess: np.ndarray | None = None) -> ClearanceResult:
    """The clearance along the motion through block ends ``joints`` (M, 5) (mm, rad; block k runs
    from end k-1 to end k, block 0 is the positioning before the program and is only sampled at
    its end). ``place(joints, tool, alpha_guess, names)`` gives the bodies (at least ``names``; None:
    all) at joint sets (NaN where out of
    reach) with tool ``tool`` (per joint set: an index of the tools' stacks). Pairs in
    ``pairs``; a clearance under ``margin`` (mm) is a contact. With ``first_collision`` it stops
    after the first pair that meets (the motion fails: how else is not asked). ``alpha_guess`` (M,)
    rad: the platform's tilt at the block ends where known (a warm start of the kinematics).
    Blocks longer than the bound takes (MAX_SLIDER_STEP, MAX_TURN) are first cut into equal
    stretches on their lines, once for every pair."""
    pieces = _pieces(joints)
    if np.any(pieces > 1):
        return _in_pieces(joints, pieces, place, tool, pairs, margin, cap, first_collision, alpha_guess)
    m = len(joints)
    known = np.all(np.isfinite(joints), axis=1)
    moving = frozenset(name for pair in pairs for name in (pair.moving, pair.other if pair.fixed is None else ""))
    ends = place(joints, tool, alpha_guess, moving)
    smallest = np.full(m, cap)
    contacts: list[Contact] = []
    left, right = np.arange(m - 1), np.arange(1, m)
    usable = known[:-1] & known[1:]
    shapes: dict[str, tuple[np.ndarray, Capsules]] = {}
    moves: dict[int, np.ndarray] = {}
    # block k (ends k - 1 -> k) is in window (k - 1) // WINDOW; a window's last end is the next one's first
    windows = max(-(-(m - 1) // WINDOW), 0)

    def shape(name: str) -> tuple[np.ndarray, Capsules]:
        """A moving body's motion bound per block and its capsule per window (each body once)."""
        if name not in shapes:
            body_ends, r, levers = ends.bodies[name], ends.radius[name], ends.levers[name]
            if id(levers) not in moves:  # pieces of one body share its levers
                moves[id(levers)] = _motion(joints[:-1], joints[1:], levers[:-1], levers[1:])
            move = moves[id(levers)]
            shapes[name] = (move, _windows(body_ends, r, move, windows))
        return shapes[name]

    # every pair's windows at once: pairs with a fixed body of one kind, and pairs of moving capsules
    window_clearance: dict[int, np.ndarray] = {}
    for kind in {type(pair.fixed) for pair in pairs}:
        members = [k for k, pair in enumerate(pairs) if type(pair.fixed) is kind]
        moving_windows = _joined([shape(pairs[k].moving)[1] for k in members])
        if kind is type(None):
            found = distance(moving_windows, _joined([shape(pairs[k].other)[1] for k in members]))
        else:
            fixed = _joined([rows(pairs[k].fixed, np.zeros(windows, int)) for k in members])
            found = quick_bound(moving_windows, fixed)
        for k, part in zip(members, np.split(found, len(members)), strict=True):
            window_clearance[k] = part

    for k, pair in enumerate(pairs):
        move = shape(pair.moving)[0] if pair.fixed is not None else shape(pair.moving)[0] + shape(pair.other)[0]
        window = window_clearance[k]
        clear_window = np.isfinite(window) & (window >= margin)  # every block of the window clears
        clear_block = np.repeat(clear_window, WINDOW)[:m - 1]
        # the ends the other windows need (their first and last too)
        judged = np.zeros(m, bool)
        judged[:-1] |= ~clear_block
        judged[1:] |= ~clear_block
        judged[0] |= not windows or not clear_window[0]
        sphere = np.full(m, np.inf)
        rows_ = np.flatnonzero(judged & known)
        sphere[rows_] = _sphere_gap(pair, ends, rows_)
        # the slabs about the centres' direction and the bodies' faces: most pairs settle here
        rows_ = rows_[sphere[rows_] < margin + 1.0]
        if rows_.size:
            sphere[rows_] = np.maximum(sphere[rows_], quick_bound(*_pair_bodies(pair, ends, rows_)))
        active = np.ones(m, bool) if pair.active is None else pair.active
        # block k (ends k-1 -> k) is checked where the pair is active on it; block 0 at its end
        check_end = known & active
        # per block: its window's bound where that clears, else the bound from its ends' clearances
        sampled = usable & active[1:] & ~clear_block
        window_bound = np.where(clear_block & active[1:], np.repeat(window, WINDOW)[:m - 1], np.inf)
        lb = np.where(sampled, 0.5 * (sphere[:-1] + sphere[1:] - move), window_bound)
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
        lb = np.where(sampled, 0.5 * (exact[:-1] + exact[1:] - move), window_bound)
        # a block whose bound clears the margin has at least that bound; the others get their
        # ends' clearances here and the refinement's least bound below
        value = np.where(lb >= margin, np.minimum(lb, exact[1:]), exact[1:])
        np.minimum(smallest[1:], np.where(active[1:], value, cap), out=smallest[1:])
        if at0 and exact[0] < margin:
            smallest[0] = min(smallest[0], exact[0])
            contacts.append(Contact(0, 1.0, pair.moving, pair.other, float(exact[0])))
        open_ = np.flatnonzero(lb < margin)
        if open_.size:
            contacts += _refine(joints, place, tool, pair, open_, exact, margin, smallest, ends.alpha)
        if first_collision and any(c.clearance <= 0.0 for c in contacts):
            break
    return ClearanceResult(tuple(contacts), smallest, cap)


def clear_at(joints: np.ndarray, place: Place, tool: np.ndarray, pairs: list[Pair], margin: float,
             alpha_guess: np.ndarray | None = None) -> np.ndarray:
    """(N,) mm: the least clearance over ``pairs`` of the bodies standing still at joint sets
    ``joints`` (N, 5) (mm, rad; inf where unknown or out of reach) with tools ``tool`` (N,), a
    pair's ``active`` per joint set. Exact (a certified lower bound) where under ``margin``, else
    at least ``margin``.
    No motion between them: a screen (placement's room), not a check of the blocks."""
    known = np.all(np.isfinite(joints), axis=1)
    moving = frozenset(name for pair in pairs for name in (pair.moving, pair.other if pair.fixed is None else ""))
    ends = place(joints, tool, alpha_guess, moving)
    least = np.full(len(joints), np.inf)
    for pair in pairs:
        index = np.flatnonzero(known if pair.active is None else known & pair.active)
        if not index.size:
            continue
        found = _sphere_gap(pair, ends, index)
        near = found < margin + 1.0
        if near.any():
            found[near] = np.maximum(found[near], quick_bound(*_pair_bodies(pair, ends, index[near])))
        near = found < margin
        if near.any():
            found[near] = _distance(pair, ends, index[near], margin)
        np.minimum.at(least, index, np.nan_to_num(found, nan=np.inf))  # NaN: the module's FK found no pose
    return least


class MotionTooLongError(ValueError):
    """A block moves too far for its bodies to be checked along it (an endless table turned
    hundreds of times in one block): ``block`` its index; the message says how far, in mm and
    degrees."""

    def __init__(self, block: int, slider: float, turn: float) -> None:
        super().__init__(f"the block moves the sliders {slider:.0f} mm and turns the table {np.degrees(turn):.0f} deg: "
                         f"too far to check the bodies along it (at most {MAX_BLOCK_PIECES * MAX_SLIDER_STEP:.0f} mm "
                         f"or {np.degrees(MAX_BLOCK_PIECES * MAX_TURN):.0f} deg a block); split the move")
        self.block = block


def _pieces(joints: np.ndarray) -> np.ndarray:
    """(M,) the equal stretches each block is cut into so that none is too long for the bound
    (block 0, the positioning, and blocks with an unknown end: 1). Raises :class:`MotionTooLongError`
    for a block that would need more than MAX_BLOCK_PIECES."""
    step = np.abs(np.diff(joints, axis=0))
    need = np.maximum(np.sqrt(np.einsum("ij,ij->i", step[:, :3], step[:, :3])) / MAX_SLIDER_STEP,
                      (step[:, 3] + step[:, 4]) / MAX_TURN)
    with np.errstate(invalid="ignore"):
        count = np.where(np.isfinite(need) & (need > 1.0), np.ceil(need * (1.0 + 1e-9)), 1.0)
    if np.any(count > MAX_BLOCK_PIECES):
        worst = int(np.argmax(count))
        raise MotionTooLongError(worst + 1, float(np.linalg.norm(step[worst, :3])),
                                 float(step[worst, 3] + step[worst, 4]))
    return np.r_[1, count].astype(int)


def _in_pieces(joints: np.ndarray, pieces: np.ndarray, place: Place, tool: np.ndarray, pairs: list[Pair],
               margin: float, cap: float, first_collision: bool, alpha_guess: np.ndarray | None) -> ClearanceResult:
    """:func:`clear_motion` with block k cut into ``pieces[k]`` equal stretches, and its results
    told per block again (a block's least clearance over its stretches)."""
    owner = np.repeat(np.arange(len(joints)), pieces)  # the block of each stretch
    first = np.cumsum(pieces) - pieces
    share = (np.arange(len(owner)) - first[owner] + 1) / pieces[owner]  # along its block, 1 at its end
    start = joints[np.maximum(owner - 1, 0)]
    refined = np.where((share == 1.0)[:, None], joints[owner], start + share[:, None] * (joints[owner] - start))
    guess = None
    if alpha_guess is not None:
        a = np.nan_to_num(alpha_guess)
        guess = a[np.maximum(owner - 1, 0)] + share * (a[owner] - a[np.maximum(owner - 1, 0)])
    split = [Pair(p.moving, p.other, p.kind, p.fixed, None if p.active is None else p.active[owner]) for p in pairs]
    found = clear_motion(refined, place, tool[owner], split, margin, cap, first_collision, guess)
    smallest = np.full(len(joints), cap)
    np.minimum.at(smallest, owner, found.smallest)
    contacts = tuple(Contact(int(owner[c.block]), float((share[c.block] * pieces[owner[c.block]] - 1 + c.fraction)
                                                         / pieces[owner[c.block]]), c.moving, c.other, c.clearance)
                     for c in found.contacts)
    return ClearanceResult(contacts, smallest, cap)


def _joined(bodies: list[Convex]) -> Convex:
    """Bodies of one kind, the rows of each after the other's."""
    first = bodies[0]
    return type(first)(*(np.concatenate([getattr(b, name) for b in bodies]) for name in first.__dataclass_fields__))


def _windows(body_ends: np.ndarray, radius: np.ndarray, move: np.ndarray, count: int) -> Capsules:
    """Per window of :data:`WINDOW` blocks (``count`` of them, from the first end), a capsule holding
    the body (axis end points ``body_ends`` (M, 2, 3) mm, ``radius`` (M,) mm, motion bound ``move``
    (M - 1,) mm per block) over every block of the window (module docstring); NaN radius where an
    end is unknown."""
    m = len(body_ends)
    # every window's ends, the next window's first included; past the last end, the last again
    padded_ends = np.concatenate([body_ends, np.repeat(body_ends[-1:], count * WINDOW + 1 - m, axis=0)])
    start = padded_ends[:-1:WINDOW]  # (count, 2, 3)
    step = padded_ends[:-1].reshape(count, WINDOW, 2, 3) - start[:, None]
    last = padded_ends[WINDOW::WINDOW] - start
    shift = np.sqrt(np.maximum(np.einsum("wkei,wkei->wke", step, step).max(axis=(1, 2)),
                               np.einsum("wei,wei->we", last, last).max(axis=1)))
    padded_r = np.r_[radius, np.repeat(radius[-1:], count * WINDOW + 1 - m)]
    widest = np.maximum(padded_r[:-1].reshape(count, WINDOW).max(axis=1), padded_r[WINDOW::WINDOW])
    padded_move = np.r_[move, np.zeros(count * WINDOW - len(move))].reshape(count, WINDOW)
    return Capsules(start[:, 0], start[:, 1], widest + shift + 0.5 * padded_move.max(axis=1))


def _sphere_of(ends: Samples, name: str, kind: type, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A moving body's centres and bounding radii at the samples ``index``."""
    body_ends, r = ends.bodies[name][index], ends.radius[name][index]
    half = 0.5 * _norm(body_ends[:, 1] - body_ends[:, 0])
    return 0.5 * (body_ends[:, 0] + body_ends[:, 1]), (half + r if kind is Capsules else np.hypot(half, r))


def _sphere_gap(pair: Pair, ends: Samples, index: np.ndarray) -> np.ndarray:
    """(len(index),) mm: the gap between the pair's bounding spheres at the samples ``index`` (a
    lower bound of their clearance)."""
    centre_a, reach_a = _sphere_of(ends, pair.moving, pair.kind, index)
    if pair.fixed is not None:
        centre_b, reach_b = pair.fixed.centre()[0], pair.fixed.reach()[0]
    else:
        centre_b, reach_b = _sphere_of(ends, pair.other, Capsules, index)
    return np.maximum(_norm(centre_a - centre_b) - reach_a - reach_b, 0.0)


def _pair_bodies(pair: Pair, ends: Samples, index: np.ndarray) -> tuple[Convex, Convex]:
    a = _body(pair.kind, ends.bodies[pair.moving][index], ends.radius[pair.moving][index])
    if pair.fixed is None:
        b = _body(Capsules, ends.bodies[pair.other][index], ends.radius[pair.other][index])
    else:
        b = rows(pair.fixed, np.zeros(len(index), int))
    return a, b


def _distance(pair: Pair, ends: Samples, index: np.ndarray, need: float) -> np.ndarray:
    return distance(*_pair_bodies(pair, ends, index), need + 1.0)


def _refine(joints: np.ndarray, place: Place, tool: np.ndarray,
            pair: Pair, blocks: np.ndarray, exact: np.ndarray, margin: float, smallest: np.ndarray,
            alpha: np.ndarray) -> list[Contact]:
    """Split the stretches of ``blocks`` (block k + 1 runs from end k to end k + 1) whose bound is
    under the margin until it clears (module docstring): the least bound per block under the
    margin, as contacts. A stretch is cut into as many equal pieces as its bound asks for (m over
    n pieces against its ends' room above the margin; at most MAX_PIECES, at least two), not
    halved level by level. ``alpha`` (M,) rad: the platform's tilt at the block ends (the samples'
    warm start)."""
    q0, q1 = joints[blocks], joints[blocks + 1]
    alpha0, alpha1 = np.nan_to_num(alpha[blocks]), np.nan_to_num(alpha[blocks + 1])
    moving = [pair.moving] if pair.fixed is not None else [pair.moving, pair.other]
    names = frozenset(moving)
    t0, t1 = np.zeros(len(blocks)), np.ones(len(blocks))
    d0, d1 = exact[blocks], exact[blocks + 1]
    owner = np.arange(len(blocks))
    e0 = place(q0, tool[blocks + 1], alpha0, names)
    e1 = place(q1, tool[blocks + 1], alpha1, names)
    qa, qb = q0, q1  # each stretch's joints at its two samples
    lever_a = {name: e0.levers[name] for name in moving}
    lever_b = {name: e1.levers[name] for name in moving}
    best = np.minimum(d0, d1)  # sampled clearances are true lower bounds where they were taken
    where = np.where(d0 <= d1, 0.0, 1.0)
    for level in range(MAX_LEVELS + 1):
        move = sum(_motion(qa, qb, lever_a[name], lever_b[name]) for name in moving)
        lb = 0.5 * (d0 + d1 - move)
        # Branch and bound on the block's least clearance: a stretch whose bound is not below the
        # least sampled clearance so far (a collision found: 0) cannot hold a smaller one; but a
        # bound at 0 is no collision while the samples are clear, so it is cut on to RESOLUTION.
        # A block whose bodies were found to meet (0, the least there is) is settled.
        split = ((lb < margin) & ((lb < best[owner] - RESOLUTION) | (lb <= 0.0)) & (best[owner] > 0.0)
                 & (move > RESOLUTION) & (level < MAX_LEVELS))
        stop = np.flatnonzero(~split)  # resolved: its bound is the least clearance there
        low = np.maximum(np.nan_to_num(lb[stop], nan=np.inf), 0.0)
        better = low < best[owner[stop]]
        best[owner[stop[better]]] = low[better]
        where[owner[stop[better]]] = 0.5 * (t0[stop[better]] + t1[stop[better]])
        s = np.flatnonzero(split)
        if not s.size:
            break
        # n pieces of m / n each clear the margin if the ends' clearances hold along the stretch
        room = d0[s] + d1[s] - 2.0 * margin
        with np.errstate(divide="ignore", invalid="ignore"):
            wanted = np.where(room > 0.0, np.ceil(move[s] / room), 2.0)
        pieces = np.clip(np.nan_to_num(wanted, nan=2.0, posinf=MAX_PIECES), 2, MAX_PIECES).astype(int)
        parent = np.repeat(s, pieces - 1)  # a new sample inside stretch s, at share j / n of it
        j = np.arange(len(parent)) - np.repeat(np.cumsum(pieces - 1) - (pieces - 1), pieces - 1) + 1
        tm = t0[parent] + (t1[parent] - t0[parent]) * j / np.repeat(pieces, pieces - 1)
        block = owner[parent]
        qm = q0[block] + tm[:, None] * (q1[block] - q0[block])
        em = place(qm, tool[blocks[block] + 1], alpha0[block] + tm * (alpha1[block] - alpha0[block]), names)
        am, ram = em.bodies[pair.moving], em.radius[pair.moving]
        if pair.fixed is None:
            bm, rbm = em.bodies[pair.other], em.radius[pair.other]
            dm = distance(_body(Capsules, am, ram), _body(Capsules, bm, rbm), margin + 1.0)
        else:
            dm = distance(_body(pair.kind, am, ram), rows(pair.fixed, np.zeros(len(parent), int)), margin + 1.0)
        dm = np.where(np.isfinite(am).all(axis=(1, 2)), dm, np.inf)
        lowest = np.full(len(blocks), np.inf)
        np.minimum.at(lowest, block, dm)
        found = np.flatnonzero(lowest < best)
        best[found] = lowest[found]
        first = dm == lowest[block]
        where[block[first]] = tm[first]  # a block's least sample (ties: the last)
        # the pieces of each split stretch: from its start through its new samples to its end
        starts = np.cumsum(pieces) - pieces  # each split stretch's first piece among the new ones
        inner = np.arange(len(parent)) + np.repeat(np.arange(len(s)), pieces - 1) + 1  # new samples' pieces
        count = int(pieces.sum())
        new_t0, new_t1, new_d0, new_d1 = (np.empty(count) for _ in range(4))
        new_qa, new_qb = np.empty((count, 5)), np.empty((count, 5))
        new_la = {name: np.empty((count, 3)) for name in moving}
        new_lb = {name: np.empty((count, 3)) for name in moving}
        last = starts + pieces - 1
        new_t0[starts], new_d0[starts], new_qa[starts] = t0[s], d0[s], qa[s]
        new_t1[last], new_d1[last], new_qb[last] = t1[s], d1[s], qb[s]
        new_t0[inner], new_d0[inner], new_qa[inner] = tm, dm, qm
        new_t1[inner - 1], new_d1[inner - 1], new_qb[inner - 1] = tm, dm, qm
        for name in moving:
            new_la[name][starts], new_lb[name][last] = lever_a[name][s], lever_b[name][s]
            new_la[name][inner], new_lb[name][inner - 1] = em.levers[name], em.levers[name]
        owner = np.repeat(owner[s], pieces)
        t0, t1, d0, d1, qa, qb, lever_a, lever_b = new_t0, new_t1, new_d0, new_d1, new_qa, new_qb, new_la, new_lb
    np.minimum.at(smallest, blocks + 1, best)
    return [Contact(int(blocks[k] + 1), float(where[k]), pair.moving, pair.other, float(best[k]))
            for k in np.flatnonzero(best < margin)]


__all__ = ["Boxes", "ClearanceResult", "Contact", "Cylinders", "MotionTooLongError", "Pair", "Samples", "clear_motion"]
