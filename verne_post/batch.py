"""Many CL files at once (``verne-post batch``, :func:`batch`): one output per input, a summary a
CAM pipeline can act on, up-to-date files skipped.

Each file is posted by :func:`post_file`, a function of bytes to bytes: the input, the machine
file and the options go to it, the output and the figures come back, so it runs the same in a
local process pool and on the workers of a Dask cluster, which need not share the client's
file system. The client (:func:`batch`) reads the inputs, hands them to any
``concurrent.futures`` executor, and writes every output atomically as it comes back.

Every output carries ``(BATCH HASH <sha256>)`` in its header: the hash of the input (name and
bytes), the machine file (name and bytes), the options that shape the output and the
verne-post version. With ``skip_unchanged`` a file whose output already records its hash is
not posted again.
"""

from __future__ import annotations

import contextlib
import csv
import glob
import hashlib
import io
import json
import multiprocessing
import os
import re
import tempfile
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, replace
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, Protocol

from .errors import InputError, OutputError, UserError, one_line
from .machine import DEFAULT_MACHINE, load_machine
from .output.atomic import atomic_write, check_writable
from .output.gcode import header_end, with_header_line
from .processes.allocator import keep_freed_memory
from .version import __version__

if TYPE_CHECKING:
    from .options import PostOptions

#: Status of a file in the summary and the exit code the single-file command gives for it.
EXIT_CODES = {"ok": 0, "skipped": 0, "bad-input": 2, "violations": 3, "error": 1}

#: What a folder given as input contributes: its CL files (not recursive). Pose CSVs are named
#: one by one or by a glob, so that other CSV files in the folder are not taken for input.
CL_SUFFIXES = (".cls", ".cl", ".clsf", ".apt", ".aptsource", ".ncl", ".cldata")

#: Summary columns, in order (CSV header and JSON keys).
SUMMARY_COLUMNS = ("file", "status", "exit_code", "message", "line", "cl_points", "blocks", "cycle_time_s", "tools",
                   "seconds", "output", "hash")

_HASH_LINE = re.compile(r"^(?:\(BATCH HASH ([0-9a-f]{64})\)|; BATCH HASH ([0-9a-f]{64}))\s*$")


@dataclass(frozen=True)
class BatchOptions:
    """The pipeline's choices (None: the defaults) and what is written: G-code (verified unless
    ``verify`` is False) or the timed CSV at ``period`` s, t and positions with ``decimals``
    (None: enough for third differences at the period)."""

    post: PostOptions = None  # type: ignore[assignment]  # made PostOptions() at once
    output_format: Literal["gcode", "csv"] = "gcode"
    period: float = 0.001
    verify: bool = True
    report: bool = False  # also return the JSON report of each file (PostResult.report)
    decimals: int | None = None

    def __post_init__(self) -> None:
        if self.post is None:  # the pipeline (and its planner) is imported only where posting happens
            from .options import PostOptions

            object.__setattr__(self, "post", PostOptions())

    @property
    def suffix(self) -> str:
        return ".csv" if self.output_format == "csv" else ".nc"

    def canonical(self) -> str:
        """JSON of every option that shapes the output (not the planner's process count, not
        whether a report is made), keys sorted: the same choices give the same text."""
        post = asdict(self.post)
        del post["workers"]  # the planner gives the same plan with any number of processes
        shaping = {"post": post, "output_format": self.output_format, "period": self.period,
                   "decimals": self.decimals, "verify": self.verify}
        return json.dumps(shaping, sort_keys=True, separators=(",", ":"))


class MachineFile(NamedTuple):
    """A machine file as sent to the workers: its name (the G-code header names it) and bytes."""

    name: str
    data: bytes

    @classmethod
    def read(cls, path: str | os.PathLike[str] | None) -> MachineFile:
        """The file at ``path`` (validated here, so that a bad machine file stops the batch at
        once), or the shipped VERNE."""
        load_machine(path)
        if path is None:
            return cls(DEFAULT_MACHINE, (resources.files("verne_post") / "machines" / DEFAULT_MACHINE).read_bytes())
        return cls(Path(path).name, Path(path).read_bytes())


class Outcome(NamedTuple):
    """What :func:`post_file` sends back: ``figures`` holds ``line`` (of ``message``, in the
    input), ``cl_points``, ``blocks``, ``cycle_time_s``, ``tools`` and ``seconds``."""

    status: str
    message: str
    figures: dict[str, Any]
    output: bytes | None
    report: dict[str, Any] | None


