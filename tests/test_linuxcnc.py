"""LinuxCNC in the loop: the exported configuration, and a short program run through LinuxCNC 2.9's
own task, planner and servo loop (``verne-post simulate``), checked against the program's text and
an independent model of the machine (tests/independent.py), not against verne-post's own figures.

Needs Debian's linuxcnc-uspace (``scripts/test`` installs it); fails, saying so, where it is missing.
"""

from __future__ import annotations

import configparser
import importlib
import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from tests.independent import platform_from_tool, rod_residuals
from verne_post.api import forward_kinematics
from verne_post.cli import main
from verne_post.errors import InputError
from verne_post.linuxcnc import export_config, simulate
from verne_post.linuxcnc.measures import path_deviation
from verne_post.linuxcnc.simulate import SimulationResult, linuxcnc_available
from verne_post.motion.linearise import Blocks

# the module: the package's name 'simulate' is the function
simulate_module = importlib.import_module("verne_post.linuxcnc.simulate")
TOOL_LENGTH = 100.0
#: Time scale of the run: 5 is the fastest that gives the K = 1 motion (docs/linuxcnc.md).
TIME_SCALE = 5.0



def _needs_linuxcnc() -> None:
    missing = linuxcnc_available()
    assert missing is None, f"these tests run LinuxCNC: apt-get install -y linuxcnc-uspace ({missing})"

_CL = f"""PARTNO/LCNC
UNITS/MM
TLDATA/MILL,10.0,0.0,{TOOL_LENGTH},0.0,0.0
LOADTL/1
FEDRAT/MMPM,2000.0
RAPID
GOTO/0.0,0.0,20.0,0.0,0.0,1.0
GOTO/0.0,0.0,0.0,0.0,0.0,1.0
GOTO/40.0,0.0,0.0,0.0,0.0,1.0
GOTO/40.0,30.0,0.0,0.3,0.0,0.953939
GOTO/0.0,30.0,0.0,0.0,0.0,1.0
GOTO/0.0,30.0,20.0,0.0,0.0,1.0
"""

_MOVE = re.compile(r"^(?:N\d+\s+)?G[01]\s+X(\S+)\s+Y(\S+)\s+Z(\S+)\s+A(\S+)\s+C(\S+)")


def _limits(machine: vp.Machine) -> tuple[np.ndarray, np.ndarray]:
    """Travel in mm and rad, read from the machine's fields here (not verne_post.api)."""
    names = ("rho1", "rho2", "rho3", "theta1", "theta2")
    low, high = [], []
    for k, name in enumerate(names):
        joint = getattr(machine.joints, name)
        scale = 1.0 if k < 3 else np.pi / 180
        low.append(-np.inf if joint.continuous else joint.min * scale)
        high.append(np.inf if joint.continuous else joint.max * scale)
    return np.array(low), np.array(high)


@pytest.fixture(scope="module")
def posted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("linuxcnc")
    (folder / "short.cls").write_text(_CL)
    program = folder / "short.nc"
    result = CliRunner().invoke(main, ["post", str(folder / "short.cls"), "-o", str(program), "-q",
                                       "--work-offset", "0", "0", "200"])
    assert result.exit_code == 0, result.output
    return program


@pytest.fixture(scope="module")
def run(posted: Path) -> SimulationResult:
    _needs_linuxcnc()
    return simulate(posted, vp.load_machine(), time_scale=TIME_SCALE)


def _blocks(program: Path) -> np.ndarray:
    """Every move's end (X Y Z mm, A C deg) from the program's text."""
    ends = [[float(v) for v in m.groups()] for line in program.read_text().splitlines() if (m := _MOVE.match(line))]
    assert len(ends) > 5
    return np.array(ends)


