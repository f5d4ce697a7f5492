"""Joint zero offsets and kinematic calibration (``verne-post calibrate``).

Measurements are made with the project's forward kinematics of a machine whose geometry and
slider zeros are perturbed by known amounts, plus seeded Gaussian noise; the expected values
are those perturbations, never numbers produced by the calibration under test.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import verne_post as vp
from tests.conftest import random_usable_joints
from tests.independent import platform_from_tool, rod_residuals
from verne_post.api import Status, classify, pose_margins
from verne_post.calibration import PARAMETERS, FitError, Poses, calibrate, parameters_of
from verne_post.calibration.model import jacobian, predict
from verne_post.cli import main
from verne_post.kinematics import machine_ik_all, module_fk_working, module_ik_working, wrap_angle

#: Joint zero offsets used below: rho mm, theta degrees (large enough to matter, small enough
#: to keep the random poses usable).
OFFSETS_MM = (0.12, -0.08, 0.15)
OFFSETS_DEG = (0.03, -0.05)


def with_offsets(machine: vp.Machine, rho: tuple[float, float, float] = OFFSETS_MM,
                 theta: tuple[float, float] = OFFSETS_DEG) -> vp.Machine:
    """``machine`` with joint offsets (mm, degrees), through the validated model."""
    data = machine.model_dump()
    for name, value in zip(("rho1", "rho2", "rho3", "theta1", "theta2"), (*rho, *theta), strict=True):
        data["joints"][name]["offset"] = value
    return vp.Machine.model_validate(data)


def test_offsets_reach_the_kinematic_geometry(machine: vp.Machine) -> None:
    geom = with_offsets(machine).kinematic_geometry(60.0)
    assert geom.rho_offset == OFFSETS_MM
    assert geom.theta_offset == pytest.approx(np.radians(OFFSETS_DEG))
    assert not machine.kinematic_geometry().has_offsets


def test_fk_with_offsets_is_the_true_joints_fk(machine: vp.Machine) -> None:
    """FK of readings = the independent model at reading + offset (true slider heights and angles)."""
    shifted = with_offsets(machine)
    readings = random_usable_joints(machine, 3000, seed=11, tool_length=60.0)
    fk = vp.forward_kinematics(shifted, readings, tool_length=60.0)
    assert fk.reachable.all()
    true = readings + np.array([*OFFSETS_MM, *np.radians(OFFSETS_DEG)])
    geom = machine.kinematic_geometry(60.0)
    platform, alpha = platform_from_tool(geom, fk.tip, fk.axis, true[:, 3], true[:, 4])
    np.testing.assert_allclose(platform, fk.platform, atol=1e-7)
    residual = rod_residuals(geom, platform, alpha, true[:, :3])
    assert np.max(np.abs(residual)) < 1e-5  # mm^2 on L^2 ~ 1e6 mm^2
    # and the readings themselves, taken as true, do not close the rods: the offsets are applied
    assert np.max(np.abs(rod_residuals(geom, platform, alpha, readings[:, :3]))) > 10.0


def test_ik_fk_round_trip_with_offsets(machine: vp.Machine) -> None:
    shifted = with_offsets(machine)
    for tool_length, seed in ((0.0, 21), (100.0, 22)):
        readings = random_usable_joints(machine, 4000, seed=seed, tool_length=tool_length)
        fk = vp.forward_kinematics(shifted, readings, tool_length=tool_length)
        ik = vp.inverse_kinematics(shifted, fk.tip, fk.axis, theta2_hint=readings[:, 4], tool_length=tool_length)
        ok = ik.status == vp.Status.OK
        assert ok.mean() > 0.97  # the offsets move a few poses over a margin, no more
        error = np.abs(ik.joints - readings)[ok]
        error[:, 3:] = np.abs(wrap_angle(ik.joints[ok, 3:] - readings[ok, 3:]))
        assert error[:, :3].max() < 1e-6 and error[:, 3:].max() < 1e-9
        # without the offsets the same tool poses give joints off by the offsets
        plain = vp.inverse_kinematics(machine, fk.tip[ok], fk.axis[ok], theta2_hint=readings[ok, 4],
                                      tool_length=tool_length)
        np.testing.assert_allclose(plain.joints[:, :3] - ik.joints[ok, :3], np.tile(OFFSETS_MM, (ok.sum(), 1)),
                                   atol=1e-6)


def test_module_and_all_solutions_routes_apply_the_offsets(machine: vp.Machine) -> None:
    shifted = with_offsets(machine)
    geom, plain = shifted.kinematic_geometry(), machine.kinematic_geometry()
    readings = random_usable_joints(machine, 200, seed=5)
    fk = module_fk_working(geom, readings[:, :3])
    back = module_ik_working(geom, fk.platform)
    # The module IK returns the working root nearest alpha = 0: on the fringe of leg I's reach
    # that can be another working assembly than the one the FK found (skipped, a few poses).
    same_root = np.abs(back.rho - readings[:, :3]).max(axis=1) < 1.0
    assert same_root.mean() > 0.95
    np.testing.assert_allclose(back.rho[same_root], readings[same_root, :3], atol=1e-6)
    # the plain geometry reads the same platforms as the true slider heights
    np.testing.assert_allclose(module_ik_working(plain, fk.platform[same_root]).rho - back.rho[same_root],
                               np.tile(OFFSETS_MM, (same_root.sum(), 1)), atol=1e-6)
    full = vp.forward_kinematics(shifted, readings[:20])
    solutions = machine_ik_all(geom, full.tip, full.axis)
    for k in range(20):  # each pose's readings are among its solutions
        mine = solutions.joints[solutions.pose_index == k]
        distance = np.abs(mine[:, :3] - readings[k, :3]).max(axis=1) + np.abs(
            wrap_angle(mine[:, 3:] - readings[k, 3:])).max(axis=1)
        assert distance.min() < 1e-6


def test_zero_offsets_leave_results_bit_identical(machine: vp.Machine) -> None:
    zero = with_offsets(machine, (0.0, 0.0, 0.0), (0.0, 0.0))
    joints = random_usable_joints(machine, 500, seed=3)
    a, b = vp.forward_kinematics(machine, joints), vp.forward_kinematics(zero, joints)
    assert np.array_equal(a.tip, b.tip) and np.array_equal(a.axis, b.axis)
    ia = vp.inverse_kinematics(machine, a.tip, a.axis)
    ib = vp.inverse_kinematics(zero, a.tip, a.axis)
    assert np.array_equal(ia.joints, ib.joints, equal_nan=True)


# ----------------------------------------------------------------------------- calibration

NOISE = 0.003  # mm, standard deviation of each measured coordinate
HEADER = "rho1,rho2,rho3,theta1,theta2,tool_length,x,y,z"
SAMPLE_CL = Path(__file__).parent / "data" / "cl-samples" / "creo8_profilfraesen_mm.ncl"


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args))
    return result.exit_code, result.stdout, result.stderr


def perturbed(machine: vp.Machine, seed: int = 4) -> tuple[np.ndarray, vp.Machine]:
    """A VERNE as assembled: 12 geometry values off by 0.2-0.55 mm, slider zeros off by
    0.06-0.15 mm (random signs). Returns its parameter vector and its machine model."""
    rng = np.random.default_rng(seed)
    nominal = parameters_of(machine)
    truth = nominal.copy()
    truth[:12] += rng.choice([-1, 1], 12) * rng.uniform(0.2, 0.55, 12)
    truth[12:15] += rng.choice([-1, 1], 3) * rng.uniform(0.06, 0.15, 3)
    data = machine.model_dump()
    for k, name in enumerate(PARAMETERS[:12]):
        data["geometry"][name] = float(truth[k])
    for k, name in enumerate(("rho1", "rho2", "rho3")):
        data["joints"][name]["offset"] = float(truth[12 + k])
    return truth, vp.Machine.model_validate(data)


def measure(true_machine: vp.Machine, nominal: vp.Machine, n: int, seed: int, tools: tuple[float, ...],
            noise: float = NOISE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint readings (mm, rad), tool lengths and tips measured on ``true_machine`` with the
    project's own FK plus seeded Gaussian noise (mm)."""
    joints = random_usable_joints(nominal, n, seed)
    tool = np.resize(np.asarray(tools, float), n)
    fk = vp.forward_kinematics(true_machine, joints, tool_length=tool)
    assert fk.reachable.all()
    tip = fk.tip + np.random.default_rng(seed + 1000).normal(0.0, noise, (n, 3))
    return joints, tool, tip