@dataclass(frozen=True)
class BatchResult:
    """One row of the summary: ``message`` is the first error or violation, as
    ``FILE:LINE: reason``, and ``line`` its line in the input; figures are None where they are
    not known (bad input, skipped; the cycle time of a program not written)."""

    file: str
    status: str
    exit_code: int
    message: str = ""
    line: int | None = None
    cl_points: int | None = None
    blocks: int | None = None
    cycle_time_s: float | None = None
    tools: tuple[int, ...] = ()
    seconds: float = 0.0
    output: str | None = None
    hash: str = ""

    def row(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in SUMMARY_COLUMNS}


class StageChannel(Protocol):
    """Where workers report ``(file, stage)`` as a file goes through the pipeline (a queue that
    can be sent to them): a multiprocessing manager's queue, a ``distributed.Queue``."""

    def put(self, item: tuple[str, str]) -> Any: ...


def input_hash(name: str, data: bytes, machine: MachineFile, options: BatchOptions) -> str:
    """sha256 (hex) of the input's name and bytes, the machine file's, the options that shape
    the output and the verne-post version: equal hashes, equal outputs."""
    digest = hashlib.sha256()
    for part in (Path(name).name.encode(), data, machine.name.encode(), machine.data, options.canonical().encode(),
                 __version__.encode()):
        digest.update(len(part).to_bytes(8, "little"))  # length first: no two splits give one stream
        digest.update(part)
    return digest.hexdigest()


def recorded_hash(path: str | os.PathLike[str]) -> str | None:
    """The ``(BATCH HASH ...)`` in the header of the G-code at ``path``, None if there is none."""
    try:
        with open(path, encoding="ascii", errors="replace") as handle:
            for text in handle:
                if header_end(text):  # a header line: %, the program number or a comment
                    if match := _HASH_LINE.match(text):
                        return match.group(1) or match.group(2)
                else:
                    return None
    except OSError:
        return None
    return None


# ----------------------------------------------------------------------------- worker


def post_file(name: str, data: bytes, machine: MachineFile | None, options: BatchOptions,
              stages: StageChannel | None = None) -> Outcome:
    """Post one file given as bytes; pure of the caller's file system (runs on any worker).

    ``name`` is the file as the user named it: messages and the report say it. The input is
    written under its own name in a private folder (the G-code header names it), posted with
    the feed planning in this process, and the output read back with its batch hash. Bad input,
    violations and failures come back as a status and message, never raised.
    """
    from .pipeline import post as post_program
    from .pipeline import postprocess, write_output

    start = time.perf_counter()
    figures: dict[str, Any] = {"line": None, "cl_points": None, "blocks": None, "cycle_time_s": None, "tools": (),
                               "seconds": 0.0}
    with tempfile.TemporaryDirectory(prefix="verne-batch-") as folder, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numpy's warnings on rejected input: the outcome says it all
        (Path(folder) / "in").mkdir()
        source = Path(folder) / "in" / Path(name).name
        source.write_bytes(data)
        machine_path = None
        if machine is not None:
            machine_path = Path(folder) / machine.name
            machine_path.write_bytes(machine.data)

        def named(text: str) -> str:  # the user's names in place of the private folder's
            text = text.replace(str(source), name)
            return text if machine_path is None else text.replace(str(machine_path), machine.name)

        def outcome(status: str, message: str = "", output: bytes | None = None,
                    report: dict[str, Any] | None = None) -> Outcome:
            figures["seconds"] = time.perf_counter() - start
            if report is not None:
                report = {**json.loads(named(json.dumps(report))), "source": name}
            return Outcome(status, one_line(named(message)), figures, output, report)

        try:
            loaded = load_machine(machine_path)
            if loaded.controller.split is not None and options.output_format == "gcode":
                raise InputError("controller.split: tool writes a program as several files; a batch writes one "
                                 "output per input: post such a machine's parts with 'verne-post post'",
                                 machine.name if machine is not None else None)
            post = replace(options.post, workers=1)  # the batch runs files side by side: one process each
            target = Path(folder) / ("out" + options.suffix)

            def progress(stage: str) -> None:
                _report(stages, name, stage)

            if options.output_format == "gcode":  # a part of the program at a time
                result = post_program(source, loaded, post, target, verify=options.verify,
                                      timing_figures=options.report, progress=progress)
                blocks, cycle_time, verification = result.figures.blocks, result.figures.time, result.verification
            else:
                result = postprocess(source, loaded, post, progress=progress)
                blocks, cycle_time = len(result.blocks.joints), float(result.duration.sum())
            figures.update(cl_points=len(result.poses), blocks=blocks,
                           tools=tuple(t.number for t in result.poses.tools))
            report = result.report(loaded, post) if options.report else None
            if result.violations:
                first = result.violations[0]
                figures["line"] = first.line
                count = f" (and {len(result.violations) - 1} more)" if len(result.violations) > 1 else ""
                return outcome("violations", f"{name}:{first.line}: {first.message}{count}", report=report)
            if options.output_format != "gcode":
                verification = write_output(result, loaded, post, target, options.output_format, options.period,
                                            verify=options.verify, decimals=options.decimals)
            if verification is not None and not verification.ok:
                finding = verification.findings[0]
                figures["line"] = finding.cl_line
                where = f"{name}:{finding.cl_line}" if finding.cl_line is not None else name
                return outcome("violations", f"{where}: the program fails its verification at its line "
                                             f"{finding.line}: {finding.message}", report=report)
            output = target.read_bytes()
            figures["cycle_time_s"] = cycle_time  # as the G-code header says
            if options.output_format == "gcode":
                digest = input_hash(name, data, machine or MachineFile.read(None), options)
                output = with_header_line(output.decode("ascii"), f"BATCH HASH {digest}",
                                          loaded.controller.profile()).encode("ascii")
            return outcome("ok", output=output, report=report)
        except UserError as error:
            figures["line"] = error.line
            if isinstance(error, OutputError):  # the worker's own folder: not the user's mistake
                return outcome("error", str(error))
            return outcome("violations" if error.exit_code == 3 else "bad-input", str(error))
        except Exception as error:  # a bug or an exhausted machine: this file fails, the batch goes on
            return outcome("error", f"{name}: internal error: {type(error).__name__}: {error}")


