"""Motion records: GOTO, FROM, GOHOME, GODLTA, RETRCT, RAPID, MULTAX, TLAXIS (positions in file units, CL frame).

``GOTO/x,y,z[,i,j,k]``: 3 numbers carry the last tool axis (initially (0,0,1)); any other count is
an error because no CAM format we know defines it. ``FROM`` is the tool's starting position,
remembered for ``GOHOME``: a rapid pose once a tool is loaded; before the first tool load (Makino
FF CAM writes it there) it only sets the start, since no tool length could place it.
``GODLTA/d`` moves along the tool axis, ``GODLTA/dx,dy,dz`` by a vector; ``RAPID``
makes the next motion a rapid; ``MULTAX`` (bare, as CATIA and NCL write it) is ``MULTAX/ON``;
``MULTAX/OFF`` forbids 6-number GOTOs and locks the axis as the dialect says (``locked_axis``
in :mod:`.dialects`); ``TLAXIS/i,j,k`` sets the carried axis.

``RETRCT`` withdraws the tool along its axis, at rapid, until the tip is on the clearance surface
of the last ``CLEARP`` or ``CLRSRF`` (ICAM's APT vocabulary, "The RETRCT / CLEARP / CLRSRF
Command"): ``CLEARP/d`` (the plane z = d), ``CLEARP/XYPLAN|YZPLAN|ZXPLAN,d``, ``CLEARP/a,b,c,d`` and
``CLRSRF/a,b,c,d`` (the plane a·x + b·y + c·z = d), ``CLRSRF/[NORMAL,]i,j,k,d`` (NCL's form of the
same plane), ``CLRSRF/x,y,z`` (the plane through the point normal to the tool axis at the
retract); ``NOMORE`` removes it. Until a RETRCT comes these records change nothing, so any other
form (a cylinder, NCL's AVOID or TOOL) is read silently; a RETRCT onto one is refused rather than
skipped, because the move after a skipped retract may run through the part. A tool already at or
beyond the surface along its axis is not moved (ICAM ignores that RETRCT too), with a warning.
"""

from __future__ import annotations

import numpy as np

from verne_post.errors import InputError

from . import curves, cycle_records
from .lexer import Record
from .state import Clearance, ReaderState

Axis = tuple[float, float, float]


def point_axis(st: ReaderState, args: str, what: str, line: int) -> tuple[list[float], Axis]:
    vals = st.numbers(args, what, line)
    if len(vals) not in (3, 6):
        raise st.fail(f"{what} needs 3 or 6 numbers, got {len(vals)}", line)
    st.coordinate(vals[:3], what, line)
    if len(vals) == 6:
        if st.multax is False:
            raise st.fail(f"{what} has a tool axis (6 numbers) but MULTAX/OFF is in effect", line)
        st.check_axis(vals[3:], "tool axis", line)
        return vals[:3], (vals[3], vals[4], vals[5])
    st.carried_axis(what, line)
    return vals, st.axis


def motion_to(st: ReaderState, p: list[float], a: Axis, line: int) -> None:
    """A motion to ``p`` (file units, CL frame): ends a pending arc, runs a drilling cycle, or moves."""
    if st.curve is not None:
        curves.end_curve(st, p, a, line)
    elif st.cycle is not None:
        cycle_records.drill(st, p, a, line)
    else:
        if st.skip_goto is not None:
            repeat = np.allclose(p, st.skip_goto, rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(p).max())))
            st.skip_goto = None
            if repeat and st.axis == a:
                return
        st.axis = a
        st.add_pose(p, a, line, st.take_rapid())


def goto(st: ReaderState, rec: Record) -> None:
    p, a = point_axis(st, rec.args, "GOTO", rec.line)
    if rec.follows_goto and st.curve is None:
        curves.continue_arc(st)  # a point listed after an arc's end GOTO lies on that arc (Creo)
    motion_to(st, p, a, rec.line)


def from_(st: ReaderState, rec: Record) -> None:
    curves.no_pending_curve(st, "FROM", rec.line)
    p, a = point_axis(st, rec.args, "FROM", rec.line)
    st.axis = a
    st.take_rapid()
    if st.tools is not None:
        st.add_pose(p, a, rec.line, rapid=True)
    st.home = (st.frame_id, np.array(p, dtype=float), np.array(a) / np.linalg.norm(a))


def gohome(st: ReaderState, rec: Record) -> None:
    """GOHOME: a rapid to the FROM position; GOHOME/x,y,z[,i,j,k] to that point (NX's GOHOME UDE
    has its own point: NX Post Builder's ``mom_gohome_pos``)."""
    curves.no_pending_curve(st, "GOHOME", rec.line)
    if rec.args.strip():
        p, axis = point_axis(st, rec.args, "GOHOME", rec.line)
    elif st.home is None:  # the machine's home: fine as the program's last motion (Autodesk's posts end so)
        st.warn(rec.line, "GOHOME without a FROM position: the machine's home is not known here, so the program "
                "ends at its last motion before it")
        st.homeless = rec.line
        return
    else:
        frame, tip, home_axis = st.home
        p, a = st.to_current(tip, home_axis, frame)
        axis = (float(a[0]), float(a[1]), float(a[2]))
        st.locked_axis_line = None  # the axis is known again
    st.axis = axis
    st.take_rapid()
    st.add_pose(p, axis, rec.line, rapid=True)


