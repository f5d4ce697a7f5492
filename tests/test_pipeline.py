"""The main job on every shipped example, checked through the G-code it writes.

The G-code is read back (our own parse at full precision, and LinuxCNC's interpreter), taken
through the forward kinematics with the tool length the program declares, and compared with
the CL path read independently from the CL file.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from verne_post.cl import read_toolpath
from verne_post.cli import main
from verne_post.motion.linearise import angle_to_arc, distance_to_segment
from verne_post.verify.rs274 import run_rs274

EXAMPLES = Path(__file__).parent.parent / "examples"
# (file, work offset X Y Z mm): docs/post.md gives the same offsets.
CASES = [
    ("nx_variable_axis_inch.cls", (0.0, 0.0, 0.0)),
    ("nx_swarf_inch_crlf.cls", (0.0, 0.0, 0.0)),
    ("impeller_5axis.cls", (0.0, 0.0, 0.0)),
]
TOL, AXIS_TOL = 0.005, 0.05
_MOVE = re.compile(r"^(?:N\d+ )?G([01]) X(\S+) Y(\S+) Z(\S+) A(\S+) C(\S+)")
_TOOL = re.compile(r"^\(TOOL (\d+) LENGTH (\S+) DELTA (\S+)\)")


def read_gcode(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(joints (M, 5) mm/rad, rapid (M,), tool length (M,) mm) of every motion block."""
    joints, rapid, lengths = [], [], []
    length = np.nan
    for text in path.read_text().splitlines():
        tool = _TOOL.match(text)
        if tool:
            length = float(tool.group(2))
        move = _MOVE.match(text)
        if move:
            values = [float(v) for v in move.groups()[1:]]
            joints.append(values[:3] + list(np.radians(values[3:])))
            rapid.append(move.group(1) == "0" or text.endswith("(RAPID)"))  # a move between cuts
            lengths.append(length)
    return np.array(joints), np.array(rapid), np.array(lengths)


def _walk(blocks: list[list[float]], cl: list[list[float]], rapid: list[bool], name: str,
          between: list[bool], block_axis: list[list[float]], cl_axis: list[list[float]]) -> np.ndarray:
    """(block, CL pose) pairs where a block ends on a CL pose; asserts every block end is on the
    CL move it belongs to (CL poses to 1 micrometre, ends between them within the
    tolerance), in order, except the ends of the moves between cuts
    (``between``: judged in tests/test_safe_motion.py) that reach no CL pose. Plain floats: one
    pass over 10^5 blocks; a move between cuts reaches a CL pose with its tip and axis)."""
    def close(p: list[float], a: list[float], limit: float = 1e-3) -> bool:
        return (p[0] - a[0]) ** 2 + (p[1] - a[1]) ** 2 + (p[2] - a[2]) ** 2 <= limit * limit

    def on_segment(p: list[float], a: list[float], b: list[float]) -> bool:
        d = [b[i] - a[i] for i in range(3)]
        length2 = d[0] ** 2 + d[1] ** 2 + d[2] ** 2
        t = 0.0 if length2 == 0 else max(0.0, min(1.0, sum((p[i] - a[i]) * d[i] for i in range(3)) / length2))
        # ends between CL poses: the linearisation's on the CL move; guard blocks at rotary corners
        # (linuxcnc.blending) on the joint-space line, which keeps within the tolerance of it
        return close(p, [a[i] + t * d[i] for i in range(3)], TOL)

    pairs, k = [], 0
    for m, point in enumerate(blocks):
        if between[m]:
            ahead = next((j for j in range(k, min(k + 3, len(cl))) if close(point, cl[j])
                          and sum(u * v for u, v in zip(block_axis[m], cl_axis[j], strict=True)) > 1 - 1e-6), None)
            if ahead is None:
                continue
            k = ahead
        while not close(point, cl[k]) and not (k > 0 and not rapid[k] and on_segment(point, cl[k - 1], cl[k])):
            k += 1
            assert k < len(cl), f"block {m} of {name} is off the CL path"
        if close(point, cl[k]):
            pairs.append((m, k))
    return np.array(pairs)


def post(tmp_path: Path, name: str, offset: tuple[float, float, float], *extra: str) -> tuple[Path, dict]:
    output, report = tmp_path / (Path(name).stem + ".nc"), tmp_path / "report.json"
    result = CliRunner().invoke(main, [str(EXAMPLES / name), "-o", str(output), "--report", str(report), "--quiet",
                                       "--work-offset", *map(str, offset), "--tol", str(TOL), "--axis-tol",
                                       str(AXIS_TOL)])
    assert result.exit_code == 0, result.stderr
    return output, json.loads(report.read_text())