def _report(stages: StageChannel | None, name: str, stage: str) -> None:
    if stages is not None:
        stages.put((name, stage))


# ----------------------------------------------------------------------------- client


def expand_inputs(inputs: Iterable[str | os.PathLike[str]]) -> list[Path]:
    """Files, folders (their CL files, see :data:`CL_SUFFIXES`) and glob patterns, in the order
    given (a folder's and a pattern's sorted by name), each file once. A named file that does
    not exist is kept (the batch records it); a folder without CL files or a pattern that
    matches nothing is an :class:`InputError`."""
    found: list[Path] = []
    for given in map(str, inputs):
        if os.path.isdir(given):
            files = sorted(p for p in Path(given).iterdir() if p.suffix.lower() in CL_SUFFIXES and p.is_file())
            if not files:
                raise InputError(f"no CL files ({' '.join(CL_SUFFIXES)}) in the folder", given)
        elif any(c in given for c in "*?[") and not os.path.exists(given):
            files = sorted(Path(p) for p in glob.glob(given, recursive=True) if os.path.isfile(p))
            if not files:
                raise InputError("the pattern matches no file", given)
        else:
            files = [Path(given)]
        found.extend(files)
    seen: set[str] = set()
    unique = []
    for path in found:
        key = os.path.realpath(path)
        if key not in seen:
            seen.add(key)
            unique.append(path)
    return unique


def output_paths(files: Sequence[Path], output_dir: Path, suffix: str) -> list[Path]:
    """``output_dir/STEM.suffix`` for each input; an :class:`InputError` when two inputs would
    write one output or an output would overwrite an input."""
    outputs = [output_dir / (path.stem + suffix) for path in files]
    owners: dict[str, Path] = {}
    inputs = {os.path.realpath(path) for path in files}
    for path, output in zip(files, outputs, strict=True):
        key = os.path.realpath(output)
        if key in owners:
            raise InputError(f"{owners[key]} and {path} would both write {output}: post them into different folders")
        if key in inputs:
            raise InputError("the output would overwrite an input file", str(output))
        owners[key] = path
    return outputs


