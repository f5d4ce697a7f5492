"""Placement: the work offset it finds runs, the room it reports is the real edge, and when
no offset works it says why. Judged by the full ``check`` (the CLI), not by the search."""

from __future__ import annotations

import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from verne_post.api import Status, classify, pose_margins
from verne_post.checks.headroom import headroom, smallest
from verne_post.checks.stage import Checked, check_poses
from verne_post.cl import read_toolpath
from verne_post.cli import main
from verne_post.motion.poses import machine_poses
from verne_post.options import PostOptions
from verne_post.placement import search
from verne_post.placement.search import place

DATA = Path(__file__).parent / "data"
EXAMPLES = Path(__file__).parent.parent / "examples"
REAL = DATA / "creo8_profilfraesen_mm.ncl"  # Creo 8, no tool length in the file
TOOL = "50"


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args))
    return result.exit_code, result.stdout, result.stderr


def check_at(path: Path, offset: np.ndarray, *extra: str) -> int:
    return run("check", str(path), "--tool-length", TOOL, "--work-offset", *(f"{v:.4f}" for v in offset), "-q",
               *extra)[0]


@pytest.fixture(scope="module")
def placed(tmp_path_factory: pytest.TempPathFactory) -> dict:
    report = tmp_path_factory.mktemp("place") / "place.json"
    code, out, err = run("place", str(REAL), "--tool-length", TOOL, "--report", str(report), "-q")
    assert code == 0, err
    assert re.search(r"^work offset \S+ \S+ \S+ mm", out, re.M)
    return json.loads(report.read_text())


def test_found_offset_runs_the_real_program(placed: dict) -> None:
    assert placed["feasible"] and placed["smallest_headroom"] > 0
    assert check_at(REAL, np.array(placed["work_offset_mm"])) == 0  # the full check, timing included


@pytest.mark.parametrize("axis", range(3))
@pytest.mark.parametrize("sign", [-1, 1])
def test_room_is_the_edge_of_the_feasible_region(placed: dict, axis: int, sign: int) -> None:
    """Moving the part by the reported room still runs; by 1 mm more, it does not."""
    room = placed["room_mm"]["xyz"[axis]]["minus" if sign < 0 else "plus"]
    offset = np.array(placed["work_offset_mm"])
    step = np.zeros(3)
    step[axis] = sign
    assert room > 1.0
    assert check_at(REAL, offset + room * step, "--no-timing") == 0
    assert check_at(REAL, offset + (room + 1.0) * step, "--no-timing") == 3


def test_found_offset_is_a_local_optimum_of_the_whole_program(placed: dict) -> None:
    """No offset 5 mm away (26 directions) has a larger smallest headroom over every block end
    of the full checks: the search did not stop short of the optimum."""
    machine = vp.load_machine()
    options = PostOptions(tool_length=float(TOOL), plan=False)
    zero = machine_poses(read_toolpath(REAL), machine, work_offset=(0, 0, 0), tool_length=float(TOOL))

    def smallest_headroom(offset: np.ndarray) -> float:
        blocks = check_poses(machine, replace(zero, tip=zero.tip + offset), options).blocks
        blocks = blocks.rows(np.flatnonzero(~blocks.between))  # the cuts' (moves between them only run)
        return float(np.min(smallest(headroom(machine, blocks.joints, blocks.result.margins))[0]))

    centre = np.array(placed["work_offset_mm"])
    best = smallest_headroom(centre)
    assert best == pytest.approx(placed["smallest_headroom"], abs=2e-3)
    steps = [np.array(d, float) for d in np.ndindex(3, 3, 3) if d != (1, 1, 1)]
    around = [smallest_headroom(centre + 5.0 * (d - 1) / np.linalg.norm(d - 1)) for d in steps]
    assert max(around) <= best + 5e-3


def test_the_impeller_example_is_placed_and_runs() -> None:
    machine = vp.load_machine()
    path = EXAMPLES / "impeller_5axis.cls"
    zero = machine_poses(read_toolpath(path), machine, work_offset=(0, 0, 0))
    placement = place(machine, zero, PostOptions(plan=False))
    assert placement.feasible and placement.margin > 0.2
    assert all(lo > 10 and hi > 10 for lo, hi in placement.room)
    code, _, err = run("check", str(path), "--work-offset", *(f"{v:.4f}" for v in placement.offset), "-q",
                       "--no-timing")
    assert code == 0, err


