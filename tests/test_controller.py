"""Controller profiles: the ``controller:`` section of a machine file, the programs written with
it, and ``verify`` reading them back with the same profile.

The programs are judged with the test's own regular expressions and with facts from outside
the writer: the machine file's geometry (Delta = spindle nose + tool length), the CL file's
tools and spindle speeds, the vendor manuals' syntax (see ``verne_post/output/controller.py``).
"""

from __future__ import annotations

import itertools
import json
import re
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import verne_post as vp
from verne_post.cl import read_cl
from verne_post.cli import main
from verne_post.errors import InputError
from verne_post.options import PostOptions
from verne_post.output.controller import DIALECTS, LINUXCNC
from verne_post.pipeline import post
from verne_post.placement.machine_facts import schema
from verne_post.verify.gcode_reader import read_gcode
from verne_post.verify.rs274 import run_rs274
from verne_post.verify.verifier import verify_program

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "verne_post" / "machines" / "verne.yaml"
DIALECT_LINE = "  dialect: linuxcnc\n"

# Three tools, spindle speeds and coolant: LOADTL carries each tool's gauge length (mm).
TOOLS_CL = """PARTNO/BRACKET 7
UNITS/MM
LOADTL/1,LENGTH,60.0
SPINDL/RPM,8000,CLW
COOLNT/ON
FEDRAT/MMPM,500.0
RAPID
GOTO/0.0,0.0,20.0,0.0,0.0,1.0
GOTO/0.0,0.0,0.0,0.0,0.0,1.0
GOTO/30.0,0.0,0.0,0.0,0.0,1.0
LOADTL/2,LENGTH,100.0
SPINDL/RPM,12500,CCLW
COOLNT/MIST
RAPID
GOTO/30.0,30.0,20.0,0.0,0.0,1.0
GOTO/30.0,30.0,0.0,0.0,0.0,1.0
GOTO/0.0,30.0,0.0,0.0,0.0,1.0
LOADTL/5,LENGTH,80.0
RAPID
GOTO/10.0,10.0,20.0,0.0,0.0,1.0
GOTO/10.0,10.0,0.0,0.0,0.0,1.0
GOTO/20.0,10.0,0.0,0.0,0.0,1.0
"""
TOOLS = {1: 60.0, 2: 100.0, 5: 80.0}
SPEEDS = {1: 8000, 2: 12500, 5: 12500}  # tool 5: no SPINDL of its own, the speed in force carries on


def _machine_file(tmp_path: Path, controller: str, name: str = "m.yaml") -> Path:
    text = SHIPPED.read_text()
    assert DIALECT_LINE in text
    path = tmp_path / name
    path.write_text(text.replace(DIALECT_LINE, controller))
    return path


def _post(tmp_path: Path, controller: str) -> tuple[vp.Machine, Path, str]:
    cl = tmp_path / "part.cls"
    cl.write_text(TOOLS_CL)
    machine = vp.load_machine(_machine_file(tmp_path, controller))
    target = tmp_path / "part.nc"
    posted = post(cl, machine, PostOptions(), target)
    assert not posted.violations and posted.verification is not None and posted.verification.ok
    return machine, cl, target.read_text() if target.exists() else ""


def _code(line: str) -> str:
    """A line without its comment (either style) and block number."""
    return re.sub(r"^N\d+\s*", "", re.sub(r"\([^()]*\)|;.*", "", line)).strip()


CUSTOM = """  dialect: linuxcnc
  axes: {rho1: U, rho2: V, rho3: W, theta1: B, theta2: C}
  comment: semicolon
  program_start: ["G21 G90 G17 G40 G49 G94", "M11 ; table unclamped", "G64 P{tolerance:.4f} Q0"]
  program_end: ["M5 M9", "M12", "G94", "M30"]
  tool_change: ["T{tool} M6", "; DELTA {delta} MM FOR TOOL {tool}"]
  block_numbers: {start: 100, step: 5}
"""