@pytest.mark.parametrize(("name", "offset"), CASES)
def test_example_gcode_follows_the_cl_path(tmp_path: Path, name: str, offset: tuple[float, float, float]) -> None:
    machine = vp.load_machine()
    output, report = post(tmp_path, name, offset)
    assert report["ok"] and report["violations"] == []
    joints, rapid, lengths = read_gcode(output)
    assert np.isfinite(lengths).all()
    fk = vp.forward_kinematics(machine, joints, tool_length=lengths)
    assert fk.reachable.all()
    cl = read_toolpath(EXAMPLES / name)
    tip, axis = cl.tip + np.asarray(offset), cl.axis
    # Walk the blocks along the CL path: each block end lies on the CL move it belongs to
    # (within 1 micrometre) and every CL pose is reached.
    reached = _walk(fk.tip.tolist(), tip.tolist(), cl.rapid.tolist(), output.name, rapid.tolist(),
                    fk.axis.tolist(), axis.tolist())
    angle = 2 * np.arcsin(np.linalg.norm(fk.axis[reached[:, 0]] - axis[reached[:, 1]], axis=1) / 2)
    assert angle.max() <= np.radians(machine.pole.cone) + 1e-6
    missing = np.setdiff1d(np.arange(len(tip)), reached[:, 1])
    # A CL pose without a block of its own repeats the previous pose (a motion of zero length).
    assert np.all(np.linalg.norm(tip[missing] - tip[missing - 1], axis=1) <= 1e-6)
    assert np.all(np.linalg.norm(axis[missing] - axis[missing - 1], axis=1) <= 1e-9)
    # Between blocks: the joint interpolation stays within the tolerances (10 samples a block).
    feed = np.flatnonzero(~rapid[1:] & (lengths[1:] == lengths[:-1])) + 1
    s = (np.arange(10) + 0.5) / 10
    rows = np.repeat(feed, len(s))
    f = np.tile(s, len(feed))
    q = joints[rows - 1] + f[:, None] * (joints[rows] - joints[rows - 1])
    mid = vp.forward_kinematics(machine, q, tool_length=lengths[rows])
    assert np.max(distance_to_segment(mid.tip, fk.tip[rows - 1], fk.tip[rows])) <= TOL
    assert np.degrees(np.max(angle_to_arc(mid.axis, fk.axis[rows - 1], fk.axis[rows]))) <= AXIS_TOL
    assert report["points"]["blocks"] >= len(joints)


@pytest.mark.parametrize(("name", "offset"), CASES)
def test_example_passes_linuxcnc(tmp_path: Path, name: str, offset: tuple[float, float, float]) -> None:
    """LinuxCNC's interpreter accepts the program and reaches the joints the pipeline computed."""
    from verne_post.options import PostOptions
    from verne_post.output.gcode import write_program
    from verne_post.pipeline import gcode_format, postprocess

    machine = vp.load_machine()
    result = postprocess(EXAMPLES / name, machine, PostOptions(work_offset=offset))
    output = tmp_path / "out.nc"
    write_program(result.program, gcode_format(machine), output)
    tools = [int(t) for t in re.findall(r"^T(\d+) M6", output.read_text(), re.M)]
    interpreted = run_rs274(output, tool_numbers=tools or [1])
    assert interpreted.errors == []
    joints = result.program.joints
    expected = np.column_stack([joints[:, :3], np.degrees(joints[:, 3]), np.zeros(len(joints)),
                                np.degrees(joints[:, 4])])
    assert interpreted.moves.shape == expected.shape
    # rs274 prints 4 decimals; the program has 4 (mm) and 5 (degrees).
    np.testing.assert_allclose(interpreted.moves, expected, atol=0.5e-4 + 0.5e-5 + 1e-9)
    assert np.array_equal(interpreted.kinds == 0, result.program.rapid)


def test_repeated_runs_give_identical_files(tmp_path: Path) -> None:
    first, _ = post(tmp_path, CASES[0][0], CASES[0][1])
    text = first.read_text()
    second, _ = post(tmp_path, CASES[0][0], CASES[0][1])
    assert second.read_text() == text
    assert "(TOOL 0 LENGTH 76.2000 DELTA 572.0000)" in text


@pytest.mark.parametrize(("name", "offset"), CASES)
def test_margins_between_block_ends_stay_above_the_ends(name: str, offset: tuple[float, float, float]) -> None:
    """checks.motion_samples samples feed-block midpoints only near thresholds: that relies on
    the margins at a midpoint never being measurably below the smaller end value."""
    from verne_post.checks.limits import motion_samples
    from verne_post.options import PostOptions
    from verne_post.pipeline import postprocess

    machine = vp.load_machine()
    result = postprocess(EXAMPLES / name, machine, PostOptions(work_offset=offset))
    blocks = result.blocks
    lengths = result.poses.tool_length[blocks.pose]
    samples = motion_samples(machine, blocks.result, result.rapid, lengths, result.poses.line[blocks.pose],
                             every_feed_block=True)
    feed = ~result.rapid[samples.block]
    assert feed.sum() > 100
    for field in ("serial", "parallel", "machine", "rod_clearance"):
        ends = np.minimum(getattr(blocks.result.margins, field)[samples.block - 1],
                          getattr(blocks.result.margins, field)[samples.block])[feed]
        assert np.min(getattr(samples.margins, field)[feed] / ends) >= 0.99