def write_csv(path: Path, joints: np.ndarray, tool: np.ndarray, tip: np.ndarray, extra: str = "") -> Path:
    lines = [HEADER + extra]
    for q, t, x in zip(joints, tool, tip, strict=True):
        lines.append(",".join(f"{v:.6f}" for v in (*q[:3], *np.degrees(q[3:]), t, *x)))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def assembled(machine: vp.Machine) -> tuple[np.ndarray, vp.Machine]:
    return perturbed(machine)


@pytest.fixture(scope="module")
def measured(machine: vp.Machine, assembled: tuple[np.ndarray, vp.Machine], tmp_path_factory: pytest.TempPathFactory
             ) -> Path:
    """80 poses, three tools, 3 um noise."""
    joints, tool, tip = measure(assembled[1], machine, 80, seed=31, tools=(60.0, 80.0, 100.0))
    return write_csv(tmp_path_factory.mktemp("cal") / "measured.csv", joints, tool, tip)


@pytest.fixture(scope="module")
def calibrated(measured: Path) -> tuple[Path, Path, str]:
    out = measured.parent / "calibrated.yaml"
    report = measured.parent / "report.json"
    code, stdout, stderr = run("calibrate", str(measured), "-o", str(out), "--report", str(report))
    assert code == 0, stderr
    return out, report, stdout


