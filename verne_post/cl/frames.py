"""Frame records: MSYS, CSYS, ORIGIN, TRNTYP; what they do to the data is the dialect's ``frames``.

``MSYS/x,y,z,xi,xj,xk,yi,yj,yk`` (origin, X axis, Y axis) and ``CSYS/`` (a 3x4 matrix, row-major:
columns X, Y, Z, origin) describe a frame; ``ORIGIN/x,y,z`` one with the same axes as the CAM's
absolute frame, ``ORIGIN/x,y,z,xx,xy,xz,zx,zy,zz`` one with the X and Z axes given (CATIA).
X and Y must be unit and orthogonal within 1e-3 (they are then orthonormalised and Z = X x Y).
In ``world`` dialects the data are already in one frame and these records are read for validity
only; ``TRNTYP`` (SolidWorks CAM's statement of that) is informational.
"""

from __future__ import annotations

import math

import numpy as np

from .lexer import Record
from .state import ReaderState

_ANG_TOL = 1e-3  # tolerance on unit length / orthogonality of MSYS and CSYS axes


def _make_frame(st: ReaderState, o: list[float], x: list[float], y: list[float], z: list[float] | None, what: str,
                line: int) -> None:
    st.coordinate(o, what, line)
    xa, ya = np.array(x, dtype=float), np.array(y, dtype=float)
    nx, ny = float(np.linalg.norm(xa)), float(np.linalg.norm(ya))
    if nx < 1e-9 or ny < 1e-9:
        raise st.fail(f"{what} axis has zero length", line)
    if abs(nx - 1.0) > _ANG_TOL or abs(ny - 1.0) > _ANG_TOL:
        raise st.fail(f"{what} axes are not unit vectors (|X|={nx:.6g}, |Y|={ny:.6g})", line)
    xa, ya = xa / nx, ya / ny
    c = float(xa @ ya)
    if abs(c) > _ANG_TOL:
        deg = math.degrees(math.acos(max(-1.0, min(1.0, c))))
        raise st.fail(f"{what} X and Y axes are not orthogonal ({deg:.4f} deg apart)", line)
    ya = ya - c * xa
    ya /= np.linalg.norm(ya)
    za = np.cross(xa, ya)
    if z is not None:
        zg = np.array(z, dtype=float)
        nz = float(np.linalg.norm(zg))
        if abs(nz - 1.0) > _ANG_TOL or float(za @ zg) / max(nz, 1e-12) < 1.0 - _ANG_TOL:
            raise st.fail(f"{what} matrix is not a right-handed rotation", line)
    if st.dialect.frames == "world":
        return
    frame = (np.column_stack([xa, ya, za]), np.array(o, dtype=float))
    if st.dialect.frames == "local" and not st.frame_declared:
        # The first MCS: poses before it (a FROM, say) were written in it too.
        st.frames[0] = frame
    else:
        st.frames.append(frame)
        st.frame_id = len(st.frames) - 1
    st.frame_declared = True
    st.push_state()


def msys(st: ReaderState, rec: Record) -> None:
    v = st.numbers(rec.args, "MSYS", rec.line)
    if len(v) != 9:
        raise st.fail(f"MSYS needs 9 numbers (origin, X axis, Y axis), got {len(v)}", rec.line)
    _make_frame(st, v[0:3], v[3:6], v[6:9], None, "MSYS", rec.line)


def csys(st: ReaderState, rec: Record) -> None:
    v = st.numbers(rec.args, "CSYS", rec.line)
    if len(v) != 12:
        raise st.fail(f"CSYS needs 12 numbers (3x4 matrix, row-major), got {len(v)}", rec.line)
    m = np.array(v, dtype=float).reshape(3, 4)
    _make_frame(st, list(m[:, 3]), list(m[:, 0]), list(m[:, 1]), list(m[:, 2]), "CSYS", rec.line)


def origin(st: ReaderState, rec: Record) -> None:
    """``ORIGIN/x,y,z`` or, as CATIA documents its NC axis ("APT Format: Syntaxes Interpreted by
    APT Import"), ``ORIGIN/x,y,z,xx,xy,xz,zx,zy,zz``: the origin, X axis and Z axis (Y = Z x X)."""
    v = st.numbers(rec.args, "ORIGIN", rec.line)
    if not st.dialect.origin_is_frame:
        st.warn(rec.line, f"ORIGIN read as {st.dialect.name}'s setup information (where the rotary table sits), "
                "not a frame: the data after it are not moved", kind="ORIGIN")
        return
    if len(v) == 3:
        _make_frame(st, v, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], None, "ORIGIN", rec.line)
    elif len(v) == 9:
        if abs(float(np.dot(v[3:6], v[6:9]))) > _ANG_TOL:
            raise st.fail("ORIGIN X and Z axes are not orthogonal", rec.line)
        y = np.cross(v[6:9], v[3:6])
        _make_frame(st, v[0:3], v[3:6], [float(c) for c in y], v[6:9], "ORIGIN", rec.line)
    else:
        raise st.fail(f"ORIGIN needs 3 numbers (the work origin) or 9 (origin, X axis, Z axis), got {len(v)}",
                      rec.line)


