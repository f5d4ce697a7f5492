"""Tests of the G-code writer, checked against LinuxCNC's interpreter ``rs274``.

The rs274 tests need Debian's ``linuxcnc-uspace`` package; without it they FAIL (not skip) and
say how to install it.
"""

from __future__ import annotations

import os
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import verne_post.output.gcode as gcode
from verne_post.cl.toolpath import Comment, Coolant, Spindle, Stop, ToolChange
from verne_post.errors import CheckError, OutputError
from verne_post.output.controller import LINUXCNC, Controller
from verne_post.output.gcode import (
    MAX_COMMENT_CHARS,
    FeedRateError,
    GcodeFormat,
    Program,
    comment_text,
    format_program,
    write_program,
)
from verne_post.verify.rs274 import (
    FEED_INVERSE_TIME,
    INSTALL_HINT,
    Rs274Error,
    Rs274Result,
    find_rs274,
    inverse_time_rate,
    run_rs274,
)

LINE_LIMIT = 252  # LinuxCNC: "Command too long" above this many characters
TOOLS = {1: (120.0, 0.5), 12: (85.25, -1.125), 5: (60.0, 0.0)}


def numbered(step: int) -> Controller:
    """The default profile with block numbers from ``step`` by ``step``."""
    return replace(LINUXCNC, block_numbers=(step, step))