def test_a_profile_with_other_letters_comments_lines_and_numbers_is_followed_and_certified(tmp_path: Path) -> None:
    """The issue's scenario: U V W B C, ';' comments, custom start and end lines, a tool change
    with {tool} and {delta}, block numbers from 100 by 5."""
    machine, cl, text = _post(tmp_path, CUSTOM)
    lines = text.splitlines()
    assert lines[0] == "%" and lines[-1] == "%"
    body = lines[1:-1]
    comments = [line for line in body if line.startswith(";")]
    blocks = [line for line in body if not line.startswith(";")]
    assert comments and all("(" not in _code(c) for c in body)
    # block numbers on every block, from 100 by 5; comment lines have none
    assert [int(re.match(r"N(\d+) ", b).group(1)) for b in blocks] == list(range(100, 100 + 5 * len(blocks), 5))
    codes = [_code(b) for b in blocks]
    # the start lines right after the header, the end lines last
    assert codes[:2] == ["G21 G90 G17 G40 G49 G94", "M11"]
    assert codes[-4:] == ["M5 M9", "M12", "G94", "M30"]
    # every motion block moves U V W B C, never X Y Z A
    motion = [c for c in codes if re.match(r"G[01] ", c)]
    assert len(motion) > 20
    words = "".join(rf" {letter}-?\d+\.\d+" for letter in "UVWBC")
    for c in motion:
        assert re.fullmatch(rf"G[01]{words}( F\d+\.\d+)?", c), c
    assert not any(re.search(r"(?<![A-Z])[XYZA]-?\d", c) for c in codes)
    # the tool changes: T M6, then the Delta of the machine file's geometry for that tool
    nose = machine.geometry.spindle_nose
    changes = [(k, int(m.group(1))) for k, b in enumerate(body) if (m := re.fullmatch(r"N\d+ T(\d+) M6", b))]
    assert [tool for _, tool in changes] == list(TOOLS)
    for k, tool in changes:  # a comment line of the profile: no block number (docs/controllers.md)
        assert body[k + 1] == f"; DELTA {nose + TOOLS[tool]:.4f} MM FOR TOOL {tool}"
    # moves between cuts carry the mark in the profile's style
    assert any(b.endswith(" ; RAPID") for b in blocks) and "(RAPID)" not in text
    # verify reads it with the profile, and certifies it against the CL path
    assert verify_program(text, machine, against=read_cl(cl)).ok
    # the default profile cannot read it: the profile is what makes the letters axes
    with pytest.raises(InputError, match="word U"):
        read_gcode(text, controller=LINUXCNC)


def test_a_profile_changes_how_the_program_reads_not_where_the_machine_goes(tmp_path: Path) -> None:
    """The same part posted with the default profile and with another: the reader finds the same
    joint positions, durations and moves between cuts in both."""
    (tmp_path / "a").mkdir()
    default_machine, _, default = _post(tmp_path / "a", DIALECT_LINE)
    machine, _, custom = _post(tmp_path, CUSTOM)
    a = read_gcode(default, controller=default_machine.controller.profile())
    b = read_gcode(custom, controller=machine.controller.profile())
    assert np.array_equal(a.joints, b.joints, equal_nan=True)
    assert np.array_equal(a.duration, b.duration, equal_nan=True)
    assert np.array_equal(a.rapid, b.rapid) and np.array_equal(a.tool, b.tool)


def test_the_default_profile_is_accepted_by_rs274(tmp_path: Path) -> None:
    """LinuxCNC's interpreter runs the default profile's program to its end, every block a move."""
    _, _, text = _post(tmp_path, DIALECT_LINE)
    result = run_rs274(tmp_path / "part.nc", tool_numbers=TOOLS)
    assert len(result.moves) == len(re.findall(r"^G[01] ", text, re.M))


@pytest.mark.parametrize("placeholder", ["tool", "length", "delta", "spindle", "name", "program"])
def test_every_placeholder_is_filled_with_its_value(tmp_path: Path, placeholder: str) -> None:
    controller = (f"  dialect: linuxcnc\n  program_number: 4711\n"
                  f"  tool_change: [\"T{{tool}} M6\", \"(VALUE {{{placeholder}}})\"]\n")
    machine, _, text = _post(tmp_path, controller)
    values = re.findall(r"^\(VALUE (.*)\)$", text, re.M)
    nose = machine.geometry.spindle_nose
    expected = {
        "tool": [str(t) for t in TOOLS],
        "length": [f"{length:.4f}" for length in TOOLS.values()],
        "delta": [f"{nose + length:.4f}" for length in TOOLS.values()],
        "spindle": [str(SPEEDS[t]) for t in TOOLS],
        "name": ["BRACKET 7"] * 3,
        "program": ["4711"] * 3,
    }[placeholder]
    assert values == expected


def test_placeholders_in_the_start_and_end_lines_and_formats(tmp_path: Path) -> None:
    controller = ("  dialect: linuxcnc\n  program_number: 12\n"
                  "  program_start: [\"(PROGRAM {program:05d} FOR {name})\", \"G21 G90 G17 G40 G49 G94\"]\n"
                  "  tool_change: [\"T{tool} M6\", \"(L {length:.1f})\"]\n"
                  "  program_end: [\"M5 M9\", \"(END OF {name})\", \"M30\"]\n")
    _, _, text = _post(tmp_path, controller)
    assert "\n(PROGRAM 00012 FOR BRACKET 7)\nG21 G90" in text
    assert re.findall(r"^\(L (.*)\)$", text, re.M) == ["60.0", "100.0", "80.0"]
    assert text.endswith("M5 M9\n(END OF BRACKET 7)\nM30\n%\n")


