"""verne-post verify and the certification of every post run.

The programs are posted from the shipped examples; the mistakes are made in the G-code text
(as a person or another program would) and the finding must name the line that was changed.
The lines expected, and the blocks chosen for each mistake, are found here from the text, the
CL file and the forward kinematics, never from the verifier's own output. The reader is
compared with LinuxCNC's interpreter on randomly formatted programs.
"""

from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from verne_post.cl import read_toolpath
from verne_post.cli import main
from verne_post.errors import InputError
from verne_post.motion.linearise import distance_to_segment
from verne_post.verify.gcode_reader import read_gcode
from verne_post.verify.rs274 import find_rs274, inverse_time_rate, run_rs274
from verne_post.verify.verifier import Finding, verify_program

EXAMPLES = Path(__file__).parent.parent / "examples"
NAMES = ["nx_variable_axis_inch", "nx_swarf_inch_crlf", "impeller_5axis"]
MISTAKES = "nx_variable_axis_inch"  # the example the mistakes are made in
_MOVE = re.compile(r"^G([01]) X(\S+) Y(\S+) Z(\S+) A(\S+) C(\S+)")


@pytest.fixture(scope="module")
def posted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Every example posted the normal way (verification on)."""
    folder = tmp_path_factory.mktemp("posted")
    out = {}
    for name in NAMES:
        target = folder / f"{name}.nc"
        result = CliRunner().invoke(main, [str(EXAMPLES / f"{name}.cls"), "-o", str(target), "--quiet"])
        assert result.exit_code == 0, result.output
        out[name] = target
    return out


def _no_nan(text: str) -> dict:
    def refuse(constant: str) -> None:
        raise AssertionError(f"{constant} in the JSON report")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize("name", NAMES)
def test_every_example_program_passes(posted: dict[str, Path], tmp_path: Path, name: str) -> None:
    text = posted[name].read_text()
    certificate = re.search(r"^\(VERIFIED: MAX TIP DEVIATION (\S+) MM, MAX AXIS DEVIATION (\S+) DEG, MAX RAPID "
                            r"DEVIATION (\S+) MM, ALL LIMITS HELD, NO BODIES MEET\)$", text, re.M)
    assert certificate is not None
    assert float(certificate.group(1)) <= 0.005 and float(certificate.group(2)) <= 0.05
    assert float(certificate.group(3)) <= 0.5
    report = tmp_path / "r.json"
    result = CliRunner().invoke(main, ["verify", str(posted[name]), "--against", str(EXAMPLES / f"{name}.cls"),
                                       "--report", str(report)])
    assert result.exit_code == 0, result.output
    data = _no_nan(report.read_text())
    assert data["ok"] and data["findings"] == []
    assert data["cl_points_reached"] == data["cl_points"] == len(read_toolpath(EXAMPLES / f"{name}.cls"))
    # The certificate is what reading the written file gives (its own header line aside).
    assert f"{data['max_tip_deviation_mm']:.4f}" == certificate.group(1)


def test_without_cl_path_limits_only_and_json_nulls(posted: dict[str, Path], tmp_path: Path) -> None:
    report = tmp_path / "r.json"
    result = CliRunner().invoke(main, ["verify", str(posted["nx_swarf_inch_crlf"]), "--report", str(report)])
    assert result.exit_code == 0, result.output
    data = _no_nan(report.read_text())
    assert data["max_tip_deviation_mm"] is None and data["against"] is None and data["cl_points"] is None


def test_sampling_bounds_the_deviation_between_samples(posted: dict[str, Path]) -> None:
    """64 samples per feed block, distance to the nearest of all CL segments (a lower bound of the
    distance to the segments the block belongs to): never above the verifier's figure."""
    machine = vp.load_machine()
    name = "nx_swarf_inch_crlf"
    text = posted[name].read_text()
    cl = read_toolpath(EXAMPLES / f"{name}.cls")
    verification = verify_program(text, machine, against=cl)
    program = read_gcode(text)
    feed = np.flatnonzero(~program.rapid[1:]) + 1
    f = (np.arange(64) + 0.5) / 64
    rows, frac = np.repeat(feed, len(f)), np.tile(f, len(feed))
    q = program.joints[rows - 1] + frac[:, None] * (program.joints[rows] - program.joints[rows - 1])
    tip = vp.forward_kinematics(machine, q, tool_length=program.tool_length[rows]).tip
    dense = np.full(len(tip), np.inf)
    for s in range(1, len(cl.tip)):
        a, b = np.broadcast_to(cl.tip[s - 1], tip.shape), np.broadcast_to(cl.tip[s], tip.shape)
        dense = np.minimum(dense, distance_to_segment(tip, a, b))
    assert dense.max() > 0.5 * verification.tol  # the blocks do bend away from the path
    assert dense.max() <= verification.tip_deviation <= verification.tol


