"""Workspace maps against an independent route: random joint sets taken through the forward
kinematics with the map's tool axis; where the machine stands clear of every limit, the map
must say the tip is usable, with the same headroom."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from verne_post.api import Status, classify, pose_margins
from verne_post.checks.headroom import headroom, smallest
from verne_post.cli import main
from verne_post.placement.workspace import solve_tips, tool_axis

EXAMPLES = Path(__file__).parent.parent / "examples"


@pytest.mark.parametrize(("tilt", "rotary", "length"), [(0.0, 0.0, 0.0), (30.0, 0.0, 60.0), (55.0, 120.0, 100.0)])
def test_map_agrees_with_forward_kinematics(machine: vp.Machine, tilt: float, rotary: float, length: float) -> None:
    rng = np.random.default_rng(int(tilt + rotary))
    rho = rng.uniform(0.0, 1300.0, (20000, 3))
    # theta1 = alpha - phi1 gives the tool axis the wanted tilt; theta2 = rotary.
    module = vp.forward_kinematics(machine, np.column_stack([rho, np.zeros((len(rho), 2))]), tool_length=length)
    joints = np.column_stack([rho, module.alpha - np.radians(tilt), np.full(len(rho), np.radians(rotary))])
    fk = vp.forward_kinematics(machine, joints, tool_length=length, alpha_guess=module.alpha)
    found = pose_margins(machine, joints, fk.platform, fk.alpha, fk.reachable, length)
    ok = classify(machine, joints, fk.reachable, found) == Status.OK
    assert ok.sum() > 500
    assert np.allclose(fk.axis[ok], tool_axis(tilt, rotary), atol=1e-9)
    value, _ = solve_tips(machine, fk.tip[ok], tool_length=length, tilt=tilt, rotary=rotary)
    assert np.all(value >= 0)
    expected, _ = smallest(headroom(machine, joints[ok], pose_margins(machine, joints[ok], fk.platform[ok],
                                                                      fk.alpha[ok], fk.reachable[ok], length)))
    assert np.allclose(value, expected, atol=1e-6)


def test_sections_are_planes_through_the_table_centre(machine: vp.Machine) -> None:
    ws = vp.workspace(machine, tool_length=60.0, tilt=20.0, step=25.0)
    planes = {s.plane: s for s in ws.sections}
    assert set(planes) == {"xz", "yz", "xy"}
    for section in ws.sections:
        assert section.headroom.shape == section.limit.shape == (len(section.v), len(section.u))
        assert np.nanmax(section.headroom) > 0.3  # the machine works somewhere in every section
        assert np.any(np.isnan(section.headroom))  # and the grid reaches past its reach
    # The plan view at the default height is where the x-z section is widest, so it cuts the usable region.
    assert np.sum(planes["xy"].headroom >= 0) > 100
    # One cell checked by hand: the x-z section's (u, v) is the tip (x, 0, z).
    xz = planes["xz"]
    i, j = np.argwhere(xz.headroom >= 0)[0]
    value, _ = solve_tips(machine, np.array([[xz.u[j], 0.0, xz.v[i]]]), tool_length=60.0, tilt=20.0, rotary=0.0)
    assert value[0] == pytest.approx(xz.headroom[i, j])


@pytest.mark.parametrize("suffix", [".png", ".svg"])
def test_cli_draws_the_map_with_the_program(tmp_path: Path, suffix: str) -> None:
    out = tmp_path / f"ws{suffix}"
    result = CliRunner().invoke(main, ["workspace", "-o", str(out), "--tool-length", "80", "--tilt", "30",
                                       "--step", "25", "--program", str(EXAMPLES / "nx_swarf_inch_crlf.cls")])
    assert result.exit_code == 0, result.stderr
    data = out.read_bytes()
    if suffix == ".png":
        assert data.startswith(b"\x89PNG\r\n\x1a\n") and len(data) > 20_000
        import matplotlib.image

        image = matplotlib.image.imread(out)
        assert image.shape[0] > 300 and np.std(image[..., :3]) > 0.05  # drawn, not blank
    else:
        assert b"<svg" in data[:2000] and b"slider rho" in data  # constraint labels are text


def test_cli_rejects_a_bad_output_name(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["workspace", "-o", str(tmp_path / "ws.jpg")])
    assert result.exit_code == 2
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("verne-post: error:")
    assert not (tmp_path / "ws.jpg").exists()