def test_fanuc_preset(tmp_path: Path) -> None:
    """FANUC: '%', the O number on the next line, ( ) comments only, G21 and G49/G80, T.. M6, M30."""
    machine, _, text = _post(tmp_path, "  dialect: fanuc\n  program_number: 1234\n")
    lines = text.splitlines()
    assert lines[:2] == ["%", "O1234"] and lines[-2:] == ["M30", "%"]
    assert ";" not in "".join(_code(line) + line for line in lines if not line.startswith("("))
    assert "G21 G90 G17 G40 G49 G80 G94" in lines
    assert [line for line in lines if re.fullmatch(r"T\d+ M6", line)] == [f"T{t} M6" for t in TOOLS]
    assert any(line.endswith(" (RAPID)") for line in lines)
    with pytest.raises(InputError, match="';' is not a comment on fanuc"):
        read_gcode("G21\n; comment\n", controller=machine.controller.profile())


def test_sinumerik_preset(tmp_path: Path) -> None:
    """SINUMERIK: no '%', ';' comments, TRAFOOF and G71, T then M6 then D0, M30."""
    machine, _, text = _post(tmp_path, "  dialect: sinumerik\n")
    lines = text.splitlines()
    assert "%" not in lines and lines[-1] == "M30"
    assert not any(line.startswith("(") or "(" in _code(line) for line in lines)
    assert lines[lines.index("TRAFOOF") + 1] == "G71 G90 G17 G40 G94"
    for tool in TOOLS:
        k = lines.index(f"T{tool}")
        assert lines[k + 1:k + 3] == ["M6", "D0"]
    assert any(line.endswith(" ; RAPID") for line in lines)
    profile = machine.controller.profile()
    with pytest.raises(InputError, match="parentheses are not a comment on sinumerik"):
        read_gcode("G71\n(comment)\n", controller=profile)
    with pytest.raises(InputError, match="D1: a tool offset"):
        read_gcode("T1\nM6\nD1\n", controller=profile)
    with pytest.raises(InputError, match="G21 is not supported"):  # G21 is not metric on SINUMERIK
        read_gcode("G21\n", controller=profile)


def test_verify_without_machine_names_the_machine_file_of_the_header(tmp_path: Path) -> None:
    """A SINUMERIK program verified without --machine (the default LinuxCNC profile): the error at
    its first foreign line says which machine file the header names and that --machine reads it."""
    cl = tmp_path / "part.cls"
    cl.write_text(TOOLS_CL)
    target = tmp_path / "part.mpf"
    machine = vp.load_machine(_machine_file(tmp_path, "  dialect: sinumerik\n", "shop.yaml"))
    assert post(cl, machine, PostOptions(), target).verification.ok
    result = CliRunner().invoke(main, ["verify", str(target)])
    assert result.exit_code == 2 and len(result.stderr.splitlines()) == 1
    assert result.stderr.rstrip().endswith("the program's header names the machine file shop.yaml: --machine "
                                           "shop.yaml reads it with that file's controller profile")
    assert CliRunner().invoke(main, ["verify", str(target), "--machine", str(tmp_path / "shop.yaml")]).exit_code == 0


def test_linuxcnc_has_no_program_number_line(tmp_path: Path) -> None:
    """O words are subroutine labels in LinuxCNC: a program number only fills {program}."""
    _, _, text = _post(tmp_path, "  dialect: linuxcnc\n  program_number: 77\n")
    assert not re.search(r"^O\d", text, re.M)
    with pytest.raises(InputError, match="word O"):
        read_gcode("O77\n", controller=LINUXCNC)


def test_every_preset_posts_and_verifies_the_example(tmp_path: Path) -> None:
    cl = ROOT / "examples" / "nx_swarf_inch_crlf.cls"
    for dialect in DIALECTS:
        machine = vp.load_machine(_machine_file(tmp_path, f"  dialect: {dialect}\n  program_number: 5\n"
                                                          "  block_numbers: true\n",
                                                f"{dialect}.yaml"))
        target = tmp_path / f"{dialect}.nc"
        posted = post(cl, machine, PostOptions(), target)
        assert posted.verification is not None and posted.verification.ok, dialect
        again = verify_program(target.read_text(), machine, against=read_cl(cl))
        assert again.ok and again.blocks == posted.verification.blocks, dialect


def test_optional_stop_before_every_tool_change_but_the_first(tmp_path: Path) -> None:
    _, _, text = _post(tmp_path, "  dialect: linuxcnc\n  optional_stop: true\n  m_codes: {optional_stop: 101}\n")
    lines = text.splitlines()
    stops = [k for k, line in enumerate(lines) if line == "M101"]
    changes = [k for k, line in enumerate(lines) if re.fullmatch(r"T\d+ M6", line)]
    assert len(stops) == 2 and [k + 2 for k in stops] == changes[1:]  # M1, the TOOL comment, T M6


def test_m_codes_are_the_profiles(tmp_path: Path) -> None:
    _, _, text = _post(tmp_path, "  dialect: linuxcnc\n  m_codes: {spindle_cw: 13, spindle_ccw: 14, coolant_flood: "
                                 "108, coolant_mist: 107, end: 2}\n")
    lines = text.splitlines()
    assert "S8000 M13" in lines and "S12500 M14" in lines and "M108" in lines and "M107" in lines
    assert lines[-2:] == ["M2", "%"]