def test_analytic_jacobian_matches_finite_differences_of_the_fk(machine: vp.Machine) -> None:
    p = parameters_of(machine) + np.r_[np.zeros(12), 0.1, -0.05, 0.12, 3e-4, -2e-4]
    joints = random_usable_joints(machine, 60, seed=8)
    tool = np.resize([60.0, 100.0], 60)
    d_tip, d_axis = jacobian(p, joints, tool, predict(p, joints, tool))
    for k in range(len(PARAMETERS)):
        h = 1e-4 if k < 15 else 1e-7
        step = np.zeros(len(PARAMETERS))
        step[k] = h
        plus = vp.forward_kinematics(_machine_of(machine, p + step), joints, tool_length=tool)
        minus = vp.forward_kinematics(_machine_of(machine, p - step), joints, tool_length=tool)
        np.testing.assert_allclose(d_tip[:, :, k], (plus.tip - minus.tip) / (2 * h), atol=2e-5 * max(
            1.0, np.abs(d_tip[:, :, k]).max()), err_msg=PARAMETERS[k])
        np.testing.assert_allclose(d_axis[:, :, k], (plus.axis - minus.axis) / (2 * h), atol=1e-6,
                                   err_msg=PARAMETERS[k])


def _machine_of(machine: vp.Machine, p: np.ndarray) -> vp.Machine:
    """A machine model with parameter vector ``p`` (mm, rad), built through the YAML model."""
    data = machine.model_dump()
    for k, name in enumerate(PARAMETERS[:12]):
        data["geometry"][name] = float(p[k])
    for k, name in enumerate(("rho1", "rho2", "rho3")):
        data["joints"][name]["offset"] = float(p[12 + k])
    for k, name in enumerate(("theta1", "theta2")):
        data["joints"][name]["offset"] = float(np.degrees(p[15 + k]))
    return vp.Machine.model_validate(data)


def test_common_slider_offset_and_table_height_are_one_thing(machine: vp.Machine,
                                                             assembled: tuple[np.ndarray, vp.Machine]) -> None:
    """Why da is held: raising every slider zero and da by the same c changes no tool tip."""
    truth = assembled[0]
    shifted = truth + np.r_[np.zeros(10), 0.7, 0.0, 0.7, 0.7, 0.7, 0.0, 0.0]
    joints = random_usable_joints(machine, 300, seed=12)
    a = vp.forward_kinematics(_machine_of(machine, truth), joints, tool_length=80.0)
    b = vp.forward_kinematics(_machine_of(machine, shifted), joints, tool_length=80.0)
    np.testing.assert_allclose(a.tip, b.tip, atol=1e-8)


