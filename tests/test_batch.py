"""verne-post batch: many files through local processes and a real Dask LocalCluster.

The reference for every output is the single-file command (``verne-post post``) run on the same
file: a batch output must be that file plus its one ``(BATCH HASH ...)`` header line. Bad input
and violations are put at lines chosen here, so the expected file and line come from the test.
"""

from __future__ import annotations

import csv
import importlib
import json
import os
import re
import shutil
import sys
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

import verne_post as vp
from verne_post.batch import (
    SUMMARY_COLUMNS,
    BatchOptions,
    MachineFile,
    expand_inputs,
    input_hash,
    post_file,
    recorded_hash,
)
from verne_post.cli import main
from verne_post.pipeline import PostOptions

ROOT = Path(__file__).parent.parent
SWARF = ROOT / "examples" / "nx_swarf_inch_crlf.cls"
TOOL_LENGTH = 60.0  # mm, for the CSV pose files (they name no tool)
OPTIONS = BatchOptions(PostOptions(tool_length=TOOL_LENGTH))
BAD_LINE = 3  # line of the malformed record in b_bad.cls
FAR_LINE = 11  # line of the unreachable pose in d_far.csv
HASH_LINE = re.compile(r"^\(BATCH HASH ([0-9a-f]{64})\)\n", re.MULTILINE)


def _poses(far_at: int | None = None) -> str:
    """A 40-pose CSV along x at z 30 mm, tool tilted 11.5 deg (reachable); with ``far_at`` an
    unreachable pose (x 3000 mm) on that file line."""
    rows = [f"{x:.3f},5.000,30.000,0.2,0.0,0.98,1500" for x in np.linspace(-20.0, 20.0, 40)]
    if far_at is not None:
        rows.insert(far_at - 2, "3000.000,5.000,30.000,0.2,0.0,0.98,1500")
    return "x,y,z,i,j,k,feed\n" + "\n".join(rows) + "\n"


def _parts(folder: Path) -> list[Path]:
    """a ok, b bad input (line 3), c ok (a real NX file), d violations (line 11): sorted by name."""
    folder.mkdir()
    (folder / "a_line.csv").write_text(_poses())
    (folder / "b_bad.cls").write_text("PARTNO/BAD\nUNITS/MM\nGOTO/1.0,2.0\nFINI\n")
    shutil.copy(SWARF, folder / "c_swarf.cls")
    (folder / "d_far.csv").write_text(_poses(FAR_LINE))
    return sorted(folder.iterdir())


def _single(path: Path, out: Path) -> bytes:
    """What 'verne-post post' writes for ``path`` (the reference)."""
    result = CliRunner().invoke(main, ["post", str(path), "-o", str(out), "--tool-length", str(TOOL_LENGTH), "-q"])
    assert result.exit_code == 0, result.output
    return out.read_bytes()


def _batch_cli(*args: str) -> Any:
    return CliRunner().invoke(main, ["batch", *args, "--tool-length", str(TOOL_LENGTH), "-q"])


@pytest.fixture(scope="module")
def local_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], Path, list[vp.BatchResult]]:
    """The four parts through the local process pool, 2 workers."""
    root = tmp_path_factory.mktemp("local")
    files = _parts(root / "parts")
    results = vp.batch([str(root / "parts" / "*")], None, OPTIONS, output_dir=root / "out", jobs=2)
    return files, root / "out", results


def test_outputs_are_the_single_file_programs_plus_their_hash(local_run: Any, tmp_path: Path) -> None:
    files, out, results = local_run
    assert [r.file for r in results] == [str(f) for f in files]
    for path, r in zip(files, results, strict=True):
        if r.status != "ok":
            continue
        written = Path(r.output).read_bytes().decode()
        assert Path(r.output) == out / (path.stem + ".nc")
        hashes = HASH_LINE.findall(written)
        assert hashes == [r.hash]
        assert HASH_LINE.sub("", written).encode() == _single(path, tmp_path / (path.stem + ".nc"))
        assert written.index("(BATCH HASH") < written.index("G21 G90")  # in the header