def test_max_line_length_shortens_comments_and_refuses_long_blocks(tmp_path: Path) -> None:
    cl = tmp_path / "part.cls"
    cl.write_text(TOOLS_CL.replace("UNITS/MM\n", "UNITS/MM\nPPRINT/" + "A LONG REMARK " * 20 + "\n"))
    machine = vp.load_machine(_machine_file(tmp_path, "  dialect: linuxcnc\n  max_line_length: 80\n"))
    target = tmp_path / "part.nc"
    assert post(cl, machine, PostOptions(), target).verification.ok
    assert max(len(line) for line in target.read_text().splitlines()) <= 80
    numbered = vp.load_machine(_machine_file(tmp_path, "  dialect: linuxcnc\n  max_line_length: 60\n"
                                                       "  block_numbers: {start: 100000000, step: 1}\n", "n.yaml"))
    result = CliRunner().invoke(main, [str(cl), "--machine", str(tmp_path / "n.yaml"), "-o", str(tmp_path / "n.nc")])
    assert result.exit_code == 3 and "max_line_length 60" in result.stderr
    assert not (tmp_path / "n.nc").exists()
    assert numbered.controller.profile().max_line_length == 60


def test_split_by_tool_writes_files_that_each_verify_and_together_are_the_program(tmp_path: Path) -> None:
    cl = tmp_path / "part.cls"
    cl.write_text(TOOLS_CL.replace("LOADTL/5,LENGTH,80.0\n", "COOLNT/OFF\nLOADTL/5,LENGTH,80.0\n"))
    whole = vp.load_machine(_machine_file(tmp_path, "  dialect: linuxcnc\n  block_numbers: true\n", "whole.yaml"))
    machine = vp.load_machine(_machine_file(tmp_path, "  dialect: linuxcnc\n  block_numbers: true\n  split: tool\n"))
    assert post(cl, whole, PostOptions(), tmp_path / "whole.nc").verification.ok
    posted = post(cl, machine, PostOptions(), tmp_path / "part.nc")
    names = [tmp_path / f"part_{k}_T{t}.nc" for k, t in enumerate(TOOLS, 1)]
    assert list(posted.files) == names and not (tmp_path / "part.nc").exists()
    programs = []
    for name in names:
        text = name.read_text()
        assert text.startswith("%\n(PART BRACKET 7)") and text.endswith("M30\n%\n")
        assert verify_program(text, machine).ok, name
        programs.append(read_gcode(text))
    # each file after the first starts with its tool change, then a G0 to where the one before ends
    for before, after in itertools.pairwise(programs):
        assert after.rapid[0] and np.allclose(after.joints[0], before.joints[-1], atol=1e-4)
    # the spindle and coolant in force carry over: tool 5's file restarts them (M9: the CL's last word)
    third = names[2].read_text()
    assert re.search(r"T5 M6\nN\d+ S12500 M4\nN\d+ M9\nN\d+ G0 ", third)
    # together, without the positioning G0s, they are the whole program's moves
    joined = np.concatenate([programs[0].joints] + [p.joints[1:] for p in programs[1:]])
    assert np.array_equal(joined, read_gcode((tmp_path / "whole.nc").read_text()).joints)


# -------------------------------------------------------------------------------------------
# machine-file errors of the controller section, each at its line


def _problem(tmp_path: Path, controller: str) -> str:
    path = _machine_file(tmp_path, controller)
    result = CliRunner().invoke(main, ["machine", "check", str(path)])
    assert result.exit_code == 2
    return result.stderr


