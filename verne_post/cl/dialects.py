"""CAM dialects of APT / CLSF: what each CAM system means by the records they all share.

A dialect is a small table of conventions, found from the file's header and records. The
reader consults it instead of branching on the CAM system.

Conventions
-----------
``arc_direction``: how the motion runs about the ``CIRCLE`` axis (i,j,k):

- ``"cw"``: clockwise about (i,j,k). Siemens NX, CLSF Manager documentation (NX Doc Center >
  Manufacturing > User Defined Operations and CLSF > CLSF Manager, ``CIRCLE``): "x,y,z is the
  center of the curve or helix in MCS. i,j,k is the circle or helix axis vector in the MCS
  (assuming a clockwise direction)". Measured on real files: 1,018 of 1,018 NX arcs entered
  tangentially only under this reading; Makino FF CAM's APT-CL, 25 of 25.
- ``"ccw"``: counter-clockwise (right-hand rule about (i,j,k)): PTC Creo / Pro/CLfile and
  SolidWorks CAM (measured: every tangent arc of the real files).
- ``None``: not documented for this family: decided from the file's own tangent arcs (the
  reader compares the moves into and out of every arc with both readings).

``frames``: what ``MSYS`` / ``CSYS`` / ``ORIGIN`` records mean for the GOTO data after them:

- ``"local"``: the data are in the frame the record describes (NX's MCS; Fusion/HSM's work
  origin); the record only says where that frame sits in the CAM's absolute frame (ICAM's
  post-processor vocabulary calls MSYS "informational"). The work offset places the first
  frame's origin on the table; operations in other frames are transformed into the first one.
- ``"world"``: the data are already in the common frame (SolidWorks CAM writes ``TRNTYP/WORLD``
  and its GOTO tool axes equal the CSYS third column; Creo outputs all CL data in the machine
  coordinate system, PTC Creo help "Machine and NC Sequence Coordinate Systems"): frame
  records are ignored.
- ``"apply"``: the frame record maps the data into the part frame (``tip = origin + R p``); only
  on request (``--frame apply``) for files written that way.

``centre_line``: the CL points are the tool centre (True), tool contact points (False) or
not said (None); cutter compensation records are only acceptable on centre-line data.

``origin_is_frame``: ``ORIGIN/x,y,z`` is a frame record (True), or, in NX, the setup information
of its Origin UDE, "the distance from the origin of the MCS to the center of the rotary table"
(NX Post Builder's MOM variable list, ``mom_origin``), which leaves the GOTO data where they are.

``select_loads``: ``SELECT/TOOL,n`` alone loads tool n (True), or is only the pre-selection of the
next tool, as in NX (Post Builder's ude.cdl: ``SELECT/TOOL`` is the ``tool_preselect`` event,
``LOAD/TOOL`` the tool change).

``cycle_point``: what the GOTO of a cycle in the classic positional form
``CYCLE/DRILL,d,unit,f,c[,RAPTO,r]`` is:

- ``"top"``: the hole top, c the clearance above it (classic APT, as Creo's fixed cycle format
  and Surfcam's generic post describe it);
- ``"bottom"``: the hole bottom, c the clearance plane's height and r its distance down to the
  retract plane: Autodesk's "Common ISO 4343 APT" posts write the cycle point onCyclePoint gets
  (the hole bottom) and ``c = cycle.clearance``, ``r = c - cycle.retract``.

``locked_axis``: the tool axis of the 3-number GOTOs after ``MULTAX/OFF``:

- ``"last"``: the axis of the last position before it. CATIA / DELMIA "APT Format: Syntax of
  APT Instructions", MULTAX: "the tool axis is considered as locked. The components of the
  locked tool axis are the components defined on the last 5-axis position preceding the
  MULTAX/OFF statement" (NCL's APT processor also keeps the axis in effect).
- ``"z"``: (0,0,1) of the current frame: Autodesk's APT post-processors for Fusion / HSM write
  ``MULTAX/OFF`` only for sections whose tool axis is the work plane's Z.
- ``None``: not documented. Where the two readings agree (the axis is (0,0,1) at the
  ``MULTAX/OFF``) that is the axis; otherwise a 3-number GOTO before a ``TLAXIS`` is refused
  rather than guessed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Literal

__all__ = ["DIALECTS", "ArcDirection", "Dialect", "FrameMode", "detect_dialect"]

ArcDirection = Literal["cw", "ccw"]
FrameMode = Literal["local", "world", "apply"]


@dataclass(frozen=True)
class Dialect:
    """Conventions of one CAM family's CL output (see the module docstring)."""

    name: str
    arc_direction: ArcDirection | None
    frames: FrameMode
    centre_line: bool | None = None
    locked_axis: Literal["last", "z"] | None = None
    origin_is_frame: bool = True
    cycle_point: Literal["top", "bottom"] = "top"
    select_loads: bool = True

    def describe(self, resolved: ArcDirection) -> str:
        """One line for the user: the dialect and the conventions applied (``resolved``: the arc direction used)."""
        arcs = {"cw": "clockwise", "ccw": "counter-clockwise"}[resolved]
        how = "" if self.arc_direction else ", from the file's tangent arcs"
        return f"{self.name} (arcs {arcs} about the CIRCLE axis{how}; frames {self.frames})"

    def with_overrides(self, arc_direction: ArcDirection | None, frames: FrameMode | None) -> Dialect:
        return replace(
            self,
            arc_direction=arc_direction or self.arc_direction,
            frames=frames or self.frames,
        )