def batch(inputs: Iterable[str | os.PathLike[str]], machine: str | os.PathLike[str] | None = None,
          options: BatchOptions | None = None, executor: Executor | None = None, *,
          output_dir: str | os.PathLike[str], skip_unchanged: bool = False, report_each: bool = False,
          jobs: int | None = None, stages: StageChannel | None = None,
          on_done: Callable[[BatchResult], None] | None = None,
          on_stage: Callable[[str, str], None] | None = None) -> list[BatchResult]:
    """Post every input into ``output_dir`` (same stem, ``.nc`` or ``.csv``; with ``report_each``
    a ``.json`` report next to each); one :class:`BatchResult` per input, in input order.

    ``executor``: any ``concurrent.futures`` executor (e.g. a Dask ``Client.get_executor()``);
    None: local processes, ``jobs`` of them (default: the CPU count). A file that fails is
    recorded and the others go on. ``skip_unchanged`` skips a file whose output records the
    hash of this input, machine file and options (G-code only). ``on_done`` is called as each
    file ends; ``on_stage`` with ``(file, stage)`` as workers report to ``stages``.
    Raises :class:`InputError` for mistakes that concern the whole batch (no input, a bad
    machine file, clashing outputs).
    """
    options = options or BatchOptions()
    if options.output_format == "csv" and not options.post.plan:
        raise InputError("a timed CSV needs the time-parametrisation: drop --no-timing")
    if skip_unchanged and options.output_format != "gcode":
        raise InputError("--skip-unchanged needs G-code outputs: a timed CSV has no header to record its hash in")
    if report_each:
        options = replace(options, report=True)
    files = expand_inputs(inputs)
    if not files:
        raise InputError("no input files")
    folder = Path(output_dir)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OutputError(f"cannot make the output folder: {error.strerror or error}", str(folder)) from None
    outputs = output_paths(files, folder, options.suffix)
    check_writable(outputs[0])
    machine_file = MachineFile.read(machine)
    if executor is None:
        with local_executor(jobs) as pool:
            return _run(files, outputs, machine_file, options, pool, (jobs or os.cpu_count() or 1),
                        skip_unchanged, stages, on_done, on_stage)
    return _run(files, outputs, machine_file, options, executor, jobs or 8, skip_unchanged, stages, on_done,
                on_stage)


def _run(files: Sequence[Path], outputs: Sequence[Path], machine: MachineFile, options: BatchOptions,
         executor: Executor, width: int, skip_unchanged: bool, stages: StageChannel | None,
         on_done: Callable[[BatchResult], None] | None, on_stage: Callable[[str, str], None] | None
         ) -> list[BatchResult]:
    """Submit the files, at most two per worker in flight (only those inputs are held in memory),
    and write each output as it comes back."""
    results: dict[int, BatchResult] = {}
    running: dict[Future[Outcome], tuple[int, str]] = {}
    order = iter(range(len(files)))

    def done(k: int, result: BatchResult) -> None:
        results[k] = result
        if on_done is not None:
            on_done(result)

    def submit_more() -> None:
        for k in order:  # resumes where the last call stopped
            name = str(files[k])
            try:
                data = files[k].read_bytes()
            except OSError as error:
                done(k, _failed(name, "bad-input", str(InputError(f"cannot read: {error.strerror or error}", name))))
                continue
            digest = input_hash(name, data, machine, options)
            if skip_unchanged and recorded_hash(outputs[k]) == digest and (
                    not options.report or outputs[k].with_suffix(".json").exists()):
                done(k, BatchResult(name, "skipped", 0, output=str(outputs[k]), hash=digest))
                continue
            running[executor.submit(post_file, name, data, machine, options, stages)] = (k, digest)
            if len(running) >= 2 * width:
                return

    try:
        submit_more()
        while running:
            finished, _ = wait(running, timeout=0.2 if on_stage else None, return_when=FIRST_COMPLETED)
            if on_stage is not None and stages is not None:
                for file, stage in _drain(stages):
                    on_stage(file, stage)
            for future in finished:
                k, digest = running.pop(future)
                done(k, _collect(str(files[k]), future, outputs[k], digest))
            submit_more()
    except BaseException:  # interrupted: what has not started never will
        for future in running:
            future.cancel()
        raise
    return [results[k] for k in range(len(files))]


def _collect(name: str, future: Future[Outcome], output: Path, digest: str) -> BatchResult:
    """The result of a finished file; its output (and report) written atomically."""
    try:
        outcome = future.result()
    except Exception as error:  # the worker died or the cluster lost it
        return _failed(name, "error", f"{name}: the worker failed: {one_line(f'{type(error).__name__}: {error}')}")
    figures = outcome.figures
    result = BatchResult(name, outcome.status, EXIT_CODES[outcome.status], outcome.message, figures["line"],
                         figures["cl_points"], figures["blocks"], figures["cycle_time_s"], tuple(figures["tools"]),
                         figures["seconds"], None, digest)
    try:
        if outcome.report is not None:
            from .output.tables import write_json

            write_json(output.with_suffix(".json"), outcome.report)
        if outcome.output is not None:
            with atomic_write(output, binary=True) as handle:
                handle.write(outcome.output)
            result = replace(result, output=str(output))
    except OutputError as error:
        return replace(result, status="error", exit_code=error.exit_code, message=str(error), line=None)
    return result


def _failed(name: str, status: str, message: str) -> BatchResult:
    return BatchResult(name, status, EXIT_CODES[status], message)