@pytest.mark.parametrize(("controller", "line", "key", "reason"), [
    ("  dialect: linuxcnc\n  tool_change: [\"T{tool} M6\",\n    \"(D {diameter})\"]\n", 2, "controller.tool_change.1",
     "unknown placeholder {diameter}"),
    ("  dialect: linuxcnc\n  program_start: [\"(P {program})\"]\n", 1, "controller.program_start.0",
     "{program} needs controller.program_number"),
    ("  dialect: linuxcnc\n  tool_change: [\"T{tool}\"]\n", 1, "controller.tool_change",
     "must hold {tool} and M6"),
    ("  dialect: linuxcnc\n  program_end: [\"M5\"]\n", 1, "controller.program_end", "M30"),
    ("  dialect: linuxcnc\n  program_end: [\"M5\",\n    \"G0 Z100\", \"M30\"]\n", 2, "controller.program_end.1",
     "moves the rho3 axis"),
    ("  dialect: linuxcnc\n  program_start: [\"G91\"]\n", 1, "controller.program_start.0",
     "verify could not read 'G91' back: G91 is not supported"),
    ("  dialect: sinumerik\n  program_start: [\"(HELLO)\"]\n", 1, "controller.program_start.0",
     "parentheses are not a comment on sinumerik"),
    ("  dialect: linuxcnc\n  axes: {rho1: U, rho2: U}\n", 1, "controller.axes.rho2", "U is the letter of rho1 too"),
    ("  dialect: linuxcnc\n  axes: {theta1: X}\n", 1, "controller.axes.theta1", "X is the letter of rho1 too"),
    # inch input (SINUMERIK "NC programming" 12/2019: G70 inch, G71 metric; LinuxCNC and FANUC: G20)
    ("  dialect: sinumerik\n  program_start: [\"G17 G70 G90\"]\n", 1, "controller.program_start.0",
     "G70 selects inch input"),
    ("  dialect: linuxcnc\n  tool_change: [\"T{tool} M6\", \"G20\"]\n", 1, "controller.tool_change.1",
     "G20 selects inch input"),
    # work offsets: G54 to G59 (LinuxCNC, FANUC), G500 and G505 to G599 (SINUMERIK settable frames)
    ("  dialect: linuxcnc\n  program_start: [\"G21 G90 G54\"]\n", 1, "controller.program_start.0",
     "G54 selects a work offset"),
    ("  dialect: fanuc\n  program_start: [\"G21 G90 G54.1 P1\"]\n", 1, "controller.program_start.0",
     "G54.1 selects a work offset"),
    ("  dialect: sinumerik\n  program_start: [\"TRAFOOF\", \"G71 G90 G500\"]\n", 1, "controller.program_start.1",
     "G500 selects a work offset"),
    ("  dialect: sinumerik\n  program_start: [\"G505\"]\n", 1, "controller.program_start.0",
     "G505 selects a work offset"),
    # a comment style the dialect does not read: at the key, not at the program's first line
    ("  dialect: sinumerik\n  comment: parentheses\n", 1, "controller.comment",
     "sinumerik does not read parentheses as a comment"),
    ("  dialect: fanuc\n  comment: semicolon\n", 1, "controller.comment", "fanuc does not read semicolon"),
    ("  dialect: linuxcnc\n  axes: {rho1: Q}\n", 1, "controller.axes.rho1", "Input should be"),
    ("  dialect: haas\n", 0, "controller.dialect", "Input should be 'linuxcnc', 'fanuc' or 'sinumerik'"),
    ("  dialect: linuxcnc\n  tool_change: [\"T{tool M6\"]\n", 1, "controller.tool_change.0", "malformed placeholder"),
])
def test_controller_errors_name_their_line(tmp_path: Path, controller: str, line: int, key: str, reason: str) -> None:
    text = SHIPPED.read_text()
    at = text[:text.index(DIALECT_LINE)].count("\n") + 1  # the dialect's line
    stderr = _problem(tmp_path, controller)
    assert f":{at + line}: {key}: " in stderr and reason in stderr, stderr


def test_the_old_block_number_keys_say_where_they_went(tmp_path: Path) -> None:
    path = tmp_path / "old.yaml"
    text = SHIPPED.read_text().replace("  feed_decimals: 5\n", "  feed_decimals: 5\n  block_numbers: true\n")
    path.write_text(text)
    line = text.splitlines().index("  block_numbers: true") + 1
    result = CliRunner().invoke(main, ["machine", "check", str(path)])
    assert result.exit_code == 2
    assert f"{path}:{line}: gcode.block_numbers: moved to controller.block_numbers" in result.stderr


def test_three_errors_in_three_sections_are_all_listed(tmp_path: Path) -> None:
    text = SHIPPED.read_text().replace(DIALECT_LINE, "  dialect: linuxcnc\n  comment: hash\n")
    text = text.replace("  R1: 129.71", "  R1: 12x9.71").replace("  clearance: 10.0", "  clearance: -1")
    path = tmp_path / "m.yaml"
    path.write_text(text)
    result = CliRunner().invoke(main, ["machine", "check", str(path)])
    keys = re.findall(r":\d+: ([\w.]+): ", result.stderr)
    assert result.exit_code == 2 and keys == ["geometry.R1", "controller.comment", "safe.clearance"]


def test_init_writes_each_dialect_and_check_summarises_the_profile(tmp_path: Path) -> None:
    for dialect in DIALECTS:
        out = tmp_path / f"{dialect}.yaml"
        assert CliRunner().invoke(main, ["machine", "init", "-o", str(out), "--dialect", dialect]).exit_code == 0
        assert vp.load_machine(out).controller.profile().dialect == dialect
        result = CliRunner().invoke(main, ["machine", "check", str(out)])
        assert result.exit_code == 0 and f"controller: {dialect};" in result.stdout


def test_the_schema_checks_the_controller_section() -> None:
    document = yaml.safe_load(SHIPPED.read_text())
    jsonschema.validate(document, schema())
    for bad in ({"dialect": "linuxcnc", "colour": "red"}, {"block_numbers": {"start": "ten"}},
                {"axes": {"rho1": "Q"}}, {"max_line_length": "long"}):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate({**document, "controller": bad}, schema())