@pytest.mark.parametrize("room", [False, True])
def test_work_offset_auto_is_recorded_in_the_gcode_header(tmp_path: Path, placed: dict, room: bool) -> None:
    """The offset 'place' finds, and with --room the room it reports (else a line saying it was
    not measured, never a room no full check confirmed)."""
    out, page = tmp_path / "part.nc", tmp_path / "part.html"
    code, _, err = run("post", str(REAL), "--tool-length", TOOL, "--work-offset", "auto", *(["--room"] * room),
                       "-o", str(out), "--report", str(page), "-q")
    assert code == 0, err
    text = out.read_text()
    assert bool(re.search(r"room x -[\d.]+/\+[\d.]+, y", page.read_text())) == room
    assert ("room not measured" in page.read_text()) != room
    x, y, z = (float(v) for v in re.search(r"\(WORK OFFSET (\S+) (\S+) (\S+) MM", text).groups())
    assert np.allclose([x, y, z], placed["work_offset_mm"], atol=1e-3)  # deterministic: the same as 'place'
    assert "WORK OFFSET CHOSEN BY VERNE-POST PLACE" in text
    moves = re.search(r"PART MAY MOVE BY X -(\S+)/\+(\S+) Y -(\S+)/\+(\S+) Z -(\S+)/\+(\S+) MM", text)
    if room:
        expected = [placed["room_mm"][a][side] for a in "xyz" for side in ("minus", "plus")]
        assert np.allclose([float(v) for v in moves.groups()], expected, atol=0.051)  # printed to 0.1 mm
    else:
        assert moves is None and "ROOM AROUND IT NOT MEASURED" in text


def test_room_without_an_automatic_offset_is_a_one_line_error(tmp_path: Path) -> None:
    out = tmp_path / "part.nc"
    code, _, err = run("post", str(REAL), "--tool-length", TOOL, "--room", "-o", str(out), "-q")
    assert code == 2 and not out.exists()
    assert err.count("\n") == 1 and "--work-offset auto" in err


def test_first_failure_gives_the_verdict_of_the_full_checks() -> None:
    """check_poses(first_failure=True), which placement's room uses, against the complete check
    at offsets across two edges of the NX example's feasible region: the same verdict; block
    ends that are the complete linearisation's own; everything the same where the program runs."""
    machine = vp.load_machine()
    zero = machine_poses(read_toolpath(EXAMPLES / "nx_variable_axis_inch.cls"), machine, work_offset=(0, 0, 0))
    options = PostOptions(plan=False)
    centre = np.array([0.9, 0.1, -74.1])  # near where 'place' puts it: the program runs here (asserted below)
    # out along -x and +y the bodies meet from about 350 mm, the joint limits fail from about 405 mm
    offsets = [centre] + [centre + t * np.array(d) for d, span in (((-1, 0, 0), range(398, 423, 3)),
                                                                   ((0, 1, 0), range(396, 421, 3))) for t in span]
    seen = set()

    def inserted(checked: Checked) -> int:
        return int(np.sum((checked.blocks.fraction < 1) & ~checked.blocks.between))

    for k, offset in enumerate(offsets):
        shifted = replace(zero, tip=zero.tip + offset)
        full = check_poses(machine, shifted, options)
        quick = check_poses(machine, shifted, options, first_failure=True)
        assert bool(quick.violations) == bool(full.violations)
        ends = {(int(p), float(f)): q for p, f, q in zip(full.blocks.pose, full.blocks.fraction, full.blocks.joints,
                                                            strict=True)}
        for p, f, q in zip(quick.blocks.pose, quick.blocks.fraction, quick.blocks.joints, strict=True):
            assert np.array_equal(ends[(int(p), float(f))], q, equal_nan=True)
        if not full.violations:
            assert quick.violations == full.violations and np.array_equal(quick.blocks.pose, full.blocks.pose)
            seen.add("runs")
        # the moves between cuts are made in any case: what the linearisation inserted tells
        elif inserted(quick) == 0:
            seen.add("stopped at the CL poses")
        elif inserted(quick) < inserted(full):
            seen.add("stopped at an inserted pose")
        assert k > 0 or not full.violations
    assert seen == {"runs", "stopped at the CL poses", "stopped at an inserted pose"}