def test_a_failing_file_in_the_middle_does_not_stop_the_others(local_run: Any) -> None:
    files, out, results = local_run
    rows = {Path(r.file).name: r for r in results}
    assert [rows[n].status for n in ("a_line.csv", "b_bad.cls", "c_swarf.cls", "d_far.csv")] == [
        "ok", "bad-input", "ok", "violations"]
    bad, far = rows["b_bad.cls"], rows["d_far.csv"]
    assert (bad.exit_code, bad.line) == (2, BAD_LINE)
    assert bad.message.startswith(f"{files[1]}:{BAD_LINE}: ")  # the user's file, not the worker's copy
    assert (far.exit_code, far.line) == (3, FAR_LINE)
    assert far.message.startswith(f"{files[3]}:{FAR_LINE}: ")
    assert bad.output is None and far.output is None
    assert sorted(p.name for p in out.iterdir()) == ["a_line.nc", "c_swarf.nc"]  # nothing for the failures


def test_figures_are_those_of_the_program(local_run: Any) -> None:
    _, _, results = local_run
    for r in results:
        if r.status != "ok":
            assert r.cycle_time_s is None  # no program, no cycle time
            assert r.blocks is None if r.status == "bad-input" else r.blocks > 0
            continue
        text = Path(r.output).read_text()
        motion = re.findall(r"^G[01] X", text, re.MULTILINE)
        assert r.blocks == len(motion)
        assert r.tools == tuple(int(t) for t in re.findall(r"^\(TOOL (\d+) LENGTH", text, re.MULTILINE))
        feeds = re.findall(r"^G1 .* F(\S+)$", text, re.MULTILINE)
        # each inverse-time F is the planned 60 / duration rounded to its last decimal: the time it
        # implies may be off the planned one by up to half that decimal's worth
        rounding = sum(30.0 * 10.0 ** -len(f.partition(".")[2]) / float(f) ** 2 for f in feeds)
        assert r.cycle_time_s >= sum(60.0 / float(f) for f in feeds) - rounding
        assert r.seconds > 0
    assert {Path(r.file).name: r.cl_points for r in results}["a_line.csv"] == 40


def test_summary_csv_and_json_columns(tmp_path: Path) -> None:
    files = _parts(tmp_path / "parts")
    result = _batch_cli(str(files[0]), str(files[1]), "-o", str(tmp_path / "out"), "--jobs", "1",
                        "--summary", str(tmp_path / "s.csv"))
    assert result.exit_code == 2  # a bad input among them
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"verne-post: error: {files[1]}:{BAD_LINE}: ")
    with open(tmp_path / "s.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == ("file", "status", "exit_code", "message", "line", "cl_points", "blocks", "cycle_time_s",
                              "tools", "seconds", "output", "hash")
    assert [(r["file"], r["status"], r["exit_code"], r["line"]) for r in rows] == [
        (str(files[0]), "ok", "0", ""), (str(files[1]), "bad-input", "2", str(BAD_LINE))]
    assert rows[0]["output"] == str(tmp_path / "out" / "a_line.nc") and rows[1]["output"] == ""
    assert rows[0]["hash"] == recorded_hash(tmp_path / "out" / "a_line.nc")
    assert float(rows[0]["cycle_time_s"]) > 0 and int(rows[0]["blocks"]) >= 40

    result = _batch_cli(str(files[0]), str(files[3]), "-o", str(tmp_path / "out"), "--summary",
                        str(tmp_path / "s.json"))
    assert result.exit_code == 3  # violations, no bad input
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["exit_code"] == 3 and summary["counts"]["ok"] == 1 and summary["counts"]["violations"] == 1
    assert [tuple(row) for row in summary["files"]] == [SUMMARY_COLUMNS] * 2
    assert summary["files"][1]["line"] == FAR_LINE and summary["files"][1]["tools"] == [0]