def test_a_file_that_changes_only_comments_or_order_posts_the_same_program(tmp_path: Path) -> None:
    _, _, first = _post(tmp_path, CUSTOM)
    reordered = "\n".join(reversed(CUSTOM.rstrip("\n").split("\n")[1:])) + "\n  # a remark\n  dialect: linuxcnc\n"
    (tmp_path / "again").mkdir()
    _, _, second = _post(tmp_path / "again", reordered)
    assert first.replace("m.yaml", "") == second.replace("m.yaml", "")


def test_a_batch_refuses_a_machine_that_splits_by_tool(tmp_path: Path) -> None:
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "part.cls").write_text(TOOLS_CL)
    path = _machine_file(tmp_path, "  dialect: linuxcnc\n  split: tool\n")
    result = CliRunner().invoke(main, ["batch", str(tmp_path / "in" / "part.cls"), "-o", str(tmp_path / "out"),
                                       "--machine", str(path), "--jobs", "1", "-q"])
    assert result.exit_code == 2 and "controller.split: tool writes a program as several files" in result.output
    assert not list((tmp_path / "out").glob("*.nc"))


def test_fanuc_feeds_and_block_numbers_stay_within_its_ranges(tmp_path: Path) -> None:
    """FANUC takes inverse-time F from 0.001 to 9999.999 and sequence numbers N1 to N99999
    (B-62764EN 5, B-63684EN 13): a block too short for the largest F is written at it (slower),
    the others at their planned F to 3 decimals, block numbers wrap, and the program still verifies."""
    cl = ROOT / "examples" / "nx_variable_axis_inch.cls"
    # the reference: SINUMERIK's profile, which writes the plan's F without a limit (the default
    # linuxcnc dialect keeps LinuxCNC's own floor on rotary blocks, planning/controller.py)
    default = vp.load_machine(_machine_file(tmp_path, "  dialect: sinumerik\n", "default.yaml"))
    fanuc = vp.load_machine(_machine_file(tmp_path, "  dialect: fanuc\n  program_number: 7\n"
                                                    "  block_numbers: {start: 1, step: 50}\n"))
    assert post(cl, default, PostOptions(), tmp_path / "default.nc").verification.ok
    posted = post(cl, fanuc, PostOptions(), tmp_path / "fanuc.nc")
    assert posted.verification.ok
    text = (tmp_path / "fanuc.nc").read_text()
    words = re.findall(r"^N\d+ G1 .* F(\S+)", text, re.M)
    assert words and all(re.fullmatch(r"\d+\.\d{3}", f) for f in words) and max(map(float, words)) <= 9999.999
    before = read_gcode((tmp_path / "default.nc").read_text(), controller=default.controller.profile())
    after = read_gcode(text, controller=fanuc.controller.profile())
    assert np.array_equal(before.joints, after.joints, equal_nan=True)
    short = before.duration < 60 / 9999.999
    assert short.sum() > 10  # the example has such blocks
    assert np.allclose(after.duration[short], 60 / 9999.999)
    timed = ~short & (before.duration > 0)  # the others: their F as planned, to 3 decimals
    assert np.all(np.abs(60 / after.duration[timed] - 60 / before.duration[timed]) <= 0.0005 + 1e-6)
    numbers = [int(n) for n in re.findall(r"^N(\d+) ", text, re.M)]
    assert min(numbers) >= 1 and max(numbers) <= 99999 and len(numbers) * 50 > 99999  # wrapped


@pytest.mark.parametrize(("controller", "reason"), [
    ("  dialect: fanuc\n  program_number: 0\n", "fanuc takes O1 to O9999, not 0"),
    ("  dialect: fanuc\n  program_number: 12345\n", "fanuc takes O1 to O9999, not 12345"),
    ("  dialect: fanuc\n  block_numbers: {start: 0, step: 10}\n", "fanuc numbers blocks from N1 to N99999, not N0"),
])
def test_fanuc_ranges_are_checked_when_the_file_is_read(tmp_path: Path, controller: str, reason: str) -> None:
    assert reason in _problem(tmp_path, controller)


def test_a_program_under_a_work_offset_is_refused_by_verify() -> None:
    """A joint-space program's words are the joints' positions: a work offset would shift them
    (G54..G59 and FANUC's G54.1; SINUMERIK's settable frames G54..G57, G500, G505..G599)."""
    move = "G0 X100 Y47 Z46 A0 C0\n"
    for dialect, program, code in [("linuxcnc", "G21 G90\nG54\n", "G54"), ("linuxcnc", "G21 G55\n", "G55"),
                                   ("fanuc", "O1\nG21\nG54.1 P2\n", "G54.1"),
                                   ("sinumerik", "TRAFOOF\nG71\nG500\n", "G500"),
                                   ("sinumerik", "G71 G54\n", "G54")]:
        with pytest.raises(InputError, match=rf"G{code[1:]} selects a work offset"):
            read_gcode(program + move + "M30\n", controller=DIALECTS[dialect])