DIALECTS: dict[str, Dialect] = {
    "nx": Dialect("Siemens NX CLSF", "cw", "local", origin_is_frame=False, select_loads=False),
    "makino": Dialect("Makino FF CAM APT-CL", "cw", "local"),
    "creo": Dialect("PTC Creo / Pro/CLfile", "ccw", "world"),
    "solidworks": Dialect("SolidWorks CAM APT", "ccw", "world"),
    "catia": Dialect("CATIA APT", None, "local", locked_axis="last"),
    "fusion": Dialect("Autodesk Fusion / HSM APT", None, "local", locked_axis="z", cycle_point="bottom"),
    "apt": Dialect("generic APT", None, "local"),
}

# Signatures in the header and records, checked in this order (the first that matches wins).
_SIGNATURES: tuple[tuple[str, re.Pattern[str]], ...] = (
    ("creo", re.compile(r"Pro/CLfile|^\s*\$\$->\s*(?:MFGNO|FEATNO|CUTCOM_GEOMETRY_TYPE)", re.I | re.M)),
    ("makino", re.compile(r"APTCL-SPEC\s*,\s*MAKINO", re.I)),
    ("solidworks", re.compile(r"^\s*(?:CSI_SET_\w*\s*/|TRNTYP\s*/)|SOLIDWORKS|CAMWORKS", re.I | re.M)),
    ("catia", re.compile(r"^\s*\$\$\*?\s*CATIA", re.I | re.M)),
    # Autodesk's ISO 4343 APT posts open with [MACHIN/id,] MODE/MILL|TURN, PARTNO/'name'
    ("fusion", re.compile(r"^\s*MOVARC\s*/|HSMWorks|Autodesk|Fusion 360|"
                          r"^\s*MODE\s*/\s*(?:MILL|TURN)\s*\n\s*PARTNO\s*/\s*'", re.I | re.M)),
    ("nx", re.compile(r"^\s*TOOL PATH\s*/|^\s*\$\$ (?:centerline|contact|tool tip) data|Tool Path Listing has|"
                      r"Information listing created by", re.I | re.M)),
)  # fmt: skip
_CONTACT_RE = re.compile(r"^\s*\$\$.*(?:contact data|OUTPUT_ON_PROFILE)", re.I | re.M)
_CENTRE_RE = re.compile(r"^\s*\$\$.*(?:centerline data|centreline data|OUTPUT_ON_CENTER)", re.I | re.M)


def detect_dialect(text: str) -> Dialect:
    """The dialect whose signature appears in ``text`` (else generic APT), with its centre-line flag."""
    head = text[:200_000]  # headers and first operations; signatures never sit deeper
    dialect = DIALECTS["apt"]
    for key, pattern in _SIGNATURES:
        if pattern.search(head):
            dialect = DIALECTS[key]
            break
    if _CONTACT_RE.search(head):
        return replace(dialect, centre_line=False)
    if _CENTRE_RE.search(head):
        return replace(dialect, centre_line=True)
    return dialect
