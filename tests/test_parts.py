"""Posting a long program a part at a time (memory that does not grow with the program) must
give exactly what posting it all at once gives: the same G-code bytes, the same violations and
verification, however the program is split.

The whole-program route (``pipeline.postprocess`` then ``write_output``) solves, linearises,
checks, plans, formats and verifies every array of the program at once; ``pipeline.post`` carries
state across parts instead. The pieces that carry state are also checked against independent
routes: numpy's own ``unwrap``, ``str.splitlines``, and reading a program in one piece.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import verne_post as vp
import verne_post.pipeline as pipeline
from verne_post.cl import lexer
from verne_post.motion.branch import _unwrap
from verne_post.options import PostOptions
from verne_post.pipeline import post, postprocess, write_output
from verne_post.verify.gcode_reader import read_gcode
from verne_post.verify.verifier import Verifier, verify_program

EXAMPLES = Path(__file__).parent.parent / "examples"
NUMBERED = "  dialect: linuxcnc\n  block_numbers: {start: 7, step: 3}\n"


def _whole(tmp_path: Path, name: str, machine: vp.Machine, options: PostOptions) -> tuple[Path, object]:
    result = postprocess(EXAMPLES / name, machine, options)
    assert not result.violations
    target = tmp_path / "whole.nc"
    return target, write_output(result, machine, options, target)


@pytest.mark.parametrize(("name", "size", "numbered"), [
    ("impeller_5axis.cls", 1500, False),  # rapids, zig-zag passes without rapids, the pole crossed
    ("nx_variable_axis_inch.cls", 40, True),  # block numbers carried across parts
    ("nx_swarf_inch_crlf.cls", 25, False),
])
def test_parts_write_the_program_posted_whole(tmp_path: Path, name: str, size: int, numbered: bool) -> None:
    machine = vp.load_machine()
    if numbered:
        text = (Path(vp.__file__).parent / "machines" / "verne.yaml").read_text()
        assert "  dialect: linuxcnc\n" in text
        (tmp_path / "numbered.yaml").write_text(text.replace("  dialect: linuxcnc\n", NUMBERED))
        machine = vp.load_machine(tmp_path / "numbered.yaml")
    whole, verification = _whole(tmp_path, name, machine, PostOptions())
    target = tmp_path / "parts.nc"
    posted = post(EXAMPLES / name, machine, PostOptions(), target, part_poses=size)
    assert posted.parts > 3 and not posted.violations
    assert replace(posted.verification, source=verification.source) == verification
    assert target.read_bytes() == whole.read_bytes()
    if numbered:
        numbers = [int(n) for n in re.findall(r"^N(\d+) ", target.read_text(), re.M)]
        assert numbers == list(range(7, 7 + 3 * len(numbers), 3))


def test_parts_are_bounded_and_end_where_the_machine_stops(monkeypatch: pytest.MonkeyPatch) -> None:
    """No stage sees more poses than a part's window, and the cut passes of the impeller's blade
    flanks (no rapid between them) are split too: at poses that start a feed sequence."""
    solved: list[int] = []
    real = pipeline.solve_poses

    def spy(machine: vp.Machine, poses: object, *args: object, **kwargs: object) -> object:
        solved.append(len(poses))
        return real(machine, poses, *args, **kwargs)

    monkeypatch.setattr(pipeline, "solve_poses", spy)
    firsts: list[int] = []
    real_parts = pipeline._parts

    def parts(*args: object, **kwargs: object) -> object:
        for part in real_parts(*args, **kwargs):
            firsts.append(part.first)
            yield part

    monkeypatch.setattr(pipeline, "_parts", parts)
    machine = vp.load_machine()
    posted = post(EXAMPLES / "impeller_5axis.cls", machine, PostOptions(plan=False), None, part_poses=2000)
    assert max(solved) <= 2000 and len(posted.poses) > 15 * 2000
    poses = posted.poses
    inside = [k for k in firsts[1:] if not poses.rapid[k]]
    assert inside, "every part started at a rapid"
    assert any(poses.sequence[k] == poses.sequence[k - 1] for k in inside)  # within one cut


def test_parts_report_the_same_findings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the feed planning, and feed blocks made 3 % shorter than the programmed feeds allow,
    the NX variable-axis job fails its verification (tip too fast): split into parts, the same
    findings and figures."""
    durations = pipeline.block_durations
    monkeypatch.setattr(pipeline, "block_durations", lambda *args: 0.97 * durations(*args))
    machine = vp.load_machine()
    options = PostOptions(plan=False)
    _, verification = _whole(tmp_path, "nx_variable_axis_inch.cls", machine, options)
    assert not verification.ok
    posted = post(EXAMPLES / "nx_variable_axis_inch.cls", machine, options, tmp_path / "parts.nc", part_poses=30)
    assert posted.parts > 3
    assert replace(posted.verification, source=verification.source) == verification
    assert not (tmp_path / "parts.nc").exists()


