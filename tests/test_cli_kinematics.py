"""verne-post ik / fk: JSON for single poses, CSV batches, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from tests.conftest import random_usable_joints
from verne_post.cli import main


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args))
    return result.exit_code, result.stdout, result.stderr


def test_ik_tool_pose_gives_both_working_solutions(machine: vp.Machine) -> None:
    code, out, _ = run("ik", "--tip", "-338.6527", "-298.1621", "462.2935", "--axis", "0.1532797", "0.3728936",
                       "0.9151261", "--radians")
    assert code == 0
    solutions = json.loads(out)["solutions"]
    assert len(solutions) == 2 and all(s["working_mode"] for s in solutions)
    np.testing.assert_allclose(solutions[0]["rho"], [674, 685, 250], atol=1e-3)
    np.testing.assert_allclose(solutions[0]["theta"], [0.19, 0.39], atol=1e-6)
    for s in solutions:
        fk = vp.forward_kinematics(machine, [s["rho"] + s["theta"]])
        np.testing.assert_allclose(fk.tip[0], [-338.6527, -298.1621, 462.2935], atol=1e-6)


def test_ik_all_and_degrees() -> None:
    code, out, _ = run("ik", "--tip", "0", "0", "50", "--axis", "0.3", "0", "1", "--all")
    assert code == 0
    solutions = json.loads(out)["solutions"]
    assert sum(s["working_mode"] for s in solutions) == 2 and len(solutions) > 2
    worked = [s for s in solutions if s["working_mode"]]
    phi1 = np.degrees(np.arctan2(0.3, 1.0))
    assert sorted(abs(s["phi"][0]) for s in worked) == pytest.approx([phi1, phi1])


def test_ik_platform_all_matches_figure5() -> None:
    code, out, _ = run("ik", "--platform", "-240", "-86", "1000", "--all", "--radians")
    solutions = json.loads(out)["solutions"]
    assert code == 0 and len(solutions) == 16
    assert solutions[0]["working_mode"] and solutions[0]["alpha"] == pytest.approx(0.051789, abs=1e-6)
    assert sum(s["working_mode"] for s in solutions) == 1


def test_fk_all_modes_and_tool() -> None:
    code, out, _ = run("fk", "--rho", "674", "685", "250", "--all", "--radians", "--theta", "0.19", "0.39")
    solutions = json.loads(out)["solutions"]
    assert code == 0 and len(solutions) == 4
    assert solutions[0]["working_mode"]
    np.testing.assert_allclose(solutions[0]["tip"], [-338.6527, -298.1621, 462.2935], atol=1e-3)
    code, out, _ = run("fk", "--rho", "674", "685", "250")
    assert [s["working_mode"] for s in json.loads(out)["solutions"]] == [True]
    assert "tip" not in json.loads(out)["solutions"][0]


def test_batch_round_trip(tmp_path: Path, machine: vp.Machine) -> None:
    joints = random_usable_joints(machine, 500, 21)
    fk = vp.forward_kinematics(machine, joints)
    poses = tmp_path / "poses.csv"
    poses.write_text("x,y,z,i,j,k\n" + "\n".join(",".join(f"{v:.12f}" for v in row)
                                                for row in np.c_[fk.tip, fk.axis]) + "\n")
    code, _, err = run("ik", str(poses), "-o", str(tmp_path / "joints.csv"))
    assert code == 0, err
    lines = (tmp_path / "joints.csv").read_text().splitlines()
    assert lines[0] == "rho1,rho2,rho3,theta1,theta2,alpha,status"
    assert len(lines) == 501
    rows = [line.split(",") for line in lines[1:]]
    assert {r[-1] for r in rows} == {"ok"}
    table = np.array([[float(v) for v in r[:5]] for r in rows])
    # theta2 continuous row to row: never a jump of a full turn.
    assert np.all(np.abs(np.diff(table[:, 4])) <= 180.0 + 1e-9)
    joints_file = tmp_path / "j.csv"
    joints_file.write_text("\n".join(lines[0:1] + [",".join(r[:5]) for r in rows]).replace(",theta2,alpha,status",
                                                                                        ",theta2") + "\n")
    code, _, err = run("fk", str(joints_file), "-o", str(tmp_path / "back.csv"))
    assert code == 0, err
    back = np.genfromtxt(tmp_path / "back.csv", delimiter=",", names=True, dtype=None, encoding="ascii")
    np.testing.assert_allclose(np.c_[back["x"], back["y"], back["z"]], fk.tip, atol=1e-6)
    np.testing.assert_allclose(np.c_[back["i"], back["j"], back["k"]], fk.axis, atol=1e-9)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("x,y,z,i,j,k\n1,2,3,0,0,1\n4,5,six,0,0,1\n", "poses.csv:3: 'six' is not a number (column z)"),
        ("x,y,z,i,j,q\n1,2,3,0,0,1\n", "poses.csv:1: unknown column 'q'"),
        ("x,y,z,i,j,k\n1,2,3,0,0,0\n", "poses.csv:2: tool axis has zero length"),
        ("x,y,z,i,j,k\n1,2,3,nan,0,1\n", "poses.csv:2: 'nan' is not a finite number"),
        ("x,y,z,i,j,k\n1,2,3,0,1\n", "poses.csv:2: row has 5 fields"),
        ("", "poses.csv: empty file"),
    ],
)
def test_batch_bad_input(tmp_path: Path, content: str, message: str) -> None:
    poses = tmp_path / "poses.csv"
    poses.write_text(content)
    out = tmp_path / "joints.csv"
    result = subprocess.run([sys.executable, "-m", "verne_post", "ik", str(poses), "-o", str(out)],
                            capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.strip() == f"verne-post: error: {poses.parent}/{message}" or message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == [poses]


def test_missing_arguments_are_one_line_errors() -> None:
    code, _, err = run("ik", "--tip", "1", "2", "3")
    assert code == 2 and "give --tip" in err
    code, _, err = run("ik", "--tip", "1", "2", "3", "--axis", "0", "0", "0")
    assert code == 2 and "--axis: tool axis has zero length" in err
    code, _, err = run("fk", "--rho", "1", "2", "x")
    assert code == 2 and "x" in err