def test_summary_inside_the_output_folder_the_batch_makes(tmp_path: Path) -> None:
    """OUT does not exist yet: the batch makes it, and the summary goes into it; a summary in a
    folder nobody makes is still refused before any file is posted."""
    files = _parts(tmp_path / "parts")
    out = tmp_path / "new" / "out"
    result = _batch_cli(str(files[0]), "-o", str(out), "--jobs", "1", "--summary", str(out / "summary.csv"))
    assert result.exit_code == 0, result.stderr
    with open(out / "summary.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["file"], r["status"]) for r in rows] == [(str(files[0]), "ok")]
    assert (out / "a_line.nc").is_file()

    other = tmp_path / "other"
    result = _batch_cli(str(files[0]), "-o", str(other), "--summary", str(tmp_path / "nowhere" / "s.csv"))
    assert result.exit_code != 0 and "does not exist" in result.stderr and not other.exists()


def test_skip_unchanged_really_skips(tmp_path: Path) -> None:
    files = _parts(tmp_path / "parts")
    machine = tmp_path / "verne.yaml"
    shutil.copy(ROOT / "machines" / "verne.yaml", machine)
    out = tmp_path / "out"
    args = [str(files[0]), str(files[2]), str(files[1]), "-o", str(out), "--machine", str(machine),
            "--skip-unchanged", "--summary", str(tmp_path / "s.json")]

    def run(*extra: str) -> dict[str, str]:
        result = _batch_cli(*args, *extra)
        assert result.exit_code == 2, result.output  # b_bad.cls each time: a failure is never skipped
        return {Path(r["file"]).name: r["status"] for r in json.loads((tmp_path / "s.json").read_text())["files"]}

    def stamps() -> dict[str, tuple[int, int]]:
        return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in out.iterdir()}

    assert run() == {"a_line.csv": "ok", "c_swarf.cls": "ok", "b_bad.cls": "bad-input"}
    before = stamps()
    assert run() == {"a_line.csv": "skipped", "c_swarf.cls": "skipped", "b_bad.cls": "bad-input"}
    assert stamps() == before  # not rewritten: same file, same time

    with open(files[0], "a") as handle:  # the input changes
        handle.write("# one more comment line\n")
    assert run() == {"a_line.csv": "ok", "c_swarf.cls": "skipped", "b_bad.cls": "bad-input"}
    assert stamps()["c_swarf.nc"] == before["c_swarf.nc"] and stamps()["a_line.nc"] != before["a_line.nc"]

    with open(machine, "a") as handle:  # the machine file changes: every file again
        handle.write("# re-measured\n")
    assert run() == {"a_line.csv": "ok", "c_swarf.cls": "ok", "b_bad.cls": "bad-input"}
    assert run("--tol", "0.004") == {"a_line.csv": "ok", "c_swarf.cls": "ok", "b_bad.cls": "bad-input"}
    assert run("--tol", "0.004") == {"a_line.csv": "skipped", "c_swarf.cls": "skipped", "b_bad.cls": "bad-input"}


def test_the_hash_covers_input_machine_options_and_version(monkeypatch: pytest.MonkeyPatch) -> None:
    machine = MachineFile.read(None)
    data = SWARF.read_bytes()
    base = input_hash("part.cls", data, machine, OPTIONS)
    assert base == input_hash("elsewhere/part.cls", data, machine, replace(OPTIONS, report=True))
    assert base == input_hash("part.cls", data, machine, replace(OPTIONS, post=replace(OPTIONS.post, workers=7)))
    changed = [
        input_hash("part.cls", data + b"\n", machine, OPTIONS),
        input_hash("other.cls", data, machine, OPTIONS),  # the header names the input
        input_hash("part.cls", data, machine._replace(data=machine.data + b"#\n"), OPTIONS),
        input_hash("part.cls", data, machine._replace(name="other.yaml"), OPTIONS),
        input_hash("part.cls", data, machine, replace(OPTIONS, post=replace(OPTIONS.post, axis_tol=0.04))),
        input_hash("part.cls", data, machine, replace(OPTIONS, post=replace(OPTIONS.post, plan=False))),
        input_hash("part.cls", data, machine, replace(OPTIONS, verify=False)),
        input_hash("part.cls", data, machine, replace(OPTIONS, output_format="csv")),
    ]
    monkeypatch.setattr(sys.modules["verne_post.batch"], "__version__", "9.9.9")  # the module, not vp.batch
    changed.append(input_hash("part.cls", data, machine, OPTIONS))
    assert len({base, *changed}) == len(changed) + 1


