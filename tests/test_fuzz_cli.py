"""The whole pipeline through the CLI on generated CL programs and options (hypothesis).

Whatever the input: exit 0 with the output written, 2 (bad input) or 3 (violations) with
nothing written but the report; never an exception; every stderr line one of verne-post's own
one-line messages; no file left in the output folder but the expected ones. Small programs and
mostly --no-timing keep it fast; ``benchmarks/fuzz.py`` runs the long version on real files.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

from click.testing import CliRunner
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from verne_post.cli import main

WEIRD = ["nan", "NaN", "inf", "-inf", "1e308", "1e999", "-1e999", "-0", "0", "", "1e-320", "9" * 60, "abc", "1e",
         ".", "1,5", "0x10", "+", "1e+"]
coordinate = st.one_of(st.floats(-150, 150).map(lambda v: f"{v:.4f}"), st.floats(-2000, 2000).map(lambda v: f"{v:g}"))
number = st.one_of(coordinate, coordinate, coordinate, st.sampled_from(WEIRD), st.floats().map(repr))


def _axis(tilt: tuple[float, float]) -> tuple[str, str, str]:
    i, j = tilt
    return f"{i:.7f}", f"{j:.7f}", f"{math.sqrt(max(0.0, 1.0 - i * i - j * j)):.7f}"


axis = st.one_of(st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)).map(_axis), st.tuples(number, number, number),
                 st.just(("0", "0", "1")))
goto = st.builds(lambda p, a: "GOTO/" + ",".join(p + a), st.tuples(coordinate, coordinate, coordinate),
                 st.one_of(axis, axis, st.just(())))
wild_goto = st.builds(lambda p, a: "GOTO/" + ",".join(p + a), st.tuples(number, number, number),
                      st.one_of(axis, st.just(()), st.lists(number, max_size=4).map(tuple)))
record = st.one_of(
    goto, goto, goto, goto, wild_goto,
    st.just("RAPID"),
    st.builds(lambda unit, value: f"FEDRAT/{unit},{value}",
              st.sampled_from(["MMPM", "IPM", "INVERS", "MMPR", "PERMIN"]),
              st.one_of(st.sampled_from(["500", "1000", "2500"]), number)),
    st.sampled_from(["MULTAX/ON", "MULTAX/OFF", "UNITS/MM", "UNITS/INCHES", "CYCLE/OFF", "GOHOME", "END", "FINI",
                     "STOP", "OPSTOP", "COOLNT/FLOOD", "SPINDL/RPM,8000,CLW", "SPINDL/OFF", "$$ comment", ""]),
    st.builds(lambda n: f"LOAD/TOOL,{n}", st.one_of(st.integers(0, 9).map(str), number)),
    st.builds(lambda v: "TLDATA/MILL," + ",".join(v), st.lists(st.one_of(st.sampled_from(["10", "0", "80"]), number),
                                                             min_size=0, max_size=6)),
    st.builds(lambda c, a, r: "CIRCLE/" + ",".join((*c, *a, r)), st.tuples(coordinate, coordinate, coordinate), axis,
              st.one_of(st.sampled_from(["5", "10", "20"]), number)),
    st.builds(lambda v: "CYCLE/DRILL," + ",".join(v), st.lists(st.one_of(st.sampled_from(["5", "2", "MMPM", "300"]),
                                                                         number), max_size=6)),
    st.builds(lambda v: "FROM/" + ",".join(v), st.tuples(coordinate, coordinate, coordinate)),
    st.builds(lambda t: f"PPRINT/{t}", st.text(max_size=30)),
    st.text(max_size=40),
)
HEADER = "PARTNO/FUZZ\nUNITS/MM\nMULTAX/ON\nTLDATA/MILL,10,0,80,0,0\nLOAD/TOOL,1\nFEDRAT/MMPM,1000\n"
sane_goto = st.builds(lambda x, y, z, a: f"GOTO/{x:.4f},{y:.4f},{z:.4f}," + ",".join(a), st.floats(-150, 150),
                      st.floats(-150, 150), st.floats(0, 150),
                      st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)).map(_axis))
sane_record = st.one_of(sane_goto, sane_goto, sane_goto, sane_goto, st.sampled_from(
    ["RAPID", "FEDRAT/MMPM,800", "FEDRAT/2500", "COOLNT/ON", "SPINDL/RPM,12000", "$$ comment", "PPRINT/TEXT"]))
sane = st.lists(sane_record, min_size=1, max_size=25).map(lambda body: HEADER + "\n".join(body) + "\nFINI\n")


def _insert(source: str, line: str, where: int) -> str:
    lines = source.split("\n")
    lines.insert(where % len(lines), line)
    return "\n".join(lines)


program = st.one_of(
    sane,  # mostly runs through every stage
    st.builds(_insert, sane, record, st.integers(0, 40)),  # one record anything
    st.builds(lambda header, body, ending: (HEADER if header else "") + "\n".join(body) + ending,
              st.booleans(), st.lists(record, max_size=25), st.sampled_from(["\nFINI\n", "\n", ""])),
)


@st.composite
def options(draw: st.DrawFn, timing: bool) -> tuple[list[str], bool, bool]:
    """(extra arguments, writes a report, output is a timed CSV); one case in ten may hold
    values the CLI must refuse."""
    absurd = draw(st.integers(0, 9)) == 0

    def value(*usual: str) -> str:
        return draw(st.one_of(st.sampled_from(usual), number) if absurd else st.sampled_from(usual))

    args: list[str] = []
    csv = timing and draw(st.booleans())
    if csv:
        args += ["--period", value("0", "0.001", "0.01")]
    if not timing:
        args.append("--no-timing")
    if draw(st.booleans()):
        args += ["--tool-length", value("0", "50", "80")]
    if draw(st.booleans()):
        args += ["--work-offset", value("0", "-20"), value("0", "35.5"), value("0", "-40", "60")]
    for option, usual in (("--tol", ("0.01", "0.001")), ("--axis-tol", ("0.1", "0.01")), ("--arc-tol", ("0.01",)),
                          ("--units", ("mm", "inch")), ("--max-messages", ("0", "3"))):
        if draw(st.integers(0, 4)) == 0:
            args += [option, value(*usual)]
    return args, draw(st.booleans()), csv


def _check_run(source: str, extra: list[str], report: bool, csv: bool, check: bool = False) -> None:
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        (root / "in").mkdir()
        out = root / "out"
        out.mkdir()
        part = root / "in" / "part.cls"
        part.write_text(source, encoding="utf-8", errors="surrogateescape")
        output = out / ("part.csv" if csv else "part.nc")
        args = ["check", str(part)] if check else [str(part), "-o", str(output)]
        args += [*extra, *(["--report", str(out / "r.json")] if report else []), "--quiet"]
        result = CliRunner().invoke(main, args)
        event(f"exit {result.exit_code}")
        assert result.exception is None or isinstance(result.exception, SystemExit), result.exc_info
        assert result.exit_code in (0, 2, 3), result.stderr
        assert all(line.startswith("verne-post: ") for line in result.stderr.splitlines()), result.stderr
        expected = {0: {output.name} if not check else set(), 3: set()}.get(result.exit_code, set())
        if report and result.exit_code in (0, 3):
            expected.add("r.json")
        assert {p.name for p in out.iterdir()} == expected, (result.exit_code, result.stderr)
        if result.exit_code == 0 and not check and not csv:
            text = output.read_text()
            assert text.startswith("%\n") and text.endswith("%\n") and "nan" not in text.lower()


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program, options(timing=False), st.integers(0, 9))
def test_any_program_without_timing(source: str, choice: tuple[list[str], bool, bool], command: int) -> None:
    _check_run(source, *choice, check=command == 0)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program, options(timing=True))
def test_any_program_with_timing(source: str, choice: tuple[list[str], bool, bool]) -> None:
    _check_run(source, *choice)