# ---------------------------------------------------------------------------------------------
# mistakes, each found at its line


@pytest.fixture(scope="module")
def program_text(posted: dict[str, Path]) -> list[str]:
    return posted[MISTAKES].read_text().splitlines()


@pytest.fixture(scope="module")
def cl_path() -> vp.Toolpath:
    return read_toolpath(EXAMPLES / f"{MISTAKES}.cls")


def _moves(lines: list[str]) -> list[tuple[int, list[float], bool]]:
    """(0-based line index, X Y Z A C, feed) of every motion block, read with a plain regex."""
    out = []
    for i, line in enumerate(lines):
        match = _MOVE.match(line)
        if match:
            out.append((i, [float(v) for v in match.groups()[1:]], match.group(1) == "1"))
    return out


def _findings(lines: list[str], cl: vp.Toolpath) -> list[Finding]:
    verification = verify_program("\n".join(lines) + "\n", vp.load_machine(), against=cl)
    assert not verification.ok
    return list(verification.findings)


def _fk(values: list[list[float]], tool_length: float) -> np.ndarray:
    joints = np.array(values)
    joints[:, 3:] = np.radians(joints[:, 3:])
    return vp.forward_kinematics(vp.load_machine(), joints, tool_length=tool_length).tip


def _tool_length(lines: list[str]) -> float:
    lengths = {float(m.group(1)) for m in (re.match(r"\(TOOL \d+ LENGTH (\S+) DELTA", x) for x in lines) if m}
    assert len(lengths) == 1
    return lengths.pop()


