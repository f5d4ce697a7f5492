"""Collisions refused where the bodies meet: cases made from the bodies' own dimensions.

Each case is a hand-made CL file whose geometry puts one head body into one obstacle by a margin
worked out here from the machine file's sizes (holder, spindle, table), so the test says which
body meets which, and at which CL line, before the code is run.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from click.testing import CliRunner

import verne_post as vp
from verne_post.cli import main

TOOL_LENGTH = 120.0  # mm: cutter 0..30 (3 diameters), shank 30..50, holders 50..120 from the tip
DIAMETER = 10.0


def _cl(points: list[tuple[float, float, float, float, float, float]], rapid_first: bool = True) -> str:
    lines = ["PARTNO/CASE", "UNITS/MM", f"TLDATA/MILL,{DIAMETER},0.0,{TOOL_LENGTH},0.0,0.0", "LOADTL/1",
             "FEDRAT/MMPM,500.0"]
    for k, p in enumerate(points):
        if k == 0 and rapid_first:
            lines.append("RAPID")
        lines.append("GOTO/" + ",".join(f"{v:.6f}" for v in p))
    return "\n".join(lines) + "\n"


def _line_of_first(cl: str, keep: np.ndarray) -> int:
    """The CL file's line (1-based) of the first GOTO where ``keep`` (per GOTO) holds."""
    gotos = [k + 1 for k, line in enumerate(cl.splitlines()) if line.startswith("GOTO/")]
    return gotos[int(np.argmax(keep))]


def _run(tmp_path: Path, cl: str, *options: str) -> tuple[int, str, Path]:
    source = tmp_path / "case.cls"
    source.write_text(cl)
    out = tmp_path / "case.nc"
    result = CliRunner().invoke(main, ["post", str(source), "-o", str(out), "-q", *options])
    return result.exit_code, result.output, out


def _line_cut(x: np.ndarray, z: float) -> list[tuple[float, float, float, float, float, float]]:
    return [(float(v), 0.0, z, 0.0, 0.0, 1.0) for v in x]


def test_a_clamp_the_shank_passes_through_is_refused_at_its_line(tmp_path: Path) -> None:
    machine = vp.load_machine()
    x = np.linspace(-40.0, 40.0, 17)
    cl = _cl(_line_cut(x, 0.0))
    # the shank spans 30..50 mm above the tip: a clamp at 35..45 mm height, x from 20 to 30
    clamp = "box:20,-30,35,30,30,45"
    expected = _line_of_first(cl, x + 0.5 * DIAMETER >= 20.0)
    for offset in (["--work-offset", "0", "0", "200"], ["--work-offset", "auto"]):
        code, output, out = _run(tmp_path, cl, "--fixture", clamp, *offset)
        assert code == 3, output
        assert not out.exists()
        assert f"case.cls:{expected}: the shank meets the fixture 1" in output, output
    assert machine.bodies.margin > 0


def test_the_holder_into_a_tall_clamp_beside_the_cut_is_refused(tmp_path: Path) -> None:
    machine = vp.load_machine()
    holder = machine.bodies.holder[-1]  # the holder's piece nearest the tip: 50..80 mm up
    x = np.linspace(-40.0, 45.0, 18)
    cl = _cl(_line_cut(x, 0.0))
    # a tall clamp from x = 60: the cutter (radius 5) and shank stay clear of it, the holder does not
    clamp = "clamp=box:60,-30,-10,90,30,75"  # below holder 1 (80..120 mm up), in holder 2's span
    expected = _line_of_first(cl, x + 0.5 * holder.diameter >= 60.0)
    code, output, out = _run(tmp_path, cl, "--fixture", clamp, "--work-offset", "0", "0", "200")
    assert code == 3 and not out.exists(), output
    assert f"case.cls:{expected}: the holder 2 meets the clamp" in output, output
    # the same cut stopped short of the holder's reach posts
    short = _cl(_line_cut(x[x + 0.5 * holder.diameter < 60.0 - 2 * machine.bodies.margin], 0.0))
    code, output, out = _run(tmp_path, short, "--fixture", clamp, "--work-offset", "0", "0", "200")
    assert code == 0 and out.exists(), output