def test_check_lists_a_wrong_key_and_the_joints_that_share_a_letter(tmp_path: Path) -> None:
    """The controller section's own checks run although another of its keys is wrong."""
    stderr = _problem(tmp_path, "  dialect: linuxcnc\n  coment: semicolon\n"
                                "  axes: {rho1: U, rho2: V, rho3: W, theta1: W, theta2: C}\n")
    keys = re.findall(r":\d+: ([\w.]+): (.*)", stderr)
    assert [key for key, _ in keys] == ["controller.coment", "controller.axes.theta1"], stderr
    assert "did you mean comment?" in keys[0][1] and "W is the letter of rho3 too" in keys[1][1]


@pytest.mark.parametrize(("controller", "missing"), [
    ("  dialect: sinumerik\n  program_start: [\"G17 G71 G90\"]\n", "TRAFOOF G40 G94"),
    ("  dialect: fanuc\n  program_start: [\"G21 G90 G17 G40 G49 G94\"]\n", "G80"),
    ("  dialect: linuxcnc\n  program_start: [\"G21 G90 G17 G40 G94\"]\n", "G49 G64"),
])
def test_a_start_that_leaves_out_the_dialects_modes_is_warned_at_its_line(tmp_path: Path, controller: str,
                                                                          missing: str) -> None:
    """docs/controllers.md: TRAFOOF, G40, G49, G80 and G94 put the controller in the modes the
    program is written for; an override without them leaves whatever mode the machine was in."""
    path = _machine_file(tmp_path, controller)
    text = path.read_text()
    line = text.splitlines().index(controller.splitlines()[1]) + 1
    result = CliRunner().invoke(main, ["machine", "check", str(path)])
    assert result.exit_code == 0
    assert f"verne-post: warning: {path}:{line}: controller.program_start: leaves out {missing} of the" in result.stderr
    machine = vp.load_machine(path)
    assert machine.warnings and f":{line}: controller.program_start" in machine.warnings[0]
    # the post says it too
    cl = tmp_path / "part.cls"
    cl.write_text(TOOLS_CL)
    posted = CliRunner().invoke(main, ["check", str(cl), "--machine", str(path)])
    assert f"warning: {path}:{line}: controller.program_start: leaves out {missing}" in posted.stderr


def test_a_start_with_the_dialects_modes_in_another_order_is_not_warned(tmp_path: Path) -> None:
    path = _machine_file(tmp_path, "  dialect: sinumerik\n  program_start: [\"G710 G40 G90\", \"TRAFOOF\", "
                                   "\"G94 G17\", \"M11 ; table unclamped\"]\n")
    assert vp.load_machine(path).warnings == ()


def test_init_comments_out_the_dialects_own_values_and_writes_the_schema_it_names(tmp_path: Path) -> None:
    for dialect, preset in DIALECTS.items():
        out = tmp_path / dialect / "shop.yaml"
        out.parent.mkdir()
        result = CliRunner().invoke(main, ["machine", "init", "-o", str(out), "--dialect", dialect])
        assert result.exit_code == 0
        text = out.read_text()
        # the editor's schema, named by the first line, beside the file, and the model's own
        named = re.match(r"# yaml-language-server: \$schema=(\S+)\n", text).group(1)
        assert json.loads((out.parent / named).read_text()) == schema()
        # every key the dialect sets, uncommented, gives the dialect's value
        keys = ("axes", "comment", "program_start", "tool_change", "program_end", "max_line_length", "m_codes")
        uncommented = re.sub(rf"(?m)^  # ({'|'.join(keys)}):", r"  \1:", text)
        uncommented = re.sub(r"(?m)^  #( +coolant_through)", r"  \1", uncommented)
        assert uncommented != text
        (tmp_path / "u.yaml").write_text(uncommented)
        profile = vp.load_machine(tmp_path / "u.yaml").controller.profile()
        for key in ("axes", "comment", "program_start", "tool_change_lines", "end_lines", "max_line_length",
                    "m_codes"):
            assert getattr(profile, key) == getattr(preset, key), (dialect, key)
    # a schema there already is kept
    kept = tmp_path / "linuxcnc" / "verne.schema.json"
    kept.write_text("{}")
    assert CliRunner().invoke(main, ["machine", "init", "-o", str(kept.parent / "b.yaml")]).exit_code == 0
    assert kept.read_text() == "{}"


def test_the_shipped_file_comments_out_the_linuxcnc_values(tmp_path: Path) -> None:
    from verne_post.cli.machine import controller_keys

    assert "\n" + controller_keys("linuxcnc") + "\n\nsafe:" in SHIPPED.read_text()


# An NX tool given by its data alone (TLDATA, no LOAD/TOOL: as in ../shared/cl-samples/nx_zlevel_coremill_mm.cls)
UNNUMBERED_CL = """TOOL PATH/ZLEVEL,TOOL,MILL_10
TLDATA/MILL,10.0000,0.0000,75.0000,0.0000,0.0000
MSYS/0.0000,0.0000,0.0000,1.0000000,0.0000000,0.0000000,0.0000000,1.0000000,0.0000000
FEDRAT/MMPM,500.0000
RAPID
GOTO/0.0000,0.0000,20.0000,0.0000000,0.0000000,1.0000000
GOTO/0.0000,0.0000,0.0000
GOTO/30.0000,0.0000,0.0000
"""


