"""Time-parametrised output of every example, resampled and checked against the limits."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from tests.test_pipeline import CASES, EXAMPLES
from verne_post.cl import read_toolpath
from verne_post.cli import main
from verne_post.cli.common import MIN_PERIOD
from verne_post.errors import InputError
from verne_post.options import PostOptions
from verne_post.output.trajectory import MAX_DECIMALS, default_decimals, write_timed_csv
from verne_post.pipeline import postprocess
from verne_post.planning.schedule import Schedule, Segment
from verne_post.planning.timing import RapidPlan

NAMES = ("rho1", "rho2", "rho3", "theta1", "theta2")
# The impeller runs for 20 minutes: sampled at 5 ms (its jerk filter spans ~60 ms), the rest at 1 ms.
PERIOD = {"impeller_5axis.cls": 0.005}


def _limits(machine: vp.Machine) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    joints = [getattr(machine.joints, n) for n in NAMES]
    return tuple(np.array([getattr(j, field) for j in joints]) for field in ("velocity", "acceleration", "jerk"))


def _run(tmp_path: Path, name: str, offset: tuple[float, ...], suffix: str, *extra: str) -> Path:
    output = tmp_path / (Path(name).stem + suffix)
    result = CliRunner().invoke(main, [str(EXAMPLES / name), "-o", str(output), "--quiet", "--work-offset",
                                       *map(str, offset), *extra])
    assert result.exit_code == 0, result.stderr
    return output


@pytest.mark.parametrize("planning", [(), ("--optimize",)], ids=["filtered", "optimized"])
@pytest.mark.parametrize(("name", "offset"), CASES)
def test_timed_csv_respects_every_limit(tmp_path: Path, name: str, offset: tuple[float, ...],
                                        planning: tuple[str, ...]) -> None:
    machine = vp.load_machine()
    h = PERIOD.get(name, 0.001)
    path = _run(tmp_path, name, offset, ".csv", "--period", str(h), *planning)
    header = path.read_text().split("\n", 1)[0].split(",")
    assert header[:6] == ["t", *NAMES] and header[-3:] == ["feed", "motion", "line"]
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(17))
    text = np.loadtxt(path, delimiter=",", skiprows=1, usecols=(17, 18), dtype=str)
    t, q, v, a = data[:, 0], data[:, 1:6], data[:, 6:11], data[:, 11:16]
    np.testing.assert_allclose(np.diff(t), h, atol=1e-6)
    velocity, acceleration, jerk = _limits(machine)
    # Finite differences at the sample period (positions -> velocity, velocity -> acceleration,
    # acceleration -> jerk), against the YAML limits (mm and degrees).
    assert np.all(np.abs(np.diff(q, axis=0)) / h <= 1.02 * velocity)
    assert np.all(np.abs(np.diff(v, axis=0)) / h <= 1.02 * acceleration)
    assert np.all(np.abs(np.diff(a, axis=0)) / h <= 1.02 * jerk)
    # Tool-tip speed relative to the part, by forward kinematics of consecutive samples, within
    # the feed the CAM programmed for the CL line being run.
    cl = read_toolpath(EXAMPLES / name)
    feed_of_line = dict(zip(cl.line.tolist(), cl.feed.tolist(), strict=True))
    result = postprocess(EXAMPLES / name, machine, PostOptions(work_offset=offset, plan=False))
    length_of_line = dict(zip(result.poses.line.tolist(), result.poses.tool_length.tolist(), strict=True))
    lines = text[:, 1].astype(int)
    lengths = np.array([length_of_line[k] for k in lines])
    fk = vp.forward_kinematics(machine, np.column_stack([q[:, :3], np.radians(q[:, 3:])]), tool_length=lengths)
    speed = np.linalg.norm(np.diff(fk.tip, axis=0), axis=1) / h * 60.0  # mm/min
    feed_move = (text[1:, 0] == "feed") & (text[:-1, 0] == "feed") & (lines[1:] == lines[:-1])
    programmed = np.array([feed_of_line[k] for k in lines[1:][feed_move]])
    assert feed_move.sum() > 100
    assert np.all(speed[feed_move] <= 1.02 * programmed)


@pytest.mark.parametrize(("name", "offset"), CASES)
def test_block_ends_and_inverse_time_feeds_follow_the_plan(tmp_path: Path, name: str, offset: tuple[float, ...]
                                                           ) -> None:
    machine = vp.load_machine()
    result = postprocess(EXAMPLES / name, machine, PostOptions(work_offset=offset))
    program, schedule = result.program, result.schedule
    # The timed CSV with period 0: one row per block end of the plan, at the pipeline's joints.
    path = _run(tmp_path, name, offset, ".csv", "--period", "0")
    rows = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(6))
    plan = result.blocks.joints
    expected = np.column_stack([plan[1:, :3], np.degrees(plan[1:, 3:])])
    np.testing.assert_allclose(rows[:, 1:], expected, atol=2e-6)
    np.testing.assert_allclose(rows[:, 0], np.cumsum(schedule.duration)[1:], atol=2e-6)
    # The G-code's inverse-time F words reproduce the planned durations, each kept at least at
    # what LinuxCNC 2.9's planner needs for a block that turns A or C (the default dialect's):
    # sqrt(2 max_i |dq_i| / AMAX_i) (tp.c: no blending, no lookahead for rotary lines; tc.c: half
    # the acceleration in a parabolic blend; docs/linuxcnc.md). The program may split a planned
    # block into pieces on its line (guard blocks at rotary corners): each piece keeps that floor
    # too, and a planned block's pieces together take at least its kept time.
    gcode = _run(tmp_path, name, offset, ".nc").read_text()
    f_words = np.array([float(f) for f in re.findall(r"^G1 .* F([0-9.]+)", gcode, re.M)])  # feeds, RAPID too
    amax = np.array([getattr(machine.joints, j).acceleration for j in ("rho1", "rho2", "rho3", "theta1", "theta2")])
    amax[3:] = np.radians(amax[3:])

    def floor(joints: np.ndarray) -> np.ndarray:
        step = np.abs(np.diff(joints, axis=0))
        return np.where(np.any(step[:, 3:] > 0, axis=1), np.sqrt(2.0 * np.max(step / amax, axis=1)), 0.0)

    written = program.joints
    assert len(f_words) == len(written) - 1 - np.sum(program.rapid[1:])
    seconds = np.zeros(len(written))
    seconds[1:][~program.rapid[1:]] = 60.0 / f_words
    ends, k = [], 0  # every planned block end is written, in order (guards only between them)
    for row in plan:
        while not np.array_equal(written[k], row):
            k += 1
        ends.append(k)
        k += 1
    ends = np.array(ends)
    kept = np.maximum(schedule.duration[1:], floor(plan))
    pieces = np.add.reduceat(seconds, ends[:-1] + 1) if len(ends) > 1 else np.zeros(0)
    assert np.all(pieces >= kept * (1 - 1e-3) - 1e-6)
    assert np.all(seconds[1:] >= floor(written) * (1 - 1e-3) - 1e-6)
    assert np.sum(seconds) >= sum(s.plan.total for s in schedule.segments if not s.rapid) * (1 - 1e-3)
    header = float(re.search(r"CYCLE TIME (\d+\.\d) S", gcode).group(1))
    assert header == pytest.approx(np.sum(seconds), abs=0.05 + 1e-4 * header)


def _rounding(decimals: int, h: float) -> float:
    """The most rounding to ``decimals`` adds to a jerk estimate |x3 - 3 x2 + 3 x1 - x0| / h^3:
    each of the four values moves by at most half a unit of its last decimal."""
    return (1 + 3 + 3 + 1) * 0.5 * 10.0**-decimals / h**3


def _jerk_estimates(path: Path, h: float) -> np.ndarray:
    """Third differences of the position columns / h^3 (mm/s^3, deg/s^3), signed, (N - 3, 5)."""
    q = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(1, 6))
    return np.diff(q, 3, axis=0) / h**3


def test_jerk_can_be_checked_from_the_timed_csv_alone(tmp_path: Path) -> None:
    # For a C2 motion (every feed sequence and rapid starts and ends at rest with no acceleration)
    # the third divided difference is a weighted mean of the jerk over the three periods (its
    # Peano kernel is a B-spline: positive, unit integral), so it never exceeds the largest jerk:
    # the allowance is the limit (with the 2 % the other checks of this file give the plan) plus
    # what rounding the printed positions can add, nothing for the finite difference itself.
    _, _, jerk = _limits(vp.load_machine())
    h, name = 0.001, "nx_swarf_inch_crlf.cls"  # rides the theta2 jerk limit; has rapids
    fine = _run(tmp_path, name, (0.0, 0.0, 0.0), ".csv", "--period", str(h))
    decimals = len(fine.read_text().split("\n", 2)[1].split(",")[1].partition(".")[2])
    assert decimals >= 9
    assert _rounding(decimals, h) <= 1e-3 * jerk.min()  # resolves a tenth of a percent of every limit
    estimate = _jerk_estimates(fine, h)
    assert np.all(np.abs(estimate) <= 1.02 * jerk + _rounding(decimals, h))
    # With 6 decimals the same check is impossible: rounding can add 4,000 deg/s^3, more than the
    # 2 % tolerance of the rotary limits, and in this file it does; the plan, within its limits,
    # would fail the check.
    coarse = _run(tmp_path, name, (0.0, 0.0, 0.0), "_6.csv", "--period", str(h), "--decimals", "6")
    coarse_estimate = _jerk_estimates(coarse, h)
    assert coarse_estimate.shape == estimate.shape
    assert np.all(_rounding(6, h) > 0.02 * jerk[3:])
    assert np.any(np.abs(coarse_estimate - estimate).max(axis=0) > 0.02 * jerk)
    assert np.any(np.abs(coarse_estimate) > 1.02 * jerk)


@pytest.mark.parametrize("period", [MIN_PERIOD, 2e-4, 3.3e-4, 5e-4, 7e-4, 1e-3, 5e-3, 0.0])
def test_default_decimals_keep_the_rounding_of_jerk_estimates_small(period: float) -> None:
    decimals = default_decimals(period)
    assert 9 <= decimals <= MAX_DECIMALS
    if period > 0:  # enough, and not one more than needed (or 9)
        assert _rounding(decimals, period) <= 4.0 * (1 + 1e-9)
        assert decimals == 9 or _rounding(decimals - 1, period) > 4.0


def test_a_value_too_large_for_its_decimals_is_an_error_and_no_file(tmp_path: Path) -> None:
    machine = vp.load_machine()
    # A rotary table turned continuously through 10^7 degrees: 10^19 at 12 decimals overflows the
    # 64-bit integers the numbers are formatted through; 9 decimals fit.
    joints = np.array([600.0, 600.0, 600.0, 0.0, math.radians(1e7)])
    schedule = Schedule(np.zeros(2), (Segment(1, 1, True, RapidPlan(joints, joints.copy(), 0.0, None), 0.0),))
    args = (machine, schedule, np.zeros(2), np.array([5, 7]), 0.0)
    with pytest.raises(InputError, match="fewer --decimals"):
        write_timed_csv(tmp_path / "big.csv", *args, decimals=MAX_DECIMALS)
    assert not (tmp_path / "big.csv").exists()
    write_timed_csv(tmp_path / "big.csv", *args, decimals=9)
    row = (tmp_path / "big.csv").read_text().splitlines()[1].split(",")
    assert float(row[5]) == pytest.approx(1e7, abs=1e-6)