def _cl(tmp_path: Path, name: str, operations: list[tuple[int, float, list[tuple[float, ...]]]]) -> Path:
    lines = ["PARTNO/" + name, "UNITS/MM"]
    for tool, length, poses in operations:
        lines += [f"LOADTL/{tool}", f"TLDATA/MILL,10.0,0.0,{length},0.0,0.0", "RAPID"]
        for k, pose in enumerate(poses):
            lines.append("GOTO/" + ",".join(f"{v:.6f}" for v in pose))
            if k == 0:
                lines.append("FEDRAT/MMPM,1000.0")
    path = tmp_path / f"{name}.cls"
    path.write_text("\n".join([*lines, "FINI", ""]))
    return path


def _line(a: tuple[float, float, float], b: tuple[float, float, float], axis: tuple[float, float, float], n: int = 20
          ) -> list[tuple[float, ...]]:
    return [tuple(a[q] + (b[q] - a[q]) * t / (n - 1) for q in range(3)) + axis for t in range(n)]


def test_no_offset_reaches_a_tilt_beyond_the_machine(tmp_path: Path) -> None:
    tilt = math.radians(150.0)
    path = _cl(tmp_path, "overtilt", [(1, 60.0, _line((0, 0, 0), (50, 0, 0), (math.sin(tilt), 0.0, math.cos(tilt))))])
    code, _, err = run("place", str(path), "-q")
    assert code == 3
    assert len(err.strip().splitlines()) == 1
    assert re.search(r"line 6: the tool axis is tilted 150\.0 deg", err) and "smaller tilt" in err


def test_operations_that_need_different_offsets_are_named(tmp_path: Path) -> None:
    vertical = (0.0, 0.0, 1.0)
    path = _cl(tmp_path, "apart", [(1, 60.0, _line((0, 0, 0), (50, 0, 0), vertical)),
                                   (2, 60.0, _line((0, 0, 2500), (50, 0, 2500), vertical))])
    code, _, err = run("place", str(path), "-q")
    assert code == 3
    assert "tool 2 (from CL line 30) needs a different work offset" in err
    code, _, err = run("check", str(path), "--work-offset", "auto", "-q")
    assert code == 3 and "no work offset lets the whole program run" in err


def test_headroom_is_negative_exactly_where_a_check_fails(machine: vp.Machine) -> None:
    """The headroom's sign against the checks' own verdict (classify) on random joint sets."""
    rng = np.random.default_rng(7)
    joints = np.column_stack([rng.uniform(-50, 1350, (20000, 3)), rng.uniform(-1.7, 1.7, 20000),
                              rng.uniform(-4, 4, 20000)])
    fk = vp.forward_kinematics(machine, joints, tool_length=60.0)
    found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, 60.0)
    status = classify(machine, joints, fk.reachable, found)
    value, _ = smallest(headroom(machine, np.where(fk.reachable[:, None], joints, np.nan), found))
    reachable = status != Status.UNREACHABLE
    assert reachable.sum() > 5000 and (status == Status.OK).sum() > 2000
    assert np.array_equal(value[reachable] >= 0, status[reachable] == Status.OK)
    assert np.all(value[~reachable] < 0)


def test_every_reader_option_of_check_is_an_option_of_place() -> None:
    """Every keyword of the CL reader has its option on 'check', and 'place' (and the other
    commands that read a CL file) take each of them: they share one group."""
    import inspect

    from verne_post.cl import read_cl

    flags = {"units": "--units", "chordal_tolerance": "--arc-tol", "arc_direction": "--arc-direction",
             "frame": "--frame", "feed": "--feed"}
    keywords = [name for name, p in inspect.signature(read_cl).parameters.items() if p.kind is p.KEYWORD_ONLY]
    assert set(keywords) <= set(flags), "a reader keyword without its option here"
    wanted = {flags[name] for name in keywords}

    def options(command: str) -> set[str]:
        return {o for p in main.commands[command].params for o in p.opts}

    assert wanted <= options("check")
    for command in ("place", "post", "batch", "toolpath"):
        assert wanted <= options(command), command


