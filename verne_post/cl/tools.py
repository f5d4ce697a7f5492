"""Tool records: LOAD, LOADTL, SELECT, TLDATA, CUTTER and TOOL PATH (lengths in file units).

``LOAD/TOOL,n[,ADJUST,h]``, ``LOADTL/n[,LENGTH,l][,ADJUST|OSETNO,h][,IN,p]`` and ``SELECT/TOOL,n``
(a load only when the operation header has no LOAD/LOADTL, otherwise a pre-selection; in NX
always the pre-selection, its tool_preselect event, NX's load being LOAD/TOOL) give one
:class:`~verne_post.toolpath.ToolChange` per load. ``TLDATA/MILL|DRILL,dia,r,length,...`` and
``CUTTER/dia[,...]`` in the same header (the records between two motions) are merged into that
load, before or after it. Without any load in the header they produce a ToolChange for the
current tool number (0 if none was ever loaded, with a warning) when the geometry differs from
the active one. A tool change ends an active drilling cycle (CAM systems that leave it active
into the next operation never mean the next tool to drill the same way).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from verne_post.toolpath import Comment, ToolChange

from .lexer import Record
from .state import MAX_COORD, MAX_TOOL_NUMBER, ReaderState, Token


@dataclass
class ToolHeader:
    """Tool loads and tool data seen since the last motion (the current operation's header)."""

    open: bool = False
    loads: list[dict[str, Any]] = field(default_factory=list)
    geoms: list[dict[str, Any]] = field(default_factory=list)
    select: dict[str, Any] | None = None
    active_geom: tuple[float | None, float | None] | None = None

    @staticmethod
    def _compatible(target: dict[str, Any], geom: dict[str, Any]) -> bool:
        return all(target[k] is None or geom[k] is None for k in ("length", "diameter"))

    @staticmethod
    def _merge(target: dict[str, Any], geom: dict[str, Any]) -> None:
        for k in ("length", "diameter"):
            if geom[k] is not None:
                target[k] = geom[k]

    def attach_geom(self, st: ReaderState, length: float | None, diameter: float | None, line: int) -> None:
        self.open = True
        geom = {"length": length, "diameter": diameter, "line": line}
        if self.loads and self._compatible(self.loads[-1], geom):
            self._merge(self.loads[-1], geom)
            return
        geom["slot"] = _slot(st)
        self.geoms.append(geom)

    def new_load(self, st: ReaderState, tool: int, adjust: int | None, length: float | None, line: int,
                 slot: int | None = None) -> None:
        self.open = True
        load: dict[str, Any] = {"slot": _slot(st) if slot is None else slot, "line": line, "tool": tool,
                                "length": length, "diameter": None, "adjust": adjust}
        for geom in list(self.geoms):
            if self._compatible(load, geom):
                self._merge(load, geom)
                self.geoms.remove(geom)
        self.loads.append(load)

    def close(self, st: ReaderState) -> None:
        """At the first motion after the header: turn loads and tool data into ToolChange events."""
        index = len(st.lines)
        if self.select is not None and not self.loads:
            sel = self.select
            self.new_load(st, sel["tool"], None, None, sel["line"], slot=sel["slot"])
        for load in self.loads:
            st.events[load["slot"]] = ToolChange(index=index, line=load["line"], tool=load["tool"],
                                                 length=load["length"], diameter=load["diameter"],
                                                 adjust=load["adjust"])
            st.tool = load["tool"]
            self.active_geom = (load["length"], load["diameter"])
        if self.geoms:
            first = self.geoms[0]
            if self.loads:
                for geom in self.geoms:
                    st.warn(geom["line"], "tool data does not fit the tool load of this operation; ignored")
            else:
                merged: dict[str, Any] = {"length": None, "diameter": None}
                for geom in self.geoms:
                    self._merge(merged, geom)
                if self.active_geom != (merged["length"], merged["diameter"]):
                    if st.tool == 0:
                        st.warn(first["line"], "tool data without a tool load (LOAD/TOOL, LOADTL, SELECT/TOOL): "
                                "ToolChange with tool number 0 carries it")
                    st.events[first["slot"]] = ToolChange(index=index, line=first["line"], tool=st.tool,
                                                          length=merged["length"], diameter=merged["diameter"])
                    self.active_geom = (merged["length"], merged["diameter"])
        self.loads, self.geoms, self.select, self.open = [], [], None, False
        st.push_state()


def _slot(st: ReaderState) -> int:
    st.events.append(None)
    return len(st.events) - 1


def _header(st: ReaderState) -> ToolHeader:
    if st.tools is None:
        st.tools = ToolHeader()
    return st.tools


def _tool_number(st: ReaderState, v: float, line: int) -> int:
    if v != int(v) or not 0 <= v <= MAX_TOOL_NUMBER:
        raise st.fail(f"tool number must be a whole number from 0 to {MAX_TOOL_NUMBER}, got {v:g}", line)
    return int(v)


MAX_TOOL_LENGTH = 2000.0  # mm, as for --tool-length and the machine's tool table


def _length(st: ReaderState, v: float, what: str, line: int) -> float:
    if not 0 < v * st.scale <= MAX_TOOL_LENGTH:
        raise st.fail(f"{what}: tool length must be positive and at most {MAX_TOOL_LENGTH:g} mm, got {v:g}", line)
    return v * st.scale


def _keywords(st: ReaderState, toks: list[Token], start: int, what: str, line: int) -> dict[str, float]:
    """Keyword/value pairs after position ``start`` (ADJUST/OSETNO,h, LENGTH,l, IN,p); stray numbers ignored."""
    out: dict[str, float] = {}
    i = start
    while i < len(toks):
        t = toks[i]
        if isinstance(t, str):
            if i + 1 >= len(toks) or not isinstance(toks[i + 1], float):
                raise st.fail(f"{what}: {t} needs a number", line)
            if t in ("ADJUST", "OSETNO", "LENGTH"):
                out["ADJUST" if t == "OSETNO" else t] = float(toks[i + 1])  # type: ignore[arg-type]
            elif t != "IN":  # IN,p: the magazine pocket, nothing the program needs
                st.warn(line, f"{what}: {t} ignored", kind=f"{what} {t}")
            i += 2
        else:
            i += 1
    return out


def _load_with(st: ReaderState, tool: float, kw: dict[str, float], what: str, line: int) -> None:
    adjust = _tool_number(st, kw["ADJUST"], line) if "ADJUST" in kw else None
    length = _length(st, kw["LENGTH"], what, line) if "LENGTH" in kw else None
    _header(st).new_load(st, _tool_number(st, tool, line), adjust, length, line)
    st.cycle = None
    bad = st.malformed.pop("SPINDL", None)
    if bad is not None:  # the tool change stops the spindle (M6) before any motion: the record ran for no cut
        st.warn(bad[0], f"{bad[1]} is malformed ({bad[2].reason}); the tool change at line {line} stops the spindle "
                "before any motion: ignored")


def load(st: ReaderState, rec: Record) -> None:
    toks = st.tokens(rec.args, "LOAD", rec.line)
    if len(toks) < 2 or toks[0] != "TOOL" or not isinstance(toks[1], float):
        raise st.fail("LOAD needs the form LOAD/TOOL,n[,ADJUST,h]", rec.line)
    _load_with(st, toks[1], _keywords(st, toks, 2, "LOAD/TOOL", rec.line), "LOAD/TOOL", rec.line)


def loadtl(st: ReaderState, rec: Record) -> None:
    toks = st.tokens(rec.args, "LOADTL", rec.line)
    if not toks or not isinstance(toks[0], float):
        raise st.fail("LOADTL needs a tool number", rec.line)
    _load_with(st, toks[0], _keywords(st, toks, 1, "LOADTL", rec.line), "LOADTL", rec.line)


def select(st: ReaderState, rec: Record) -> None:
    toks = st.tokens(rec.args, "SELECT", rec.line)
    if len(toks) < 2 or toks[0] != "TOOL" or not isinstance(toks[1], float):
        st.warn(rec.line, f"SELECT/{rec.args.strip()[:40]}: only SELECT/TOOL,n is understood; ignored")
        return
    tool = _tool_number(st, toks[1], rec.line)
    if not st.dialect.select_loads:
        return  # NX: SELECT/TOOL is its tool pre-select event (Post Builder's ude.cdl, tool_preselect)
    header = _header(st)
    header.open = True
    if header.select is None and not header.loads:
        header.select = {"tool": tool, "line": rec.line, "slot": _slot(st)}
    # otherwise a pre-selection of the next tool: no load


def tldata(st: ReaderState, rec: Record) -> None:
    toks = st.tokens(rec.args, "TLDATA", rec.line)
    kind = toks[0] if toks and isinstance(toks[0], str) else None
    nums = [t for t in toks if isinstance(t, float)]
    if kind not in ("MILL", "DRILL"):
        st.warn(rec.line, f"TLDATA/{kind or '?'}: tool type not supported, tool data ignored")
        return
    if len(nums) < 3:
        raise st.fail(f"TLDATA/{kind} needs at least 3 numbers (diameter, radius, length), got {len(nums)}",
                      rec.line)
    dia, length = nums[0], nums[2]
    if not 0 <= dia <= MAX_COORD:
        raise st.fail(f"TLDATA/{kind}: diameter must be from 0 to {MAX_COORD:g}, got {dia:g}", rec.line)
    if length < 0:
        raise st.fail(f"TLDATA/{kind}: tool length must not be negative, got {length:g}", rec.line)
    if length == 0:
        st.warn(rec.line, f"TLDATA/{kind}: tool length 0: length unknown")
    tool_length = _length(st, length, f"TLDATA/{kind}", rec.line) if length > 0 else None
    _header(st).attach_geom(st, tool_length, dia * st.scale, rec.line)


def cutter(st: ReaderState, rec: Record) -> None:
    nums = st.numbers(rec.args, "CUTTER", rec.line)
    if not nums:
        raise st.fail("CUTTER needs a diameter", rec.line)
    if not 0 <= nums[0] <= MAX_COORD:
        raise st.fail(f"CUTTER diameter must be from 0 to {MAX_COORD:g}, got {nums[0]:g}", rec.line)
    _header(st).attach_geom(st, None, nums[0] * st.scale, rec.line)


def toolpath_name(st: ReaderState, rec: Record) -> None:
    """NX's ``TOOL PATH/name,TOOL,tool``: a new operation, which NX posts as a path of its own
    (MOM_start_of_path): a drilling cycle left on by the one before does not carry into it."""
    st.cycle = None
    fields = [f.strip() for f in rec.args.split(",")]
    name = fields[0] if fields and fields[0] else "?"
    text = name
    if len(fields) >= 3 and fields[1].upper() == "TOOL" and fields[2]:
        text = f"{name} (tool {fields[2]})"
    st.events.append(Comment(index=len(st.lines), line=rec.line, text=text))


HANDLERS = {
    "LOAD": load, "LOADTL": loadtl, "SELECT": select, "TLDATA": tldata, "CUTTER": cutter,
    "TOOL PATH": toolpath_name,
}  # fmt: skip