def _post_unnumbered(tmp_path: Path, controller: str) -> tuple[vp.Machine, list[str]]:
    cl = tmp_path / "nx.cls"
    cl.write_text(UNNUMBERED_CL)
    machine = vp.load_machine(_machine_file(tmp_path, controller))
    target = tmp_path / "nx.mpf"
    posted = post(cl, machine, PostOptions(), target)
    assert not posted.violations and posted.verification is not None and posted.verification.ok
    return machine, target.read_text().splitlines()


def test_a_tool_without_a_number_is_loaded_by_hand_with_the_profiles_other_tool_change_words(tmp_path: Path) -> None:
    """SINUMERIK: D0 still cancels the cutting edge that stays active from the tool before (the
    joints hold the tool); no T and no M6, which would change to a tool no one named."""
    _, lines = _post_unnumbered(tmp_path, "  dialect: sinumerik\n")
    k = next(k for k, line in enumerate(lines) if line.startswith("; TOOL 0 LENGTH 75.0000"))
    assert lines[k + 1] == "D0"
    assert not any(re.fullmatch(r"T\d+|M6", line) for line in lines)
    assert any("LOAD THE TOOL BY HAND" in line for line in lines)


def test_a_tool_without_a_number_gets_the_machine_files_tool_number(tmp_path: Path) -> None:
    machine, lines = _post_unnumbered(tmp_path, "  dialect: sinumerik\n  tool_number: 7\n")
    k = next(k for k, line in enumerate(lines) if line.startswith("; TOOL 7 LENGTH 75.0000"))
    assert lines[k + 1:k + 4] == ["T7", "M6", "D0"]
    assert not any("BY HAND" in line or "TOOL 0" in line for line in lines)
    program = read_gcode("\n".join(lines) + "\n", controller=machine.controller.profile())
    assert set(program.tool[~np.isnan(program.joints).all(axis=1)][1:]) == {7}


# --- The controller's pace and path control (issue 33) ----------------------------------------------

def _block_seconds(text: str) -> np.ndarray:
    """Each G93 block's duration (s) as the controller reads it: 60 / F (inverse time)."""
    return np.array([60.0 / float(m.group(1)) for line in text.splitlines()
                     if (m := re.search(r"^(?:N\d+\s*)?G1\b.*\bF([0-9.]+)", _code(line)))])


def test_block_time_gives_every_block_at_least_that_long(tmp_path: Path) -> None:
    """With controller.block_time the program's F words ask no block for less than that time (read
    back from the text), the header's cycle time grows accordingly and says so."""
    _, _, plain = _post(tmp_path, "  dialect: fanuc\n")
    slow_dir = tmp_path / "slow"
    slow_dir.mkdir()
    _, _, slow = _post(slow_dir, "  dialect: fanuc\n  block_time: 0.05\n")
    before, after = _block_seconds(plain), _block_seconds(slow)
    assert before.min() < 0.05 - 1e-3  # the test can fail: some block was planned shorter
    assert after.min() >= 0.05 * (1 - 1e-6)
    cycle = [float(re.search(r"CYCLE TIME (\d+\.\d+) S", t).group(1)) for t in (plain, slow)]
    assert cycle[1] > cycle[0]
    assert "AT LEAST 50 MS A BLOCK" in slow and "BLENDING NOT MODELLED" in slow


@pytest.mark.parametrize(("dialect", "lines"), [
    ("sinumerik", '["TRAFOOF", "G71 G90 G17 G40 G94", "G642", "COMPCAD", "SOFT"]'),
    ("fanuc", '["G21 G90 G17 G40 G49 G80 G94", "G05.1 Q1", "G08 P1"]'),
])
def test_path_control_codes_of_the_vendors_are_written_and_read(tmp_path: Path, dialect: str, lines: str) -> None:
    """The documented path-control codes (SINUMERIK's G642 rounding and COMPCAD compressor, FANUC's
    AI contour control G05.1 Q1 and look-ahead G08 P1) can stand in program_start: the post writes
    them and verify, reading with the same profile, certifies the program."""
    _, _, text = _post(tmp_path, f"  dialect: {dialect}\n  program_start: {lines}\n")
    for line in json.loads(lines):
        assert any(_code(written) == line for written in text.splitlines()), line


def test_a_g5_1_is_still_refused_on_linuxcnc(tmp_path: Path) -> None:
    """G5.1 is a quadratic spline on LinuxCNC, not path control: its line is refused at the YAML line."""
    path = _machine_file(tmp_path, '  dialect: linuxcnc\n  program_start: ["G21 G90", "G5.1 Q1"]\n')
    with pytest.raises(InputError, match=r"G5\.1"):
        vp.load_machine(path)