def test_export_is_the_machine_in_joint_space(tmp_path: Path, machine: vp.Machine) -> None:
    ini_path = export_config(machine, tmp_path / "cfg", home=(100, 47, 46, 0, 0))
    ini = configparser.ConfigParser(inline_comment_prefixes=None, interpolation=None)
    ini.optionxform = str  # LinuxCNC's keys are upper case
    ini.read(ini_path)
    assert ini["KINS"]["KINEMATICS"] == "trivkins coordinates=XYZAC"
    assert ini["KINS"]["JOINTS"] == "5"
    for k, name in enumerate(("rho1", "rho2", "rho3", "theta1", "theta2")):
        section, joint = ini[f"JOINT_{k}"], getattr(machine.joints, name)
        assert float(section["MAX_VELOCITY"]) == pytest.approx(joint.velocity)  # mm/s, deg/s
        assert float(section["MAX_ACCELERATION"]) == pytest.approx(joint.acceleration)
        assert section["HOME_SEARCH_VEL"] == "0"
        if not joint.continuous:
            assert (float(section["MIN_LIMIT"]), float(section["MAX_LIMIT"])) == (joint.min, joint.max)
    assert float(ini["JOINT_0"]["HOME"]) == 100.0 and ini["JOINT_3"]["TYPE"] == "ANGULAR"
    hal = (tmp_path / "cfg" / "verne.hal").read_text()
    assert all(f"joint.{k}.motor-pos-cmd => joint.{k}.motor-pos-fb" in hal for k in range(5))
    # time scale K: velocities x K, accelerations x K^2, servo period / K
    fast = configparser.ConfigParser(interpolation=None)
    fast.optionxform = str
    fast.read(export_config(machine, tmp_path / "fast", time_scale=4.0))
    assert float(fast["JOINT_1"]["MAX_VELOCITY"]) == pytest.approx(4 * machine.joints.rho2.velocity)
    assert float(fast["JOINT_4"]["MAX_ACCELERATION"]) == pytest.approx(16 * machine.joints.theta2.acceleration)
    assert int(fast["EMCMOT"]["SERVO_PERIOD"]) == 250_000


def test_export_command(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["machine", "export", "linuxcnc", "-o", str(tmp_path / "c")])
    assert result.exit_code == 0, result.output
    assert {p.name for p in (tmp_path / "c").iterdir()} >= {"verne.ini", "verne.hal", "verne.tbl"}


