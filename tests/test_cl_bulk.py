"""The reader's bulk route for runs of plain GOTOs must read exactly what the one-record-at-a-time
route reads: the same poses to the bit, the same line numbers, the same warnings and the same
refusals, on random files that mix every case the routes tell apart (3 and 6 numbers, axes off
unit length, huge and non-finite numbers, digits with '_', bad numbers, comments and
continuations between GOTOs, subroutines, runs longer than the lexer's run limit) and on the
real samples."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from verne_post.cl import lexer, read_toolpath, reader
from verne_post.errors import InputError

SAMPLES = Path(__file__).parent / "data" / "cl-samples"


def _read(path: Path, bulk: bool, monkeypatch: pytest.MonkeyPatch) -> object:
    with monkeypatch.context() as patch:
        if not bulk:
            patch.setattr(reader, "_bulk_gotos", lambda st, run: 0)
        try:
            path_ = read_toolpath(path)
        except InputError as error:
            return ("error", str(error))
    return (path_.tip.tobytes(), path_.axis.tobytes(), path_.line.tobytes(), path_.feed.tobytes(),
            path_.rapid.tobytes(), path_.tool.tobytes(), path_.events, tuple(path_.warnings))


def _goto(rng: np.random.Generator) -> str:
    numbers = [f"{v:.4f}" for v in rng.uniform(-500, 500, 3)]
    if rng.random() < 0.5:
        axis = rng.normal(size=3)
        axis *= rng.choice([1.0, 0.995, 1.005]) / np.linalg.norm(axis)  # within the 2 % the reader takes
        numbers += [f"{v:.6f}" for v in axis]
    return "GOTO/" + ",".join(numbers)


#: GOTOs one of the routes must refuse or hand on: 4 or 7 numbers, an axis off unit length,
#: huge or non-finite coordinates, numbers that are not (or are not plainly) numbers.
_FAULTS = ("GOTO/1.0,2.0,3.0,4.0", "GOTO/1,2,3,0,0,1,5", "GOTO/1,2,3,0,0,0.5", "GOTO/1,2,3,0,0,2",
           "GOTO/1,2,3,0,0.989,0", "GOTO/1,2,3,1.011,0,0", "GOTO/3e7,0,0", "GOTO/nan,0,0", "GOTO/inf,0,0,0,0,1",
           "GOTO/1_0,2,3", "GOTO/abc,2,3", "GOTO/,2,3", "GOTO/0x10,2,3", "GOTO/ 7 , 8 ,9", "GOTO/")


def _program(rng: np.random.Generator, gotos: int, fault: bool) -> str:
    lines = ["PARTNO/BULK TEST", "UNITS/MM", "MULTAX/ON", "LOAD/TOOL,1,LENGTH,50", "FEDRAT/MMPM,500.0"]
    for _ in range(gotos):
        r = rng.random()
        if r < 0.01:
            lines.append("$$ a comment between GOTOs")
        elif r < 0.015:
            lines.append("")
        elif r < 0.02:
            lines.append(f"FEDRAT/MMPM,{rng.uniform(100, 2000):.1f}")
        elif r < 0.025:
            lines.append("RAPID")
        elif r < 0.03:
            lines += ["GOTO/1.0,2.0,$", "3.0"]  # a continued GOTO
        else:
            lines.append(_goto(rng))
    if fault:
        lines.insert(int(rng.integers(5, len(lines) + 1)), str(rng.choice(_FAULTS)))
    return "\n".join([*lines, "END-OF-PATH", ""])


@pytest.mark.parametrize("seed", range(8))
def test_bulk_route_reads_what_one_record_at_a_time_reads(tmp_path: Path, seed: int,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(seed)
    path = tmp_path / "bulk.cls"
    path.write_text(_program(rng, int(rng.integers(50, 3000)), fault=False))
    bulk = _read(path, True, monkeypatch)
    assert bulk[0] != "error" and bulk == _read(path, False, monkeypatch)


@pytest.mark.parametrize("fault", range(len(_FAULTS)))
def test_bulk_route_stops_where_one_record_at_a_time_stops(tmp_path: Path, fault: int,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """One GOTO the fast route does not take, amid hundreds it does: the same outcome, poses or refusal."""
    rng = np.random.default_rng(100 + fault)
    text = _program(rng, 600, fault=False).splitlines()
    text.insert(int(rng.integers(100, 500)), _FAULTS[fault])
    path = tmp_path / "fault.cls"
    path.write_text("\n".join(text))
    assert _read(path, True, monkeypatch) == _read(path, False, monkeypatch)


def test_runs_longer_than_the_lexer_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(99)
    gotos = [f"GOTO/{x:.3f},{y:.3f},{z:.3f},0.0,0.0,1.0" for x, y, z in rng.uniform(-100, 100, (3 * lexer._RUN, 3))]
    path = tmp_path / "long.cls"
    path.write_text("\n".join(["UNITS/MM", "MULTAX/ON", "LOAD/TOOL,1,LENGTH,50", "FEDRAT/MMPM,500", *gotos, ""]))
    runs = [item for item in lexer.record_runs(lexer.split_lines(path.read_text())) if isinstance(item, lexer.GotoRun)]
    assert len(runs) == 3 and all(len(run.args) == lexer._RUN for run in runs)
    assert _read(path, True, monkeypatch) == _read(path, False, monkeypatch)


def test_subroutines_keep_their_gotos(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """GOTOs inside DEFSUB are stored, not read, until CALSUB runs them."""
    body = [f"GOTO/{k}.0,0.0,0.0,0.0,0.0,1.0" for k in range(5)]
    path = tmp_path / "sub.cls"
    path.write_text("\n".join(["UNITS/MM", "MULTAX/ON", "LOAD/TOOL,1,LENGTH,50", "FEDRAT/MMPM,500",
                               "DEFSUB/1", *body, "ENDSUB", "GOTO/9.0,9.0,9.0,0.0,0.0,1.0", "CALSUB/1", "CALSUB/1",
                               ""]))
    bulk = _read(path, True, monkeypatch)
    assert bulk == _read(path, False, monkeypatch)
    tip = np.frombuffer(bulk[0]).reshape(-1, 3)
    np.testing.assert_array_equal(tip[:, 0], [9, 0, 1, 2, 3, 4, 0, 1, 2, 3, 4])


def test_records_are_the_runs_flattened() -> None:
    text = "UNITS/MM\nGOTO/1,2,3\n$$ c\nGOTO/4,5,6\nGOTO/1,$\n2,3\nPPRINT/x\nGOTO/7,8,9\n"
    flat = []
    for item in lexer.record_runs(lexer.split_lines(text)):
        flat += list(item.records()) if isinstance(item, lexer.GotoRun) else [item]
    assert flat == list(lexer.records(lexer.split_lines(text)))
    assert [r.line for r in flat] == [1, 2, 4, 5, 7, 8]


@pytest.mark.parametrize("name", sorted(p.name for p in SAMPLES.iterdir() if p.suffix != ".md"))
def test_real_samples_read_alike(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    assert _read(SAMPLES / name, True, monkeypatch) == _read(SAMPLES / name, False, monkeypatch)