def test_calibration_recovers_the_perturbation(machine: vp.Machine, assembled: tuple[np.ndarray, vp.Machine],
                                               calibrated: tuple[Path, Path, str]) -> None:
    truth = assembled[0]
    _, report_path, stdout = calibrated
    report = json.loads(report_path.read_text())
    parameters = {p["name"]: p for p in report["parameters"]}
    assert parameters["da"]["status"] == "held"
    assert "rho1_offset" in parameters["da"]["reason"] and "held: da" in stdout
    # With da held at nominal, the slider offsets take its error (previous test): what they
    # can be is the true offset minus the true da error.
    da_error = truth[PARAMETERS.index("da")] - parameters_of(machine)[PARAMETERS.index("da")]
    expected = {name: truth[k] for k, name in enumerate(PARAMETERS)}
    for name in ("rho1_offset", "rho2_offset", "rho3_offset"):
        expected[name] -= da_error
    expected["theta1_offset"] = expected["theta2_offset"] = 0.0
    scores = []
    for k, name in enumerate(PARAMETERS):
        p = parameters[name]
        if name == "da":
            assert p["fitted"] == p["nominal"]
            continue
        assert p["status"] == "fitted", name
        want = np.degrees(expected[name]) if name.startswith("theta") else expected[name]
        error = p["fitted"] - want
        assert abs(error) < 4.0 * p["std"], (name, error, p["std"])
        scores.append(error / p["std"])
        assert p["std"] < (0.15 if name in ("R1", "r1") else 0.03)
        if k < 12:  # the perturbation itself is far outside the uncertainty (R1 and r1 only weakly separate)
            assert abs(truth[k] - parameters_of(machine)[k]) > (3 if name in ("R1", "r1") else 10) * p["std"]
    # the standard deviations are honest: the normalised errors scatter like N(0, 1)
    assert 0.2 < float(np.mean(np.square(scores))) < 3.0


def _predict_with_cli(tmp_path: Path, machine_file: Path | None, joints: np.ndarray, tool_length: float
                      ) -> np.ndarray:
    """Tool tips (mm) predicted by 'verne-post fk' from a joints CSV."""
    source = tmp_path / f"joints_{tool_length:g}.csv"
    source.write_text("rho1,rho2,rho3,theta1,theta2\n" + "\n".join(
        ",".join(f"{v:.6f}" for v in (*q[:3], *np.degrees(q[3:]))) for q in joints) + "\n")
    out = tmp_path / f"tips_{tool_length:g}_{machine_file.stem if machine_file else 'nominal'}.csv"
    args = ["fk", str(source), "-o", str(out), "--tool-length", str(tool_length)]
    code, _, stderr = run(*args, *(["--machine", str(machine_file)] if machine_file else []))
    assert code == 0, stderr
    table = np.genfromtxt(out, delimiter=",", names=True, dtype=None, encoding="utf-8")
    return np.column_stack([table["x"], table["y"], table["z"]])


def test_calibrated_file_predicts_other_poses_and_tools(machine: vp.Machine, assembled: tuple[np.ndarray, vp.Machine],
                                                        calibrated: tuple[Path, Path, str], tmp_path: Path) -> None:
    """Done means: 40 other poses, other tools, predicted to about 10 um where the nominal is off by mm."""
    out = calibrated[0]
    errors, nominal_errors = [], []
    for tool_length, seed in ((45.0, 41), (130.0, 42)):
        joints, _, truth_tip = measure(assembled[1], machine, 20, seed=seed, tools=(tool_length,), noise=0.0)
        errors.append(_predict_with_cli(tmp_path, out, joints, tool_length) - truth_tip)
        nominal_errors.append(_predict_with_cli(tmp_path, None, joints, tool_length) - truth_tip)
    rms = np.sqrt(np.mean(np.sum(np.concatenate(errors) ** 2, axis=1)))
    nominal_rms = np.sqrt(np.mean(np.sum(np.concatenate(nominal_errors) ** 2, axis=1)))
    assert rms < 0.010
    assert nominal_rms > 1.0


