"""Workspace maps: where the tool tip can go (table frame, mm) for one tool-axis direction.

A parallel kinematic machine's workspace is no box: it changes with the tool length and the
tool axis. For a given tilt (angle of the tool axis from the table normal) and rotary angle
theta2 (the table's turn, which fixes the axis' direction in the table frame) every grid point
of three sections is solved with the working-mode IK of the machine and given its smallest
headroom (:mod:`verne_post.checks.headroom`) and the constraint that sets it: an x-z section and a
y-z section through the table centre (y = 0, x = 0) and a plan view (x-y) at height ``z``.

    ws = verne_post.workspace(machine, tool_length=60, tilt=30)
    for s in ws.sections: s.u, s.v, s.headroom, s.limit   # arrays, mm and fractions

:func:`plot_workspace` draws them with matplotlib (the optional ``[plot]`` extra).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..api import Status, inverse_kinematics_pair
from ..checks.headroom import LABELS, headroom, smallest
from ..kinematics import axis_from_angles
from ..machine import Machine

#: The sections' extent (mm, table frame): beyond the VERNE's reach for any tool.
EXTENT_XY = (-1100.0, 1100.0)
EXTENT_Z = (-1300.0, 1300.0)


@dataclass(frozen=True)
class Section:
    """One planar section: ``headroom[i, j]`` at (u[j], v[i]) with the third coordinate ``level``."""

    plane: str  # "xz", "yz" or "xy": the axes of u and v
    level: float  # mm: y of the x-z section, x of the y-z section, z of the plan view
    u: np.ndarray  # (nu,) mm
    v: np.ndarray  # (nv,) mm
    headroom: np.ndarray  # (nv, nu) smallest headroom; NaN where the tip cannot be reached
    limit: np.ndarray  # (nv, nu) index into LABELS of the constraint setting it (REACH if unreachable)

    @property
    def fixed_axis(self) -> str:
        return ({"x", "y", "z"} - set(self.plane)).pop()


@dataclass(frozen=True)
class Workspace:
    """Sections of the tool-tip workspace for one tool length (mm), tilt and rotary angle (deg)."""

    tool_length: float
    tilt: float
    rotary: float
    axis: np.ndarray  # (3,) the tool axis in the table frame
    sections: tuple[Section, ...]
    labels: tuple[str, ...] = LABELS


def tool_axis(tilt: float, rotary: float) -> np.ndarray:
    """Unit tool axis in the table frame for a tilt from the table normal and the table's turn
    theta2 (deg): phi1 = tilt, phi2 = -theta2 (paper eq. 26)."""
    return axis_from_angles(np.radians([tilt]), np.radians([-rotary]))[0]


def solve_tips(machine: Machine, tips: np.ndarray, *, tool_length: float, tilt: float, rotary: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """(smallest headroom (N,), limiting constraint (N,)) of tool tips (N, 3) mm, table frame,
    with the axis of ``tilt`` and ``rotary`` (deg); headroom NaN where unreachable."""
    axis = np.broadcast_to(tool_axis(tilt, rotary), tips.shape)
    # The pair whose theta2 is the requested rotary angle: +1 for a positive tilt.
    pair = 1 if tilt >= 0 else -1
    ik = inverse_kinematics_pair(machine, tips, axis, pair, tool_length=tool_length,
                                 theta2_at_pole=np.radians(rotary))
    value, which = smallest(headroom(machine, ik.joints, ik.margins))
    value = np.where(ik.status == Status.UNREACHABLE, np.nan, value)
    return value, which


def workspace(machine: Machine, *, tool_length: float = 0.0, tilt: float = 0.0, rotary: float = 0.0,
              z: float | None = None, step: float = 10.0) -> Workspace:
    """Sections of the reachable tool tips (see module docstring); ``step`` (mm) is the grid
    spacing; ``z`` (mm, table frame) the plan view's height, by default the height where the
    x-z section is widest."""
    u = np.arange(EXTENT_XY[0], EXTENT_XY[1] + step / 2, step)
    heights = np.arange(EXTENT_Z[0], EXTENT_Z[1] + step / 2, step)
    sections = []
    for plane in ("xz", "yz"):
        uu, vv = np.meshgrid(u, heights)
        zeros = np.zeros_like(uu)
        tips = np.stack([uu, zeros, vv] if plane == "xz" else [zeros, uu, vv], axis=-1).reshape(-1, 3)
        value, which = solve_tips(machine, tips, tool_length=tool_length, tilt=tilt, rotary=rotary)
        sections.append(Section(plane, 0.0, u, heights, value.reshape(uu.shape), which.reshape(uu.shape)))
    if z is None:
        width = np.sum(sections[0].headroom >= 0, axis=1)
        z = float(heights[np.argmax(width)]) if width.any() else 0.0
    uu, vv = np.meshgrid(u, u)
    tips = np.stack([uu, vv, np.full_like(uu, z)], axis=-1).reshape(-1, 3)
    value, which = solve_tips(machine, tips, tool_length=tool_length, tilt=tilt, rotary=rotary)
    sections.append(Section("xy", z, u, u, value.reshape(uu.shape), which.reshape(uu.shape)))
    return Workspace(tool_length, tilt, rotary, tool_axis(tilt, rotary), tuple(sections))


def boundary_labels(section: Section) -> list[tuple[str, float, float]]:
    """(label, u, v) for each constraint that bounds the usable region: at the middle of the
    usable cells next to the edge that constraint sets (its cells beyond the edge)."""
    usable = section.headroom >= 0
    out = []
    beyond = ~usable
    edge = np.zeros_like(usable)
    edge[1:] |= usable[1:] & beyond[:-1]
    edge[:-1] |= usable[:-1] & beyond[1:]
    edge[:, 1:] |= usable[:, 1:] & beyond[:, :-1]
    edge[:, :-1] |= usable[:, :-1] & beyond[:, 1:]
    rows, cols = np.nonzero(edge)
    for which in np.unique(section.limit[rows, cols]):
        pick = section.limit[rows, cols] == which
        if pick.sum() < 3:
            continue
        k = np.flatnonzero(pick)[pick.sum() // 2]
        out.append((LABELS[which], float(section.u[cols[k]]), float(section.v[rows[k]])))
    return out


def plot_workspace(ws: Workspace, path: str | Path, program_tips: np.ndarray | None = None) -> None:
    """Draw the sections (PNG or SVG by the suffix of ``path``): :func:`workspace_figure`."""
    import matplotlib.pyplot as plt

    from ..output.atomic import atomic_write

    figure = workspace_figure(ws, program_tips)
    suffix = Path(path).suffix.lower().lstrip(".") or "png"
    with atomic_write(path, binary=True) as handle:
        figure.savefig(handle, format=suffix, dpi=FIGURE_DPI)
    plt.close(figure)


FIGURE_DPI = 110


def workspace_figure(ws: Workspace, program_tips: np.ndarray | None = None) -> Any:
    """The sections as a matplotlib figure, coloured by the smallest headroom; the constraint
    bounding the usable region is written along its edge, inside its section and clear of the
    other labels; optional program tool tips (N, 3) mm, table frame, are overlaid (projected
    onto each section)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.colors import ListedColormap
    except ImportError:  # pragma: no cover - depends on the installation
        from ..errors import InputError

        raise InputError("drawing workspace maps needs matplotlib: pip install 'verne-post[plot]'") from None

    figure, axes = plt.subplots(1, 3, figsize=(16, 5.8), constrained_layout=True, dpi=FIGURE_DPI)
    colours = plt.get_cmap("viridis")
    image = None
    for ax, section in zip(axes, ws.sections, strict=True):
        value = np.ma.masked_invalid(section.headroom)
        extent = (section.u[0], section.u[-1], section.v[0], section.v[-1])
        failing = np.ma.masked_where(~(section.headroom < 0), np.ones_like(section.headroom))
        ax.imshow(failing, origin="lower", extent=extent, cmap=ListedColormap(["#f4c7c3"]), aspect="equal")
        image = ax.imshow(np.ma.masked_less(value, 0), origin="lower", extent=extent, cmap=colours, vmin=0, vmax=1,
                          aspect="equal")
        for label, u, v in boundary_labels(section):
            ax.annotate(label, (u, v), xytext=(0, 0), textcoords="offset pixels", fontsize=7, ha="center",
                        color="black", bbox={"boxstyle": "round,pad=0.2", "fc": "white", "alpha": 0.7, "lw": 0})
        if program_tips is not None and len(program_tips):
            index = {"x": 0, "y": 1, "z": 2}
            ax.plot(program_tips[:, index[section.plane[0]]], program_tips[:, index[section.plane[1]]], ",",
                    color="#d62728", alpha=0.6, rasterized=True)
        ax.set_xlabel(f"{section.plane[0]} (mm)")
        ax.set_ylabel(f"{section.plane[1]} (mm)")
        ax.set_title(f"{section.plane[0]}-{section.plane[1]} at {section.fixed_axis} = {section.level:g} mm")
        usable = np.argwhere(section.headroom >= -0.5)
        if usable.size:
            (r0, c0), (r1, c1) = usable.min(axis=0), usable.max(axis=0)
            pad = 5
            ax.set_xlim(section.u[max(c0 - pad, 0)], section.u[min(c1 + pad, len(section.u) - 1)])
            ax.set_ylim(section.v[max(r0 - pad, 0)], section.v[min(r1 + pad, len(section.v) - 1)])
    figure.colorbar(image, ax=axes, shrink=0.8, label="smallest headroom (0 at a limit)")
    figure.suptitle(f"VERNE tool-tip workspace, table frame: tool {ws.tool_length:g} mm, tilt {ws.tilt:g} deg, "
                    f"rotary theta2 {ws.rotary:g} deg. Pink: reachable but past a limit"
                    + ("; red dots: the program's tool tips" if program_tips is not None else ""))
    figure.canvas.draw()  # the layout, then the labels' sizes are known: keep it as it is
    figure.set_layout_engine("none")
    for ax in axes:
        _spread_labels(ax, figure.canvas.get_renderer())
    return figure


def _spread_labels(ax: Any, renderer: Any) -> None:
    """Move the labels of ``ax`` (pixels) into its frame, then each clear of those before it,
    stepping along its edge point's column by a label's height."""
    frame = ax.get_window_extent(renderer)
    placed: list[Any] = []
    for text in ax.texts:
        box = text.get_window_extent(renderer)
        dx = max(frame.x0 + 2 - box.x0, 0) + min(frame.x1 - 2 - box.x1, 0)
        dy = max(frame.y0 + 2 - box.y0, 0) + min(frame.y1 - 2 - box.y1, 0)
        step = box.height + 2
        tries = [dy + sign * k * step for k in range(int(frame.height // step) + 1) for sign in (1, -1)]
        for offset in tries:
            moved = box.translated(dx, offset)
            if frame.y0 <= moved.y0 and moved.y1 <= frame.y1 and not any(moved.overlaps(p) for p in placed):
                dy = offset
                break
        text.xyann = (dx, dy)
        placed.append(box.translated(dx, dy))


__all__ = ["Section", "Workspace", "boundary_labels", "plot_workspace", "solve_tips", "tool_axis", "workspace",
           "workspace_figure"]