def trntyp(st: ReaderState, rec: Record) -> None:
    words = [t for t in st.tokens(rec.args, "TRNTYP", rec.line) if isinstance(t, str)]
    if words and words[0] != "WORLD":
        st.warn(rec.line, f"TRNTYP/{words[0][:40]}: only TRNTYP/WORLD is known; the data are read as they are")


_ROTARY_AXES = {"AAXIS": 0, "BAXIS": 1, "CAXIS": 2}


def _rotation(axis: int, degrees: float) -> np.ndarray:
    """The right-handed rotation by ``degrees`` about coordinate axis ``axis`` (0 X, 1 Y, 2 Z)."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    j, k = (axis + 1) % 3, (axis + 2) % 3
    r = np.eye(3)
    r[j, j], r[j, k], r[k, j], r[k, k] = c, -s, s, c
    return r


def rotate(st: ReaderState, rec: Record) -> None:
    """``ROTATE/AAXIS|BAXIS|CAXIS[,INCR|ATANGL],angle[,CLW|CCLW]``: a rotary index of the part
    (Pro/ENGINEER writes ``ROTATE / AAXIS, INCR, -36.000000, CCLW`` between subroutine calls, each
    followed by the rotated frame as a ``$$-> CSYS`` comment). The CL data after it are written in
    the frame of the part so turned; they are taken back into the part frame, as the posts of NX,
    Creo and Vericut do with a table index: with the table at angle t (right-handed about the
    axis through the CL origin), a point written at m is the part's point R(-t) m.

    The fields are those of NX's Rotate event (NX Post Builder, ``pblib/ude.cdl``, EVENT rotate: the
    axis Aaxis|Baxis|Caxis, the type Absolute|Incremental, the direction CLW|CCLW and the angle as
    separate parameters). ``ATANGL`` (the default) sets the angle, ``INCR`` adds to it;
    ``CLW``/``CCLW`` say which way round the table turns to get there, which changes where the data
    lie not at all (the move between is a retract, an index and an approach). Any other form is
    refused.
    """
    toks = st.tokens(rec.args, "ROTATE", rec.line)
    words = [t for t in toks if isinstance(t, str)]
    numbers = [t for t in toks if isinstance(t, float)]
    axes = [w for w in words if w in _ROTARY_AXES]
    modes = [w for w in words if w in ("INCR", "ATANGL")]
    unknown = [w for w in words if w not in _ROTARY_AXES and w not in ("INCR", "ATANGL", "CLW", "CCLW")]
    if len(axes) != 1 or len(modes) > 1 or len(numbers) != 1 or unknown or words.count("CLW") + words.count("CCLW") > 1:
        raise st.fail(f"ROTATE/{rec.args.strip()[:40]}: only ROTATE/AAXIS|BAXIS|CAXIS,[INCR|ATANGL],angle,[CLW|CCLW] "
                      "(a rotary index) is documented", rec.line)
    if abs(numbers[0]) > 36000.0:
        raise st.fail(f"ROTATE angle {numbers[0]:g} deg is absurd", rec.line)
    axis = _ROTARY_AXES[axes[0]]
    if st.index is None or st.index[0] != axis:
        if st.index is not None and st.index[2] % 360.0:
            raise st.fail(f"ROTATE about {axes[0]} while the part is indexed about another axis: an index about two "
                          "rotary axes is not supported", rec.line)
        st.index = (axis, st.frame_id, 0.0)
    _axis, base, angle = st.index
    angle = angle + numbers[0] if modes == ["INCR"] else numbers[0]
    st.index = (axis, base, angle)
    R0, o0 = st.frames[base]
    st.frames.append((R0 @ _rotation(axis, -angle), o0))
    st.frame_id = len(st.frames) - 1
    st.frame_declared = True
    st.push_state()


HANDLERS = {"MSYS": msys, "CSYS": csys, "ORIGIN": origin, "TRNTYP": trntyp, "ROTATE": rotate}
