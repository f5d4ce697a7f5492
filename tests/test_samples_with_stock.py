"""Every shared real sample posted as a shop would: `--work-offset auto` and a stock box around
what the CAM cuts. The program is read back here line by line (G0/G1 words and the TOOL comments),
every move between cuts sampled along its joint-space line, and the tool (cutter and shank, from
the tip up its axis by the tool length) placed by the forward kinematics: no point of its
surface may lie inside the stock, except on the CAM's own moves into and out of its cut (a move
that starts or ends with the tip within the stock grown by the cutter's radius).

The same for a job with side work at a 90 deg tilt (the issue's held-out job is not here: this
one is built to its description, a 4 x 4 x 3.5 in part whose walls are faced by a horizontal tool).
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
# stock is below them). Where the head itself goes down into the room the CAM has cleared (a thread
# mill 4 in down its hole, Z-levels down around a core) a solid box there would be met by the
# holder: material a box cannot know has gone (the in-process stock). There the stock is "floor":
# the same box's footprint, 10 mm thick, under the deepest feed point.
POSTED = [("nx_zlevel_coremill_mm.cls", "floor"), ("creo8_schruppen_roughing_mm.ncl", "box"),
          ("creo8_profilfraesen_mm.ncl", "box"), ("makino_ffcam_plane1_mm.cldata", "box"),
          ("creo_v19_thread_mill_helical_inch.ncl", "floor"), ("nx_variable_axis_inch.cls", "box"),
          ("nx_swarf_inch_crlf.cls", "box")]
# nx_swarf chamfers the top edge of a 4 x 4 x 3.5 in block with a 0.75 in end mill tilted 48.6 to
# 64.7 deg over the block's top face, its tip 8 mm below it. Its TLDATA length, 4.0 in, is the
# tool's own length (its gauge adds the holder, less the depth it is clamped in it). Read as the
# gauge, it puts the default holder and spindle 101.6 mm from the tip: at CL line 49 (64.7 deg)
# the spindle housing's (170 mm) rim would be 36 mm down in the block, the holder 10 mm (the last
# test). With this stock box the shortest gauge that posts is 130 mm (129: the holder's 40 mm
# piece meets the stock at lines 49-51): the 4 in tool clamped 42 mm deep in the 70 mm default
# holder. A CL length wins over --tool-length, so the gauge goes in place of the file's length.
SWARF_GAUGE = 130.0  # mm
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


def _posted_moves_between_cuts_stay_out(tmp_path: Path, path: Path, spec: str, box: np.ndarray) -> str:
    """Post ``path`` with ``--work-offset auto`` and the stock ``spec`` (``box``: mm, part frame),
    then check its moves between cuts by FK of the program as written (see the module's
    docstring); the program's text."""
    machine = vp.load_machine()
    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, [str(path), "-o", str(out), "--no-timing", "-q", "--tool-length",
                                       str(TOOL_LENGTH), "--work-offset", "auto", "--stock", spec])
    assert result.exit_code == 0, result.output
    text = out.read_text()
    assert "ALL LIMITS HELD, NO BODIES MEET" in text
    offset = np.array([float(v) for v in re.search(r"\(WORK OFFSET (\S+) (\S+) (\S+) MM", text).groups()])
    joints, rapid, length = _blocks(text)
    diameters = [e.diameter for e in read_toolpath(path).events if getattr(e, "diameter", None)]
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
    return text


@pytest.mark.parametrize(("name", "kind"), POSTED)
def test_sample_posts_with_auto_offset_and_stock_and_its_moves_between_cuts_stay_out(tmp_path: Path, name: str,
                                                                                   kind: str) -> None:
    assert vp.load_machine().bodies.cutter_diameter == CUTTER_DIAMETER
    path = SAMPLES / name
    if name.startswith("nx_swarf"):
        text = path.read_bytes()
        tldata = b"TLDATA/MILL,0.7500,0.1200,4.0000,"
        assert text.count(tldata) == 1
        path = tmp_path / name
        path.write_bytes(text.replace(tldata, f"TLDATA/MILL,0.7500,0.1200,{SWARF_GAUGE / 25.4:.4f},".encode()))
    spec, box = _stock(path, kind)
    _posted_moves_between_cuts_stay_out(tmp_path, path, spec, box)


