"""Machine YAML validation: clear one-line errors naming the file and the field."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

import verne_post as vp
from verne_post.errors import InputError

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
    assert vp.load_machine(SHIPPED) == vp.load_machine().model_copy(update={"source": "verne.yaml"})


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
        (lambda d: d["geometry"].pop("L1"), "geometry.L1: Field required"),
        (lambda d: d["geometry"].update(L2=-5), "geometry.L2: Input should be greater than 0"),
        (lambda d: d["joints"]["rho1"].update(min=1400), "joints.rho1: Value error, min (1400.0) must be smaller"),
        (lambda d: d["joints"]["theta1"].update(velocity="fast"), "joints.theta1.velocity: Input should be a valid"),
        (lambda d: d["geometry"].update(dt=float("nan")), "geometry.dt: Input should be a finite number"),
        (lambda d: d["joints"]["rho2"].update(continuous=True), "joints.rho2"),
    ],
)
def test_bad_machine_files(tmp_path: Path, mutate, message: str) -> None:
    data = _shipped()
    mutate(data)
    path = _write(tmp_path, data)
    with pytest.raises(InputError) as error:
        vp.load_machine(path)
    text = str(error.value)
    assert text.startswith(f"{path}: invalid machine: ")
    assert message in text
    assert "\n" not in text


def test_not_yaml(tmp_path: Path) -> None:
    path = _write(tmp_path, "geometry: [1, 2\n  bad")
    with pytest.raises(InputError, match="invalid YAML"):
        vp.load_machine(path)
    with pytest.raises(InputError, match="cannot read machine file"):
        vp.load_machine(tmp_path / "missing.yaml")