def test_calibrated_file_keeps_the_input_and_posts(machine: vp.Machine, calibrated: tuple[Path, Path, str],
                                                   tmp_path: Path) -> None:
    out = calibrated[0]
    original_text = (Path(vp.__file__).parent / "machines" / "verne.yaml").read_text()
    text = out.read_text()
    # Byte for byte the input, but for the lines of fitted values (geometry keys other than da,
    # the five joint lines) and the calibration block appended at the end.
    original_lines, lines = original_text.splitlines(), text.splitlines()
    assert len(lines) > len(original_lines)
    changed_lines = [k for k, (a, b) in enumerate(zip(original_lines, lines, strict=False)) if a != b]
    keys = [original_lines[k].split(":")[0].strip() for k in changed_lines]
    assert sorted(keys) == sorted([*(set(PARAMETERS[:12]) - {"da"}), "rho1", "rho2", "rho3", "theta1", "theta2"])
    for k in changed_lines:  # the value changed, the comment and the alignment did not
        before_line, after_line = original_lines[k], lines[k]
        assert before_line.partition("#")[2] == after_line.partition("#")[2]
        assert before_line[: before_line.index(":") + 1] == after_line[: after_line.index(":") + 1]
    assert lines[len(original_lines) + 1].startswith("# Written by 'verne-post calibrate'")
    before, after = yaml.safe_load(original_text), yaml.safe_load(text)
    block = after.pop("calibration")
    assert block["poses"] == 80 and block["rejected"] == 0 and block["held"] == ["da"]
    assert block["rms_before"] > 1.0 and block["rms_after"] < 0.008 and block["max_after"] < 0.025
    assert after["geometry"]["da"] == before["geometry"]["da"]
    changed = {k for k in before["geometry"] if before["geometry"][k] != after["geometry"][k]}
    assert changed == set(PARAMETERS[:12]) - {"da"}
    for name in before["joints"]:
        offset = after["joints"][name].pop("offset")
        assert isinstance(offset, float)
        assert after["joints"][name] == before["joints"][name]
    for key in before:
        if key not in ("geometry", "joints"):
            assert after[key] == before[key], key
    loaded = vp.load_machine(out)
    assert loaded.calibration is not None and loaded.calibration.held == ["da"]
    code, _, stderr = run("post", str(SAMPLE_CL), "--machine", str(out), "-o", str(tmp_path / "cal.nc"), "-q")
    assert code == 0, stderr
    code, _, stderr = run("post", str(SAMPLE_CL), "-o", str(tmp_path / "nominal.nc"), "-q")
    assert code == 0, stderr
    assert (tmp_path / "cal.nc").read_bytes() != (tmp_path / "nominal.nc").read_bytes()


def test_block_style_joints_and_a_second_calibration(measured: Path, tmp_path: Path) -> None:
    """A joint written as a block mapping gets its offset too (through the round-trip dump, which
    keeps the comments); calibrating a calibrated file replaces its block, not appends one."""
    original = (Path(vp.__file__).parent / "machines" / "verne.yaml").read_text()
    flow = "  rho1:   {min: 0.0, max: 1300.0, velocity: 1000.0, acceleration: 10000.0, jerk: 200000.0}\n"
    assert flow in original
    source = tmp_path / "block.yaml"
    source.write_text(original.replace(flow, "  rho1:\n    min: 0.0\n    max: 1300.0   # travel of slider 1\n"
                                              "    velocity: 1000.0\n    acceleration: 10000.0\n    jerk: 200000.0\n"))
    first, second = tmp_path / "first.yaml", tmp_path / "second.yaml"
    assert run("calibrate", str(measured), "--machine", str(source), "-o", str(first))[0] == 0
    text = first.read_text()
    assert "# travel of slider 1" in text and "# ASSUMPTION: margins below which" in text
    machine = vp.load_machine(first)
    assert machine.joints.rho1.offset != 0.0 and machine.calibration is not None
    assert run("calibrate", str(measured), "--machine", str(first), "-o", str(second))[0] == 0
    again = second.read_text()
    assert again.count("calibration:") == 1 and again.count("# Written by 'verne-post calibrate'") == 1
    recalibrated = vp.load_machine(second).calibration
    assert recalibrated is not None and recalibrated.rms_before < 0.008  # it starts from the calibrated file


def test_fix_holds_a_parameter(measured: Path, tmp_path: Path) -> None:
    out = tmp_path / "fixed.yaml"
    code, _stdout, stderr = run("calibrate", str(measured), "-o", str(out), "--fix", "L1,spindle_nose")
    assert code == 0, stderr
    machine = vp.load_machine(out)
    assert machine.geometry.L1 == 849.97 and machine.geometry.spindle_nose == 495.80
    assert machine.calibration is not None and {"L1", "spindle_nose", "da"} <= set(machine.calibration.held)
    # two true errors of 0.2-0.55 mm held at nominal: the residual stays well above the noise
    assert machine.calibration.rms_after > 0.02