def test_a_tilt_that_drives_the_spindle_into_the_table_is_refused(tmp_path: Path) -> None:
    machine = vp.load_machine()
    bodies = machine.bodies
    tilt = np.radians(60.0)
    # the tip above the table face by h; the spindle's lowest rim point (at the nose, tilted
    # toward -x) is then h + L cos(tilt) - R sin(tilt) above it: below the face for this h
    radius = 0.5 * bodies.spindle.diameter
    drop = TOOL_LENGTH * np.cos(tilt) - radius * np.sin(tilt)
    axis = (-np.sin(tilt), 0.0, np.cos(tilt))
    x = np.linspace(0.0, 100.0, 11)
    rim_x = x - TOOL_LENGTH * np.sin(tilt) - radius * np.cos(tilt)
    assert np.all(np.abs(rim_x) < 0.5 * bodies.table.diameter)  # over the table's face

    def points(h: float) -> list[tuple[float, float, float, float, float, float]]:
        return [(float(v), 0.0, bodies.table.top + h, *axis) for v in x]

    cutter_drop = 0.5 * DIAMETER * np.sin(tilt)  # the cutter's lowest rim point below its tip
    low = 0.5 * (cutter_drop - drop)  # the tip between: the spindle's rim under the face, the cutter above
    assert low + drop < 0 < low - cutter_drop
    code, output, out = _run(tmp_path, _cl(points(low)), "--work-offset", "0", "0", "0")
    assert code == 3 and not out.exists(), output
    assert "meets the table" in output and ("spindle" in output or "holder" in output), output
    # the same tilt with the tip high enough that the spindle's rim clears the face posts
    code, output, out = _run(tmp_path, _cl(points(-drop + 2.0 * bodies.margin + 5.0)), "--work-offset", "0", "0", "0")
    assert code == 0 and out.exists(), output


def test_a_near_miss_before_a_collision_at_the_same_line_is_still_a_collision(tmp_path: Path) -> None:
    """Two blocks of one CL line, the first within the margin, the second into the body: the line
    is refused (per line and pair of bodies the least clearance counts, whatever comes first)."""
    from verne_post.bodies.clearance import ClearanceResult, Contact
    from verne_post.checks.collision import check_collisions, world_of
    from verne_post.cl import read_toolpath
    from verne_post.motion.poses import machine_poses

    machine = vp.load_machine()
    source = tmp_path / "case.cls"
    source.write_text(_cl(_line_cut(np.array([0.0, 10.0]), 0.0)))
    poses = machine_poses(read_toolpath(source), machine, work_offset=(0, 0, 200))
    world = world_of(machine, poses)

    class Found:  # the world with the clearance given: what check_collisions makes of contacts
        stacks = world.stacks

        @staticmethod
        def clearance(*args: object) -> ClearanceResult:
            contacts = (Contact(1, 0.5, "shank@table", "clamp", 0.5 * machine.bodies.margin),
                        Contact(2, 0.5, "shank@table", "clamp", 0.0))
            return ClearanceResult(contacts, np.zeros(3), 100.0)

    joints = np.zeros((3, 5))
    found = check_collisions(machine, poses, joints, np.array([0, 1, 1]), np.zeros(3, bool), np.zeros((3, 3)),
                             world=Found())  # type: ignore[arg-type]
    line = int(poses.line[1])
    assert [(v.line, v.message) for v in found.violations] == [(line, "the shank meets the clamp (clearance 0.000 mm)")]
    assert found.warnings == []