def _side_job() -> str:
    """A 4 x 4 x 3.5 in block (part zero at its lower corner, inch): its top faced with a vertical
    0.5 in end mill, then its four walls from z 3.3 to 1.5 in, each faced with the tool horizontal
    along the wall's outward normal (a 90 deg tilt), zig-zag 0.4 in beyond both edges; a RAPID
    before each operation. Gauge 6 in."""
    lines = ["PARTNO/SIDE_WALLS_90", "UNITS/INCHES", "LOADTL/1,LENGTH,6.0000", "CUTTER/0.5000", "FEDRAT/IPM,20.0000"]

    def goto(point: np.ndarray, axis: np.ndarray | None = None) -> None:
        words = [f"{v:.4f}" for v in point] + ([] if axis is None else [f"{v:.7f}" for v in axis])
        lines.append("GOTO/" + ",".join(words))

    lines.append("RAPID")
    goto(np.array([-0.4, 0.2, 4.0]), np.array([0.0, 0.0, 1.0]))
    for k, y in enumerate(np.arange(0.2, 4.0, 0.4)):
        for x in ((-0.4, 4.4) if k % 2 == 0 else (4.4, -0.4)):
            goto(np.array([x, y, 3.5]))
    goto(np.array([x, y, 4.0]))
    levels = np.arange(3.3, 1.45, -0.3)
    # (outward normal, wall origin, direction along the wall)
    walls = [((1, 0, 0), (4, 0, 0), (0, 1, 0)), ((0, 1, 0), (4, 4, 0), (-1, 0, 0)),
             ((-1, 0, 0), (0, 4, 0), (0, -1, 0)), ((0, -1, 0), (0, 0, 0), (1, 0, 0))]
    for normal, origin, along in walls:
        n, o, a = np.array(normal, float), np.array(origin, float), np.array(along, float)
        lines.append("RAPID")
        goto(o - 0.4 * a + [0, 0, levels[0]] + n, n)
        for k, z in enumerate(levels):
            for s in ((-0.4, 4.4) if k % 2 == 0 else (4.4, -0.4)):
                goto(o + s * a + [0, 0, z])
        goto(o + s * a + [0, 0, levels[-1]] + n)
    return "\n".join(lines) + "\n"


def test_side_work_at_90_degrees_posts_with_auto_offset_and_stock_and_its_moves_between_cuts_stay_out(
        tmp_path: Path) -> None:
    path = tmp_path / "side.cls"
    path.write_text(_side_job())
    toolpath = read_toolpath(path)
    tilt = np.degrees(np.arccos(np.clip(toolpath.axis[~toolpath.rapid, 2], -1.0, 1.0)))
    assert (tilt > 89.99).sum() > 0.7 * len(tilt) and (tilt < 0.01).sum() > 10  # side work, and a top face
    stock = np.array([[-0.02, -0.02, 0.0], [4.02, 4.02, 3.52]])  # in: the block with 0.02 in to cut
    spec = "box:" + ",".join(f"{v:g}" for v in stock.ravel())
    text = _posted_moves_between_cuts_stay_out(tmp_path, path, spec, 25.4 * stock)
    # the walls' passes are in the program as horizontal-axis feed blocks
    joints, rapid, length = _blocks(text)
    axis = vp.forward_kinematics(vp.load_machine(), joints[~rapid], tool_length=length[~rapid]).axis
    assert (np.abs(axis[:, 2]) < 1e-3).sum() > 100


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


def test_the_swarf_sample_at_its_tldata_length_is_refused_where_the_spindle_enters_the_block(tmp_path: Path) -> None:
    """At the file's own 4.0 in as the gauge, the spindle housing's rim, 101.6 mm up the axis tilted
    64.7 deg at CL line 49, lies inside the block (the 4 x 4 x 3.5 in block the chamfer is on,
    measured here from the CL pose alone): the post refuses it at that line, naming the spindle."""
    machine = vp.load_machine()
    path = SAMPLES / "nx_swarf_inch_crlf.cls"
    toolpath = read_toolpath(path)
    k = int(np.flatnonzero(toolpath.line == 49)[0])
    tip, axis = toolpath.tip[k], toolpath.axis[k]
    assert np.degrees(np.arccos(axis[2])) == pytest.approx(64.7, abs=0.05)
    gauge = next(e.length for e in toolpath.events if getattr(e, "length", None))
    assert gauge == pytest.approx(101.6)
    # the housing's bottom rim, at the nose: 72 points round the axis
    e1 = np.cross(axis, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    phi = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)[:, None]
    rim = tip + gauge * axis + 0.5 * machine.bodies.spindle.diameter * (np.cos(phi) * e1 + np.sin(phi) * e2)
    block = np.array([[0.0, 0.0, 0.0], [4.0, 4.0, 3.5]]) * 25.4
    inside = np.all((rim > block[0]) & (rim < block[1]), axis=1)
    assert inside.any() and block[1, 2] - rim[inside, 2].min() > 30.0  # mm below the top face
    result = CliRunner().invoke(main, ["check", str(path), "--no-timing", "-q", "--work-offset", "auto",
                                       "--stock", "box:0,0,0,4,4,3.5"])
    assert result.exit_code == 3, result.output
    assert "nx_swarf_inch_crlf.cls:49: the spindle meets the stock" in result.output