def test_place_reads_with_the_frame_it_is_given(tmp_path: Path) -> None:
    """An NX MCS whose Z points down in the absolute frame, tool axes down in the MCS: read in
    the MCS the tool is upside down and no offset works; mapped by MSYS (--frame apply) the
    tool points up and the part is placed."""
    rows = [f"GOTO/{x:.3f},0.000,-20.000,0.000000,0.000000,-1.000000" for x in np.linspace(0.0, 40.0, 20)]
    path = tmp_path / "down.cls"
    path.write_text("\n".join(["TOOL PATH/DOWN,TOOL,T1", "TLDATA/MILL,10.0,0.0,60.0,0.0,0.0", "LOAD/TOOL,1",
                               "MSYS/0,0,0,0,1,0,1,0,0", "RAPID", rows[0], "FEDRAT/MMPM,1000", *rows[1:],
                               "END-OF-PATH", ""]))
    code, _, err = run("place", str(path), "--frame", "local", "-q")
    assert code == 3 and "tilted 180.0 deg" in err, err
    assert "(with --frame apply the tool axes point away from the table)" in err  # which --frame would
    for frame in (["--frame", "apply"], []):  # without --frame: the reading with the tool above the part
        code, out, err = run("place", str(path), *frame, "-q")
        assert code == 0, err
        assert out.startswith("work offset ")


def test_check_with_an_automatic_offset_fails_with_the_placement_reason_only(tmp_path: Path) -> None:
    """Nothing can be placed: 'check --work-offset auto' says why in one error line, as 'place'
    does, instead of checking every pose at an offset known to fail."""
    tilt = math.radians(150.0)
    path = _cl(tmp_path, "overtilt", [(1, 60.0, _line((0, 0, 0), (50, 0, 0), (math.sin(tilt), 0.0, math.cos(tilt)),
                                                      n=200))])
    _, _, placed = run("place", str(path), "-q")
    code, _, err = run("check", str(path), "--work-offset", "auto", "-q")
    assert code == 3
    errors = [line for line in err.splitlines() if line.startswith("verne-post: error:")]
    assert len(errors) == 1 and "no work offset lets the whole program run" in errors[0]
    assert placed.split("run: ", 1)[1].strip() in errors[0]  # the reason place gives
    assert "more violations" not in err


def test_the_room_checked_in_processes_is_the_room_checked_in_one(monkeypatch: pytest.MonkeyPatch) -> None:
    """The room's full checks of different directions run side by side in forked processes: the
    same offset and room as in one process, with fewer of the checks in this one."""
    machine = vp.load_machine()
    zero = machine_poses(read_toolpath(REAL), machine, work_offset=(0, 0, 0), tool_length=float(TOOL))
    here = []
    real = search.check_poses

    def counted(*args: object, **kwargs: object) -> object:
        here.append(1)  # a forked process counts in its own copy
        return real(*args, **kwargs)

    monkeypatch.setattr(search, "check_poses", counted)
    found = {}
    for workers in (1, 2):
        here.clear()
        placement = place(machine, zero, PostOptions(tool_length=float(TOOL), plan=False, workers=workers))
        found[workers] = (placement.offset, placement.room, placement.margin, len(here))
    assert found[1][:3] == found[2][:3]
    assert found[2][3] < found[1][3]


def test_place_in_one_process_reports_the_room_of_the_default(tmp_path: Path, placed: dict) -> None:
    """'place --workers 1' (every full check in this process) against the default (one process per
    core): the same JSON but for the seconds; --workers 0 is a one-line error."""
    report = tmp_path / "one.json"
    code, _, err = run("place", str(REAL), "--tool-length", TOOL, "--workers", "1", "--report", str(report), "-q")
    assert code == 0, err
    one = json.loads(report.read_text())
    assert {k: v for k, v in one.items() if k != "seconds"} == {k: v for k, v in placed.items() if k != "seconds"}
    code, _, err = run("place", str(REAL), "--tool-length", TOOL, "--workers", "0", "-q")
    assert code == 2 and err.count("\n") == 1 and "--workers" in err
