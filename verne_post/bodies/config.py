"""The ``bodies:`` section of a machine file: the sizes of the machine's bodies (mm), validated.

Each body rides on the link that carries it (docs/collision.md): the head (spindle housing,
holder, tool) on the platform's axis, the platform and the rods between the joint centres the
kinematics computes, the guideways on the base, the cradle on the tilt, the table and the setup
(stock, fixtures) on the rotary table. Only sizes live here; where each body is comes from the
kinematics (:mod:`verne_post.bodies.layout`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from .setup import MM_PER_INCH, Setup, SetupBody, SetupError, parse_spec

# As the machine file's other sections: every number finite, unknown keys refused.
_STRICT = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, use_attribute_docstrings=True)
Size = Annotated[float, Field(gt=0, le=1e5)]
Offset = Annotated[float, Field(ge=-1e5, le=1e5)]


class CylinderSize(BaseModel):
    """A cylinder on the spindle axis: diameter and length (mm)."""

    model_config = _STRICT
    diameter: Size
    """mm."""
    length: Size
    """mm, along the spindle axis."""


class BoxSize(BaseModel):
    """An axis-aligned box (mm) in the frame of the link that carries it."""

    model_config = _STRICT
    name: Annotated[str, Field(min_length=1, max_length=60)]
    """Named in collision reports."""
    lo: tuple[Offset, Offset, Offset]
    """mm: the corner of the smallest x, y, z."""
    hi: tuple[Offset, Offset, Offset]
    """mm: the corner of the largest x, y, z."""

    @model_validator(mode="after")
    def _ordered(self) -> BoxSize:
        if not all(a < b for a, b in zip(self.lo, self.hi, strict=True)):
            raise ValueError(f"box '{self.name}': every coordinate of lo must be below hi")
        return self


class Platform(BaseModel):
    """Where the legs meet the platform along its x axis (only the differences D1 - d1 and D2 - d2
    enter the kinematics; the bodies need the absolute values), and its size."""

    model_config = _STRICT
    D1: Offset = 0.0
    """mm: x of leg I's joints on the platform (its slider's joints at D1 - (D1 - d1))."""
    D2: Offset = 0.0
    """mm: x of legs II and III's joints on the platform."""
    diameter: Size = 120.0
    """mm: the platform as a bar along its y axis across its legs' joints, of this diameter."""


class Rods(BaseModel):
    """The legs' rods as capsules between their joint centres."""

    model_config = _STRICT
    leg1_diameter: Size = 30.0
    """mm: each of leg I's two rods."""
    parallelogram_width: Size = 80.0
    """mm: legs II and III (parallelograms) as one capsule of this diameter along their mid-line."""


class Guideways(BaseModel):
    """The three vertical guideways (with their sliders) as capsules beside the slider joints."""

    model_config = _STRICT
    diameter: Size = 100.0
    """mm."""
    outboard: Offset = 150.0
    """mm: the guideway's axis beside its slider's joint, away from the machine's vertical axis
    (base x = y = 0): the joint sits on the carriage's inner face, the rail behind it."""
    top: Offset = -100.0
    """mm, base-frame z (down): the guideways' upper end."""
    bottom: Offset = 1450.0
    """mm, base-frame z (down): the guideways' lower end."""

    @model_validator(mode="after")
    def _ordered(self) -> Guideways:
        if not self.top < self.bottom:
            raise ValueError("guideways: top must be above bottom (base-frame z points down: top < bottom)")
        return self


class Table(BaseModel):
    """The rotary table: a cylinder on the rotary axis, its top face at ``top``."""

    model_config = _STRICT
    diameter: Size = 630.0
    """mm."""
    thickness: Size = 80.0
    """mm, below its top face."""
    top: Offset = -60.0
    """mm, table-frame z of the table's top face (the table frame's origin is dt below the tilt
    axis; the paper does not say where the table's face is)."""


def _default_cradle() -> tuple[BoxSize, ...]:
    return (BoxSize(name="cradle base", lo=(-600.0, -200.0, -180.0), hi=(600.0, 200.0, -80.0)),
            BoxSize(name="cradle left cheek", lo=(-600.0, -200.0, -80.0), hi=(-520.0, 200.0, 200.0)),
            BoxSize(name="cradle right cheek", lo=(520.0, -200.0, -80.0), hi=(600.0, 200.0, 200.0)))