def test_violations_in_any_part_write_nothing(tmp_path: Path) -> None:
    """A tilt limit that the impeller's blade flanks exceed (tilted up to 58 degrees): every
    violating line is named, as posted whole, and no file is left."""
    text = (Path(vp.__file__).parent / "machines" / "verne.yaml").read_text()
    limited = text.replace("theta1: {min: -90.0, max: 90.0", "theta1: {min: -56.0, max: 56.0")
    assert limited != text
    (tmp_path / "tilt56.yaml").write_text(limited)
    machine = vp.load_machine(tmp_path / "tilt56.yaml")
    whole = postprocess(EXAMPLES / "impeller_5axis.cls", machine, PostOptions(plan=False))
    assert whole.violations
    target = tmp_path / "part.nc"
    posted = post(EXAMPLES / "impeller_5axis.cls", machine, PostOptions(plan=False), target, part_poses=2000)
    assert posted.violations == whole.violations
    assert list(tmp_path.iterdir()) == [tmp_path / "tilt56.yaml"]


def test_unwrap_continues_numpy_unwrap_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        angles = np.cumsum(rng.normal(0.0, 1.5, rng.integers(2, 400)))
        wrapped = np.angle(np.exp(1j * angles))
        wrapped[rng.random(len(wrapped)) < 0.05] = np.pi  # the boundary case numpy treats apart
        whole = np.unwrap(wrapped)
        cut = int(rng.integers(1, len(wrapped)))
        first, added = _unwrap(wrapped[:cut], None, 0.0)
        second, _ = _unwrap(wrapped[cut:], float(wrapped[cut - 1]), float(added[-1]))
        assert np.array_equal(np.r_[first, second], whole)


def test_lines_a_block_at_a_time_are_the_lines(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(lexer, "_BLOCK", 7)
    rng = np.random.default_rng(3)
    for _ in range(300):
        text = "".join(rng.choice(["GOTO/1,2,3", "", "\n", "\r\n", "\r", "$$ x", " "], rng.integers(0, 40)))
        expected = text.splitlines()  # LF, CRLF and CR (the CL files' line ends) all end a line
        assert list(lexer.iter_lines(text)) == expected, repr(text)


def _program(tmp_path: Path) -> str:
    machine = vp.load_machine()
    result = postprocess(EXAMPLES / "nx_swarf_inch_crlf.cls", machine, PostOptions(plan=False))
    target = tmp_path / "p.nc"
    write_output(result, machine, PostOptions(plan=False), target, verify=False)
    return target.read_text()


def test_a_program_read_in_pieces_is_the_program_read_whole(tmp_path: Path) -> None:
    lines = _program(tmp_path).splitlines(keepends=True)
    whole = read_gcode("".join(lines))
    rng = np.random.default_rng(5)
    for _ in range(5):
        cuts = [0, *sorted(rng.choice(np.arange(1, len(lines)), 6, replace=False)), len(lines)]
        state, pieces = None, []
        for a, b in itertools.pairwise(cuts):
            piece = read_gcode("".join(lines[a:b]), state=state, final=b == len(lines))
            state = piece.state
            pieces.append(piece)
        for name in ("joints", "rapid", "inverse_time", "feed", "duration", "line", "tool", "tool_length"):
            joined = np.concatenate([getattr(p, name) for p in pieces])
            assert np.array_equal(joined, getattr(whole, name), equal_nan=joined.dtype.kind == "f"), name
        assert sum((p.tool_notes for p in pieces), ()) == whole.tool_notes
        assert (pieces[-1].end_line, pieces[-1].last_line) == (whole.end_line, whole.last_line)


def test_a_program_verified_in_pieces_is_verified_whole(tmp_path: Path) -> None:
    """Also a program with mistakes: a slider beyond its travel (and too fast), a G1 without F."""
    text = _program(tmp_path)
    moves = [k for k, line in enumerate(text.splitlines()) if line.startswith("G1 ")]
    lines = text.splitlines(keepends=True)
    lines[moves[40]] = re.sub(r"X(\S+)", "X1300.5000", lines[moves[40]])
    lines[moves[200]] = re.sub(r" F\S+", "", lines[moves[200]])
    machine = vp.load_machine()
    kwargs = {"source": "p.nc", "tol": 0.005, "axis_tol": 0.05, "work_offset": (0.0, 0.0, 0.0)}
    whole = verify_program("".join(lines), machine, **kwargs)
    assert not whole.ok
    rng = np.random.default_rng(11)
    cuts = [0, *sorted(rng.choice(np.arange(1, len(lines)), 9, replace=False)), len(lines)]
    verifier = Verifier(machine, **kwargs)
    for a, b in itertools.pairwise(cuts):
        verifier.read("".join(lines[a:b]), final=b == len(lines))
    assert verifier.result() == whole