def godlta(st: ReaderState, rec: Record) -> None:
    curves.no_pending_curve(st, "GODLTA", rec.line)
    if st.cycle is not None:
        raise st.fail("GODLTA inside a drilling CYCLE is not supported", rec.line)
    vals = st.numbers(rec.args, "GODLTA", rec.line)
    st.coordinate(vals, "GODLTA", rec.line)
    p, a = st.current_pose("GODLTA", rec.line)
    st.carried_axis("GODLTA", rec.line)
    if len(vals) == 1:
        q = p + vals[0] * a
    elif len(vals) == 3:
        q = p + np.array(vals)
    else:
        raise st.fail(f"GODLTA needs 1 or 3 numbers, got {len(vals)}", rec.line)
    motion_to(st, [float(v) for v in q], st.axis, rec.line)


_PLANE_WORDS = {"XYPLAN": (0.0, 0.0, 1.0), "YZPLAN": (1.0, 0.0, 0.0), "ZXPLAN": (0.0, 1.0, 0.0)}


def clearance(st: ReaderState, rec: Record) -> None:
    """CLEARP / CLRSRF: remember the clearance surface for RETRCT (file units, the current CL frame)."""
    unusable = Clearance(rec.line, st.frame_id)  # any other form: refused only if a RETRCT needs it
    try:
        toks = st.tokens(rec.args, rec.word, rec.line)
        numbers = [t for t in toks if isinstance(t, float)]
        st.coordinate(numbers, rec.word, rec.line)
    except InputError:
        st.clearance = unusable
        return
    words = [t for t in toks if isinstance(t, str)]
    normal: tuple[float, ...] | None = None
    if words == ["NOMORE"] and not numbers:
        st.clearance = None
        return
    if not words and len(numbers) == 3 and rec.word == "CLRSRF":
        st.clearance = Clearance(rec.line, st.frame_id, point=np.array(numbers))
        return
    if not words and len(numbers) == 1 and rec.word == "CLEARP":
        normal, distance = (0.0, 0.0, 1.0), numbers[0]
    elif len(words) == 1 and words[0] in _PLANE_WORDS and len(numbers) == 1 and toks[0] == words[0]:
        normal, distance = _PLANE_WORDS[words[0]], numbers[0]
    elif len(numbers) == 4 and (not words or (words == ["NORMAL"] and toks[0] == "NORMAL")):
        normal, distance = tuple(numbers[:3]), numbers[3]
    length = float(np.linalg.norm(normal)) if normal is not None else 0.0
    if normal is None or length < 1e-9:
        st.clearance = unusable
        return
    st.clearance = Clearance(rec.line, st.frame_id, normal=np.array(normal) / length, distance=distance / length)


def retrct(st: ReaderState, rec: Record) -> None:
    curves.no_pending_curve(st, "RETRCT", rec.line)
    if st.cycle is not None:
        raise st.fail("RETRCT inside a drilling CYCLE is not supported", rec.line)
    surface = st.clearance
    if surface is None:
        raise st.fail("RETRCT without a clearance plane (no CLEARP or CLRSRF before it)", rec.line)
    st.carried_axis("RETRCT", rec.line)
    p, a = st.current_pose("RETRCT", rec.line)
    if surface.point is not None:
        normal, distance = a, float(a @ st.to_current(surface.point, a, surface.frame)[0])
    elif surface.normal is not None:
        origin, normal = st.to_current(surface.distance * surface.normal, surface.normal, surface.frame)
        distance = float(normal @ origin)
    else:
        raise st.fail(f"RETRCT onto the clearance surface of line {surface.line}, a form not supported here "
                      "(a plane or a point is): give the retract as a GOTO", rec.line)
    along = float(normal @ a)
    if abs(along) < 1e-6:
        raise st.fail(f"RETRCT: the tool axis is parallel to the clearance plane of line {surface.line}, "
                      "so no retract along it reaches the plane", rec.line)
    travel = (distance - float(normal @ p)) / along
    st.take_rapid()  # a RAPID before it applies to it: it is a rapid anyway
    if travel <= 0.0:
        st.warn(rec.line, f"RETRCT: the tool is already at or beyond the clearance plane of line {surface.line} "
                "along its axis; no move", kind="RETRCT beyond")
        return
    st.add_pose([float(v) for v in p + travel * a], st.axis, rec.line, rapid=True)


def rapid(st: ReaderState, rec: Record) -> None:
    if rec.args.strip():
        st.warn(rec.line, f"RAPID/{rec.args.strip()[:40]}: arguments ignored", kind="RAPID args")
    st.rapid_next = True


def tlaxis(st: ReaderState, rec: Record) -> None:
    vals = st.numbers(rec.args, "TLAXIS", rec.line)
    if len(vals) != 3:
        raise st.fail(f"TLAXIS needs 3 numbers, got {len(vals)}", rec.line)
    st.check_axis(vals, "tool axis", rec.line)
    st.axis = (vals[0], vals[1], vals[2])
    st.locked_axis_line = None


def multax(st: ReaderState, rec: Record) -> None:
    word = rec.args.strip().upper()
    if word in ("", "ON"):
        st.multax = True
        st.locked_axis_line = None
    elif word == "OFF":
        st.multax = False
        vertical = np.allclose(st.axis, (0.0, 0.0, 1.0), rtol=0.0, atol=1e-9)
        if st.dialect.locked_axis == "z" or (st.dialect.locked_axis is None and vertical):
            st.axis = (0.0, 0.0, 1.0)
        elif st.dialect.locked_axis is None:
            st.locked_axis_line = rec.line
    else:
        raise st.fail(f"MULTAX needs ON or OFF, got '{rec.args.strip()[:40]}'", rec.line)


HANDLERS = {
    "GOTO": goto, "FROM": from_, "GOHOME": gohome, "GODLTA": godlta, "RAPID": rapid, "TLAXIS": tlaxis,
    "MULTAX": multax, "RETRCT": retrct, "CLEARP": clearance, "CLRSRF": clearance,
}  # fmt: skip