def test_report_each_names_the_users_file(tmp_path: Path) -> None:
    files = _parts(tmp_path / "parts")
    result = _batch_cli(str(files[2]), str(files[3]), "-o", str(tmp_path / "out"), "--report-each", "--jobs", "1")
    assert result.exit_code == 3
    ok = json.loads((tmp_path / "out" / "c_swarf.json").read_text())
    far = json.loads((tmp_path / "out" / "d_far.json").read_text())  # a report for the violations too
    assert ok["source"] == str(files[2]) and ok["ok"] and ok["points"]["blocks"] > 0
    assert far["source"] == str(files[3]) and far["violations"][0]["line"] == FAR_LINE
    assert "verne-batch-" not in json.dumps(ok) + json.dumps(far)  # no trace of the worker's folder


def test_timed_csv_outputs(tmp_path: Path) -> None:
    result = _batch_cli(str(SWARF), "-o", str(tmp_path / "out"), "--format", "csv", "--period", "0")
    assert result.exit_code == 0, result.output
    single = CliRunner().invoke(main, ["post", str(SWARF), "-o", str(tmp_path / "single.csv"), "--period", "0", "-q"])
    assert single.exit_code == 0
    assert (tmp_path / "out" / "nx_swarf_inch_crlf.csv").read_bytes() == (tmp_path / "single.csv").read_bytes()
    skip = _batch_cli(str(SWARF), "-o", str(tmp_path / "out"), "--format", "csv", "--skip-unchanged")
    assert skip.exit_code == 2 and "--skip-unchanged needs G-code outputs" in skip.stderr


@pytest.mark.parametrize("case", ["same stem", "no file", "output over input"])
def test_batch_wide_mistakes_are_one_line_and_write_nothing(tmp_path: Path, case: str) -> None:
    (tmp_path / "x").mkdir()
    (tmp_path / "y").mkdir()
    (tmp_path / "x" / "p.cls").write_bytes(SWARF.read_bytes())
    (tmp_path / "y" / "p.cls").write_bytes(SWARF.read_bytes())
    args = {"same stem": [str(tmp_path / "x"), str(tmp_path / "y"), "-o", str(tmp_path / "out")],
            "no file": [str(tmp_path / "x" / "*.apt"), "-o", str(tmp_path / "out")],
            "output over input": [str(tmp_path / "x"), "-o", str(tmp_path / "x"), "--format", "csv"]}[case]
    if case == "output over input":
        (tmp_path / "x" / "p.csv").write_text(_poses())
        args[0] = str(tmp_path / "x" / "p.csv")
    result = _batch_cli(*args)
    assert result.exit_code == 2
    assert len(result.stderr.splitlines()) == 1 and result.stderr.startswith("verne-post: error: ")
    assert "Traceback" not in result.output
    assert not list((tmp_path / "out").glob("*")) if (tmp_path / "out").exists() else True
    if case == "output over input":
        assert (tmp_path / "x" / "p.csv").read_text() == _poses()


def test_a_folder_gives_its_cl_files(tmp_path: Path) -> None:
    files = _parts(tmp_path / "parts")
    (tmp_path / "parts" / "notes.txt").write_text("not a CL file")
    assert expand_inputs([tmp_path / "parts", files[0], files[1]]) == [files[1], files[2], files[0]]


class _LosingExecutor(Executor):
    """Runs files in a thread, but loses the worker of one file (as a killed process would)."""

    def __init__(self, lose: str) -> None:
        self.lose, self.pool = lose, ThreadPoolExecutor(1)

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> Future[Any]:
        if Path(args[0]).name == self.lose:
            future: Future[Any] = Future()
            future.set_exception(BrokenProcessPool("a worker died"))
            return future
        return self.pool.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, **kwargs: Any) -> None:
        self.pool.shutdown(wait)


