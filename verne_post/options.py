"""What the user chose for one post (mm and degrees, as on the command line).

Its own module because every stage that takes the choices (placement, the checks, the report)
would otherwise import the pipeline that calls it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from .bodies.config import SetupConfig, setup_in_force
from .bodies.setup import Setup, SetupError
from .errors import InputError
from .planning.topp import Engine

if TYPE_CHECKING:
    from .machine import Machine


@dataclass(frozen=True)
class PostOptions:
    """User choices (mm and degrees, as on the command line)."""

    # Part zero in the table frame, mm; None: the machine file's; "auto": found by verne_post.placement.search.
    work_offset: tuple[float, float, float] | Literal["auto"] | None = None
    # with work_offset "auto": also the room around the offset (verne_post.placement.search.place)
    placement_room: bool = False
    tool_length: float | None = None  # mm, for tools whose length nothing else gives
    units: Literal["mm", "inch"] | None = None  # override the CL file's units
    tol: float = 0.005  # mm: tool tip deviation from the CL path between blocks
    axis_tol: float = 0.05  # deg: tool axis deviation from the CL path between blocks
    rapid_tol: float = 0.5  # mm: tool tip deviation from a CL rapid's straight line (never below it)
    rapid_axis_tol: float = 0.5  # deg: tool axis deviation from a CL rapid's interpolated axis
    arc_tol: float = 0.001  # mm: chordal deviation of CIRCLE arcs expanded into CL points
    arc_direction: Literal["cw", "ccw"] | None = None  # override the CL dialect's arc direction
    frame: Literal["local", "world", "apply"] | None = None  # override the CL dialect's frame reading
    feed: float | None = None  # mm/min: the feed of feed moves before the CL file's first FEDRAT
    plan: bool = True  # time-parametrise (TOPP2, ruckig); False: feeds from the programmed feed only
    planner: Engine = "copp"  # TOPP2 engine of the feed moves (planning.topp): copp-py, or toppra the reference
    optimize: bool = False  # also the third-order programme on long feed sequences (verne_post.planning.third_order)
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)  # processes for the feed planning
    stock: tuple[str, ...] = ()  # --stock specs (part frame, CL units; verne_post.bodies.setup)
    fixtures: tuple[str, ...] = ()  # --fixture specs
    setup: SetupConfig | None = None  # --setup FILE, read
    setup_source: str | None = None  # its path (STL paths are relative to its folder)


def work_offset_in_force(machine: Machine, options: PostOptions) -> tuple[float, float, float]:
    """The work offset in force (mm): the option's, else the machine file's."""
    offset = machine.work_offset if options.work_offset is None else options.work_offset
    assert offset != "auto", "postprocess resolves the automatic work offset first"
    return offset


def setup_of(machine: Machine, options: PostOptions, cl_units: str) -> Setup:
    """The stock and fixtures of a post (mm, part frame): ``--stock``/``--fixture``, else
    ``--setup``'s, else the machine file's (:func:`verne_post.bodies.config.setup_in_force`)."""
    base = None if options.setup_source is None else Path(options.setup_source).parent
    try:
        return setup_in_force(cl_units, machine.setup, options.setup, base, options.stock, options.fixtures)
    except SetupError as exc:
        where = ("--stock/--fixture" if options.stock or options.fixtures else options.setup_source
                 or f"{machine.source} setup")
        raise InputError(f"{exc}", where) from None
