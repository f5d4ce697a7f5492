"""Every shared real sample posted as a shop would: `--work-offset auto` and a stock box around
what the CAM cuts. The program is read back here line by line (G0/G1 words and the TOOL comments),
every move between cuts sampled along its joint-space line, and the tool (cutter and shank, from
the tip up its axis by the tool length) placed by the forward kinematics: no point of its
surface may lie inside the stock, except on the CAM's own moves into and out of its cut (a move
that starts or ends with the tip within the stock grown by the cutter's radius).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from verne_post.cl import read_toolpath
from verne_post.cli import main

SAMPLES = Path(__file__).parent / "data" / "cl-samples"
# The stock: "box", the feed points' box, 10 mm deeper (a face cut's points lie in a plane: the
# stock is below them). Where the head itself goes down into the room the CAM has cleared (swarf
# walls 3.5 in deep, a thread mill 4 in down its hole, Z-levels down around a core) a solid box
# there would be met by the holder: material a box cannot know has gone (the in-process stock). There
# the stock is "floor": the same box's footprint, 10 mm thick, under the deepest feed point.
# Not here: nx_swarf and nx_variable_axis, whose tilted 100 mm tools put the spindle's rim below
# the deepest tip, into any floor under the walls (a longer tool is what a shop would give them).
POSTED = [("nx_zlevel_coremill_mm.cls", "floor"), ("creo8_schruppen_roughing_mm.ncl", "box"),
          ("creo8_profilfraesen_mm.ncl", "box"), ("makino_ffcam_plane1_mm.cldata", "box"),
          ("creo_v19_thread_mill_helical_inch.ncl", "floor")]
TOOL_LENGTH = 100.0
CUTTER_DIAMETER = 10.0  # mm: the machine file's default cutter where the CL file gives none (asserted)
_WORD = re.compile(r"([XYZAC])(-?\d+(?:\.\d*)?)")


def _stock(path: Path, kind: str = "box") -> tuple[str, np.ndarray]:
    """The stock (part frame, see POSTED) as a --stock spec (the CL file's units) and in mm."""
    toolpath = read_toolpath(path)
    scale = 25.4 if toolpath.units == "inch" else 1.0
    feed = toolpath.tip[~toolpath.rapid]
    box = np.array([feed.min(axis=0) - [0.0, 0.0, 10.0], feed.max(axis=0)])
    if kind == "floor":
        box[1, 2] = box[0, 2] + 10.0
    spec = "box:" + ",".join(f"{v / scale:.6f}" for v in box.ravel())
    return spec, box


def _blocks(text: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per motion block: joints (mm, rad), whether it is a move between cuts (G0, or G1 marked
    RAPID), and the tool length in force (mm)."""
    joints, rapid, length = [], [], []
    state = dict.fromkeys("XYZAC", np.nan)
    lengths: dict[int, float] = {}
    tool, mode = -1, "G0"
    for line in text.splitlines():
        if m := re.match(r"\(TOOL (\d+) LENGTH (\S+)", line):
            lengths[int(m.group(1))] = float(m.group(2))
            continue
        code = line.split("(")[0]
        if m := re.search(r"\bT(\d+)", code):
            tool = int(m.group(1))
        if m := re.search(r"\bG0?([01])\b", code):
            mode = f"G{m.group(1)}"
        words = dict(_WORD.findall(code))
        if not words:
            continue
        state.update({k: float(v) for k, v in words.items()})
        joints.append([state["X"], state["Y"], state["Z"], np.radians(state["A"]), np.radians(state["C"])])
        rapid.append(mode == "G0" or "RAPID" in line)
        length.append(lengths.get(tool, lengths.get(0, TOOL_LENGTH)) if lengths else TOOL_LENGTH)
    return np.array(joints), np.array(rapid), np.array(length)


def _surface(tip: np.ndarray, axis: np.ndarray, length: np.ndarray, radius: float) -> np.ndarray:
    """(N, K, 3) points on the tool's surface: rings of 12 at 11 heights from the tip to the top,
    and the end disc's centre."""
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    phi = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    h = np.linspace(0.0, 1.0, 11)
    ring = np.cos(phi)[None, :, None] * e1[:, None] + np.sin(phi)[None, :, None] * e2[:, None]  # (N, 12, 3)
    points = (tip[:, None, None] + h[None, :, None, None] * (length[:, None, None, None] * axis[:, None, None])
              + radius * ring[:, None])
    return np.concatenate([points.reshape(len(tip), -1, 3), tip[:, None]], axis=1)


@pytest.mark.parametrize(("name", "kind"), POSTED)
def test_sample_posts_with_auto_offset_and_stock_and_its_moves_between_cuts_stay_out(tmp_path: Path, name: str,
                                                                                   kind: str) -> None:
    machine = vp.load_machine()
    assert machine.bodies.cutter_diameter == CUTTER_DIAMETER
    spec, box = _stock(SAMPLES / name, kind)
    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, [str(SAMPLES / name), "-o", str(out), "--no-timing", "-q", "--tool-length",
                                       str(TOOL_LENGTH), "--work-offset", "auto", "--stock", spec])
    assert result.exit_code == 0, result.output
    text = out.read_text()
    offset = np.array([float(v) for v in re.search(r"\(WORK OFFSET (\S+) (\S+) (\S+) MM", text).groups()])
    joints, rapid, length = _blocks(text)
    diameters = [e.diameter for e in read_toolpath(SAMPLES / name).events if getattr(e, "diameter", None)]
    radius = 0.5 * max(diameters, default=CUTTER_DIAMETER)  # mm: the widest cutter, for every tool
    lo, hi = box[0] + offset, box[1] + offset  # table frame, mm
    ends = vp.forward_kinematics(machine, joints, tool_length=length)
    near = np.all((ends.tip >= lo - radius) & (ends.tip <= hi + radius), axis=1)
    # moves between cuts whose ends are both outside the stock grown by the cutter's radius: the post's own
    moves = np.flatnonzero(rapid[1:] & ~near[1:] & ~near[:-1]) + 1
    assert len(moves) > 0
    s = np.linspace(0.0, 1.0, 25)
    q = joints[moves - 1, None] + s[None, :, None] * (joints[moves, None] - joints[moves - 1, None])
    along = vp.forward_kinematics(machine, q.reshape(-1, 5), tool_length=np.repeat(length[moves], len(s)))
    points = _surface(along.tip, along.axis, np.repeat(length[moves], len(s)), radius)
    inside = np.all((points > lo + 1e-6) & (points < hi - 1e-6), axis=2)
    assert not inside.any(), f"{int(inside.any(axis=1).sum())} tool samples inside the stock"


def test_the_catia_sample_is_beyond_the_machine_at_any_offset(tmp_path: Path) -> None:
    """The one shared sample that does not post: its tool axis tilts about 140 deg from the table
    normal, past what the VERNE's table tilts, which no work offset changes. The figure the refusal
    gives is the CL file's own largest tilt, measured here."""
    path = SAMPLES / "catia_v5_isoparametric_5axis_mm.aptsource"
    toolpath = read_toolpath(path)
    tilt = float(np.degrees(np.arccos(np.clip(toolpath.axis[:, 2], -1.0, 1.0))).max())
    result = CliRunner().invoke(main, [str(path), "-o", str(tmp_path / "c.nc"), "--no-timing", "-q", "--tool-length",
                                       str(TOOL_LENGTH), "--work-offset", "auto", "--stock", _stock(path)[0]])
    assert result.exit_code == 3 and not (tmp_path / "c.nc").exists(), result.output
    found = re.search(r"the tool axis is tilted ([\d.]+) deg from the table normal; .* at most about ([\d.]+) deg",
                      result.output)
    assert found, result.output
    assert float(found.group(1)) == pytest.approx(tilt, abs=0.1) and tilt > float(found.group(2))