def _middle_feed_block(moves: list, condition: object = lambda values: True) -> int:
    """Index into ``moves`` of a feed block in the middle of a feed run whose values pass ``condition``."""
    chosen = [k for k in range(1, len(moves) - 1) if moves[k - 1][2] and moves[k][2] and moves[k + 1][2]
              and condition(moves[k][1])]
    return chosen[len(chosen) // 2]


def test_slider_off_by_50_micrometres(program_text: list[str], cl_path: vp.Toolpath) -> None:
    moves = _moves(program_text)
    k = _middle_feed_block(moves)
    i = moves[k][0]
    x = float(re.search(r"X(\S+)", program_text[i]).group(1))
    changed = program_text.copy()
    changed[i] = re.sub(r"X\S+", f"X{x + 0.05:.4f}", program_text[i])
    found = _findings(changed, cl_path)
    lines = {f.line for f in found}
    assert i + 1 in lines and lines <= {i + 1, moves[k + 1][0] + 1}  # the block and the move out of it
    assert {"tip"} <= {f.kind for f in found if f.line == i + 1}


def test_rotary_sign_flipped(program_text: list[str], cl_path: vp.Toolpath) -> None:
    moves = _moves(program_text)
    k = _middle_feed_block(moves, lambda v: abs(v[3]) > 5 and abs(v[4]) > 5)
    i = moves[k][0]
    changed = program_text.copy()
    changed[i] = re.sub(r"C(-?)(\S+)", lambda m: f"C{'' if m.group(1) else '-'}{m.group(2)}", program_text[i])
    assert changed[i] != program_text[i]
    found = _findings(changed, cl_path)
    lines = {f.line for f in found}
    assert i + 1 in lines and lines <= {i + 1, moves[k + 1][0] + 1}


def test_block_deleted_from_a_curved_pass(program_text: list[str], cl_path: vp.Toolpath) -> None:
    moves = _moves(program_text)
    tips = _fk([v for _, v, _ in moves], _tool_length(program_text))
    # a feed block ending on a CL point where the path bends by more than 0.1 mm
    on_cl = np.linalg.norm(tips[:, None, :] - cl_path.tip[None, :, :], axis=2).min(axis=1) < 1e-3
    bend = np.r_[0.0, distance_to_segment(tips[1:-1], tips[:-2], tips[2:]), 0.0]
    chosen = [j for j in range(1, len(moves) - 1) if moves[j - 1][2] and moves[j][2] and moves[j + 1][2]
              and on_cl[j] and bend[j] > 0.1]
    k = chosen[len(chosen) // 2]
    i = moves[k][0]
    cl_line = int(cl_path.line[np.argmin(np.linalg.norm(cl_path.tip - tips[k], axis=1))])
    changed = program_text[:i] + program_text[i + 1:]
    found = _findings(changed, cl_path)
    spanning = moves[k + 1][0]  # the next block, one line up now
    assert {f.line for f in found} == {spanning}
    assert any(f.kind == "reach" and f.cl_line == cl_line for f in found)
    assert any(f.kind == "tip" for f in found)


def test_wrong_delta(program_text: list[str], cl_path: vp.Toolpath) -> None:
    i = next(i for i, line in enumerate(program_text) if re.match(r"\(TOOL \d+ LENGTH", line))
    changed = program_text.copy()
    changed[i] = re.sub(r"DELTA ([\d.]+)", lambda m: f"DELTA {float(m.group(1)) + 1.0:.4f}", program_text[i])
    found = _findings(changed, cl_path)
    assert [(f.line, f.kind) for f in found] == [(i + 1, "tool")]


def test_feed_word_20_percent_too_fast(program_text: list[str], cl_path: vp.Toolpath) -> None:
    moves = _moves(program_text)
    tips = _fk([v for _, v, _ in moves], _tool_length(program_text))
    feed_words = [float(re.search(r"F(\S+)", program_text[i]).group(1)) if f else np.nan for i, _, f in moves]
    # tip speed (chord over the G93 duration 1/F min) against the CL feed (FEDRAT 10 IPM)
    programmed = float(np.nanmax(cl_path.feed))
    chord = np.r_[np.nan, np.linalg.norm(np.diff(tips, axis=0), axis=1)]
    speed = chord * np.array(feed_words)
    chosen = [j for j in range(1, len(moves) - 1) if moves[j][2] and speed[j] > 0.97 * programmed]
    k = chosen[len(chosen) // 2]
    i = moves[k][0]
    changed = program_text.copy()
    changed[i] = re.sub(r"F(\S+)", f"F{feed_words[k] * 1.2:.5f}", program_text[i])
    found = _findings(changed, cl_path)
    assert {f.line for f in found} == {i + 1}
    assert "feed" in {f.kind for f in found}


def test_program_cut_off_before_m30(program_text: list[str], tmp_path: Path) -> None:
    end = program_text.index("M30")
    path = tmp_path / "cut.nc"
    path.write_text("\n".join(program_text[:end]) + "\n")
    result = CliRunner().invoke(main, ["verify", str(path), "--against", str(EXAMPLES / f"{MISTAKES}.cls")])
    assert result.exit_code == 3
    assert f"cut.nc:{end}: the program ends without M2/M30" in result.output


def test_failed_verification_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A writer that put a wrong number in the text: the post run stops with exit 3, no file."""
    from verne_post.output.gcode import GcodeWriter

    real = GcodeWriter.body

    def corrupted(*args: object) -> list[str]:
        text = "".join(real(*args))
        # the first block of a cut (not of a move between cuts, whose rules allow a millimetre high up)
        return [re.sub(r"^(G1 X)(\d+)(?![^\n]*\(RAPID\))", lambda m: m.group(1) + str(int(m.group(2)) + 1), text,
                       count=1, flags=re.M)]

    monkeypatch.setattr(GcodeWriter, "body", corrupted)
    target = tmp_path / "part.nc"
    result = CliRunner().invoke(main, [str(EXAMPLES / "nx_swarf_inch_crlf.cls"), "-o", str(target), "--quiet"])
    assert result.exit_code == 3
    assert "fails its verification: nothing written" in result.output
    assert not target.exists() and list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# the reader


def test_reader_durations_follow_the_rs274_feed_rule() -> None:
    """G94: F along the XYZ path, or in degrees per minute when only A/C move; G93: 1/F min;
    G94 cancels the feed rate; G20 makes lengths and feeds inches (RS-274/NGC, LinuxCNC)."""
    text = """%
G21 G90 G94
G0 X0 Y0 Z0 A0 C0
G1 X3 Y4 F100 (5 mm at 100 mm/min: 3 s)
G1 C90 F180 (rotary only: 90 deg at 180 deg/min: 30 s)
G93 G1 X6 Y8 A10 F2 (inverse time: 1/2 min)
G94 G1 X7
G20 G1 Z1 F10 (1 inch at 10 inch/min: 6 s)
M30
%
"""
    program = read_gcode(text)
    np.testing.assert_allclose(program.duration[1:4], [3.0, 30.0, 30.0])
    assert program.problems == ((7, "G1 with no feed rate (no F since the start or since G94)"),)
    assert np.isnan(program.duration[4])
    assert program.duration[5] == pytest.approx(6.0)
    np.testing.assert_allclose(program.joints[5, :3], [7.0, 8.0, 25.4])
    assert program.end_line == 9 and program.line.tolist() == [3, 4, 5, 6, 7, 8]


def _random_text(seed: int, spaces_in_numbers: bool, blocks: int = 300) -> str:
    """A program in many spellings of the same RS-274: case, spaces (inside numbers too), word
    order, N numbers, comments, blank lines, modal words left out, G93/G94 switches."""
    rng = np.random.default_rng(seed)

    def number(value: float) -> str:
        decimals = int(rng.integers(0, 6))
        text = f"{value:.{decimals}f}"
        if rng.random() < 0.2 and "." in text and abs(value) < 1:
            text = text.replace("0.", ".", 1)
        if rng.random() < 0.1 and value >= 0:
            text = "+" + text
        if rng.random() < 0.1:
            text = "0" + text if not text.startswith(("-", "+")) else text
        if spaces_in_numbers and rng.random() < 0.05 and len(text) > 2:
            text = text[:2] + " " + text[2:]
        elif rng.random() < 0.05:
            text = " " + text  # a space between the letter and its number
        return text

    def spell(words: list[str]) -> str:
        rng.shuffle(words)
        line = (" " if rng.random() < 0.5 else "").join(words)
        if rng.random() < 0.2:
            line = line.lower()
        if rng.random() < 0.2:
            line = f"N{int(rng.integers(1, 99999))} " + line
        if rng.random() < 0.15:
            line += " (a comment; with F1 X2 in it)"
        if rng.random() < 0.1:
            line += " ; trailing note"
        return line

    lines = ["%", "(random program)", spell(["G21", "G90", "G17", "G40", "G49", "G94"])]
    inverse = False
    feed_known = False
    motion = None
    for k in range(blocks):
        if rng.random() < 0.05:
            inverse = not inverse
            lines.append(spell(["G93" if inverse else "G94"]))
            feed_known = False
        words = []
        g = "G0" if rng.random() < 0.15 else "G1"
        if g != motion or rng.random() < 0.5:
            words.append(g)
        motion = g
        values = [rng.uniform(0, 1300), rng.uniform(0, 1300), rng.uniform(0, 1300), rng.uniform(-90, 90),
                  rng.uniform(-720, 720)]
        for letter, value in zip("XYZAC", values, strict=True):
            if k == 0 or rng.random() < 0.7:
                words.append(letter + number(value))
        if g == "G1" and (inverse or not feed_known or rng.random() < 0.3):
            words.append("F" + number(rng.uniform(1, 5000)))
            feed_known = True
        lines.append(spell(words))
        if rng.random() < 0.05:
            lines.append("")
    lines += ["M5 M9", "G94", "M30", "%"]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(("seed", "spaces_in_numbers"), [(1, False), (2, False), (3, True)])
def test_reader_agrees_with_linuxcnc(tmp_path: Path, seed: int, spaces_in_numbers: bool) -> None:
    exe = find_rs274()
    if exe is None:
        pytest.fail("LinuxCNC's rs274 is needed: apt-get install linuxcnc-uspace", pytrace=False)
    text = _random_text(seed, spaces_in_numbers)
    path = tmp_path / "random.ngc"
    path.write_text(text)
    interpreted = run_rs274(path, tool_numbers=[], executable=exe)
    program = read_gcode(text)
    assert program.problems == ()
    assert len(program) == len(interpreted.moves)
    ours = np.column_stack([program.joints[:, :3], np.degrees(program.joints[:, 3:])])
    np.testing.assert_allclose(ours, interpreted.moves[:, [0, 1, 2, 3, 5]], atol=0.5e-4 + 1e-9)
    assert np.array_equal(program.rapid, interpreted.kinds == 0)
    feed = ~program.rapid
    assert np.array_equal(program.inverse_time[feed], interpreted.feed_modes[feed] == 1)
    per_minute = feed & ~program.inverse_time
    np.testing.assert_allclose(program.feed[per_minute], interpreted.feed_rates[per_minute], atol=0.5e-4 + 1e-9)
    inverse = np.flatnonzero(feed & program.inverse_time)
    inverse = inverse[inverse > 0]
    rate = inverse_time_rate(interpreted.moves[inverse - 1], interpreted.moves[inverse], program.feed[inverse])
    big = rate > 1.0  # rs274 reports max(0.1, L * F) from its 4-decimal positions
    np.testing.assert_allclose(rate[big], interpreted.feed_rates[inverse][big], rtol=1e-3)


@pytest.mark.parametrize(("text", "line", "reason"), [
    ("G21 G90\nG0 X1 Y1 Z1 A0 C0\nG2 X2 Y2 I1 J0 F100\nM30\n", 3, "G2 is not supported"),
    ("G21\nG91\nG0 X1\nM30\n", 2, "G91 is not supported"),
    ("G0 X1 Y1 Z1 A0 C0\nG0 B10\nM30\n", 2, "word B10"),
    ("G0 X1 Y1 Z1 A0 C0 (unclosed\nM30\n", 1, "parenthesis"),
    ("G0 X1 Y1 Z1 A0 C0\nG1 X#1 F10\nM30\n", 2, "cannot read"),
    ("X1 Y1\nM30\n", 1, "without a motion mode"),
    ("G0 X1 X2\nM30\n", 1, "two X words"),
])
def test_reader_refuses_what_it_cannot_read(text: str, line: int, reason: str) -> None:
    with pytest.raises(InputError, match=reason) as error:
        read_gcode(text, "p.nc")
    assert error.value.line == line


def test_unreadable_program_is_a_one_line_error(tmp_path: Path) -> None:
    path = tmp_path / "arc.nc"
    path.write_text("G21 G90\nG0 X1 Y1 Z1 A0 C0\nG3 X2 Y2 R5 F100\nM30\n")
    result = CliRunner().invoke(main, ["verify", str(path)])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [f"verne-post: error: {path}:3: G3 is not supported: a joint-space "
                                                  f"program uses G0/G1 in absolute distance (G90) without offsets"]


def test_tilt_beyond_its_travel(program_text: list[str], cl_path: vp.Toolpath) -> None:
    moves = _moves(program_text)
    k = _middle_feed_block(moves)
    i = moves[k][0]
    changed = program_text.copy()
    changed[i] = re.sub(r"A\S+", "A95.00000", program_text[i])
    found = [f for f in _findings(changed, cl_path) if f.kind == "limit"]
    assert (found[0].line, found[0].value, found[0].limit) == (i + 1, 95.0, 90.0)  # degrees, as the machine file
    # the move out of it comes back from 95 degrees: beyond 90 until partway
    assert [f.line for f in found[1:]] == [moves[k + 1][0] + 1] and 90.0 < found[1].value < 95.0


def test_inverse_time_moves_and_turns_on_the_spot(tmp_path: Path) -> None:
    """FEDRAT/INVERS,10: the 10 mm move takes 6 s; the turn on the spot that follows runs at the
    machine's timing.rotary_feed. Faster F words on either are found at their lines."""
    cl = tmp_path / "it.cls"
    cl.write_text("UNITS/MM\nMULTAX/ON\nTLDATA/MILL,10,0,80,0,0\nLOAD/TOOL,1\nFEDRAT/MMPM,1000\n"
                  "GOTO/0,0,50,0,0,1\nFEDRAT/INVERS,10\nGOTO/10,0,50,0,0,1\nGOTO/10,0,50,0.2,0,0.98\nFINI\n")
    target = tmp_path / "it.nc"
    assert CliRunner().invoke(main, [str(cl), "-o", str(target), "--quiet"]).exit_code == 0
    lines = target.read_text().splitlines()
    feeds = [i for i, line in enumerate(lines) if line.startswith("G1 ") and not line.endswith("(RAPID)")]
    moves = _moves(lines)
    tips = _fk([v for _, v, _ in moves], 80.0)
    # the first feed block covers the whole 10 mm move (its end is on the second CL point)
    first = feeds[0]
    assert np.linalg.norm(tips[[i for i, _, _ in moves].index(first)] - [10, 0, 50]) < 1e-3
    turn = feeds[len(feeds) // 2]  # a block of the turn on the spot
    toolpath = read_toolpath(cl)
    for i, factor, cl_line in ((first, 1.5, 8), (turn, 2.0, 9)):
        changed = lines.copy()
        changed[i] = re.sub(r"F(\S+)", lambda m, f=factor: f"F{float(m.group(1)) * f:.5f}", lines[i])
        found = _findings(changed, toolpath)
        assert [(f.line, f.kind, f.cl_line) for f in found if f.kind != "joint_speed"] == [(i + 1, "feed", cl_line)]


def test_tool_length_from_the_command_line_is_in_the_program(tmp_path: Path) -> None:
    """Poses with no tool in the file and --tool-length: the program says which length its
    joints are for (DELTA = spindle nose 495.8 + 50 mm), so that it can be verified from its text."""
    source = tmp_path / "poses.csv"
    source.write_text("x,y,z,i,j,k,feed\n0,0,50,0,0,1,1000\n10,0,50,0.1,0,0.995,1000\n")
    target = tmp_path / "p.nc"
    result = CliRunner().invoke(main, [str(source), "-o", str(target), "--tool-length", "50", "--quiet"])
    assert result.exit_code == 0, result.output
    assert "(TOOL 0 LENGTH 50.0000 DELTA 545.8000)" in target.read_text().splitlines()


def test_near_finds_every_pair_within_the_radius_in_each_coordinate() -> None:
    """_near (a hashed grid) against every pair tested one by one: clusters, exact repeats, pairs
    exactly the radius apart, points on the grid's cell sides, negative and large coordinates."""
    from verne_post.verify.cl_path import _CELL, _near

    rng = np.random.default_rng(5)
    for _ in range(60):
        radius = 10.0 ** rng.uniform(-4, 0)
        size = _CELL * radius
        centres = rng.uniform(-1e3, 1e3, (int(rng.integers(1, 6)), 6))
        points = centres[rng.integers(0, len(centres), 300)] + rng.normal(0, radius, (300, 6))
        points[:20] = np.round(points[:20] / size) * size  # on cell sides
        queries = np.concatenate([points[rng.integers(0, 300, 100)] + rng.normal(0, radius, (100, 6)),
                                  points[:50] + radius * rng.choice([-1.0, 0.0, 1.0], (50, 6)),  # at the radius
                                  points[:10]])  # repeats
        pair = set(zip(*(a.tolist() for a in _near(queries, points, radius)), strict=True))
        far = np.max(np.abs(queries[:, None, :] - points[None, :, :]), axis=2)
        expected = set(zip(*(a.tolist() for a in np.nonzero(far <= radius)), strict=True))
        assert expected <= pair, sorted(expected - pair)[:5]


def test_cl_points_take_the_earliest_block_at_or_after_the_one_before() -> None:
    """_match against a brute-force reading of its rule on paths that pass points many times (more
    than the k-d tree's first candidates), with blocks missing and out of order: every CL pose takes
    the earliest block end within tolerance at or after the block the pose before took, else the
    last such block; -1 where none is within tolerance."""
    from types import SimpleNamespace

    from verne_post.verify.cl_path import _angle, _match

    rng = np.random.default_rng(21)
    tol, axis_tol = 0.005, np.radians(0.05)
    for _ in range(20):
        spots = rng.uniform(-50, 50, (12, 3))
        normals = rng.normal(size=(12, 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        visits = rng.integers(0, 12, 300)  # a CL path over 12 spots, each passed ~25 times
        cl_tip = spots[visits] + rng.normal(0, tol / 4, (300, 3))
        cl_axis = normals[visits]
        order = np.arange(300)
        swap = rng.integers(0, 299, 15)  # some blocks out of order, some CL points never reached
        order[swap], order[swap + 1] = order[swap + 1], order[swap]
        order = order[rng.random(300) > 0.05]
        ends = SimpleNamespace(tip=spots[visits[order]] + rng.normal(0, tol / 4, (len(order), 3)),
                               axis=normals[visits[order]], reachable=rng.random(len(order)) > 0.02)
        known = rng.random(len(order)) > 0.02
        matched = _match(SimpleNamespace(tip=cl_tip, axis=cl_axis), ends, known, tol, axis_tol)
        previous, expected = -1, np.full(300, -1)
        for p in range(300):
            near = np.flatnonzero(known & ends.reachable & (np.linalg.norm(ends.tip - cl_tip[p], axis=1) <= tol)
                                  & (_angle(ends.axis, cl_axis[p]) <= axis_tol))
            if near.size:
                later = near[near >= previous]
                previous = expected[p] = later[0] if later.size else near[-1]
        np.testing.assert_array_equal(matched, expected)


# ---------------------------------------------------------------------------------------------
# a program that does not follow its CL path (another CL file, machine file or work offset)

_PEAK = 1 << 30  # bytes: the peak resident memory a verification may take (the bound, 1 GB)
_CAP = 4 << 30  # bytes of address space: a run that would need more stops (MemoryError) instead of the machine


def _verify_bounded(program: Path, *args: str) -> tuple[int, str]:
    """``verne-post verify`` in a process of its own, its address space capped; its exit status
    and stderr, after checking that its peak resident memory (the kernel's) stayed under 1 GiB."""
    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (_CAP, _CAP))

    process = subprocess.Popen([sys.executable, "-m", "verne_post", "verify", str(program), *args],
                               stderr=subprocess.PIPE, text=True, preexec_fn=cap,
                               env={**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"})
    stderr = process.stderr.read() if process.stderr else ""
    _, status, usage = os.wait4(process.pid, 0)
    assert usage.ru_maxrss * 1024 < _PEAK, f"peak {usage.ru_maxrss >> 10} MiB"
    return os.waitstatus_to_exitcode(status), stderr


@pytest.mark.parametrize("args", [["--against", str(EXAMPLES / "nx_swarf_inch_crlf.cls")],
                                  ["--against", str(EXAMPLES / "impeller_5axis.cls"), "--work-offset", "1", "0", "0"]],
                         ids=["another CL file", "another work offset"])
def test_a_program_that_follows_another_path_says_so_first(posted: dict[str, Path], tmp_path: Path,
                                                          args: list[str]) -> None:
    """The impeller's program checked against the wrong CL file, or 1 mm off: the poses are not
    reached at all; one line says so, with the counts, in a bounded process."""
    report = tmp_path / "r.json"
    status, stderr = _verify_bounded(posted["impeller_5axis"], *args, "--report", str(report))
    assert status == 3, stderr[-2000:]
    first = stderr.splitlines()[0]
    poses = len(read_toolpath(args[1]))
    assert re.search(rf"impeller_5axis\.nc:\d+: 0 of {poses} CL points reached: .*another CL file, machine file "
                     r"or work offset\?$", first), first
    assert "rapid where the CL path feeds" not in stderr
    data = _no_nan(report.read_text())
    assert data["cl_points_reached"] == 0 and data["findings"][0]["kind"] == "mismatch"


def test_a_program_that_leaves_its_path_midway_stays_bounded(posted: dict[str, Path], tmp_path: Path) -> None:
    """The last 40 % of the impeller's feed blocks moved 1 mm in X: the first finding is where it
    leaves the path, and the rest (thousands of poses, each a finding) fits in the bounded process."""
    lines = posted["impeller_5axis"].read_text().splitlines()
    start = int(0.6 * len(lines))
    moved = [re.sub(r"^(G1 X)(-?[\d.]+)", lambda m: f"{m.group(1)}{float(m.group(2)) + 1.0:.4f}", line)
             if i >= start else line for i, line in enumerate(lines)]
    program = tmp_path / "moved.nc"
    program.write_text("\n".join(moved) + "\n")
    report = tmp_path / "r.json"
    status, stderr = _verify_bounded(program, "--against", str(EXAMPLES / "impeller_5axis.cls"), "--report",
                                     str(report))
    assert status == 3, stderr[-2000:]
    data = _no_nan(report.read_text())
    first_moved = next(i + 1 for i in range(start, len(lines)) if moved[i] != lines[i])
    assert first_moved - 1 <= data["findings"][0]["line"] <= first_moved + 1
    assert 0 < data["cl_points_reached"] < data["cl_points"]
