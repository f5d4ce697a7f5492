"""Numbers on the command line: NaN, infinities, overflow, negative and absurd values are one-line
mistakes (exit 2) before any work is done; a timed CSV has a bounded number of rows."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from verne_post.cli import main

HEADER = "PARTNO/TEST\nUNITS/MM\nMULTAX/ON\nTLDATA/MILL,10,0,80,0,0\nLOAD/TOOL,1\nFEDRAT/MMPM,1000\n"
GOOD = "GOTO/0,0,50,0,0,1\nGOTO/10,0,50,0.1,0,0.995\nGOTO/20,5,50,0,0,1\nFINI\n"

NOT_FINITE = ["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e999", "-1e400"]
POSITIVE_OPTIONS = ["--tol", "--axis-tol", "--arc-tol", "--period", "--tool-length", "--max-messages"]


def _run(tmp_path: Path, *args: str, command: tuple[str, ...] = ()) -> tuple[int, str]:
    source = tmp_path / "part.cls"
    source.write_text(HEADER + GOOD)
    result = CliRunner().invoke(main, [*command, str(source), *args])
    return result.exit_code, result.stderr


def _rejected(code: int, stderr: str, option: str) -> None:
    assert code == 2, stderr
    assert stderr.startswith(f"verne-post: error: Invalid value for '{option}'") and len(stderr.splitlines()) == 1


@pytest.mark.parametrize("value", NOT_FINITE)
@pytest.mark.parametrize("option", [*POSITIVE_OPTIONS, "--work-offset"])
def test_not_finite_is_rejected(tmp_path: Path, option: str, value: str) -> None:
    values = ["0", "0", value] if option == "--work-offset" else [value]
    code, stderr = _run(tmp_path, "-o", str(tmp_path / "p.nc"), option, *values)
    _rejected(code, stderr, option)
    assert not (tmp_path / "p.nc").exists()


@pytest.mark.parametrize(("option", "value"), [
    *((option, "-1") for option in POSITIVE_OPTIONS),
    ("--tol", "0"), ("--axis-tol", "0"), ("--arc-tol", "0"),
    ("--tol", "1e-300"), ("--arc-tol", "1e-12"), ("--period", "1e-9"),  # no end of subdivision or samples
    ("--tol", "1e6"), ("--axis-tol", "720"), ("--period", "1e9"), ("--tool-length", "1e12"),
    ("--max-messages", "1e3"), ("--max-messages", "9" * 30), ("--tol", "abc"), ("--tol", "0x10"),
    ("--decimals", "3"), ("--decimals", "13"), ("--decimals", "9.5"), ("--decimals", "nan"), ("--decimals", "-9"),
])
def test_negative_and_absurd_values_are_rejected(tmp_path: Path, option: str, value: str) -> None:
    _rejected(*_run(tmp_path, "-o", str(tmp_path / "p.nc"), option, value), option)


@pytest.mark.parametrize("value", ["1e300", "-1e7", "nan"])
def test_work_offset_out_of_any_machine(tmp_path: Path, value: str) -> None:
    _rejected(*_run(tmp_path, "--work-offset", value, "0", "0", command=("check",)), "--work-offset")


@pytest.mark.parametrize(("command", "args", "option"), [
    ("ik", ["--tip", "0", "0", "nan", "--axis", "0", "0", "1"], "--tip"),
    ("ik", ["--tip", "0", "0", "0", "--axis", "0", "inf", "1"], "--axis"),
    ("ik", ["--platform", "1e999", "0", "0"], "--platform"),
    ("fk", ["--rho", "600", "600", "nan"], "--rho"),
    ("fk", ["--rho", "600", "600", "600", "--theta", "0", "inf"], "--theta"),
    ("fk", ["--rho", "600", "600", "600", "--tool-length", "-1"], "--tool-length"),
])
def test_kinematics_commands_reject_non_finite(command: str, args: list[str], option: str) -> None:
    result = CliRunner().invoke(main, [command, *args])
    _rejected(result.exit_code, result.stderr, option)


# a tool of length 0 (a gauge point) and no message at all are allowed: 0 is not tried for them
_OTHER_COMMANDS = [(command, option, value) for command, option in [
    ("verify", "--tol"), ("verify", "--axis-tol"), ("verify", "--arc-tol"), ("verify", "--max-messages"),
    ("place", "--tol"), ("place", "--axis-tol"), ("place", "--arc-tol"), ("place", "--tool-length"),
    ("toolpath", "--arc-tol"),
] for value in ("nan", "inf", "0", "-1") if not (value == "0" and option in ("--tool-length", "--max-messages"))]


@pytest.mark.parametrize(("command", "option", "value"), _OTHER_COMMANDS)
def test_the_other_commands_reject_the_same_values(tmp_path: Path, command: str, option: str, value: str) -> None:
    """The checking commands take the tolerances as 'post' does (a NaN tolerance once made 'verify'
    match every block end with every CL pose, until it ran out of memory)."""
    program, part = tmp_path / "p.nc", tmp_path / "part.cls"
    program.write_text("%\nG21 G90\nG0 X600 Y600 Z600 A0 C0\nM2\n%\n")
    part.write_text(HEADER + GOOD)
    args = [str(program), "--against", str(part)] if command == "verify" else [str(part)]
    result = CliRunner().invoke(main, [command, *args, option, value])
    _rejected(result.exit_code, result.stderr, option)


def test_a_program_header_without_a_usable_tolerance_is_refused(tmp_path: Path) -> None:
    """A header tolerance of 0 (edited by hand) is a one-line error naming the program, not a
    verification that can match nothing."""
    program = tmp_path / "p.nc"
    program.write_text("%\n(TOLERANCE 0 MM 0.05 DEG)\nG21 G90\nG0 X600 Y600 Z600 A0 C0\nM2\n%\n")
    (tmp_path / "part.cls").write_text(HEADER + GOOD)
    result = CliRunner().invoke(main, ["verify", str(program), "--against", str(tmp_path / "part.cls")])
    assert result.exit_code == 2, result.stderr
    assert str(program) in result.stderr and "tolerances must be positive" in result.stderr
    assert len(result.stderr.splitlines()) == 1


@pytest.mark.parametrize(("option", "value"), [
    ("--step", "nan"), ("--step", "0"), ("--step", "1e-9"),  # 1e-9 mm once asked for 16 TiB
    ("--tilt", "nan"), ("--tilt", "200"), ("--rotary", "inf"), ("--z", "nan"), ("--z", "1e5"),
])
def test_the_workspace_map_rejects_values_it_cannot_draw(tmp_path: Path, option: str, value: str) -> None:
    result = CliRunner().invoke(main, ["workspace", "-o", str(tmp_path / "ws.png"), option, value])
    _rejected(result.exit_code, result.stderr, option)
    assert not (tmp_path / "ws.png").exists()


def test_the_quoted_value_is_short_and_one_line(tmp_path: Path) -> None:
    code, stderr = _run(tmp_path, "--tol", "1\n2" + "9" * 500)
    _rejected(code, stderr, "--tol")
    assert "\\x0a" in stderr and len(stderr) < 120


def test_usual_values_are_accepted(tmp_path: Path) -> None:
    code, stderr = _run(tmp_path, "-o", str(tmp_path / "p.nc"), "--tol", "0.01", "--axis-tol", "0.1", "--arc-tol",
                        "0.002", "--tool-length", "80", "--work-offset", "0", "0", "-1.5", "--max-messages", "0",
                        "--no-timing", "--quiet")
    assert code == 0, stderr
    assert (tmp_path / "p.nc").read_text().startswith("%\n")


def test_timed_csv_rows_are_bounded(tmp_path: Path) -> None:
    """A slow programmed feed: 1 mm/min over ~20 mm takes ~20 min, 1.2e7 rows at 0.1 ms: fine;
    at 1e-4 mm/min (2e5 min) it would be 1.2e11 rows: refused before writing, naming the output."""
    source = tmp_path / "slow.cls"
    target = tmp_path / "slow.csv"
    source.write_text(HEADER.replace("FEDRAT/MMPM,1000", "FEDRAT/MMPM,0.0001") + GOOD)
    result = CliRunner().invoke(main, [str(source), "-o", str(target), "--period", "0.0001", "--quiet"])
    assert result.exit_code == 2, result.stderr
    assert result.stderr.startswith(f"verne-post: error: {target}: the timed CSV would have ")
    assert "--period" in result.stderr and not target.exists()


def test_a_file_without_feed_needs_and_takes_feed(tmp_path: Path) -> None:
    """No FEDRAT at all (NCL's APT source): the error names --feed; with it the program is
    posted at that feed and the header says where it came from."""
    source = tmp_path / "nofeed.cls"
    source.write_text(HEADER.replace("FEDRAT/MMPM,1000\n", "") + GOOD)
    target = tmp_path / "nofeed.nc"
    result = CliRunner().invoke(main, [str(source), "-o", str(target), "--quiet"])
    assert result.exit_code == 2 and "--feed" in result.stderr and len(result.stderr.splitlines()) == 1
    assert not target.exists()
    result = CliRunner().invoke(main, [str(source), "-o", str(target), "--feed", "750", "--quiet"])
    assert result.exit_code == 0, result.stderr
    text = target.read_text()
    assert "(CL READING FEED 750 MM/MIN FROM --feed FOR THE 3 FEED MOVES BEFORE THE FIRST FEDRAT" in text