def test_verify_finds_the_clamp_a_program_was_posted_without(tmp_path: Path) -> None:
    """The program posted for an empty table passes verify there; given the clamp the shank passes
    through, verify (the text read back, forward kinematics) finds it at the G-code line of the
    CL line the post refuses, and a program posted with the clamp is certified clear of it."""
    x = np.linspace(-40.0, 40.0, 17)
    cl = _cl(_line_cut(x, 0.0))
    clamp = "box:20,-30,35,30,30,45"
    code, output, out = _run(tmp_path, cl, "--work-offset", "0", "0", "200")
    assert code == 0, output
    assert "NO BODIES MEET" in out.read_text()

    def verify(*options: str) -> tuple[int, str]:
        result = CliRunner().invoke(main, ["verify", str(out), "--against", str(tmp_path / "case.cls"), *options])
        return result.exit_code, result.output

    code, output = verify()
    assert code == 0, output
    code, output = verify("--fixture", clamp)
    assert code == 3, output
    lines = out.read_text().splitlines()
    found = sorted(int(m) for m in re.findall(r"case\.nc:(\d+): the shank meets the fixture 1", output))
    assert found, output

    def tip_x(line: int) -> float:  # the block end's tool tip by the forward kinematics, part frame x
        words = dict(re.findall(r"([XYZAC])(-?[\d.]+)", lines[line - 1]))
        joints = np.array([[float(words[a]) for a in "XYZ"] + [np.radians(float(words[a])) for a in "AC"]])
        return float(vp.forward_kinematics(vp.load_machine(), joints, tool_length=TOOL_LENGTH).tip[0, 0])

    # the first block found ends where the shank's side has reached the clamp's face (x = 20), the
    # block before it short of there (blocks are about 1 mm of travel)
    assert tip_x(found[0]) + 0.5 * DIAMETER >= 20.0 - 1.0
    assert tip_x(found[0] - 1) + 0.5 * DIAMETER <= 20.0 + 1.0


def test_a_coordinate_kilometres_away_is_a_limit_violation_not_bodies_bisected(tmp_path: Path) -> None:
    """A corrupt GOTO (z = 1e7 mm, from the pipeline fuzzer): its sliders are kilometres beyond
    their travel. The limit check reports it; no bodies are placed there (on main the clearance
    bisected the metres-long moves for minutes and reported the legs meeting)."""
    from verne_post.api import joint_bounds, placeable

    text = ("PARTNO/FAR\nUNITS/MM\nLOADTL/1\nFEDRAT/MMPM,250\nGOTO/0,0,50,0,0,1\nGOTO/10,0,50,0,0,1\n"
            "GOTO/20,0,1e7,0,0,1\nGOTO/30,0,50,0,0,1\nGOTO/40,0,50,0,0,1\n")
    path = tmp_path / "far.cls"
    path.write_text(text)
    result = CliRunner().invoke(main, ["check", str(path), "--no-timing", "--tool-length", "50", "-q"])
    assert result.exit_code == 3
    assert f"{path}:7: slider rho1 = " in result.stderr and "meets" not in result.stderr
    machine = vp.load_machine()
    lower, _ = joint_bounds(machine)
    inside = np.where(np.isfinite(lower), lower, 0.0)
    joints = np.array([inside, inside - [3000.0, 0, 0, 0, 0], inside - [1000.0, 0, 0, 0, 0]])
    placed = placeable(machine, joints)
    assert np.isnan(placed[1]).all() and np.array_equal(placed[[0, 2]], joints[[0, 2]])


def test_a_block_that_turns_the_endless_table_a_million_turns_is_refused_in_one_line(tmp_path: Path) -> None:
    """C has no travel limit, so a corrupt C word (1e12 deg) is no limit violation; its block
    cannot be checked for bodies (it would be cut into 10^10 stretches): verify names the line and
    why in one finding, exit 3, instead of running out of memory (it tried 520 GiB before)."""
    x = np.linspace(-40.0, 40.0, 17)
    code, output, out = _run(tmp_path, _cl(_line_cut(x, 0.0)), "--work-offset", "0", "0", "200")
    assert code == 0, output
    lines = out.read_text().splitlines()
    moves = [k for k, line in enumerate(lines) if re.match(r"G1 .*C-?[\d.]+", line)]
    target = moves[len(moves) // 2]
    lines[target] = re.sub(r"C-?[\d.]+", "C1000000000000.0", lines[target])
    corrupt = tmp_path / "corrupt.nc"
    corrupt.write_text("\n".join(lines) + "\n")
    result = CliRunner().invoke(main, ["verify", str(corrupt)])
    assert result.exit_code == 3, result.output
    # the block into the corrupt end, or the one out of it (both turn the table as far)
    found = re.search(r"corrupt\.nc:(\d+): the block moves the sliders", result.output)
    assert found and int(found.group(1)) in (target + 1, target + 2), result.output
    assert "too far to check the bodies along it" in result.output and "Traceback" not in result.output