def test_outlier_is_flagged_and_rejected(machine: vp.Machine, assembled: tuple[np.ndarray, vp.Machine],
                                         tmp_path: Path) -> None:
    joints, tool, tip = measure(assembled[1], machine, 60, seed=51, tools=(60.0, 80.0, 100.0))
    tip[17] += [0.0, 0.4, -0.3]  # a probing mistake of 0.5 mm
    path = write_csv(tmp_path / "outlier.csv", joints, tool, tip)
    line = 17 + 2  # header on line 1
    code, stdout, _ = run("calibrate", str(path), "-o", str(tmp_path / "a.yaml"), "--report", str(tmp_path / "a.json"))
    assert code == 0 and f"lines {line}" in stdout
    report = json.loads((tmp_path / "a.json").read_text())
    assert [o["line"] for o in report["outliers"]] == [line]
    code, stdout, _ = run("calibrate", str(path), "-o", str(tmp_path / "b.yaml"), "--reject")
    assert code == 0 and "dropped" in stdout
    kept = vp.load_machine(tmp_path / "b.yaml").calibration
    assert kept is not None and kept.poses == 59 and kept.rejected == 1 and kept.rms_after < 0.008


def test_library_fit_reports_non_convergence(machine: vp.Machine, assembled: tuple[np.ndarray, vp.Machine]) -> None:
    joints, tool, tip = measure(assembled[1], machine, 30, seed=61, tools=(80.0,))
    poses = Poses(joints, tool, tip, np.full((30, 3), np.nan), np.ones(30))
    with pytest.raises(FitError) as error:
        calibrate(parameters_of(machine), poses, max_evaluations=1)
    assert error.value.exit_code == 3 and "did not converge" in str(error.value)


def test_html_report_is_self_contained(measured: Path, tmp_path: Path) -> None:
    report = tmp_path / "r.html"
    code, _, stderr = run("calibrate", str(measured), "-o", str(tmp_path / "c.yaml"), "--report", str(report))
    assert code == 0, stderr
    page = report.read_text()
    assert page.count("<svg") >= 3 and "<line" in page
    assert "http://" not in page.replace('xmlns="http://www.w3.org/2000/svg"', "") and "https://" not in page
    assert "<script" not in page and "<link" not in page


BAD_INPUTS = [
    ("missing column", lambda rows: [rows[0].replace(",z", "")] + [r.rsplit(",", 1)[0] for r in rows[1:]], 1,
     "lacks column"),
    ("nan cell", lambda rows: [*rows[:5], rows[5].replace(rows[5].split(",")[6], "nan", 1), *rows[6:]], 6, "finite"),
    ("out of range", lambda rows: [*rows[:9], "1400.0," + rows[9].split(",", 1)[1], *rows[10:]], 10, "travel"),
    ("unreachable", lambda rows: [*rows[:3], "1290,0,1290,0,0,80,0,0,0", *rows[4:]], 4, "cannot be at"),
    ("far from the model", lambda rows: [*rows[:7], ",".join([*rows[7].split(",")[:6], "900", "900", "0"]),
                                         *rows[8:]], 8, "from where the machine file puts it"),
    ("too few poses", lambda rows: rows[:5], 5, "poses for 17 free parameters"),
]


@pytest.mark.parametrize(("what", "edit", "line", "words"), BAD_INPUTS, ids=[b[0] for b in BAD_INPUTS])
def test_bad_measurements_are_refused_at_their_line(measured: Path, tmp_path: Path, what: str, edit, line: int,
                                                    words: str) -> None:
    rows = measured.read_text().splitlines()
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(edit(rows)) + "\n")
    out, report = tmp_path / "out.yaml", tmp_path / "out.json"
    code, _stdout, stderr = run("calibrate", str(bad), "-o", str(out), "--report", str(report))
    assert code == 2, (what, stderr)
    assert stderr.count("\n") == 1 and f"{bad}:{line}:" in stderr and words in stderr, stderr
    assert not out.exists() and not report.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


