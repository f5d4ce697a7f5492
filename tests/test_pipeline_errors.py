"""Bad input and impossible programs: exit 2 or 3, one line per problem naming the CL line,
no traceback, and no output file (an existing one is left as it was)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

ROOT = Path(__file__).resolve().parent.parent

HEADER = "PARTNO/TEST\nUNITS/MM\nMULTAX/ON\nTLDATA/MILL,10,0,80,0,0\nLOAD/TOOL,1\nFEDRAT/MMPM,1000\n"
GOOD = "GOTO/0,0,50,0,0,1\nGOTO/10,0,50,0.1,0,0.995\nGOTO/20,5,50,0,0,1\nFINI\n"


def run(tmp_path: Path, content: str | bytes, *extra: str) -> subprocess.CompletedProcess[str]:
    source = tmp_path / "part.cls"
    if isinstance(content, bytes):
        source.write_bytes(content)
    else:
        source.write_text(content)
    return subprocess.run([sys.executable, "-m", "verne_post", str(source), "-o", str(tmp_path / "part.nc"), *extra],
                          capture_output=True, text=True, cwd=tmp_path)


def test_good_program_is_written(tmp_path: Path) -> None:
    result = run(tmp_path, HEADER + GOOD, "--quiet")
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "part.nc").read_text().startswith("%\n")


@pytest.mark.parametrize(
    ("body", "line", "reason"),
    [
        ("GOTO/0,0,50,0,0,1\nGOTO/1,2\n", 8, "GOTO"),
        ("GOTO/0,0,50,0,0,1\nGOTO/1,2x,3\n", 8, "2x"),
        ("GOTO/0,0,50,0,0,1\nGOTO/1,nan,3\n", 8, "NaN"),
        ("GOTO/0,0,50,0,0,0\n", 7, "zero length"),
        ("FEDRAT/IPM,4.9e-324\nGOTO/0,0,50,0,0,1\nGOTO/1,0,50,0,0,1\n", 7, "mm/min is outside"),  # at the FEDRAT
    ],
)
def test_malformed_cl(tmp_path: Path, body: str, line: int, reason: str) -> None:
    result = run(tmp_path, HEADER + body + "FINI\n")
    assert result.returncode == 2
    message = result.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in message
    assert f"part.cls:{line}:" in message and reason.lower() in message.lower()
    assert not (tmp_path / "part.nc").exists()


@pytest.mark.parametrize(("content", "reason"), [("", "no motion"), (b"\x00\x01\x02binary\xff", "not a text")])
def test_empty_and_binary_files(tmp_path: Path, content: str | bytes, reason: str) -> None:
    result = run(tmp_path, content)
    assert result.returncode == 2 and reason in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
    assert not (tmp_path / "part.nc").exists()


def test_unreachable_pose_names_its_line(tmp_path: Path) -> None:
    body = "GOTO/0,0,50,0,0,1\nGOTO/3000,0,50,0,0,1\n"
    result = run(tmp_path, HEADER + body + "FINI\n")
    assert result.returncode == 3
    assert "part.cls:8: pose is out of the machine's reach" in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "part.nc").exists()


def test_limit_violation_names_joint_and_limit(tmp_path: Path) -> None:
    (tmp_path / "part.nc").write_text("old program\n")
    result = run(tmp_path, HEADER + GOOD, "--work-offset", "0", "0", "-620", "--report", str(tmp_path / "r.json"))
    assert result.returncode == 3
    assert "exceeds max 1300.000 mm" in result.stderr or "is below min 0.000 mm" in result.stderr
    first = next(line for line in result.stderr.splitlines() if "error:" in line)
    assert "part.cls:7: slider rho" in first
    assert (tmp_path / "part.nc").read_text() == "old program\n"
    report = (tmp_path / "r.json").read_text()
    assert '"ok": false' in report and '"kind": "limit"' in report


def test_tilt_beyond_limit(tmp_path: Path) -> None:
    body = "GOTO/0,0,50,0,0,1\nGOTO/0,0,50,0.9,0,-0.4359\n"
    result = run(tmp_path, HEADER + body + "FINI\n")
    assert result.returncode == 3
    assert "part.cls:8:" in result.stderr


def test_unknown_tool_length_is_an_error(tmp_path: Path) -> None:
    content = "UNITS/MM\nLOAD/TOOL,7\nFEDRAT/MMPM,1000\n" + GOOD
    result = run(tmp_path, content)
    assert result.returncode == 2
    assert "part.cls:2: tool 7 has no length" in result.stderr
    result = run(tmp_path, content, "--tool-length", "50", "--quiet")
    assert result.returncode == 0
    assert "(TOOL 7 LENGTH 50.0000 DELTA 545.8000)" in (tmp_path / "part.nc").read_text()


def test_check_writes_nothing(tmp_path: Path) -> None:
    source = tmp_path / "part.cls"
    source.write_text(HEADER + GOOD)
    result = subprocess.run([sys.executable, "-m", "verne_post", "check", str(source)], capture_output=True,
                            text=True, cwd=tmp_path)
    assert result.returncode == 0 and "ok" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part.cls"]


def test_csv_poses(tmp_path: Path) -> None:
    source = tmp_path / "poses.csv"
    source.write_text("x,y,z,i,j,k,feed\n0,0,50,0,0,1,1000\n10,0,50,0.1,0,0.995,1000\n20,5,50,0,0,1,800\n")
    run_args = [sys.executable, "-m", "verne_post", str(source), "-o", str(tmp_path / "p.nc"), "--tool-length", "50"]
    result = subprocess.run([*run_args, "--quiet"], capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "G93" in (tmp_path / "p.nc").read_text()
    source.write_text("x,y,z,i,j,k\n0,0,50,0,0,1\n10,0,50,0.1,0,0.995\n")
    result = subprocess.run(run_args, capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 2 and "poses.csv:3: feed move without a programmed feed" in result.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["."], "is a directory"),
    (["missing.cls"], "missing.cls: file not found"),
    (["part.cls", "--work-offset", "1", "2", "x"], "'x' is not a number"),
    (["part.cls", "--frobnicate"], "No such option '--frobnicate'"),
])
def test_command_line_mistakes_are_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    (tmp_path / "part.cls").write_text(HEADER + GOOD)
    result = subprocess.run([sys.executable, "-m", "verne_post", *args], capture_output=True, text=True,
                            cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.startswith("verne-post: error: ") and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_report_of_a_failed_run(tmp_path: Path) -> None:
    """Exit 3 with --report: every violation printed, the report written as strict JSON (null
    where a number is undefined, e.g. the time of a rapid to a pose out of reach)."""
    import json

    body = "GOTO/0,0,50,0,0,1\nRAPID\nGOTO/3000,0,50,0,0,1\nGOTO/0,0,50,0,0,1\n"
    result = run(tmp_path, HEADER + body + "FINI\n", "--report", str(tmp_path / "r.json"))
    assert result.returncode == 3 and "Traceback" not in result.stderr
    printed = [line for line in result.stderr.splitlines() if line.startswith("verne-post: error: ")]
    assert printed and "part.cls:9: pose is out of the machine's reach" in printed[0]

    def no_constants(name: str) -> None:
        raise AssertionError(f"{name} in the report")

    report = json.loads((tmp_path / "r.json").read_text(), parse_constant=no_constants)
    assert report["ok"] is False
    source = report["source"]
    assert [f"verne-post: error: {source}:{v['line']}: {v['message']}" for v in report["violations"]] == printed
    assert not (tmp_path / "part.nc").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part.cls", "r.json"]


def test_a_path_that_never_converges_is_reported_not_split_for_ever(tmp_path: Path) -> None:
    """Found by fuzzing: a machine file whose leg I is mirrored (D1 - d1 = +320 mm, L1 = 1294.43 mm) passes
    validation, but its joint interpolation never comes within tolerance of the CL path, so every move
    kept splitting at all 24 levels (2^24 blocks each). The splitting has a budget; the moves are violations."""
    from verne_post.cli import main

    machine = (ROOT / "machines" / "verne.yaml").read_text()
    machine = re.sub(r"D1_minus_d1: *-?[\d.]+", "D1_minus_d1: 320", machine)
    machine = re.sub(r"\n  L1: *[\d.]+", "\n  L1: 1294.43", machine)
    (tmp_path / "m.yaml").write_text(machine)
    out = tmp_path / "part.nc"
    result = CliRunner().invoke(main, [str(ROOT / "tests" / "data" / "nx_multi_op_mm.cls"), "--machine",
                                       str(tmp_path / "m.yaml"), "-o", str(out), "--work-offset", "8.258", "-91.482",
                                       "45.063", "--no-timing", "--quiet"])
    assert result.exit_code == 3, result.output
    assert "cannot be kept within 0.005 mm" in result.stderr and not out.exists()