def test_without_linuxcnc_one_line_naming_the_package(posted: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(simulate_module, "PROGRAMS", ("verne-post-no-such-linuxcnc-program",))
    with pytest.raises(InputError, match="linuxcnc-uspace"):
        simulate(posted, vp.load_machine())
    result = CliRunner().invoke(main, ["simulate", str(posted)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "linuxcnc-uspace" in lines[0] and "Traceback" not in result.output


def test_the_run_stays_in_travel_and_ends_at_the_last_block(run: SimulationResult,
                                                            posted: Path, machine: vp.Machine) -> None:
    low, high = _limits(machine)
    assert run.joints.shape == (len(run.t), 5) and len(run.t) > 100
    assert np.all(run.joints >= low) and np.all(run.joints <= high)
    last = _blocks(posted)[-1]
    final = np.r_[run.joints[-1, :3], np.degrees(run.joints[-1, 3:])]
    np.testing.assert_allclose(final, last, atol=1e-3)
    # one servo period (1 ms at time scale 1) between samples, whatever the time scale
    np.testing.assert_allclose(np.diff(run.t), 1e-3, atol=1e-12)


def test_cycle_time_against_the_header(run: SimulationResult, posted: Path) -> None:
    header = float(re.search(r"\(CYCLE TIME (\d+\.\d+) S", posted.read_text()).group(1))
    moving = np.flatnonzero(np.any(np.diff(run.joints, axis=0) != 0, axis=1))
    assert run.cycle_time == pytest.approx((moving[-1] - moving[0] + 1) * 1e-3, abs=2e-3)
    # LinuxCNC 2.9's planner has no jerk limit but blends and cannot reach the plan's speed in short blocks
    assert run.cycle_time > 0 and 0.7 * header < run.cycle_time < 2.0 * header, (run.cycle_time, header)


def test_every_block_end_is_passed_in_order_within_the_blend(run: SimulationResult, posted: Path,
                                                            machine: vp.Machine) -> None:
    """LinuxCNC's default G64 blends corners: each block end is passed near, not through. Walking
    the samples forward, each block end's tip is met in turn; how near is measured here and must
    stay within the program's rapid tolerance (in the joints, a rotary corner is cut by degrees
    where the tip hardly moves: the tip is what is bounded)."""
    ends = _blocks(posted)
    ends[:, 3:] = np.radians(ends[:, 3:])
    end_tips = forward_kinematics(machine, ends, tool_length=TOOL_LENGTH).tip
    tips = forward_kinematics(machine, run.joints, tool_length=TOOL_LENGTH).tip
    rapid_tol = float(re.search(r"RAPIDS (\d+\.?\d*) MM", posted.read_text()).group(1))
    start, gaps = 0, []
    for tip in end_tips:
        distance = np.linalg.norm(tips[start:] - tip, axis=1)
        # the first sample after ``start`` that comes within the tolerance, then the closest one near it
        within = np.flatnonzero(distance < rapid_tol)
        assert len(within), f"block end {tip} never reached after sample {start}"
        first = int(within[0])
        run_end = first + int(np.argmax(distance[first:] >= rapid_tol)) if np.any(distance[first:] >= rapid_tol) \
            else len(distance)
        closest = first + int(np.argmin(distance[first:run_end]))
        gaps.append(float(distance[closest]))
        start += closest
    assert max(gaps) < rapid_tol
    assert start >= len(tips) - 2  # the last block end is where the samples end


def test_tip_deviation_against_an_independent_model(run: SimulationResult, posted: Path,
                                                    machine: vp.Machine) -> None:
    """The samples' tips (verified by the independent model's rod lengths) against the program's
    block lines, by brute force here, agree with path_deviation's figures."""
    geometry = machine.kinematic_geometry(TOOL_LENGTH)
    fk = forward_kinematics(machine, run.joints, tool_length=TOOL_LENGTH)
    assert np.all(fk.reachable)
    platform, alpha = platform_from_tool(geometry, fk.tip, fk.axis, run.joints[:, 3], run.joints[:, 4])
    residual = rod_residuals(geometry, platform, alpha, run.joints[:, :3])
    assert np.abs(residual).max() < 1e-6 * geometry.L1**2
    ends = _blocks(posted)
    ends[:, 3:] = np.radians(ends[:, 3:])
    s = np.linspace(0.0, 1.0, 201)[:, None, None]
    dense = (ends[:-1] + s * (ends[1:] - ends[:-1])).transpose(1, 0, 2).reshape(-1, 5)
    line_tips = forward_kinematics(machine, dense, tool_length=TOOL_LENGTH).tip
    a, ab = line_tips[:-1], np.diff(line_tips, axis=0)
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)

    def to_path(tip: np.ndarray) -> float:
        u = np.clip(np.einsum("ij,ij->i", tip - a, ab) / length2, 0.0, 1.0)
        return float(np.min(np.linalg.norm(a + u[:, None] * ab - tip, axis=1)))

    nearest = np.array([to_path(tip) for tip in fk.tip[::3]])
    measured = path_deviation(machine, posted.read_text(), run)
    worst = max(measured.feeds, measured.between_cuts)
    assert nearest.max() == pytest.approx(worst, abs=0.01 + 0.2 * worst)
    assert worst < float(re.search(r"RAPIDS (\d+\.?\d*) MM", posted.read_text()).group(1))


def test_simulate_command(posted: Path, tmp_path: Path) -> None:
    report = tmp_path / "r.json"
    result = CliRunner().invoke(main, ["simulate", str(posted), "--time-scale", "5", "--report", str(report)])
    assert result.exit_code == 0, result.output
    assert "cycle time: executed" in result.output and "header" in result.output
    payload = json.loads(report.read_text())
    assert payload["cycle_time_s"]["executed"] > 0 and payload["joints_within_travel"] is True


def test_without_an_ipc_namespace_nothing_of_linuxcnc_is_left(posted: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the driver may not have a System V IPC namespace of its own (a container without
    CAP_SYS_ADMIN), it removes LinuxCNC's shared memory and semaphores by key: none is left
    (keys from LinuxCNC's own NML file and emcmotcfg.h, read by ``ipcs`` here)."""
    import subprocess

    _needs_linuxcnc()
    monkeypatch.setattr(simulate_module, "_DRIVER",
                        simulate_module._DRIVER.replace("LIBC.unshare(0x08000000) == 0", "False"))
    result = simulate(posted, vp.load_machine(), time_scale=TIME_SCALE)
    assert result.cycle_time > 0
    nml = Path("/usr/share/linuxcnc/linuxcnc.nml").read_text().splitlines()
    keys = {int(f[9]) for f in (line.split() for line in nml) if len(f) > 9 and f[0] == "B" and f[2] == "SHMEM"}
    keys |= {0x48414C32, 0x90280A48, 0x48484C34, 100}
    listed = subprocess.run(["ipcs", "-m", "-s"], capture_output=True, text=True, check=True).stdout
    left = {int(word, 16) for word in re.findall(r"^(0x[0-9a-f]+)\s", listed, re.M)}
    assert not keys & left, sorted(keys & left)


# --- Guard blocks at rotary corners (verne_post.linuxcnc.blending) ---------------------------------

#: A pass of the impeller's nose dome (examples/impeller_5axis.cls, lines 15460-15479): the tool tilts
#: along the pass, then retracts along its axis. In the joints the sliders go on nearly straight at
#: the pass's end while A and C stop: LinuxCNC's G64 P bounds the sliders' blend only, and without
#: guards the tip left the path by 0.08 mm there (docs/linuxcnc.md).
_DOME_CL = """PARTNO/DOME PASS
UNITS/MM
MULTAX/ON
TLDATA/MILL,10.0000,5.0000,80.0000,0.0000,0.0000
LOAD/TOOL,3,ADJUST,3
RAPID
GOTO/-1.8555,-93.5252,130.0000,0.077080,-0.640125,0.764394
RAPID
GOTO/-7.2470,-48.7500,76.5325,0.077080,-0.640125,0.764394
FEDRAT/MMPM,600.0000
GOTO/-7.6324,-45.5494,72.7105,0.077080,-0.640125,0.764394
FEDRAT/MMPM,2500.0000
GOTO/-6.6711,-45.5494,72.8407,0.090989,-0.640125,0.762864
GOTO/-5.7077,-45.5494,72.9535,0.104868,-0.640125,0.761080
GOTO/-4.7423,-45.5494,73.0487,0.118712,-0.640125,0.759044
GOTO/-3.7753,-45.5494,73.1262,0.132516,-0.640125,0.756756
GOTO/-2.8071,-45.5494,73.1862,0.146277,-0.640125,0.754217
GOTO/-1.8380,-45.5494,73.2285,0.159989,-0.640125,0.751428
GOTO/-0.8682,-45.5494,73.2531,0.173648,-0.640125,0.748389
GOTO/0.1018,-45.5494,73.2601,0.187250,-0.640125,0.745102
GOTO/1.0718,-45.5494,73.2494,0.200789,-0.640125,0.741568
GOTO/2.0414,-45.5494,73.2211,0.214262,-0.640125,0.737788
GOTO/3.0104,-45.5494,73.1751,0.227663,-0.640125,0.733764
GOTO/3.9784,-45.5494,73.1114,0.240989,-0.640125,0.729496
GOTO/4.9450,-45.5494,73.0301,0.254236,-0.640125,0.724986
GOTO/5.9100,-45.5494,72.9313,0.267398,-0.640125,0.720235
FEDRAT/MMPM,3000.0000
GOTO/6.4448,-46.8296,74.3717,0.267398,-0.640125,0.720235
GOTO/10.3308,-46.3150,74.2128,-0.036671,-0.633091,0.773209
FEDRAT/MMPM,600.0000
GOTO/10.4041,-45.0488,72.6664,-0.036671,-0.633091,0.773209
FEDRAT/MMPM,2500.0000
GOTO/9.4605,-45.0488,72.8441,-0.050494,-0.633091,0.772429
GOTO/8.5139,-45.0488,73.0048,-0.064302,-0.633091,0.771402
RAPID
GOTO/8.5139,-45.0488,130.0,-0.064302,-0.633091,0.771402
"""


def _no_guards(machine: vp.Machine, blocks: Blocks, rapid: np.ndarray, *args: object, **kwargs: object
               ) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(len(rapid)), np.zeros(len(rapid))


def _post_dome(folder: Path) -> Path:
    (folder / "dome.cls").write_text(_DOME_CL)
    program = folder / "dome.nc"
    result = CliRunner().invoke(main, ["post", str(folder / "dome.cls"), "-o", str(program), "-q"])
    assert result.exit_code == 0, result.output
    return program


def test_blend_tolerance_read_from_the_start_lines() -> None:
    from verne_post.linuxcnc.blending import blend_tolerance

    assert blend_tolerance(("G21 G90", "G64 P{tolerance:.4f} Q0"), 0.005) == 0.005
    assert blend_tolerance(("G64 P0.02",), 0.005) == 0.02
    assert blend_tolerance(("G21 G90 G17",), 0.005) == 0.0  # LinuxCNC's default G64: no bound
    assert blend_tolerance(("G64 P0.01", "G61"), 0.005) is None  # exact path: no blends
    assert blend_tolerance(("G61.1",), 0.005) is None
    assert blend_tolerance(("G640",), 0.005) == 0.0  # not a G64


def test_guards_lie_on_the_programs_joint_lines(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              machine: vp.Machine) -> None:
    """The guarded program and the one without guards make the same motion: every block end of
    the guarded one lies on a joint-space line of the other, in order (read from both texts)."""
    import verne_post.pipeline as pipeline

    guarded = _blocks(_post_dome(tmp_path))
    plain_dir = tmp_path / "plain"
    plain_dir.mkdir()
    monkeypatch.setattr(pipeline, "corner_guards", _no_guards)
    plain = _blocks(_post_dome(plain_dir))
    assert len(guarded) > len(plain)
    scale = np.array([1, 1, 1, 10, 10])  # deg to ~mm at the table's reach, for the rounding only
    segment = 0
    for end in guarded:
        while segment < len(plain) - 1:
            a, b = plain[segment], plain[segment + 1]
            ab = (b - a) * scale
            u = float(np.clip(np.dot((end - a) * scale, ab) / max(np.dot(ab, ab), 1e-300), 0.0, 1.0))
            if np.linalg.norm((a + u * (b - a) - end) * scale) < 2e-3:
                break
            segment += 1
        assert segment < len(plain) - 1 or np.allclose(end, plain[-1], atol=1e-4), end
    np.testing.assert_allclose(guarded[-1], plain[-1])


def test_linuxcnc_keeps_the_tip_on_the_path_at_rotary_corners(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                              machine: vp.Machine) -> None:
    """Run through LinuxCNC's own planner: with guards the tip stays within the tolerance of the
    program's path (by FK of every servo sample); the same pass without them leaves it by more (the
    test can fail: LinuxCNC blends the table's corner there)."""
    import verne_post.pipeline as pipeline

    _needs_linuxcnc()
    guarded = _post_dome(tmp_path)
    tol = float(re.search(r"TOLERANCE (\d+\.?\d*) MM", guarded.read_text()).group(1))
    with_guards = path_deviation(machine, guarded.read_text(), simulate(guarded, machine, time_scale=TIME_SCALE))
    plain_dir = tmp_path / "plain"
    plain_dir.mkdir()
    monkeypatch.setattr(pipeline, "corner_guards", _no_guards)
    plain = _post_dome(plain_dir)
    without = path_deviation(machine, plain.read_text(), simulate(plain, machine, time_scale=TIME_SCALE))
    assert without.feeds > 3 * tol, without.feeds
    assert with_guards.feeds <= tol, (with_guards.feeds, with_guards.worst_line)


def test_deviation_from_the_cl_path_and_time_per_block(run: SimulationResult, posted: Path, machine: vp.Machine,
                                                      tmp_path: Path) -> None:
    """``simulate --against``: the executed tip against the CL file's feed moves agrees with a brute
    force over the samples here (the CL points read from the CL text, offset by the header's work
    offset); the time per block adds up to the time LinuxCNC ran lines, and the JSON report has it."""
    from verne_post.linuxcnc.measures import block_times, cl_deviation, program_blocks

    text = posted.read_text()
    offset = np.array(program_blocks(text, machine).work_offset)
    points, rapid, is_rapid = [], [], False
    for line in _CL.splitlines():
        if line == "RAPID":
            is_rapid = True
        elif line.startswith("GOTO/"):
            points.append([float(v) for v in line[5:].split(",")[:3]])
            rapid.append(is_rapid)
            is_rapid = False
    tips, rapid = np.array(points) + offset, np.array(rapid)
    measured = cl_deviation(machine, text, run, tips, rapid)
    feed = np.isfinite(measured.deviation)
    assert feed.sum() > 100
    sample_tips = forward_kinematics(machine, run.joints[feed], tool_length=TOOL_LENGTH).tip
    a, b = tips[:-1][~rapid[1:]], tips[1:][~rapid[1:]]
    ab = b - a
    u = np.clip(np.einsum("sij,ij->si", sample_tips[:, None, :] - a[None], ab) / np.einsum("ij,ij->i", ab, ab),
                0.0, 1.0)
    brute = np.linalg.norm(a[None] + u[..., None] * ab[None] - sample_tips[:, None, :], axis=2).min(axis=1)
    np.testing.assert_allclose(measured.deviation[feed], brute, atol=1e-9)
    assert measured.feeds == pytest.approx(brute.max())

    times = block_times(machine, text, run)
    running = run.line > 0
    assert times.executed.sum() == pytest.approx(running.sum() * run.period, abs=1e-9)
    assert sum(b[1] for b in times.bins) == np.isfinite(times.planned).sum()

    report = tmp_path / "r.json"
    cl = tmp_path / "short.cls"
    cl.write_text(_CL)
    result = CliRunner().invoke(main, ["simulate", str(posted), "--against", str(cl), "--time-scale", "5",
                                       "--report", str(report)])
    assert result.exit_code == 0, result.output
    assert "off the CL path" in result.output and "time per block" in result.output
    payload = json.loads(report.read_text())
    assert payload["cl_deviation_mm"]["feeds"] >= 0 and len(payload["blocks"]["line"]) > 5


def test_the_distance_to_a_path_that_passes_one_point_many_times_is_found_among_all_its_passes() -> None:
    """``_to_polyline`` against every segment by brute force, on paths like a CL file's passes:
    many passes through one point (a plunge at the same place, pass after pass), each cut into
    vertices at most ``spacing`` apart; points near that point, on and off the passes. (The nearest
    four vertices were once all the shared point, of other passes, and a point on its own pass was
    reported 0.084 mm away.)"""
    from verne_post.linuxcnc.measures import _to_polyline

    rng = np.random.default_rng(7)
    spacing = 0.2
    for _ in range(20):
        hub = rng.uniform(-50, 50, 3)
        passes = []
        for _ in range(int(rng.integers(2, 12))):
            direction = rng.normal(size=3)
            far = hub + rng.uniform(1.0, 8.0) * direction / np.linalg.norm(direction)
            source = hub + rng.uniform(0.5, 3.0) * np.r_[0.0, 0.0, 1.0]
            for start, end in ((source, hub), (hub, far)):  # down onto the hub, then away
                count = int(np.ceil(np.linalg.norm(end - start) / spacing))
                passes.append(start + np.linspace(0.0, 1.0, count + 1)[1:, None] * (end - start))
        vertices = np.vstack([hub[None], *passes])
        joined = np.ones(len(vertices), bool)
        starts = 1 + np.r_[0, np.cumsum([len(p) for p in passes])[:-1]]
        joined[0] = False
        joined[starts[0::2]] = False  # each pass starts anew above the hub: a rapid, not a segment
        points = hub + rng.normal(scale=0.3, size=(400, 3))
        points[:100] = vertices[rng.integers(0, len(vertices), 100)] + rng.normal(scale=1e-3, size=(100, 3))
        a, b = vertices[:-1][joined[1:]], vertices[1:][joined[1:]]
        ab = b - a
        u = np.clip(np.einsum("sij,ij->si", points[:, None] - a[None], ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        brute = np.linalg.norm(a[None] + u[..., None] * ab[None] - points[:, None], axis=2).min(axis=1)
        lone = np.flatnonzero(~joined & ~np.r_[joined[1:], False])  # vertices joined to nothing count as points
        if lone.size:
            brute = np.minimum(brute, np.linalg.norm(points[:, None] - vertices[lone][None], axis=2).min(axis=1))
        np.testing.assert_allclose(_to_polyline(points, vertices, joined, spacing), brute, atol=1e-9)
