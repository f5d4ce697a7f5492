"""The setup on the table: stock and fixtures as bodies, from ``--stock`` / ``--fixture`` specs,
a setup YAML (``--setup``) or the machine file's ``setup:`` section.

A spec is ``[NAME=]box:x0,y0,z0,x1,y1,z1`` (two opposite corners), ``cylinder:cx,cy,z0,z1,r`` (axis
along z) or ``stl:PATH``, in the part frame (the CL file's), in the CL file's units. An STL body
is checked as its bounding box (conservative: never closer than the mesh). Bodies are given in
mm in the part frame here; the checks place them at the work offset in the table frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np

from .convex import Boxes, Convex, Cylinders

Role = Literal["stock", "fixture"]
MM_PER_INCH = 25.4
#: Largest coordinate of a setup body (CL units): beyond any machine.
MAX_COORD = 1e5


class SetupError(ValueError):
    """A spec that cannot be read: the message says why and what a spec looks like."""


FORMS = "box:x0,y0,z0,x1,y1,z1, cylinder:cx,cy,z0,z1,r or stl:PATH"


@dataclass(frozen=True)
class SetupBody:
    """A body of the setup: a box (``lo``, ``hi``) or a vertical cylinder (centre x y, z0, z1,
    radius), mm, part frame; ``spec`` as given, for the program's header."""

    name: str
    role: Role
    kind: Literal["box", "cylinder"]
    lo: tuple[float, float, float]  # box corners, or the cylinder's bounding box
    hi: tuple[float, float, float]
    radius: float = 0.0  # cylinder only
    spec: str = ""

    def shifted(self, offset: np.ndarray) -> SetupBody:
        """The body moved by ``offset`` (mm)."""
        return replace(self, lo=tuple((np.asarray(self.lo) + offset).tolist()),
                       hi=tuple((np.asarray(self.hi) + offset).tolist()))

    def shape(self, offset: np.ndarray) -> Convex:
        """One row in the table frame with the part zero at ``offset`` (mm)."""
        lo, hi = np.asarray(self.lo) + offset, np.asarray(self.hi) + offset
        if self.kind == "box":
            return Boxes(lo[None], hi[None])
        centre = 0.5 * (lo[:2] + hi[:2])
        return Cylinders(np.array([[*centre, lo[2]]]), np.array([[*centre, hi[2]]]), np.array([self.radius]))

    def header(self) -> str:
        """The body in the program's header: its kind and numbers in mm, part frame."""
        if self.kind == "box":
            numbers = (*self.lo, *self.hi)
        else:
            numbers = (0.5 * (self.lo[0] + self.hi[0]), 0.5 * (self.lo[1] + self.hi[1]), self.lo[2], self.hi[2],
                       self.radius)
        return f"{self.role.upper()} {self.kind.upper()} " + " ".join(f"{v:.4f}" for v in numbers)


def _numbers(text: str, count: int, form: str) -> list[float]:
    parts = text.split(",")
    if len(parts) != count:
        raise SetupError(f"'{form}' needs {count} numbers separated by commas, got {len(parts)}")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise SetupError(f"'{form}' needs numbers (a decimal point, not a comma), got '{text}'") from None
    if not all(np.isfinite(v) and abs(v) <= MAX_COORD for v in values):
        raise SetupError(f"'{form}': every number must be finite and at most {MAX_COORD:g} in size")
    return values


def parse_spec(spec: str, role: Role, name: str, scale: float = 1.0, base: Path | None = None) -> SetupBody:
    """A setup body from its spec (see the module docstring), in CL units times ``scale`` (mm per
    CL unit); an STL path relative to ``base``. Raises :class:`SetupError`."""
    label, named, body = spec.partition("=")
    if named and ":" not in label and label.strip():
        name, spec = label.strip()[:60], body
    kind, sep, rest = spec.strip().partition(":")
    kind = kind.strip().lower()
    if not sep:
        raise SetupError(f"'{spec}' is not a setup body: give {FORMS}")
    if kind == "box":
        v = np.array(_numbers(rest, 6, "box:x0,y0,z0,x1,y1,z1")) * scale
        lo, hi = np.minimum(v[:3], v[3:]), np.maximum(v[:3], v[3:])
        if np.any(hi - lo <= 0):
            raise SetupError(f"'{spec}': the box is flat (two corners share a coordinate)")
        return SetupBody(name, role, "box", tuple(lo.tolist()), tuple(hi.tolist()), spec=spec)
    if kind == "cylinder":
        cx, cy, z0, z1, r = (np.array(_numbers(rest, 5, "cylinder:cx,cy,z0,z1,r")) * scale).tolist()
        if r <= 0 or z0 == z1:
            raise SetupError(f"'{spec}': the cylinder needs a radius above 0 and z0 != z1")
        lo, hi = (cx - r, cy - r, min(z0, z1)), (cx + r, cy + r, max(z0, z1))
        return SetupBody(name, role, "cylinder", lo, hi, r, spec)
    if kind == "stl":
        from .mesh import MeshError, mesh_bounds, read_stl

        path = Path(rest.strip())
        if base is not None and not path.is_absolute():
            path = base / path
        try:
            triangles = read_stl(path)
        except OSError as exc:
            raise SetupError(f"cannot read the STL file '{path}': {exc.strerror or exc}") from None
        except MeshError as exc:
            raise SetupError(str(exc)) from None
        bounds = mesh_bounds(triangles) * scale
        if np.any(bounds[1] - bounds[0] <= 0):
            raise SetupError(f"'{spec}': the mesh is flat")
        return SetupBody(name, role, "box", tuple(bounds[0].tolist()), tuple(bounds[1].tolist()), spec=spec)
    raise SetupError(f"'{kind}' is not a kind of setup body: give {FORMS}")


@dataclass(frozen=True)
class Setup:
    """Stock and fixtures (mm, part frame)."""

    bodies: tuple[SetupBody, ...] = ()

    def shifted(self, offset: np.ndarray) -> Setup:
        """Every body moved by ``offset`` (mm): from the part frame to the table frame."""
        offset = np.asarray(offset, dtype=float)
        return Setup(tuple(b.shifted(offset) for b in self.bodies)) if self.bodies else self

    @property
    def stock(self) -> tuple[SetupBody, ...]:
        return tuple(b for b in self.bodies if b.role == "stock")

    def bounds(self) -> np.ndarray | None:
        """(2, 3) mm, in the bodies' frame: the box around every body, None without bodies."""
        if not self.bodies:
            return None
        return np.array([np.min([b.lo for b in self.bodies], axis=0), np.max([b.hi for b in self.bodies], axis=0)])



#: No stock, no fixture.
NO_SETUP = Setup()
