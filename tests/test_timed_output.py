"""Time-parametrised output of every example, resampled and checked against the limits."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from tests.test_pipeline import CASES, EXAMPLES
from verne_post.cl import read_toolpath
from verne_post.cli import main
from verne_post.pipeline import PostOptions, postprocess

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


@pytest.mark.parametrize(("name", "offset"), CASES)
def test_timed_csv_respects_every_limit(tmp_path: Path, name: str, offset: tuple[float, ...]) -> None:
    machine = vp.load_machine()
    h = PERIOD.get(name, 0.001)
    path = _run(tmp_path, name, offset, ".csv", "--period", str(h))
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
    # The timed CSV with period 0: one row per block end, at the pipeline's joints.
    path = _run(tmp_path, name, offset, ".csv", "--period", "0")
    rows = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(6))
    expected = np.column_stack([program.joints[1:, :3], np.degrees(program.joints[1:, 3:])])
    np.testing.assert_allclose(rows[:, 1:], expected, atol=2e-6)
    np.testing.assert_allclose(rows[:, 0], np.cumsum(schedule.duration)[1:], atol=2e-6)
    # The G-code's inverse-time F words reproduce the planned feed time.
    gcode = _run(tmp_path, name, offset, ".nc").read_text()
    f_words = np.array([float(f) for f in re.findall(r"^G1 .* F(\S+)$", gcode, re.M)])
    planned_feed_time = sum(s.plan.total for s in schedule.segments if not s.rapid)
    assert np.sum(60.0 / f_words) == pytest.approx(planned_feed_time, rel=1e-3)
    assert f"CYCLE TIME {schedule.total:.1f} S" in gcode