def _drain(stages: Any) -> list[tuple[str, str]]:
    """Every stage report waiting in ``stages`` (a manager queue or a ``distributed.Queue``)."""
    if hasattr(stages, "get_nowait"):
        items = []
        while True:
            try:
                items.append(stages.get_nowait())
            except Exception:  # queue.Empty, or the manager has gone
                return items
    return [tuple(item) for item in stages.get(batch=True)]


def exit_code(results: Iterable[BatchResult]) -> int:
    """0 when every file was posted (or was up to date), 2 when any was bad input, else 3 when
    any could not be posted (violations, or a failure)."""
    statuses = {r.status for r in results}
    if "bad-input" in statuses:
        return 2
    return 3 if statuses & {"violations", "error"} else 0


def write_summary(path: str | os.PathLike[str], results: Sequence[BatchResult]) -> None:
    """The summary, atomically: CSV (:data:`SUMMARY_COLUMNS`, tools separated by spaces, empty
    where a figure is unknown), or JSON when ``path`` ends in ``.json`` (``files``: one object
    per input with the same keys; ``exit_code`` and ``counts`` per status)."""
    if str(path).lower().endswith(".json"):
        counts = {status: sum(r.status == status for r in results) for status in EXIT_CODES}
        text = json.dumps({"verne_post": __version__, "exit_code": exit_code(results), "counts": counts,
                           "files": [r.row() for r in results]}, indent=2) + "\n"
    else:
        buffer = io.StringIO(newline="")
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(SUMMARY_COLUMNS)
        for r in results:
            row = r.row()
            row["tools"] = " ".join(map(str, r.tools))
            row["seconds"] = f"{r.seconds:.3f}"
            if r.cycle_time_s is not None:
                row["cycle_time_s"] = f"{r.cycle_time_s:.3f}"
            writer.writerow(["" if row[c] is None else row[c] for c in SUMMARY_COLUMNS])
        text = buffer.getvalue()
    with atomic_write(path, binary=True) as handle:
        handle.write(text.encode("utf-8"))


# ----------------------------------------------------------------------------- executors


def local_executor(jobs: int | None = None) -> ProcessPoolExecutor:
    """A pool of ``jobs`` local processes (default: the CPU count), started clean (forkserver,
    with verne-post loaded once) rather than forked from a client that may run threads."""
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    if "forkserver" in methods:
        context.set_forkserver_preload(["verne_post.batch", "verne_post.pipeline"])
    # The workers are verne-post's own processes: they keep freed memory as the command does.
    return ProcessPoolExecutor(max_workers=jobs or os.cpu_count() or 1, mp_context=context,
                               initializer=keep_freed_memory)


@contextlib.contextmanager
def dask_client(scheduler: str, jobs: int | None = None) -> Iterator[Any]:
    """A Dask ``distributed.Client``, closed at the end: to the scheduler at ``scheduler``
    (``tcp://HOST:PORT``), or with ``"dask"`` to a local cluster of ``jobs`` (default: the CPU
    count) one-thread worker processes. Its ``get_executor()`` is what :func:`batch` takes."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("--scheduler needs Dask: pip install 'verne-post[dask]'") from None
    with contextlib.ExitStack() as stack:
        if scheduler == "dask":
            # preload: the workers keep freed memory, as the local processes do (twice as fast)
            cluster = stack.enter_context(LocalCluster(n_workers=jobs or os.cpu_count() or 1, threads_per_worker=1,
                                                       processes=True, dashboard_address=None,
                                                       preload=["verne_post.processes.allocator"]))
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout="20s"))
            except OSError as error:
                raise InputError(f"cannot reach the Dask scheduler: {error}", scheduler) from None
        yield client


@contextlib.contextmanager
def open_executor(scheduler: str | None = None, jobs: int | None = None, stages: bool = False
                  ) -> Iterator[tuple[Executor, int, StageChannel | None]]:
    """(executor, its number of workers, a stage channel when ``stages``): local processes, or
    with ``scheduler`` a Dask cluster (see :func:`dask_client`); all closed at the end."""
    with contextlib.ExitStack() as stack:
        if scheduler is None:
            executor = stack.enter_context(local_executor(jobs))
            width = jobs or os.cpu_count() or 1
            channel = stack.enter_context(multiprocessing.Manager()).Queue() if stages else None
        else:
            client = stack.enter_context(dask_client(scheduler, jobs))
            from distributed import Queue  # present: dask_client says how to install it otherwise

            executor = stack.enter_context(client.get_executor(pure=False))
            width = max(1, sum(client.nthreads().values()))
            channel = Queue(client=client) if stages else None
        yield executor, width, channel