def test_plan_picks_checked_poses_that_identify_the_parameters(machine: vp.Machine,
                                                               assembled: tuple[np.ndarray, vp.Machine],
                                                               tmp_path: Path) -> None:
    poses = tmp_path / "poses.csv"
    code, _stdout, stderr = run("calibrate", "--plan", "40", "-o", str(poses), "--tools", "60,100")
    assert code == 0, stderr
    table = np.genfromtxt(poses, delimiter=",", names=True)
    assert len(table) == 40 and set(np.unique(table["tool_length"])) == {60.0, 100.0}
    joints = np.column_stack([table["rho1"], table["rho2"], table["rho3"], np.radians(table["theta1"]),
                              np.radians(table["theta2"])])
    # every planned pose passes the machine's checks at the nominal geometry (api, not the planner)
    fk = vp.forward_kinematics(machine, joints, tool_length=table["tool_length"])
    found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, table["tool_length"])
    assert np.all(classify(machine, joints, fk.reachable, found) == Status.OK)
    np.testing.assert_allclose(np.column_stack([table["x_nominal"], table["y_nominal"], table["z_nominal"]]),
                               fk.tip, atol=1e-3)
    # measured on the assembled machine, these 40 poses calibrate it
    tip = vp.forward_kinematics(assembled[1], joints, tool_length=table["tool_length"]).tip
    tip += np.random.default_rng(71).normal(0.0, NOISE, tip.shape)
    measured = write_csv(tmp_path / "planned.csv", joints, table["tool_length"], tip)
    code, _, stderr = run("calibrate", str(measured), "-o", str(tmp_path / "p.yaml"))
    assert code == 0, stderr
    check_joints, _, check_tip = measure(assembled[1], machine, 30, seed=72, tools=(80.0,), noise=0.0)
    calibrated = vp.load_machine(tmp_path / "p.yaml")
    error = vp.forward_kinematics(calibrated, check_joints, tool_length=80.0).tip - check_tip
    assert np.sqrt(np.mean(np.sum(error**2, axis=1))) < 0.010
    # and they determine the parameters better than 40 random usable poses do
    p = parameters_of(machine)
    free = [k for k, n in enumerate(PARAMETERS) if n != "da"]

    def log_det(q: np.ndarray, tool: np.ndarray) -> float:
        d_tip, _ = jacobian(p, q, tool, predict(p, q, tool))
        j = d_tip[:, :, free].reshape(-1, len(free))
        return float(np.linalg.slogdet(j.T @ j)[1])

    random_joints = random_usable_joints(machine, 40, seed=73)
    assert log_det(joints, table["tool_length"]) > log_det(random_joints, np.resize([60.0, 100.0], 40)) + 5.0


def test_machine_file_refuses_a_bad_calibration_block(machine: vp.Machine) -> None:
    data = machine.model_dump()
    data["calibration"] = {"method": "x", "measurements": "m.csv", "poses": 3, "rms_before": 1.0, "max_before": 1.0,
                           "rms_after": 0.1, "max_after": 0.1, "date": "2026-01-01"}
    with pytest.raises(Exception, match="date"):
        vp.Machine.model_validate(data)
    data["joints"]["rho1"]["offset"] = 500.0
    del data["calibration"]
    with pytest.raises(Exception, match="offset"):
        vp.Machine.model_validate(data)


def test_measured_axes_and_weights(machine: vp.Machine, assembled: tuple[np.ndarray, vp.Machine],
                                   tmp_path: Path) -> None:
    """Rows with a measured tool axis (i, j, k) and weights: table-angle zeros of a few
    hundredths of a degree are recovered within their standard deviations."""
    truth = assembled[0].copy()
    theta_deg = (0.011, -0.017)
    truth[15:17] = np.radians(theta_deg)
    true_machine = _machine_of(machine, truth)
    joints = random_usable_joints(machine, 60, seed=81)
    tool = np.resize([60.0, 80.0, 100.0], 60)
    fk = vp.forward_kinematics(true_machine, joints, tool_length=tool)
    rng = np.random.default_rng(82)
    tip = fk.tip + rng.normal(0.0, NOISE, (60, 3))
    axis = fk.axis + rng.normal(0.0, 2e-5, (60, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    lines = [HEADER + ",i,j,k,weight"]
    for k in range(60):
        lines.append(",".join(f"{v:.8f}" for v in (*joints[k, :3], *np.degrees(joints[k, 3:]), tool[k], *tip[k],
                                                     *axis[k], 2.0 if k % 2 else 1.0)))
    path = tmp_path / "axes.csv"
    path.write_text("\n".join(lines) + "\n")
    code, _, stderr = run("calibrate", str(path), "-o", str(tmp_path / "c.yaml"), "--report", str(tmp_path / "r.json"))
    assert code == 0, stderr
    parameters = {p["name"]: p for p in json.loads((tmp_path / "r.json").read_text())["parameters"]}
    for name, want in zip(("theta1_offset", "theta2_offset"), theta_deg, strict=True):
        assert parameters[name]["status"] == "fitted"
        assert abs(parameters[name]["fitted"] - want) < 4.0 * parameters[name]["std"]
        assert parameters[name]["std"] < 0.001
    calibrated = vp.load_machine(tmp_path / "c.yaml")
    assert calibrated.joints.theta1.offset == pytest.approx(theta_deg[0], abs=0.001)