def random_program(m: int = 3000, seed: int = 7) -> Program:
    """A synthetic program: random joints, rapid/feed mix, tool changes, spindle, coolant, comments.

    rho in 0..1300 mm, theta1 in -90..90 deg, theta2 accumulating well past 360 deg (both signs),
    some rotary-only and zero-length feed blocks, durations from 1 ms to 5 min.
    """
    rng = np.random.default_rng(seed)
    rho = rng.uniform(0.0, 1300.0, (m, 3))
    theta1 = rng.uniform(-90.0, 90.0, m)
    theta2 = np.cumsum(rng.uniform(-40.0, 70.0, m))  # reaches several thousand degrees
    theta2[: m // 10] -= 800.0  # and negative values below -360
    rotary_only = rng.random(m) < 0.05
    rotary_only[0] = False
    for k in np.flatnonzero(rotary_only):
        rho[k] = rho[k - 1]
    zero_length = np.flatnonzero(rng.random(m) < 0.01)
    zero_length = zero_length[zero_length > 0]
    rho[zero_length] = rho[zero_length - 1]
    theta1[zero_length] = theta1[zero_length - 1]
    theta2[zero_length] = theta2[zero_length - 1]
    joints = np.column_stack([rho, np.radians(theta1), np.radians(theta2)])
    rapid = rng.random(m) < 0.15
    rapid[0] = True
    duration = 10.0 ** rng.uniform(-3.0, 2.5, m)
    duration[rapid] = 0.0  # ignored on rapids
    events = (
        ToolChange(index=0, line=3, tool=1, length=120.0),
        Spindle(index=0, line=4, rpm=12000.0, direction="CW"),
        Coolant(index=0, line=5, mode="FLOOD"),
        Comment(index=0, line=6, text="op (roughing) #1"),
        Comment(index=10, line=20, text="Schruppen äöü ß – 東京 (Teil 2)"),
        Comment(index=11, line=21, text="MSG, this must stay a comment"),
        Coolant(index=m // 3, line=30, mode="MIST"),
        ToolChange(index=m // 3, line=31, tool=12),
        Spindle(index=m // 3, line=32, rpm=8000.5, direction="CCW"),
        Coolant(index=m // 3 + 1, line=33, mode="THRU"),
        Stop(index=m // 2, line=40, optional=False),
        Stop(index=m // 2 + 5, line=41, optional=True),
        Spindle(index=2 * m // 3, line=50, rpm=0.0, direction="OFF"),
        ToolChange(index=2 * m // 3, line=51, tool=5),
        Spindle(index=2 * m // 3, line=52, rpm=15000.0, direction="CW"),
        Coolant(index=m, line=60, mode="OFF"),
        Comment(index=m, line=61, text="end of (part)"),
    )
    return Program(
        joints=joints,
        rapid=rapid,
        duration=duration,
        line=np.arange(100, 100 + m),
        events=events,
        part_name="bracket (rev B)",
        header=("MACHINE verne.yaml", "CL part.cl (sha1 0123abcd)"),
        tool_lengths=TOOLS,
    )


def small_program(m: int = 5, **kw: object) -> Program:
    """A tiny feed-only program with one tool."""
    joints = np.column_stack([np.linspace(1.0, 5.0, m)] * 3 + [np.zeros(m), np.linspace(0.0, 1.0, m)])
    args: dict[str, object] = dict(
        joints=joints,
        rapid=np.zeros(m, dtype=bool),
        duration=np.full(m, 0.5),
        line=np.arange(1, m + 1),
        events=(ToolChange(index=0, line=1, tool=1),),
        part_name="p",
        header=(),
        tool_lengths={1: (100.0, 0.0)},
    )
    args.update(kw)
    return Program(**args)  # type: ignore[arg-type]


def require_rs274() -> str:
    """The rs274 executable; the calling test FAILS (never skips) when LinuxCNC is not installed."""
    exe = find_rs274()
    if exe is None:
        pytest.fail(INSTALL_HINT, pytrace=False)
    return exe


def interpret(program: Program, fmt: GcodeFormat, tmp_path: Path, exe: str) -> tuple[Rs274Result, Path]:
    path = tmp_path / "prog.ngc"
    write_program(program, fmt, path)
    tools = [ev.tool for ev in program.events if isinstance(ev, ToolChange)]
    return run_rs274(path, tool_numbers=tools, executable=exe, timeout=120.0), path


def check_against_interpreter(program: Program, fmt: GcodeFormat, result: Rs274Result) -> None:
    """Every move end, kind, feed mode and inverse-time rate the interpreter reports is the program's."""
    assert result.errors == []
    m = program.joints.shape[0]
    assert result.moves.shape == (m, 6)
    expected = np.column_stack(
        [
            program.joints[:, :3],
            np.degrees(program.joints[:, 3]),
            np.zeros(m),
            np.degrees(program.joints[:, 4]),
        ]
    )
    # Half a unit of the last written decimal (rs274 prints 4 decimals, so never finer than that).
    decimals = np.array([fmt.linear_decimals] * 3 + [fmt.angular_decimals, 4, fmt.angular_decimals])
    half = np.maximum(0.5 * 10.0 ** -decimals.astype(float), 0.5e-4)
    half[4] = 0.0  # B is never written: exactly 0
    err = np.abs(result.moves - expected)
    tol = half * (1 + 1e-9) + 1e-9 * np.abs(expected)
    worst = np.unravel_index(np.argmax(err - tol), err.shape)
    assert np.all(err <= tol), (
        f"block {worst[0]} axis {'XYZABC'[worst[1]]}: rs274 {result.moves[worst]} vs {expected[worst]}"
    )
    np.testing.assert_array_equal(result.kinds, (~program.rapid).astype(np.int8))

    feed = ~program.rapid
    assert np.all(result.feed_modes[feed] == FEED_INVERSE_TIME)
    # rs274 reports max(0.1, L * F) with 4 decimals, L from the positions it reached.
    start = np.vstack([np.zeros((1, 6)), result.moves[:-1]])[feed]
    end = result.moves[feed]
    f_exact = 60.0 / program.duration[feed]
    h = 0.5 * 10.0**-fmt.feed_decimals * (1 + 1e-9)
    hi = inverse_time_rate(start, end, f_exact + h) * (1 + 1e-12) + 0.5e-4 + 1e-9
    lo = inverse_time_rate(start, end, np.maximum(f_exact - h, 0.0)) * (1 - 1e-12) - 0.5e-4 - 1e-9
    rates = result.feed_rates[feed]
    bad = np.flatnonzero((rates > hi) | (rates < lo))
    assert bad.size == 0, (
        f"feed block {np.flatnonzero(feed)[bad[0]]}: rate {rates[bad[0]]} not in [{lo[bad[0]]}, {hi[bad[0]]}]"
    )


# ---------------------------------------------------------------------------------------------
# against the interpreter


def test_rs274_random_program(tmp_path: Path) -> None:
    rs274_exe = require_rs274()
    program = random_program()
    fmt = GcodeFormat()
    result, _ = interpret(program, fmt, tmp_path, rs274_exe)
    check_against_interpreter(program, fmt, result)

    assert result.named("SELECT_TOOL") == ["1", "12", "5"]
    speeds = [float(a.split(",")[1]) for a in result.named("SET_SPINDLE_SPEED")]
    assert speeds == [12000.0, 8000.5, 15000.0]
    assert len(result.named("START_SPINDLE_CLOCKWISE")) == 2
    assert len(result.named("START_SPINDLE_COUNTERCLOCKWISE")) == 1
    assert len(result.named("FLOOD_ON")) == 2  # FLOOD and THRU
    assert len(result.named("MIST_ON")) == 1
    assert len(result.named("PROGRAM_STOP")) == 1
    assert len(result.named("OPTIONAL_PROGRAM_STOP")) == 1
    assert result.named("MESSAGE") == []  # "MSG, ..." stayed a comment
    comments = [c.strip('"') for c in result.named("COMMENT")]
    assert "PART bracket [rev B]" in comments
    assert "op [roughing] #1" in comments
    assert "TOOL 12 LENGTH 85.2500 DELTA -1.1250" in comments
    assert any(c.startswith("Schruppen aou ss") and "[Teil 2]" in c for c in comments)
    assert len(result.named("PROGRAM_END")) == 1


def test_rs274_block_numbers_and_other_decimals(tmp_path: Path) -> None:
    rs274_exe = require_rs274()
    program = random_program(m=1500, seed=11)
    fmt = GcodeFormat(
        linear_decimals=3, angular_decimals=2, feed_decimals=3, controller=numbered(5)
    )
    result, path = interpret(program, fmt, tmp_path, rs274_exe)
    check_against_interpreter(program, fmt, result)
    assert re.search(
        r"^N\d+ G1 X\d+\.\d{3} Y\d+\.\d{3} Z\d+\.\d{3} A-?\d+\.\d{2} C-?\d+\.\d{2} F\d+\.\d{3}$",
        path.read_text(),
        re.MULTILINE,
    )


def test_rs274_empty_and_rapid_only_programs(tmp_path: Path) -> None:
    rs274_exe = require_rs274()
    empty = Program(np.zeros((0, 5)), np.zeros(0, bool), np.zeros(0), np.zeros(0, int))
    result, path = interpret(empty, GcodeFormat(), tmp_path, rs274_exe)
    assert result.moves.shape == (0, 6)
    assert "G93" not in path.read_text()
    rapids = Program(np.array([[1.0, 2.0, 3.0, 0.1, 7.0]]), np.ones(1, bool), np.zeros(1), np.ones(1, int))
    result, path = interpret(rapids, GcodeFormat(), tmp_path, rs274_exe)
    assert result.kinds.tolist() == [0]
    assert "G93" not in path.read_text()


def test_rs274_reports_errors(tmp_path: Path) -> None:
    rs274_exe = require_rs274()
    bad = tmp_path / "bad.ngc"
    bad.write_text("%\nG21 G90 G93\nG1 X1 F10\nG1 X2\nM30\n%\n")  # G93 block without F
    with pytest.raises(Rs274Error, match="F word missing"):
        run_rs274(bad, tool_numbers=[], executable=rs274_exe)
    result = run_rs274(bad, tool_numbers=[], executable=rs274_exe, check=False)
    assert result.errors and result.moves.shape == (1, 6)
    early = tmp_path / "early.ngc"
    early.write_text("%\nG0 X1\n%\nG0 X2\nM30\n")  # the second % silently ends the program
    with pytest.raises(Rs274Error, match="M2/M30"):
        run_rs274(early, tool_numbers=[], executable=rs274_exe)
    tool = tmp_path / "tool.ngc"
    tool.write_text("T3 M6\nM30\n")
    with pytest.raises(Rs274Error, match="tool 3"):
        run_rs274(tool, tool_numbers=[1], executable=rs274_exe)


# ---------------------------------------------------------------------------------------------
# layout and formatting


def test_layout() -> None:
    program = random_program(m=400)
    lines = list(format_program(program, GcodeFormat()))
    assert lines[0] == "%" and lines[-1] == "%"
    assert lines[1] == "(PART bracket [rev B])"
    assert lines[2:4] == ["(MACHINE verne.yaml)", "(CL part.cl [sha1 0123abcd])"]
    assert lines[4] == "G21 G90 G17 G40 G49 G94"
    assert lines[-4:-1] == ["M5 M9", "G94", "M30"]
    assert lines.count("G93") == 1
    first_g1 = next(i for i, ln in enumerate(lines) if ln.startswith("G1 "))
    assert lines.index("G93") < first_g1
    motion = [ln for ln in lines if ln.startswith(("G0 ", "G1 "))]
    assert len(motion) == 400
    assert all(" F" in ln for ln in motion if ln.startswith("G1 "))
    assert not any(" F" in ln for ln in motion if ln.startswith("G0 "))
    assert not any(" B" in ln for ln in motion)
    assert all(len(ln) <= LINE_LIMIT and ln.isascii() for ln in lines)
    for ln in lines:  # no parentheses inside comments
        if ln.startswith("("):
            assert ln.endswith(")") and "(" not in ln[1:-1] and ")" not in ln[1:-1]
    assert "(TOOL 1 LENGTH 120.0000 DELTA 0.5000)" in lines
    i = lines.index("(TOOL 1 LENGTH 120.0000 DELTA 0.5000)")
    assert lines[i + 1 : i + 4] == ["T1 M6", "S12000 M3", "M8"]


def test_numbers_fixed_decimals_and_no_negative_zero() -> None:
    rng = np.random.default_rng(3)
    m = 5000
    joints = np.column_stack([rng.uniform(-2000, 2000, (m, 3)), rng.uniform(-60, 60, (m, 2))])
    joints[:10] = -1e-9  # rounds to zero: must print 0.0000, never -0.0000
    duration = 10.0 ** rng.uniform(-4, 3, m)
    program = Program(joints, np.zeros(m, bool), duration, np.arange(m))
    fmt = GcodeFormat(linear_decimals=4, angular_decimals=3, feed_decimals=5)
    motion = [ln for ln in format_program(program, fmt) if ln.startswith("G1 ")]
    assert len(motion) == m
    assert motion[0] == "G1 X0.0000 Y0.0000 Z0.0000 A0.000 C0.000 F" + f"{60 / duration[0]:.5f}"
    assert not any("-0.0000 " in ln or ln.endswith("-0.000") for ln in motion)
    for k in range(m):
        x, y, z = (f"{v:.4f}" for v in joints[k, :3])
        a, c = (f"{v:.3f}" for v in np.degrees(joints[k, 3:]))
        expected = f"G1 X{x} Y{y} Z{z} A{a} C{c} F{60.0 / duration[k]:.5f}"
        assert motion[k] == expected.replace("-0.0000 ", "0.0000 ").replace("-0.000 ", "0.000 ")


def test_block_numbers() -> None:
    program = random_program(m=300)
    lines = list(format_program(program, GcodeFormat(controller=numbered(10))))
    numbers = []
    for ln in lines:
        if ln == "%" or ln.startswith("("):
            continue
        match = re.match(r"N(\d+) \S", ln)
        assert match, ln
        numbers.append(int(match.group(1)))
    assert numbers == list(range(10, 10 * len(numbers) + 1, 10))
    assert not any(ln.startswith("N") for ln in lines if ln == "%" or "(" in ln)
    plain = list(format_program(program, GcodeFormat()))
    assert [re.sub(r"^N\d+ ", "", ln) for ln in lines] == plain


def test_block_numbers_across_chunks(monkeypatch: pytest.MonkeyPatch) -> None:
    program = random_program(m=300)
    fmt = GcodeFormat(controller=numbered(1))
    whole = list(format_program(program, fmt))
    monkeypatch.setattr(gcode, "_CHUNK", 7)
    assert list(format_program(program, fmt)) == whole


def test_feed_never_zero_or_infinite() -> None:
    fmt = GcodeFormat(feed_decimals=5)
    ok = small_program(duration=np.full(5, 60.0 / 1e-5))  # F = 0.00001 exactly: still written
    assert all(ln.endswith("F0.00001") for ln in format_program(ok, fmt) if ln.startswith("G1"))
    slow = small_program(duration=np.array([0.5, 0.5, 1e9, 0.5, 0.5]))  # F = 6e-8 rounds to 0
    with pytest.raises(ValueError, match=r"CL line 3: .* rounds to 0"):
        format_program(slow, fmt)
    with pytest.raises(CheckError):
        format_program(slow, fmt)
    assert issubclass(FeedRateError, ValueError)
    fast = small_program(duration=np.array([0.5, 1e-300, 0.5, 0.5, 0.5]))
    with pytest.raises(FeedRateError, match="too large"):
        format_program(fast, fmt)
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="CL line 4"):
            format_program(small_program(duration=np.array([0.5, 0.5, 0.5, bad, 0.5])), fmt)
    # Rapid blocks need no duration.
    rapid = small_program(rapid=np.ones(5, bool), duration=np.zeros(5))
    assert not any(" F" in ln for ln in format_program(rapid, fmt))


def test_invalid_input() -> None:
    with pytest.raises(ValueError, match="shape"):
        format_program(small_program(joints=np.zeros((5, 6))))
    with pytest.raises(ValueError, match="CL line 2"):
        joints = small_program().joints.copy()
        joints[1, 4] = np.nan
        format_program(small_program(joints=joints))
    with pytest.raises(ValueError, match="no tool length given for tool 9"):
        format_program(small_program(events=(ToolChange(index=0, line=1, tool=9),)))
    with pytest.raises(ValueError, match="event index 6"):
        format_program(small_program(events=(Stop(index=6, line=1),)))
    with pytest.raises(ValueError, match="feed_decimals"):
        format_program(small_program(), GcodeFormat(feed_decimals=-1))


def test_comment_text() -> None:
    assert comment_text("a (b) c") == "a [b] c"
    assert comment_text("Fräsen Ø10 – 東 5°") == "Frasen O10 - ? 5 deg"
    assert comment_text("line\nbreak\ttab") == "line break tab"
    for active in ("MSG, hi", " debug,x", "PRINT,y", "LOGOPEN,/tmp/x", "abort, no", "PYRUN,x", "probeopen f"):
        assert comment_text(active).startswith("- ")
    assert comment_text("message to operator") == "message to operator"
    long = comment_text("x" * 1000)
    assert len(long) == MAX_COMMENT_CHARS and long.endswith("...")
    assert comment_text("TOOL 3") == "TOOL 3"


def test_determinism(tmp_path: Path) -> None:
    program = random_program(m=2000)
    fmt = GcodeFormat(controller=numbered(10))
    a, b = tmp_path / "a.nc", tmp_path / "b.nc"
    write_program(program, fmt, a)
    write_program(random_program(m=2000), fmt, b)
    assert a.read_bytes() == b.read_bytes()
    assert a.read_text() == "\n".join(format_program(program, fmt)) + "\n"


# ---------------------------------------------------------------------------------------------
# atomic writes


def test_write_replaces_existing_file_and_keeps_mode(tmp_path: Path) -> None:
    target = tmp_path / "out.nc"
    target.write_text("old\n")
    target.chmod(0o640)
    write_program(small_program(), GcodeFormat(), target)
    assert target.read_text().startswith("%\n(PART p)\n")
    assert (target.stat().st_mode & 0o777) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.nc"]


def test_write_new_file_mode_follows_umask(tmp_path: Path) -> None:
    target = tmp_path / "new.nc"
    old = os.umask(0o022)
    try:
        write_program(small_program(), None, target)
    finally:
        os.umask(old)
    assert (target.stat().st_mode & 0o777) == 0o644


def test_write_failure_before_writing_leaves_nothing(tmp_path: Path) -> None:
    target = tmp_path / "out.nc"
    bad = small_program(duration=np.array([0.5, 0.5, 0.0, 0.5, 0.5]))
    with pytest.raises(ValueError):
        write_program(bad, GcodeFormat(), target)
    assert list(tmp_path.iterdir()) == []
    target.write_text("precious\n")
    with pytest.raises(ValueError):
        write_program(bad, GcodeFormat(), target)
    assert target.read_text() == "precious\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.nc"]


def test_write_failure_midway_never_clobbers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real = gcode._motion_text
    calls = {"n": 0}

    def failing(*args: object, **kwargs: object) -> object:
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError("disk full (simulated)")
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(gcode, "_CHUNK", 50)
    monkeypatch.setattr(gcode, "_motion_text", failing)
    target = tmp_path / "out.nc"
    with pytest.raises(OutputError, match=r"out\.nc: cannot write: disk full"):
        write_program(random_program(m=400), GcodeFormat(), target)
    assert list(tmp_path.iterdir()) == []  # no output, no temporary file left

    target.write_text("precious\n")
    calls["n"] = 0
    with pytest.raises(OutputError, match=r"out\.nc: cannot write: disk full"):
        write_program(random_program(m=400), GcodeFormat(), target)
    assert target.read_text() == "precious\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.nc"]
