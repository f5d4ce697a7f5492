"""Machine YAML validation: clear one-line errors naming the file and the field."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

import verne_post as vp
from verne_post.errors import InputError
from verne_post.machine import machine_problems

ROOT = Path(__file__).resolve().parent.parent

SHIPPED = Path(vp.__file__).parent / "machines" / "verne.yaml"


def _write(tmp_path: Path, data: object) -> Path:
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


def _shipped() -> dict:
    return yaml.safe_load(SHIPPED.read_text())


def test_shipped_machine_matches_identified_geometry() -> None:
    geom = vp.load_machine().geom
    assert (geom.D1_minus_d1, geom.D2_minus_d2, geom.R1, geom.r1, geom.L1, geom.R2, geom.r4, geom.L2, geom.L3,
            geom.delta, geom.da, geom.dt) == (-320.00, 240.66, 129.71, 80.22, 849.97, 190.06, 565.93, 950.37,
                                              950.90, 495.80, 2007.81, 96.91)
    assert vp.load_machine(SHIPPED) == vp.load_machine() and vp.load_machine(SHIPPED).source == "verne.yaml"


def test_top_level_machines_folder_is_the_shipped_file() -> None:
    top = Path(__file__).parent.parent / "machines" / "verne.yaml"
    assert top.read_text() == SHIPPED.read_text()


def test_tool_length_changes_delta() -> None:
    machine = vp.load_machine()
    assert machine.kinematic_geometry(76.2).delta == pytest.approx(495.80 + 76.2)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.update(colour="red"), "colour: unknown key"),
        (lambda d: d["geometry"].pop("L1"), "geometry.L1: missing (required)"),
        (lambda d: d["geometry"].update(L2=-5), "geometry.L2: Input should be greater than 0"),
        (lambda d: d["joints"]["rho1"].update(min=1400), "joints.rho1: min (1400.0) must be smaller"),
        (lambda d: d["joints"]["theta1"].update(velocity="fast"), "joints.theta1.velocity: 'fast' is not a number"),
        (lambda d: d["geometry"].update(dt=float("nan")), "geometry.dt: Input should be a finite number"),
        (lambda d: d["joints"]["rho2"].update(continuous=True), "joints.rho2"),
        (lambda d: d.update(source="other.yaml"), "source: unknown key"),
        (lambda d: d["geometry"].update(L1=float("inf")), "geometry.L1: Input should be a finite number"),
        (lambda d: d["joints"]["theta1"].update(velocity=float("inf")), "joints.theta1.velocity: Input should be"),
        (lambda d: d["joints"]["rho3"].update(max=float("inf")), "joints.rho3.max: Input should be a finite number"),
        (lambda d: d["timing"].update(rotary_feed=float("inf")), "timing.rotary_feed: Input should be a finite"),
        (lambda d: d["pole"].update(max_theta2_rate=float("nan")), "pole.max_theta2_rate: Input should be a finite"),
        (lambda d: d["tools"][1].update(length=float("inf")), "tools.1.length: Input should be a finite number"),
        (lambda d: d.update(work_offset=[0, 0, float("-inf")]), "work_offset.2: Input should be a finite number"),
        (lambda d: d["geometry"].update(da=1e9), "geometry.da: Input should be less than or equal to 100000"),
        (lambda d: d["joints"]["rho1"].update(velocity=1e-12), "joints.rho1.velocity: Input should be greater"),
        (lambda d: d["joints"]["rho1"].update(jerk=1e300), "joints.rho1.jerk: Input should be less than"),
        (lambda d: d.update(name=""), "name: String should have at least 1 character"),
    ],
)
def test_bad_machine_files(tmp_path: Path, mutate, message: str) -> None:
    data = _shipped()
    mutate(data)
    path = _write(tmp_path, data)
    with pytest.raises(InputError) as error:
        vp.load_machine(path)
    text = str(error.value)
    line = re.match(rf"{re.escape(str(path))}:(\d+): ", text)
    assert line is not None, text
    # the line holds the key at fault (or, for a missing key, the mapping that lacks it)
    key = message.split(":")[0].split(".")
    written = path.read_text().splitlines()[int(line.group(1)) - 1]
    assert any(part in written for part in key if not part.isdigit()) or key[-1].isdigit()
    assert message in text
    assert "\n" not in text


def test_machine_problems_are_all_listed_each_at_its_line(tmp_path: Path) -> None:
    text = (ROOT / "machines" / "verne.yaml").read_text()
    lines = text.splitlines()
    broken = (text.replace("  R1: 129.71", "  R1: 12x9.71")
              .replace("rho2:   {min: 0.0, max: 1300.0", "rho2:   {min: 1400.0, max: 1300.0")
              .replace("  corner_angle: 30.0", "  corner_angle: 30.0\n  bogus: 1"))
    expected = [next(k for k, line in enumerate(lines) if line.startswith(prefix)) + 1
                for prefix in ("  R1:", "  rho2:", "  corner_angle:")]
    expected[2] += 1  # the unknown key, on the line after corner_angle
    _, problems = machine_problems(broken, "m.yaml")
    assert [(p.line, p.path) for p in problems] == list(zip(expected, ["geometry.R1", "joints.rho2", "timing.bogus"],
                                                            strict=True))
    assert [p.reason for p in problems][2] == "unknown key"


def test_not_yaml(tmp_path: Path) -> None:
    path = _write(tmp_path, "geometry: [1, 2\n  bad")
    with pytest.raises(InputError, match="invalid YAML"):
        vp.load_machine(path)
    with pytest.raises(InputError, match="cannot read machine file"):
        vp.load_machine(tmp_path / "missing.yaml")


def _shipped_text() -> str:
    return SHIPPED.read_text()


def _line_of(prefix: str) -> int:
    """The 1-based line of the shipped file that starts with ``prefix``."""
    return next(k for k, line in enumerate(_shipped_text().splitlines()) if line.startswith(prefix)) + 1


@pytest.mark.parametrize(("text", "line", "message"), [
    (_shipped_text().replace("  R1: 129.71\n", "  R1: 129.71\n  R1: 130.0\n"), _line_of("  R1:") + 1,
     f"duplicate key 'R1' (first at line {_line_of('  R1:')})"),
    (_shipped_text() + "name: OTHER\n", None, f"duplicate key 'name' (first at line {_line_of('name:')})"),
    (_shipped_text().replace("L1: 849.97", "L1: .inf"), None, "geometry.L1: Input should be a finite number"),
    (_shipped_text().replace("da: 2007.81", "da: .nan"), None, "geometry.da: Input should be a finite number"),
    (_shipped_text().replace("L2: 950.37", "L2: 1.0e+400"), None, "geometry.L2: Input should be a finite number"),
    (_shipped_text() + "extra: " + "[" * 100000 + "]" * 100000 + "\n", len(_shipped_text().splitlines()) + 1,
     "nested deeper than 16 levels"),
    ("a: &a [x, x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
     "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
     "e: [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]\n", None, "more than 100000 values (aliases expanded)"),
    ("&a [*a]\n", 1, "more than 100000 values"),
    (_shipped_text() + "#" * (1 << 20), None, "machine file larger than 1048576 bytes"),
    # an integer beyond Python's 4,300-digit conversion limit, and a float as long
    (_shipped_text().replace("L1: 849.97", "L1: " + "9" * 5000), _line_of("  L1:"),
     "a number of 5000 characters (at most 100)"),
    (_shipped_text().replace("L1: 849.97", "L1: 0." + "9" * 5000), _line_of("  L1:"), "a number of 5002 characters"),
    ("a: [1, 2, -" + "1" * 101 + "]\n", 1, "a number of 102 characters"),
    (_shipped_text().replace("L1: 849.97", f"L1: {10**400}"), _line_of("  L1:"),
     "a number of 401 characters"),  # beyond any float
])
def test_malformed_machine_yaml(tmp_path: Path, text: str, line: int | None, message: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as error:
        vp.load_machine(path)
    where = f"{path}:{line}: " if line else f"{path}"
    assert str(error.value).startswith(where) and message in str(error.value) and "\n" not in str(error.value)


def test_unreachable_reference_pose_is_rejected_with_the_reason(tmp_path: Path) -> None:
    """Leg I rods of 300 mm: brute force over the tilt (axis along the table normal, so alpha =
    theta1) shows a rod whose horizontal distance to its guideway exceeds its length at every
    tilt, in the independent model; the loader must refuse the file and say why."""
    import numpy as np
    from independent import platform_from_tool

    data = _shipped()
    data["geometry"]["L1"] = 300.0
    geom = vp.Geometry(**data["geometry"])
    theta1 = np.linspace(-np.pi, np.pi, 20001)
    n = len(theta1)
    platform, alpha = platform_from_tool(geom, np.zeros((n, 3)), np.tile([0.0, 0.0, 1.0], (n, 1)), theta1,
                                         np.zeros(n))
    g = geom
    horizontal = np.hypot(platform[:, 0] + g.D1_minus_d1, platform[:, 1] + g.R1 * np.cos(alpha) - g.r1)
    assert np.all(horizontal > g.L1)
    with pytest.raises(InputError) as error:
        vp.load_machine(_write(tmp_path, data))
    assert "geometry: the reference pose" in str(error.value)
    assert "not reachable in the working mode: no assembly of the legs reaches it" in str(error.value)


# -------------------------------------------------------------------------------------------
# messages in the file's own terms: at the line where the mistake is written, the value echoed


def _check(text: str, tmp_path: Path) -> list[str]:
    """``machine check``'s error lines for a machine file of ``text``, without the file's name."""
    from click.testing import CliRunner

    from verne_post.cli import main

    path = tmp_path / "m.yaml"
    path.write_text(text)
    result = CliRunner().invoke(main, ["machine", "check", str(path)])
    assert result.exit_code == 2, result.output
    return [line.removeprefix(f"verne-post: error: {path}:") for line in result.stderr.splitlines()]


@pytest.mark.parametrize(("old", "new", "line", "message"), [
    # a misspelt key: the nearest of that section's keys (difflib, as click does for options)
    ("  dialect: linuxcnc\n", "  dialect: linuxcnc\n  block_number: true\n", "  block_number:",
     "controller.block_number: unknown key (did you mean block_numbers?)"),
    ("  1: {length: 76.2}", "  1: {length: 76.2, diamter: 6}", "  1: {length",
     "tools.1.diamter: unknown key (did you mean diameter?)"),
    # a decimal comma: the value echoed, the decimal point suggested
    ("  L1: 849.97", "  L1: 849,97", "  L1:", "geometry.L1: '849,97' is not a number: write a decimal point (849.97)"),
    # a union (false, true or {start, step}): one line at the file's key, no model names
    ("  dialect: linuxcnc\n", "  dialect: linuxcnc\n  block_numbers: {step: ten}\n", "  block_numbers:",
     "controller.block_numbers.step: 'ten' is not a whole number"),
    ("  dialect: linuxcnc\n", "  dialect: linuxcnc\n  block_numbers: ten\n", "  block_numbers:",
     "controller.block_numbers: 'ten' is not a mapping of keys or true or false"),
    # YAML notices these a line late: reported where they are written
    ("  R1: 129.71", "  R1:129.71", "  R1:", "invalid YAML: could not find expected ':': write a key as 'key: value', "
     "with a space after the colon"),
    ("jerk: 200000.0}\n  rho2:", "jerk: 200000.0\n  rho2:", "  rho1:",
     "invalid YAML: the '{' of this line is not closed by a '}'"),
    ("  R1: 129.71", "\tR1: 129.71", "\tR1:", "invalid YAML: a tab character: indent with spaces"),
    # a number in quotes: the schema (an editor) refuses it, so the program does too
    ("  R1: 129.71", '  R1: "129.71"', "  R1:", "geometry.R1: a number in quotes: write it without them"),
    ("  1: {length: 76.2}", "  1: {length: '76.2'}", "  1: {length", "tools.1.length: a number in quotes"),
])
def test_a_mistake_is_reported_in_the_files_terms_at_its_line(tmp_path: Path, old: str, new: str, line: str,
                                                              message: str) -> None:
    text = _shipped_text()
    assert old in text
    text = text.replace(old, new, 1)
    at = next(k for k, written in enumerate(text.splitlines()) if written.startswith(line)) + 1
    errors = _check(text, tmp_path)
    assert len(errors) == 1 and errors[0].startswith(f"{at}: {message}"), errors


def test_a_quoted_name_is_text_not_a_number(tmp_path: Path) -> None:
    path = tmp_path / "m.yaml"
    path.write_text(_shipped_text().replace("name: VERNE", 'name: "1234"'))
    assert vp.load_machine(path).name == "1234"


def test_the_schema_and_the_program_agree_on_a_quoted_number() -> None:
    import jsonschema

    from verne_post.placement.machine_facts import schema

    document = yaml.safe_load(_shipped_text().replace("  R1: 129.71", '  R1: "129.71"'))
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(document, schema())
    _, problems = machine_problems(_shipped_text().replace("  R1: 129.71", '  R1: "129.71"'), "m.yaml")
    assert [p.path for p in problems] == ["geometry.R1"]
