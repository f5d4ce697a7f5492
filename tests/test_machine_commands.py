"""verne-post machine check / schema / init / show, and machine-file problems at their lines."""

from __future__ import annotations

import json
import re
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import verne_post as vp
from verne_post.api import Status, inverse_kinematics_pair
from verne_post.cli import main
from verne_post.placement.machine_facts import facts, reference_joints, schema

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "verne_post" / "machines" / "verne.yaml"


def _lines_of(text: str, *prefixes: str) -> list[int]:
    lines = text.splitlines()
    return [next(k for k, line in enumerate(lines) if line.startswith(prefix)) + 1 for prefix in prefixes]


def test_check_lists_every_problem_at_its_line_and_exits_2(tmp_path: Path) -> None:
    text = SHIPPED.read_text()
    broken = (text.replace("  R1: 129.71", "  R1: 12x9.71")
              .replace("  theta1: {min: -90.0, max: 90.0", "  theta1: {min: 95.0, max: 90.0")
              .replace("  1: {length: 76.2}", "  1: {length: -3}"))
    path = tmp_path / "m.yaml"
    path.write_text(broken)
    result = CliRunner().invoke(main, ["machine", "check", str(path)])
    assert result.exit_code == 2
    r1, theta1, tool = _lines_of(broken, "  R1:", "  theta1:", "  1: {length")
    assert result.stderr.splitlines() == [
        f"verne-post: error: {path}:{r1}: geometry.R1: '12x9.71' is not a number",
        f"verne-post: error: {path}:{theta1}: joints.theta1: min (95.0) must be smaller than max (90.0)",
        f"verne-post: error: {path}:{tool}: tools.1.length: Input should be greater than or equal to 0"]
    # loading it anywhere else gives the first, the same way
    posted = CliRunner().invoke(main, [str(ROOT / "examples" / "nx_swarf_inch_crlf.cls"), "--machine", str(path),
                                       "-o", str(tmp_path / "x.nc")])
    assert posted.exit_code == 2
    assert posted.stderr.strip() == f"verne-post: error: {path}:{r1}: geometry.R1: '12x9.71' is not a number"


def test_check_summarises_a_valid_file_with_its_reference_pose(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["machine", "check", str(SHIPPED)])
    assert result.exit_code == 0
    found = re.search(r"reference pose .*: rho (\S+) (\S+) (\S+) mm, theta1 (\S+) deg, theta2 (\S+) deg",
                      result.output)
    assert found is not None
    joints = np.array([float(v) for v in found.groups()])
    joints[3:] = np.radians(joints[3:])
    # the forward kinematics of the printed joints put the spindle nose at the table origin, axis up
    fk = vp.forward_kinematics(vp.load_machine(), joints[None], tool_length=0.0)
    assert np.allclose(fk.tip[0], 0.0, atol=2e-3) and np.allclose(fk.axis[0], [0.0, 0.0, 1.0], atol=1e-5)
    assert "tools: 1: 76.2 mm" in result.output


def test_the_shipped_schema_is_the_models_and_validates_the_shipped_file() -> None:
    shipped = json.loads((SHIPPED.parent / "verne.schema.json").read_text())
    assert shipped == json.loads(json.dumps(schema()))  # regenerate with: verne-post machine schema -o ...
    assert SHIPPED.read_text().startswith("# yaml-language-server: $schema=verne.schema.json\n")
    data = yaml.safe_load(SHIPPED.read_text())
    jsonschema.validate(data, shipped)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**data, "colour": "red"}, shipped)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**data, "geometry": {**data["geometry"], "L1": "long"}}, shipped)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**data, "joints": {**data["joints"], "rho1": {**data["joints"]["rho1"], "min": "low"}}},
                            shipped)
    described = shipped["$defs"]["GeometryConfig"]["properties"]["L1"]["description"]
    assert "mm" in described


def test_schema_command_writes_the_schema(tmp_path: Path) -> None:
    out = tmp_path / "s.json"
    assert CliRunner().invoke(main, ["machine", "schema", "-o", str(out)]).exit_code == 0
    assert json.loads(out.read_text()) == json.loads(json.dumps(schema()))


def test_init_writes_a_commented_file_that_loads_and_never_overwrites(tmp_path: Path) -> None:
    out = tmp_path / "shop.yaml"
    assert CliRunner().invoke(main, ["machine", "init", "-o", str(out)]).exit_code == 0
    text = out.read_text()
    assert text.count("\n#") + text.count("  #") > 20  # commented
    assert vp.load_machine(out).model_dump() == vp.load_machine().model_dump()
    again = CliRunner().invoke(main, ["machine", "init", "-o", str(out)])
    assert again.exit_code == 2 and out.read_text() == text