class BodiesConfig(BaseModel):
    """The machine's bodies for the collision checks (mm). ASSUMPTION for the VERNE: the paper
    gives no sizes beyond the kinematic ones; these are in proportion to them."""

    model_config = _STRICT
    check: bool = True
    """Check the bodies for collisions along every block (false: the kinematic checks only)."""
    margin: Annotated[float, Field(ge=0, le=1000)] = 2.0
    """mm: a clearance below this is a near miss (a warning); at or below 0 it is a collision."""
    spindle: CylinderSize = CylinderSize(diameter=170.0, length=350.0)
    """The spindle housing: from the spindle nose up the spindle axis."""
    holder: tuple[CylinderSize, ...] = (CylinderSize(diameter=63.0, length=40.0),
                                        CylinderSize(diameter=40.0, length=30.0))
    """The tool holder of a tool whose tool-table entry gives none: cylinders from the spindle nose
    toward the tip, in that order."""
    cutter_diameter: Size = 10.0
    """mm: of a tool whose diameter neither the CL file nor the tool table gives."""
    flute_length: Size | None = None
    """mm: the cutting part of a tool, from its tip (default: 3 diameters); the rest down to the
    holder is its shank, checked against the stock in cuts too."""
    platform: Platform = Platform()
    rods: Rods = Rods()
    guideways: Guideways = Guideways()
    table: Table = Table()
    cradle: tuple[BoxSize, ...] = Field(default_factory=_default_cradle, max_length=32)
    """Boxes on the tilt (the cradle frame: the table frame at theta2 = 0; the tilt axis is at
    z = dt above the table top)."""


Spec = Annotated[str, Field(min_length=1, max_length=2000)]


class SetupConfig(BaseModel):
    """Stock and fixtures on the table (``setup:`` of a machine file, or a setup YAML given with
    ``--setup``): specs as ``--stock`` and ``--fixture`` take them (:mod:`verne_post.bodies.setup`),
    in the part frame."""

    model_config = _STRICT
    units: Literal["cl", "mm", "inch"] = "cl"
    """The specs' units: the CL file's (as on the command line), or mm or inch whatever it uses."""
    stock: tuple[Spec, ...] = Field(default=(), max_length=64)
    """The stock: what the tool cuts (the cutter meets it only in feeds)."""
    fixtures: tuple[Spec, ...] = Field(default=(), max_length=64)
    """Clamps, vices, pallets: nothing of the tool may meet them."""

    @model_validator(mode="after")
    def _specs_read(self) -> SetupConfig:
        for role, specs in (("stock", self.stock), ("fixture", self.fixtures)):
            for spec in specs:
                if "stl:" in spec.lower():
                    continue  # read where the file is known (relative to the YAML's folder)
                try:
                    parse_spec(spec, role, role)
                except SetupError as exc:
                    raise ValueError(str(exc)) from None
        return self

    def scale(self, cl_units: str) -> float:
        """mm per unit of the specs, for a CL file in ``cl_units`` ("mm" or "inch")."""
        units = cl_units if self.units == "cl" else self.units
        return MM_PER_INCH if units == "inch" else 1.0


def _bodies(specs: tuple[str, ...], role: str, scale: float, base: Path | None) -> list[SetupBody]:
    single = "stock" if role == "stock" else "fixture 1"
    return [parse_spec(s, role, single if len(specs) == 1 else f"{role} {k + 1}", scale, base)  # type: ignore[arg-type]
            for k, s in enumerate(specs)]


def setup_in_force(cl_units: str, machine: SetupConfig, given: SetupConfig | None = None, base: Path | None = None,
                   stock: tuple[str, ...] = (), fixtures: tuple[str, ...] = ()) -> Setup:
    """The setup of a post (mm, part frame): the stock, and the fixtures, each from the first that
    gives any of ``--stock``/``--fixture`` (``stock``, ``fixtures``: CL units), the setup file
    ``given`` (STL paths relative to ``base``) and the machine file's ``setup:``. Raises
    :class:`SetupError`."""
    scale_cl = MM_PER_INCH if cl_units == "inch" else 1.0
    out: list[SetupBody] = []
    for role, flags, field in (("stock", stock, "stock"), ("fixture", fixtures, "fixtures")):
        if flags:
            out += _bodies(flags, role, scale_cl, None)
        elif given is not None and getattr(given, field):
            out += _bodies(getattr(given, field), role, given.scale(cl_units), base)
        elif getattr(machine, field):
            out += _bodies(getattr(machine, field), role, machine.scale(cl_units), None)
    return Setup(tuple(out))
