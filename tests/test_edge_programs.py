"""Small programs at the edges: a single point, rapids only, repeated points, inverse time,
rotary-only moves, corners and a tool change; G-code and timed CSV, accepted by rs274."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from verne_post.cli import main
from verne_post.verify.rs274 import run_rs274

HEADER = "UNITS/MM\nMULTAX/ON\nTLDATA/MILL,10,0,80,0,0\nLOAD/TOOL,1\nFEDRAT/MMPM,1000\n"
PROGRAMS = {
    "single_point": "GOTO/0,0,50,0,0,1\n",
    "rapids_only": "RAPID\nGOTO/0,0,50,0,0,1\nRAPID\nGOTO/10,0,50,0,0,1\n",
    "repeated_points": "GOTO/0,0,50,0,0,1\nGOTO/0,0,50,0,0,1\nGOTO/0,0,50,0,0,1\n",
    "inverse_time": ("GOTO/0,0,50,0,0,1\nFEDRAT/INVERS,10\nGOTO/10,0,50,0,0,1\nGOTO/10,0,50,0.2,0,0.98\n"
                     "FEDRAT/MMPM,500\nGOTO/0,0,50\n"),
    "rotary_only": "GOTO/0,0,50,0,0,1\nGOTO/0,0,50,0.3,0,0.954\nGOTO/0,0,50,0,0.3,0.954\n",
    "corners_and_tool_change": ("GOTO/0,0,50,0,0,1\nGOTO/10,0,50,0,0,1\nGOTO/10,10,50,0,0,1\nGOTO/0,10,50,0,0,1\n"
                                "LOAD/TOOL,2\nTLDATA/MILL,6,0,100,0,0\nRAPID\nGOTO/0,0,60,0,0,1\nGOTO/5,0,60,0,0,1\n"),
}


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_edge_program(tmp_path: Path, name: str) -> None:
    source = tmp_path / f"{name}.cls"
    source.write_text(HEADER + PROGRAMS[name] + "FINI\n")
    for suffix in (".nc", ".csv"):
        result = CliRunner().invoke(main, [str(source), "-o", str(source.with_suffix(suffix)), "--quiet"])
        assert result.exit_code == 0, result.output + result.stderr
    gcode = source.with_suffix(".nc")
    tools = [int(t) for t in re.findall(r"^T(\d+) M6", gcode.read_text(), re.M)]
    assert run_rs274(gcode, tool_numbers=tools).errors == []
    assert source.with_suffix(".csv").read_text().startswith("t,rho1")