def test_show_gives_a_workspace_whose_edges_are_where_the_machine_stops(tmp_path: Path) -> None:
    machine = vp.load_machine()
    found = facts(machine, 80.0)
    result = CliRunner().invoke(main, ["machine", "show", str(SHIPPED), "--tool-length", "80"])
    assert result.exit_code == 0
    x0, x1 = found.extents["x"]
    z0, z1 = found.extents["z"]
    assert f"x: {x0:.0f} to {x1:.0f} mm" in result.output
    # an independent look along the sections' lines through the table centre: the IK of each
    # tool tip (axis up) with the machine's status, in 1 mm steps
    up = np.array([[0.0, 0.0, 1.0]])

    def usable(tips: np.ndarray) -> np.ndarray:
        ik = inverse_kinematics_pair(machine, tips, np.repeat(up, len(tips), axis=0), 1, tool_length=80.0)
        return ik.status == Status.OK

    z = np.arange(z0, z1 + 1.0, 1.0)
    column = np.column_stack([np.zeros_like(z), np.zeros_like(z), z])
    assert usable(column).mean() > 0.5
    assert not usable(np.array([[0.0, 0.0, z1 + 15.0]])).any()  # past the 10 mm grid
    # above the table only: the tool tip below its face (z < 0) is no place to cut
    assert z0 == 0.0 and f"z: 0 to {z1:.0f} mm" in result.output and usable(np.array([[0.0, 0.0, -100.0]])).all()
    ref = reference_joints(machine)
    assert f"{ref[0]:.3f}" in result.output


def test_a_file_changed_only_in_comments_and_order_posts_the_same_program(tmp_path: Path) -> None:
    text = SHIPPED.read_text()
    blocks = re.split(r"\n(?=[a-z_]+:)", text)
    head, sections = blocks[0], blocks[1:]
    reordered = head + "\n" + "\n".join(reversed(sections))
    reordered = re.sub(r"#[^\n]*", "# another comment", reordered)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    (tmp_path / "a" / "verne.yaml").write_text(text)
    (tmp_path / "b" / "verne.yaml").write_text(reordered)
    loaded = [vp.load_machine(tmp_path / folder / "verne.yaml").model_dump() for folder in ("a", "b")]
    assert loaded[0] == loaded[1]
    programs = []
    for folder in ("a", "b"):
        out = tmp_path / folder / "p.nc"
        result = CliRunner().invoke(main, [str(ROOT / "examples" / "nx_swarf_inch_crlf.cls"), "--machine",
                                           str(tmp_path / folder / "verne.yaml"), "-o", str(out), "--quiet"])
        assert result.exit_code == 0, result.output
        programs.append(out.read_bytes())
    assert programs[0] == programs[1]


def test_show_names_each_edge_where_it_is_set_and_the_joints_by_their_letters(tmp_path: Path) -> None:
    """Each limit said to set an edge is met there: the tip is usable and a tip one grid step
    (10 mm) beside it, in its section, is not (the machine's own IK status)."""
    machine = vp.load_machine()
    found = facts(machine, 100.0)
    assert len(found.edges) >= 3
    up = np.array([0.0, 0.0, 1.0])
    for label, tip in found.edges:
        tip = np.array(tip)
        steps = np.array([[10, 0, 0], [-10, 0, 0], [0, 10, 0], [0, -10, 0], [0, 0, 10], [0, 0, -10]], float)
        near = np.vstack([tip, tip + steps])
        ik = inverse_kinematics_pair(machine, near, np.tile(up, (len(near), 1)), 1, tool_length=100.0)
        assert ik.status[0] == Status.OK and (ik.status[1:] != Status.OK).any(), label
        assert tip[2] >= 0
    path = tmp_path / "uvw.yaml"
    path.write_text(SHIPPED.read_text().replace(
        "  dialect: linuxcnc\n", "  dialect: sinumerik\n  axes: {rho1: U, rho2: V, rho3: W, theta1: B, theta2: C}\n"))
    result = CliRunner().invoke(main, ["machine", "show", str(path), "--tool-length", "100"])
    assert result.exit_code == 0
    for joint, letter in zip(("rho1", "rho2", "rho3", "theta1", "theta2"), "UVWBC", strict=True):
        assert re.search(rf"^{joint} \({letter}\) (mm|deg) ", result.output, re.MULTILINE), result.output
    edges = result.output.split("its edges are set by:\n")[1]
    assert f"  {found.edges[0][0]}: at " in edges and "tightest margins" not in result.output


def test_the_maps_labels_stay_in_their_section_and_clear_of_each_other() -> None:
    import itertools

    import matplotlib.pyplot as plt

    from verne_post.placement.workspace import workspace, workspace_figure

    for tool_length, tilt in ((100.0, 0.0), (60.0, 30.0)):
        figure = workspace_figure(workspace(vp.load_machine(), tool_length=tool_length, tilt=tilt, step=10.0))
        figure.canvas.draw()
        renderer = figure.canvas.get_renderer()
        for ax in figure.axes[:3]:
            frame = ax.get_window_extent(renderer)
            boxes = [text.get_window_extent(renderer) for text in ax.texts]
            assert boxes
            for box in boxes:
                assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
            assert not any(a.overlaps(b) for a, b in itertools.combinations(boxes, 2))
        plt.close(figure)
