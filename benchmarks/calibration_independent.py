"""Calibration against an independent model: does ``verne-post calibrate`` reach the noise floor?

For each of several random VERNEs (the 12 geometry values and the 3 slider zeros each off the
machine file by up to +-0.5 mm, uniform), tool tips are made by the independent model of
tests/independent.py (the joint-point table and Table IV's matrices of VERNE-KINEMATICS.md,
solved by Newton's method; nothing from verne_post.kinematics) with 3 um Gaussian noise per
coordinate. 80 fit poses, tools 60/80/100 mm, either random usable poses or ``--plan 80`` (tips
in the default volume above the table); then ``verne-post calibrate``, and ``verne-post
calibrate --check`` on 40 other poses with other tools (20 x 45 mm, 20 x 130 mm), their true
tips without noise: random usable poses anywhere in the workspace, and random usable poses
with the tip in --plan's default volume. Figures printed, never asserted.

    python benchmarks/calibration_independent.py [--geometries 6] [--seed 0]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import re  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from click.testing import CliRunner  # noqa: E402

import verne_post as vp  # noqa: E402
from benchmarks.calibration import usable_joints  # noqa: E402
from tests.independent import machine_tips  # noqa: E402
from verne_post.calibration.plan import default_volume  # noqa: E402
from verne_post.cli import main as cli  # noqa: E402

NOISE = 0.003  # mm per coordinate
GEOMETRY_KEYS = ("D1_minus_d1", "D2_minus_d2", "R1", "r1", "L1", "R2", "r4", "L2", "L3", "spindle_nose", "da", "dt")
HEADER = "rho1,rho2,rho3,theta1,theta2,tool_length,x,y,z"


def true_tips(machine: vp.Machine, values: dict[str, float], offsets: np.ndarray, joints: np.ndarray,
              tool: np.ndarray) -> np.ndarray:
    """Tips (N, 3) mm, table frame, of a VERNE with geometry ``values`` and slider zero
    ``offsets`` (true height = reading + offset) at readings ``joints`` (mm, rad): the
    independent model, Newton started from the machine file's FK (which picks the assembly)."""
    start = vp.forward_kinematics(machine, joints, tool_length=tool)
    p = np.r_[[values[k] for k in GEOMETRY_KEYS], offsets, 0.0, 0.0]
    return machine_tips(p, joints, tool, start.platform, start.alpha)[0]


def write(path: Path, joints: np.ndarray, tool: np.ndarray, tip: np.ndarray) -> Path:
    rows = [HEADER] + [",".join(f"{v:.6f}" for v in (*q[:3], *np.degrees(q[3:]), t, *x))
                       for q, t, x in zip(joints, tool, tip, strict=True)]
    path.write_text("\n".join(rows) + "\n")
    return path


def run(*args: str) -> str:
    result = CliRunner().invoke(cli, list(args))
    if result.exit_code != 0:
        raise SystemExit(f"verne-post {' '.join(args)}: exit {result.exit_code}: {result.stderr or result.output}")
    return result.stdout


def check_figures(stdout: str) -> tuple[float, float]:
    """RMS and max (um) from the first line of ``calibrate --check``."""
    found = re.search(r"RMS ([0-9.]+) um, max ([0-9.]+) um", stdout)
    assert found is not None, stdout
    return float(found.group(1)), float(found.group(2))


def in_volume_joints(machine: vp.Machine, n: int, seed: int, tool: np.ndarray) -> np.ndarray:
    """n random usable joint sets (mm, rad) whose tips (with ``tool``) lie in --plan's default volume."""
    volume = default_volume(machine)
    kept: list[np.ndarray] = []
    for length in np.unique(tool):
        need = int(np.sum(tool == length))
        joints = usable_joints(machine, 60 * need, seed + int(length))
        inside = volume.contains(vp.forward_kinematics(machine, joints, tool_length=float(length)).tip)
        kept.append(joints[inside][:need])
    return np.concatenate(kept)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--geometries", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    machine = vp.load_machine()
    nominal = {k: float(getattr(machine.geometry, k)) for k in GEOMETRY_KEYS}
    validation_tool = np.r_[np.full(20, 45.0), np.full(20, 130.0)]
    validation = {"workspace": usable_joints(machine, 40, seed=990), "volume": in_volume_joints(
        machine, 40, 991, validation_tool)}
    print(f"{'geometry':>8} {'poses':>7} {'nominal RMS um':>15} {'fit RMS um':>11} {'noise um':>9} "
          f"{'workspace RMS/max um':>21} {'volume RMS/max um':>18}")
    worst: dict[tuple[str, str], list[float]] = {}
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        run("calibrate", "--plan", "80", "-o", str(work / "plan.csv"), "--tools", "60,80,100")
        plan = np.genfromtxt(work / "plan.csv", delimiter=",", names=True)
        planned = (np.column_stack([plan["rho1"], plan["rho2"], plan["rho3"], np.radians(plan["theta1"]),
                                    np.radians(plan["theta2"])]), plan["tool_length"])
        for g in range(args.geometries):
            rng = np.random.default_rng(args.seed + g)
            values = {k: v + rng.uniform(-0.5, 0.5) for k, v in nominal.items()}
            offsets = rng.uniform(-0.5, 0.5, 3)
            checks = {}
            for where, joints in validation.items():
                truth = true_tips(machine, values, offsets, joints, validation_tool)
                checks[where] = write(work / f"valid{g}{where}.csv", joints, validation_tool, truth)
            nominal_rms, _ = check_figures(run("calibrate", "--check", str(checks["workspace"])))
            random_joints = usable_joints(machine, 80, seed=1000 + g)
            for kind, (joints, tool) in (("random", (random_joints, np.resize([60.0, 80.0, 100.0], 80))),
                                         ("plan", planned)):
                tip = true_tips(machine, values, offsets, joints, tool) + rng.normal(0.0, NOISE, (len(tool), 3))
                measured = write(work / f"{kind}{g}.csv", joints, tool, tip)
                out = work / f"{kind}{g}.yaml"
                stdout = run("calibrate", str(measured), "-o", str(out))
                fit = re.search(r"-> ([0-9.]+) um .*noise estimate ([0-9.]+) um", stdout)
                assert fit is not None, stdout
                shown = []
                for where, check in checks.items():
                    rms, peak = check_figures(run("calibrate", "--check", str(check), "--machine", str(out)))
                    old = worst.get((kind, where), [0.0, 0.0])
                    worst[(kind, where)] = [max(old[0], rms), max(old[1], peak)]
                    shown.append(f"{rms:.2f}/{peak:.2f}")
                print(f"{g:8d} {kind:>7} {nominal_rms:15.1f} {float(fit.group(1)):11.2f} {float(fit.group(2)):9.2f} "
                      f"{shown[0]:>21} {shown[1]:>18}")
    for (kind, where), (rms, peak) in worst.items():
        print(f"worst over the geometries, {kind} fit poses, validation in the {where}: RMS {rms:.2f} um, "
              f"max {peak:.2f} um")


if __name__ == "__main__":
    main()
