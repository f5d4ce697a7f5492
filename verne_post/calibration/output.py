"""The calibrated machine file: the input's text with only the identified values changed.

A ruamel.yaml round trip keeps every comment, the key order and the flow mappings of the joint
lines; the fitted geometry values and joint offsets are replaced, and a ``calibration:`` block
records the provenance (no date: the same measurements give the same file). The result is
parsed and validated by the project's own loader (YAML safe load, pydantic) before anyone
writes it.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from ruamel.yaml import YAML
from ruamel.yaml.comments import CommentedMap, CommentedSeq

from ..machine import machine_from_text
from .fit import Calibration
from .model import GEOMETRY_NAMES, PARAMETERS, to_interface

#: Decimals written: 0.1 micrometre for lengths, 1e-6 degree for the table-angle offsets.
LENGTH_DECIMALS = 4
ANGLE_DECIMALS = 6

METHOD = "verne-post calibrate: least squares on measured tool-tip positions (table frame)"


def _round(name: str, value: float) -> float:
    decimals = ANGLE_DECIMALS if name.startswith("theta") else LENGTH_DECIMALS
    return float(round(to_interface(name, value), decimals)) + 0.0  # + 0.0: never -0.0


def _fixed_point(representer: object, value: float) -> object:
    text = f"{value:.{ANGLE_DECIMALS}f}".rstrip("0")
    return representer.represent_scalar("tag:yaml.org,2002:float", text + "0" if text.endswith(".") else text)


def record(calibration: Calibration, measurements_name: str) -> dict[str, object]:
    """The ``calibration:`` block (mm): provenance, pose counts, residuals, parameters."""
    summary = calibration.summary()
    return {
        "method": METHOD,
        "measurements": Path(measurements_name).name,
        "poses": int(calibration.used.sum()),
        "rejected": int((~calibration.used).sum()),
        **{key: round(value, 4) for key, value in summary.items()},
        "fitted": [n for n in PARAMETERS if calibration.status[n] == "fitted"],
        "held": [n for n in PARAMETERS if calibration.status[n] != "fitted"],
    }


def calibrated_text(original: str, calibration: Calibration, measurements_name: str, source: str) -> str:
    """The machine file ``original`` (YAML text) with the fitted values of ``calibration``.

    Raises :class:`~verne_post.errors.InputError` if the result does not validate.
    """
    yaml = YAML()  # round-trip mode: comments and layout survive
    yaml.width = 4096  # never re-wrap a line of the input
    yaml.preserve_quotes = True
    # New values in fixed point: '1e-06' would be a string to YAML 1.1 loaders (no dot).
    yaml.representer.add_representer(float, _fixed_point)
    data = yaml.load(original)
    for k, name in enumerate(PARAMETERS):
        if calibration.status[name] != "fitted":
            continue
        value = _round(name, calibration.fitted[k])
        if name in GEOMETRY_NAMES:
            data["geometry"][name] = value
        else:
            data["joints"][name.removesuffix("_offset")]["offset"] = value
    block = CommentedMap()
    for key, value in record(calibration, measurements_name).items():
        block[key] = CommentedSeq(value) if isinstance(value, list) else value
        if isinstance(value, list):
            block[key].fa.set_flow_style()
    if "calibration" in data:
        del data["calibration"]
    data["calibration"] = block
    data.yaml_set_comment_before_after_key(
        "calibration", before="\nWritten by 'verne-post calibrate': what was fitted, to how many measured poses, with "
                              "what tool-tip\nresiduals (mm, table frame) before and after. Joint offsets: "
                              "joints.<name>.offset.")
    out = io.StringIO()
    yaml.dump(data, out)
    text = out.getvalue()
    machine_from_text(text, source)  # the file must load as it will be loaded
    return text


def fitted_values(calibration: Calibration) -> dict[str, float]:
    """Fitted values in the interface units (mm, degrees), as written to the file."""
    return {n: _round(n, calibration.fitted[k]) for k, n in enumerate(PARAMETERS) if np.isfinite(calibration.fitted[k])}


__all__ = ["calibrated_text", "fitted_values", "record"]
