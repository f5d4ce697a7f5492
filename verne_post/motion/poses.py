"""Stage 2: CL poses (part frame) -> machine poses (table frame) with tools and sequences.

The work offset puts the part zero in the table frame (mm, same axes). Each pose gets the
length of the tool it is cut with (mm): from the CL file (TLDATA, LOADTL, CUTTER), else from
the machine's tool table, else from ``--tool-length``; a tool with no known length is an
error, never a silent zero. Sequences are the stretches the branch stage keeps continuous:
a new one starts at every rapid, tool change and feed-mode change.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..bodies.setup import NO_SETUP, Setup
from ..cl.toolpath import MIN_FEED, Event, ToolChange, Toolpath
from ..errors import InputError
from ..machine import Machine


@dataclass(frozen=True)
class ToolUse:
    """A loaded tool: number, gauge length and Delta (P to tool tip), mm; where it was loaded."""

    number: int
    length: float
    delta: float
    line: int
    source: str  # "CL file", "machine tool table" or "--tool-length"
    diameter: float | None = None  # mm: the cutter's (CL file, else tool table; None: the machine's default)
    flute_length: float | None = None  # mm (tool table; None: the machine's default)
    holder: tuple[tuple[float, float], ...] | None = None  # (diameter, length) mm from the nose (tool table)


@dataclass(frozen=True)
class MachinePoses:
    """Poses in the table frame, ready for the kinematics. Arrays (N, ...) as in Toolpath."""

    source: str
    part_name: str | None
    tip: np.ndarray  # (N, 3) mm, table frame
    axis: np.ndarray  # (N, 3) unit, table frame
    line: np.ndarray
    rapid: np.ndarray
    feed: np.ndarray  # mm/min (1/min where inverse_time)
    inverse_time: np.ndarray
    tool: np.ndarray
    tool_length: np.ndarray  # (N,) mm
    sequence: np.ndarray  # (N,) int
    events: tuple[Event, ...]
    tools: tuple[ToolUse, ...]  # in load order
    warnings: tuple[str, ...]
    dialect: str = "CSV poses"  # the CL dialect and conventions the reader applied
    notes: tuple[str, ...] = ()  # the reader's choices for the program header (Toolpath.notes)
    setup: Setup = NO_SETUP  # stock and fixtures, mm, table frame (placed at the work offset)

    def shifted(self, offset: np.ndarray) -> MachinePoses:
        """The poses with the part (tips and setup) moved by ``offset`` (mm, table frame)."""
        return replace(self, tip=self.tip + offset, setup=self.setup.shifted(offset))

    def __len__(self) -> int:
        return len(self.tip)

    def part(self, first: int, end: int) -> MachinePoses:
        """Poses ``first`` to ``end - 1`` (views), with their events (index counted from ``first``)."""
        rows = slice(first, end)
        return replace(self, tip=self.tip[rows], axis=self.axis[rows], line=self.line[rows], rapid=self.rapid[rows],
                       feed=self.feed[rows], inverse_time=self.inverse_time[rows], tool=self.tool[rows],
                       tool_length=self.tool_length[rows], sequence=self.sequence[rows],
                       events=tuple(replace(e, index=e.index - first) for e in self.events
                                    if first <= e.index < end))


def _tool_length(machine: Machine, change: ToolChange, fallback: float | None, source: str) -> tuple[float, str]:
    if change.length is not None:
        return change.length, "CL file"
    if change.tool in machine.tools:
        return machine.tools[change.tool].length, "machine tool table"
    if fallback is not None:
        return fallback, "--tool-length"
    raise InputError(f"tool {change.tool} has no length: give it in the CL file (TLDATA/LOADTL), in the "
                     f"machine's tool table, or with --tool-length", source, change.line)




def _numbered(toolpath: Toolpath, number: int | None) -> Toolpath:
    """``toolpath`` with its tool changes without a number (tool 0: tool data alone) given ``number``
    (the machine file's controller.tool_number; None leaves them)."""
    unnumbered = [e.index for e in toolpath.events if isinstance(e, ToolChange) and e.tool == 0]
    if number is None or not unnumbered:
        return toolpath
    tool = toolpath.tool.copy()
    tool[min(unnumbered):][tool[min(unnumbered):] == 0] = number
    events = tuple(replace(e, tool=number) if isinstance(e, ToolChange) and e.tool == 0 else e
                   for e in toolpath.events)
    return replace(toolpath, tool=tool, events=events)


def _tool_use(machine: Machine, number: int, length: float, line: int, source: str,
              diameter: float | None = None) -> ToolUse:
    entry = machine.tools.get(number)
    holder = None if entry is None or entry.holder is None else tuple((h.diameter, h.length) for h in entry.holder)
    return ToolUse(number, length, machine.geometry.spindle_nose + length, line, source,
                   diameter if diameter else None if entry is None else entry.diameter,
                   None if entry is None else entry.flute_length, holder)


def machine_poses(toolpath: Toolpath, machine: Machine, *, work_offset: tuple[float, float, float] | None = None,
                  tool_length: float | None = None, setup: Setup = NO_SETUP) -> MachinePoses:
    """Table-frame poses with tool lengths and continuity sequences (see module docstring);
    ``setup`` in the part frame (mm), placed at the work offset with the tips."""
    toolpath = _numbered(toolpath, machine.controller.tool_number)
    n = len(toolpath)
    offset = np.asarray(machine.work_offset if work_offset is None else work_offset, dtype=float)
    changes = [e for e in toolpath.events if isinstance(e, ToolChange)]
    tools: list[ToolUse] = []
    lengths = np.full(n, np.nan)
    first = changes[0].index if changes else n
    if first > 0:
        if tool_length is None:
            raise InputError("motion before any tool is loaded and no --tool-length given", toolpath.source,
                             int(toolpath.line[0]))
        lengths[:first] = tool_length
        tools.append(_tool_use(machine, 0, tool_length, int(toolpath.line[0]), "--tool-length"))
    overridden = []  # the tools --tool-length was given for but not used: lengths of their own
    for k, change in enumerate(changes):
        length, origin = _tool_length(machine, change, tool_length, toolpath.source)
        end = changes[k + 1].index if k + 1 < len(changes) else n
        lengths[change.index:end] = length
        tools.append(_tool_use(machine, change.tool, length, change.line, origin, change.diameter))
        if tool_length is not None and origin != "--tool-length" and abs(length - tool_length) > 1e-6:
            overridden.append((change, length, origin))
    warnings = toolpath.warnings
    if overridden:
        change, length, origin = overridden[0]
        more = f" (and {len(overridden) - 1} more tool changes)" if len(overridden) > 1 else ""
        warnings += (f"{toolpath.source}:{change.line}: --tool-length {tool_length:g} not used: the {origin} gives "
                     f"tool {change.tool} its length, {length:g} mm (--tool-length serves only tools without one)"
                     f"{more}",)
    missing_feed = ~toolpath.rapid & ~np.isfinite(toolpath.feed)
    missing_feed[0] = False  # the first motion is a positioning move (G0) anyway
    if missing_feed.any():
        k = int(np.argmax(missing_feed))
        raise InputError("feed move without a programmed feed (FEDRAT, or a feed column in a CSV)", toolpath.source,
                         int(toolpath.line[k]))
    too_slow = ~toolpath.rapid & (toolpath.feed < MIN_FEED)
    too_slow[0] = False
    if too_slow.any():
        k = int(np.argmax(too_slow))
        raise InputError(f"feed {toolpath.feed[k]:.3g} per minute is below the slowest usable, {MIN_FEED:g}",
                         toolpath.source, int(toolpath.line[k]))
    boundary = toolpath.rapid.copy()
    boundary[[c.index for c in changes if c.index < n]] = True
    boundary[1:] |= toolpath.inverse_time[1:] != toolpath.inverse_time[:-1]
    boundary[0] = True
    return MachinePoses(
        source=toolpath.source, part_name=toolpath.part_name, tip=toolpath.tip + offset, axis=toolpath.axis,
        line=toolpath.line, rapid=toolpath.rapid, feed=toolpath.feed, inverse_time=toolpath.inverse_time,
        tool=toolpath.tool, tool_length=lengths, sequence=np.cumsum(boundary) - 1, events=toolpath.events,
        tools=tuple(tools), warnings=warnings, dialect=toolpath.dialect, notes=toolpath.notes,
        setup=setup.shifted(offset),
    )