def test_a_lost_worker_is_an_error_row_and_the_batch_goes_on(tmp_path: Path) -> None:
    files = _parts(tmp_path / "parts")
    with _LosingExecutor("a_line.csv") as executor:
        results = vp.batch([files[0], files[2]], None, OPTIONS, executor, output_dir=tmp_path / "out")
    assert [(r.status, r.exit_code) for r in results] == [("error", 1), ("ok", 0)]
    assert results[0].message.startswith(f"{files[0]}: the worker failed: BrokenProcessPool")
    assert vp.batch.__module__ == "verne_post.batch"
    from verne_post.batch import exit_code

    assert exit_code(results) == 3


def test_the_worker_reads_nothing_but_its_arguments(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """post_file gets bytes and returns bytes: it runs where the input's path does not exist."""
    monkeypatch.chdir(tmp_path)
    outcome = post_file("/nowhere/on/this/worker/c_swarf.cls", SWARF.read_bytes(), MachineFile.read(None), OPTIONS)
    assert outcome.status == "ok" and outcome.message == ""
    assert b"(SOURCE c_swarf.cls)" in outcome.output
    assert list(tmp_path.iterdir()) == []


def test_without_dask_the_scheduler_option_says_how_to_install_it(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed raises ImportError
    result = _batch_cli(str(SWARF), "-o", str(tmp_path / "out"), "--scheduler", "dask")
    assert result.exit_code == 2
    assert result.stderr == "verne-post: error: --scheduler needs Dask: pip install 'verne-post[dask]'\n"


# ----------------------------------------------------------------------------- Dask


def test_the_local_dask_cluster_of_the_command_keeps_freed_memory() -> None:
    """``--scheduler dask`` starts its workers with verne_post.allocator preloaded: malloc keeps
    freed memory there as in the local processes (a worker's task thread gave it back at once:
    twice the time per file)."""
    import platform

    from verne_post.batch import dask_client

    glibc = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"
    with dask_client("dask", 1) as client:
        kept = client.run(lambda: importlib.import_module("verne_post.allocator").kept)
    assert list(kept.values()) == [glibc]


@pytest.fixture(scope="module")
def cluster() -> Any:
    distributed = pytest.importorskip("distributed")  # in the test extra: present wherever the tests run
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  host="127.0.0.1") as local:
        yield local


def test_dask_local_cluster_outputs_are_byte_identical(local_run: Any, cluster: Any, tmp_path: Path) -> None:
    from distributed import Client

    files, local_out, local_results = local_run
    with Client(cluster) as client, client.get_executor(pure=False) as executor:
        results = vp.batch(files, None, OPTIONS, executor, output_dir=tmp_path / "dask")
        workers = {w["host"] for w in client.scheduler_info()["workers"].values()}
    assert workers == {"127.0.0.1"}
    assert sorted(p.name for p in (tmp_path / "dask").iterdir()) == sorted(p.name for p in local_out.iterdir())
    for name in os.listdir(local_out):
        assert (tmp_path / "dask" / name).read_bytes() == (local_out / name).read_bytes()

    def same(r: vp.BatchResult) -> tuple[Any, ...]:  # all but the time spent and where it was written
        return (r.file, r.status, r.exit_code, r.message, r.line, r.cl_points, r.blocks, r.cycle_time_s, r.tools,
                r.hash)

    assert [same(r) for r in results] == [same(r) for r in local_results]


def test_dask_scheduler_address_from_the_command_line(cluster: Any, tmp_path: Path) -> None:
    files = _parts(tmp_path / "parts")
    result = _batch_cli(str(files[0]), str(files[1]), "-o", str(tmp_path / "out"), "--scheduler",
                        cluster.scheduler_address, "--summary", str(tmp_path / "s.csv"))
    assert result.exit_code == 2
    with open(tmp_path / "s.csv", newline="") as handle:
        assert [r["status"] for r in csv.DictReader(handle)] == ["ok", "bad-input"]
    assert (tmp_path / "out" / "a_line.nc").read_bytes().replace(
        f"(BATCH HASH {recorded_hash(tmp_path / 'out' / 'a_line.nc')})\n".encode(), b""
    ) == _single(files[0], tmp_path / "single.nc")
