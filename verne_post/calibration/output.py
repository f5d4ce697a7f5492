"""The calibrated machine file: the input's text with only the identified values changed.

A ruamel.yaml round trip keeps every comment, the key order and the flow mappings of the joint
lines; the fitted geometry values and joint offsets are replaced, and a ``calibration:`` block
records the provenance (no date: the same measurements give the same file). The result is
parsed and validated by the project's own loader (YAML safe load, pydantic) before anyone
writes it.
"""

from __future__ import annotations

import io
import re
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
    return representer.represent_scalar("tag:yaml.org,2002:float", _format(value))


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

    Every fitted value is replaced where it stands in the text (ruamel.yaml gives its line and
    column), so the rest of the file stays byte for byte; a new ``offset`` joins its joint's
    flow mapping. Where that is not possible (a value written in an unusual way), the whole
    document goes through ruamel.yaml's round-trip dump instead, which keeps the comments and
    the key order. Raises :class:`~verne_post.errors.InputError` if the result does not validate.
    """
    values = {name: _round(name, calibration.fitted[k]) for k, name in enumerate(PARAMETERS)
              if calibration.status[name] == "fitted"}
    block = record(calibration, measurements_name)
    try:
        text = _spliced(original, values, block)
    except _CannotSpliceError:
        text = _dumped(original, values, block)
    machine_from_text(text, source)  # the file must load as it will be loaded
    return text


class _CannotSpliceError(Exception):
    pass


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")

#: Comment written above the calibration block.
BLOCK_COMMENT = ("# Written by 'verne-post calibrate': what was fitted, to how many measured poses, with what\n"
                 "# tool-tip residuals (mm, table frame) before and after. Joint offsets: joints.<name>.offset.\n")


def _format(value: float) -> str:
    text = f"{value:.{ANGLE_DECIMALS}f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def _block_text(block: dict[str, object]) -> str:
    lines = ["calibration:"]
    for key, value in block.items():
        if isinstance(value, list):
            shown = "[" + ", ".join(str(v) for v in value) + "]"
        elif isinstance(value, float):
            shown = _format(value)
        elif isinstance(value, str):
            shown = "'" + value.replace("'", "''") + "'"
        else:
            shown = str(value)
        lines.append(f"  {key}: {shown}")
    return BLOCK_COMMENT + "\n".join(lines) + "\n"


def _spliced(original: str, values: dict[str, float], block: dict[str, object]) -> str:
    """``original`` with each value replaced in place (see :func:`calibrated_text`)."""
    data = YAML().load(original)
    lines = original.splitlines(keepends=True)
    edits: list[tuple[int, int, int, str]] = []  # (line, start column, end column, new text)
    for name, value in values.items():
        if name in GEOMETRY_NAMES:
            mapping, key = data["geometry"], name
        else:
            mapping, key = data["joints"][name.removesuffix("_offset")], "offset"
        if key in mapping:
            line, column = mapping.lc.value(key)
            match = _NUMBER.match(lines[line], column)
            if match is None:
                raise _CannotSpliceError
            edits.append((line, column, match.end(), _format(value)))
        elif getattr(mapping, "fa", None) is not None and mapping.fa.flow_style():
            line = mapping.lc.line
            text = lines[line]
            code = text.split("#", 1)[0]
            close = code.rfind("}")
            if close < 0 or code.count("{") != 1:  # a flow mapping over several lines
                raise _CannotSpliceError
            edits.append((line, close, close, f", offset: {_format(value)}"))
        else:
            raise _CannotSpliceError
    for line, start, end, new in sorted(edits, reverse=True):
        lines[line] = lines[line][:start] + new + lines[line][end:]
    if "calibration" in data:  # an earlier calibration: its block (and its comment) goes
        first = data.lc.key("calibration")[0]
        later = [data.lc.key(k)[0] for k in data if data.lc.key(k)[0] > first]
        last = min(later) if later else len(lines)
        while first > 0 and lines[first - 1].startswith("#") and lines[first - 1] in BLOCK_COMMENT:
            first -= 1
        del lines[first:last]
    text = "".join(lines)
    if text and not text.endswith("\n"):
        text += "\n"
    return text.rstrip("\n") + "\n\n" + _block_text(block)


def _dumped(original: str, values: dict[str, float], block: dict[str, object]) -> str:
    """``original`` through ruamel.yaml's round trip with the new values (comments kept)."""
    yaml = YAML()  # round-trip mode
    yaml.width = 4096  # never re-wrap a line of the input
    yaml.preserve_quotes = True
    # New values in fixed point: '1e-06' would be a string to YAML 1.1 loaders (no dot).
    yaml.representer.add_representer(float, _fixed_point)
    data = yaml.load(original)
    for name, value in values.items():
        if name in GEOMETRY_NAMES:
            data["geometry"][name] = value
        else:
            data["joints"][name.removesuffix("_offset")]["offset"] = value
    mapping = CommentedMap()
    for key, value in block.items():
        mapping[key] = CommentedSeq(value) if isinstance(value, list) else value
        if isinstance(value, list):
            mapping[key].fa.set_flow_style()
    if "calibration" in data:
        del data["calibration"]
    data["calibration"] = mapping
    data.yaml_set_comment_before_after_key("calibration", before="\n" + BLOCK_COMMENT.replace("# ", "").strip())
    out = io.StringIO()
    yaml.dump(data, out)
    return out.getvalue()


def fitted_values(calibration: Calibration) -> dict[str, float]:
    """Fitted values in the interface units (mm, degrees), as written to the file."""
    return {n: _round(n, calibration.fitted[k]) for k, n in enumerate(PARAMETERS) if np.isfinite(calibration.fitted[k])}


__all__ = ["calibrated_text", "fitted_values", "record"]
