"""Fuzzing the whole pipeline through the command line: mutated real CL files and machine files.

    python -m benchmarks.fuzz [--cases 100000] [--seconds S] [--seed 0] [--timeout 30] [--save DIR]
    python -m benchmarks.fuzz --case K [--seed 0]      # run one case again and show what it did
    python -m benchmarks.fuzz --reader --cases 1000000 # the CL reader alone (read_toolpath), ~1 ms a case

Seeds: the CL files of tests/data (with the real CAM samples of tests/data/cl-samples) and
examples/, and machines/verne.yaml. Each case takes a window of a seed's lines, applies a few
mutations (numbers replaced by NaN, infinities, huge or malformed values or gently scaled, lines
deleted, repeated, swapped or spliced from another file, record words changed, control bytes,
truncation, line endings), or mutates the machine file instead, picks options (some absurd), and
calls the CLI's ``main`` in this process, catching ``SystemExit``. Outcomes:

- ok: exit 0 and the output written; bad input: exit 2; violations: exit 3;
- crash: any other exception or exit code, or stderr that is not one ``verne-post: ...`` line
  per message (a traceback, a multi-line message);
- hang: the case ran over ``--timeout`` seconds;
- stray file: any file left in the output folder other than the output (and the report) that
  run should leave; a run that says ok without its output counts here too.

With ``--reader`` each case is a mutated CL file only, read by ``read_toolpath`` in this process with
random reading options: ok (read), bad input (an InputError), violations (a CheckError: a program
for another machine), crash (any other exception, or an error message that is not one line).

Done means 0 crash, 0 hang, 0 stray file. Feed planning runs in this process (one worker) so
that a timeout interrupts it; the address space is limited (``--memory-gb``) so that a runaway
allocation is a crash here instead of the machine's OOM killer. Failing cases are saved under
``--save`` (input files, command line, traceback) to be run again with ``--case``.
"""

from __future__ import annotations

import argparse
import atexit
import bisect
import contextlib
import io
import os
import random
import re
import resource
import shutil
import signal
import sys
import tempfile
import time
import traceback
import unicodedata
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CL_SEEDS = sorted([*ROOT.glob("tests/data/*.cls"), *(p for p in (ROOT / "tests/data/cl-samples").iterdir()
                                                     if p.suffix != ".md"), *ROOT.glob("examples/*.cls")])
MACHINE_SEED = ROOT / "machines" / "verne.yaml"
OUTCOMES = ("ok", "bad input", "violations", "crash", "hang", "stray file")

NUMBER = re.compile(rb"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")  # not inside a word (D1, EM16)
SPECIAL_NUMBERS = [b"nan", b"NaN", b"-nan", b"inf", b"-inf", b"INF", b"infinity", b"1e308", b"1e309", b"-1.8e308",
                   b"0", b"-0", b"0.0", b"1e-320", b"4.9e-324", b"9" * 400, b"", b"1e", b".", b"-", b"+.5e-3", b"0x1F",
                   b"1_000", b"1,5", b"1e+", b"--1", b"2147483648", b"-9223372036854775809", b"1e-7", b"1e7"]
RECORD_WORDS = [b"GOTO", b"RAPID", b"FEDRAT", b"CIRCLE", b"CYCLE", b"LOAD", b"TLDATA", b"UNITS", b"MULTAX", b"MSYS",
                b"CSYS", b"SPINDL", b"FROM", b"GOHOME", b"INSERT", b"PPRINT", b"$$", b"END", b"FINI", b"TLAXIS",
                b"GODLTA", b"LOADTL", b"CUTTER", b"SELECT", b"STOP", b"OPSTOP", b"COOLNT", b"PARTNO", b"TOOL PATH",
                b"END-OF-PATH", b"CUTCOM", b"PAINT"]
JUNK = [b"\x00", b"\xff", b"\xfe\xff", b"\xef\xbb\xbf", b"\x1b[2J", b"\r", b"\x0b", b"\x0c", b"\x85",
        "\u2028".encode(), "\u202e".encode(), "é".encode(), b"\t", b"$", b"/", b",", b"(", b")", b"'", b'"', b"%"]


class Hang(BaseException):
    """Raised by the per-case timer (a BaseException: no ``except Exception`` swallows it)."""


@dataclass
class Case:
    number: int
    files: dict[str, bytes]  # name in the input folder -> content
    args: list[str]  # with {in} and {out} for the folders
    expected: dict[int, set[str]]  # exit code -> files the output folder may hold


# ------------------------------------------------------------------------------------- mutations


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def _mutate_number(line: bytes, rng: random.Random, gentle: bool) -> bytes:
    found = list(NUMBER.finditer(line))
    if not found:
        return line
    match = rng.choice(found)
    if gentle:
        try:
            value = float(match.group()) * rng.choice([rng.uniform(0.5, 2.0), rng.uniform(0.05, 20.0),
                                                        1 + rng.gauss(0, 0.05), -1.0])
        except ValueError:
            value = 0.0
        new = f"{value:.6g}".encode()
    else:
        new = rng.choice(SPECIAL_NUMBERS)
    return line[:match.start()] + new + line[match.end():]


def mutate_lines(lines: list[bytes], rng: random.Random, donors: list[list[bytes]], gentle_share: float
                 ) -> list[bytes]:
    """One random mutation of a file's lines (a new list)."""
    lines = list(lines)
    k = rng.randrange(len(lines))
    kind = rng.randrange(14)
    if kind == 0 and len(lines) > 1:
        del lines[k]
    elif kind == 1:
        lines.insert(k, lines[k])
    elif kind == 2:
        j = rng.randrange(len(lines))
        lines[k], lines[j] = lines[j], lines[k]
    elif kind in (3, 4, 5):
        lines[k] = _mutate_number(lines[k], rng, gentle=rng.random() < gentle_share)
    elif kind == 6:
        at = rng.randrange(len(lines[k]) + 1)
        lines[k] = lines[k][:at] + rng.choice(JUNK) * rng.choice([1, 1, 2, 50]) + lines[k][at:]
    elif kind == 7:
        data = b"".join(lines)
        return _lines(data[:rng.randrange(len(data) + 1)])
    elif kind == 8:
        ending = rng.choice([b"\r\n", b"\r", b"\n\n", b""])
        return [line.rstrip(b"\r\n") + ending for line in lines]
    elif kind == 9:
        word = rng.choice(RECORD_WORDS)
        lines[k] = re.sub(rb"^\s*[A-Z$][A-Z $-]*", word, lines[k], count=1) if rng.random() < 0.7 else \
            word + b"/" + b",".join(rng.choice([*SPECIAL_NUMBERS, b"1", b"0", b"ON", b"OFF", b"MM"])
                                   for _ in range(rng.randrange(12))) + b"\n"
    elif kind == 10:
        donor = rng.choice(donors)
        start = rng.randrange(len(donor))
        lines[k:k] = donor[start:start + rng.randint(1, 20)]
    elif kind == 11:
        lines[k] = lines[k].rstrip(b"\r\n") + rng.choice([b",$", b" $", b"$$", b"$"]) + b"\n"
    elif kind == 12:
        found = list(NUMBER.finditer(lines[k]))
        token = rng.choice(found).group() if found else b"X"
        lines[k] = lines[k].rstrip(b"\r\n") + b"," + b",".join([token] * rng.choice([10, 100, 3000])) + b"\n"
    else:
        at = rng.randrange(len(lines[k]) + 1)
        lines[k] = lines[k][:at] + bytes([rng.randrange(256)]) + lines[k][at + 1:]
    return lines


# ------------------------------------------------------------------------------------- cases


_SEED_CACHE: dict[Path, list[bytes]] = {}


def _seed(path: Path) -> list[bytes]:
    if path not in _SEED_CACHE:
        _SEED_CACHE[path] = _lines(path.read_bytes())
    return _SEED_CACHE[path]


CONTEXT = re.compile(rb"^\s*(UNITS|MULTAX|TLDATA|LOAD|LOADTL|SELECT|CUTTER|FEDRAT|SPINDL|MSYS|CSYS|FROM)\b")


def _window(lines: list[bytes], rng: random.Random) -> list[bytes]:
    """A small piece of a seed: a run of lines from anywhere, mostly with the records in force
    there (the last UNITS, tool, FEDRAT, frame... before it) so that it gets past the reader."""
    start = rng.randrange(len(lines))
    piece = lines[start:start + rng.randint(3, 60)]
    if rng.random() < 0.15:
        return piece
    if id(lines) not in _CONTEXT_CACHE:  # the seeds' context records, found once
        found: dict[bytes, list[int]] = {}
        for k, line in enumerate(lines):
            match = CONTEXT.match(line)
            if match:
                found.setdefault(match.group(1), []).append(k)
        _CONTEXT_CACHE[id(lines)] = found
    last = [at[bisect.bisect_left(at, start) - 1] for at in _CONTEXT_CACHE[id(lines)].values() if at[0] < start]
    return [lines[k] for k in sorted(last)] + piece


_CONTEXT_CACHE: dict[int, dict[bytes, list[int]]] = {}  # id of a cached seed's lines -> record -> its lines


def _value(rng: random.Random, usual: list[str], weird: list[str], absurd: bool) -> str:
    return rng.choice(weird) if absurd and rng.random() < 0.5 else rng.choice(usual)


WEIRD = ["nan", "inf", "-1", "0", "1e999", "1e-300", "abc", "", "1e6"]


def make_reader_case(seed: int, number: int) -> Case:
    """A mutated window of a CL seed, and the reading options (``read_toolpath`` keywords as
    ``name=value`` arguments) of a reader case."""
    rng = random.Random(f"reader:{seed}:{number}")
    donors = [_seed(p) for p in CL_SEEDS]
    source = rng.choice(CL_SEEDS)
    lines = _window(_seed(source), rng)
    for _ in range(rng.choice([0, 1, 1, 2, 3, 5])):
        lines = mutate_lines(lines, rng, donors, gentle_share=0.4)
    part = f"part{source.suffix if rng.random() < 0.95 else rng.choice(['.csv', '.txt', ''])}"
    args = [part]
    for option, values in (("units", ["mm", "inch"]), ("arc_direction", ["cw", "ccw"]),
                           ("frame", ["local", "world", "apply"]), ("chordal_tolerance", ["0.001", "0.01", "1e-6"]),
                           ("feed", ["100", "1000"])):
        if rng.random() < 0.1:
            args.append(f"{option}={rng.choice(values)}")
    return Case(number, {part: b"".join(lines)}, args, {})


def run_reader_case(case: Case, timeout: float, keep: Path | None = None) -> Result:
    """Read the case's CL file with its options; an error must be a UserError of one printable line."""
    from verne_post.cl import read_toolpath
    from verne_post.errors import CheckError, UserError

    work = _READER_FOLDER
    [(name, data)] = case.files.items()
    (work / name).write_bytes(data)
    options: dict[str, object] = {}
    for arg in case.args[1:]:
        key, value = arg.split("=")
        options[key] = float(value) if key in ("chordal_tolerance", "feed") else value
    result = Result("ok")
    signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        read_toolpath(work / name, **options)
    except Hang:
        result = Result("hang", f"over {timeout} s")
    except UserError as error:
        text = str(error)
        outcome = "violations" if isinstance(error, CheckError) else "bad input"
        one_line = not any(unicodedata.category(ch) in ("Cc", "Zl", "Zp", "Cf", "Cs", "Co", "Cn") for ch in text)
        result = Result(outcome, text) if one_line else Result("crash", text, "message format")
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # counting every crash is the point
        result = _crash(exc)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    if keep is not None and result.outcome in ("crash", "hang"):
        _save(case, result, keep, "")
    (work / name).unlink()
    return result


_READER_FOLDER = Path(tempfile.mkdtemp(prefix="verne-fuzz-reader-"))  # one file at a time; removed at exit
atexit.register(shutil.rmtree, _READER_FOLDER, True)


def make_case(seed: int, number: int) -> Case:
    rng = random.Random(f"{seed}:{number}")
    donors = [_seed(p) for p in CL_SEEDS]
    machine_case = rng.random() < 0.2
    source = rng.choice(CL_SEEDS if not machine_case else [p for p in CL_SEEDS if p.parent.name == "data"])
    suffix = source.suffix if rng.random() < 0.9 else rng.choice([".csv", ".txt", ""])
    lines = _window(_seed(source), rng) if not machine_case else _seed(source)
    if not machine_case:
        for _ in range(rng.choice([0, 1, 1, 2, 3, 5])):
            lines = mutate_lines(lines, rng, donors, gentle_share=0.4)
    part = f"part{suffix}"
    files = {part: b"".join(lines)}
    args = [part]
    if rng.random() < 0.1:
        args.insert(0, "check")
    if machine_case:
        machine = list(_seed(MACHINE_SEED))
        if rng.random() < 0.6:  # a machine that may still be valid: a few numbers scaled
            numbered = [k for k, line in enumerate(machine) if NUMBER.search(line.split(b"#")[0])]
            for k in rng.sample(numbered, rng.randint(1, 4)):
                machine[k] = _mutate_number(machine[k], rng, gentle=True)
        else:
            for _ in range(rng.choice([1, 1, 2, 3])):
                machine = mutate_lines(machine, rng, [machine], gentle_share=0.5)
        files["m.yaml"] = b"".join(machine)
        args += ["--machine", "m.yaml"]
    absurd = rng.random() < 0.05  # options with values the CLI must refuse
    csv = rng.random() < 0.1 and args[0] != "check"
    output = "{out}/part.csv" if csv else "{out}/part.nc"
    if args[0] != "check":
        args += ["-o", output]
        if csv:
            args += ["--period", _value(rng, ["0", "0.001", "0.01", "0.05"], WEIRD, absurd)]
    if not csv and rng.random() < 0.7:
        args.append("--no-timing")
    if rng.random() < 0.8:
        args += ["--tool-length", _value(rng, ["50", "80", "100", "0"], WEIRD, absurd)]
    if rng.random() < 0.3:
        args += ["--work-offset", *(_value(rng, [f"{rng.uniform(-200, 200):.3f}"], WEIRD, absurd) for _ in range(3))]
    for option, usual in (("--tol", ["0.005", "0.01", "0.1"]), ("--axis-tol", ["0.05", "0.5"]),
                          ("--arc-tol", ["0.001", "0.01"]), ("--units", ["mm", "inch"]),
                          ("--max-messages", ["0", "3", "20"])):
        if rng.random() < 0.1:
            args += [option, _value(rng, usual, WEIRD, absurd)]
    report = rng.random() < 0.3
    if report:
        args += ["--report", "{out}/report.json"]
    args.append("--quiet")
    outputs = {"part.csv" if csv else "part.nc"} if args[0] != "check" else set()
    reports = {"report.json"} if report else set()
    return Case(number, files, args, {0: outputs | reports, 3: reports})


# ------------------------------------------------------------------------------------- running


@dataclass
class Result:
    outcome: str
    detail: str = ""
    where: str = ""  # innermost verne_post frame of a crash



def _crash(exc: BaseException) -> Result:
    """A crash: the traceback, and where in verne_post it was raised."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if "verne_post" in f.filename]
    where = f"{Path(frames[-1].filename).relative_to(ROOT)}:{frames[-1].lineno}" if frames else "?"
    return Result("crash", "".join(traceback.format_exception(exc)), f"{type(exc).__name__} at {where}")

def _on_timer(signum: int, frame: object) -> None:
    raise Hang()


def run_case(case: Case, timeout: float, keep: Path | None = None) -> Result:
    from verne_post import cli

    work = Path(tempfile.mkdtemp(prefix="verne-fuzz-"))
    folder_in, folder_out = work / "in", work / "out"
    folder_in.mkdir()
    folder_out.mkdir()
    for name, data in case.files.items():
        (folder_in / name).write_bytes(data)
    args = [str(folder_in / a) if a in case.files else a.replace("{out}", str(folder_out)) for a in case.args]
    stderr = io.StringIO()
    code: int | None = None
    result = None
    signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            cli.main.main(args=args, prog_name="verne-post")
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except Hang:
        result = Result("hang", f"over {timeout} s")
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # counting every crash is the point
        result = _crash(exc)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    if result is None:
        result = _classify(case, code, stderr.getvalue(), folder_out)
    if keep is not None and result.outcome in ("crash", "hang", "stray file"):
        _save(case, result, keep, stderr.getvalue())
    shutil.rmtree(work, ignore_errors=True)
    return result


def _classify(case: Case, code: int | None, stderr: str, folder: Path) -> Result:
    lines = stderr.splitlines()
    if code not in (0, 2, 3):
        return Result("crash", f"exit code {code}\n{stderr}", f"exit {code}")
    if "Traceback" in stderr or any(not line.startswith("verne-post: ") for line in lines):
        return Result("crash", f"stderr is not one line per message:\n{stderr[:2000]}", "message format")
    left = {p.name for p in folder.iterdir()}
    allowed = case.expected.get(code, set())
    if left - allowed:
        return Result("stray file", f"exit {code}, left {sorted(left - allowed)}", "stray")
    if code == 0 and not allowed <= left:
        return Result("stray file", f"exit 0 without {sorted(allowed - left)}", "missing output")
    return Result({0: "ok", 2: "bad input", 3: "violations"}[code], lines[-1] if lines else "")


def _save(case: Case, result: Result, keep: Path, stderr: str) -> None:
    folder = keep / f"case-{case.number}"
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in case.files.items():
        (folder / name).write_bytes(data)
    (folder / "args.txt").write_text(" ".join(case.args) + "\n")
    (folder / "result.txt").write_text(f"{result.outcome}: {result.where}\n{result.detail}\n--- stderr\n{stderr}")


def _limit_memory(gigabytes: float) -> None:
    limit = int(gigabytes * 2**30)
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (limit if hard == resource.RLIM_INFINITY else min(limit, hard), hard))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=100_000, help="number of cases (default 100000)")
    parser.add_argument("--seconds", type=float, default=None, help="stop after this long (default: no limit)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=30.0, help="per-case limit in s: beyond, a hang")
    parser.add_argument("--memory-gb", type=float, default=6.0, help="address-space limit of this process")
    parser.add_argument("--save", type=Path, default=Path(tempfile.gettempdir()) / "verne-fuzz",
                        help="folder for failing cases")
    parser.add_argument("--case", type=int, default=None, help="run only this case and print what happened")
    parser.add_argument("--reader", action="store_true", help="fuzz the CL reader alone (read_toolpath)")
    args = parser.parse_args()
    make, run = (make_reader_case, run_reader_case) if args.reader else (make_case, run_case)

    os.cpu_count = lambda: 1  # feed planning in this process: the per-case timer can interrupt it
    _limit_memory(args.memory_gb)
    signal.signal(signal.SIGALRM, _on_timer)
    if args.case is not None:
        case = make(args.seed, args.case)
        print("args:", " ".join(case.args), "\nfiles:", {k: len(v) for k, v in case.files.items()})
        result = run(case, args.timeout, keep=args.save)
        print(f"{result.outcome}: {result.where}\n{result.detail}")
        return

    counts: Counter[str] = Counter()
    signatures: dict[str, list[int]] = {}
    start = time.perf_counter()
    done = 0
    for number in range(args.cases):
        if args.seconds is not None and time.perf_counter() - start > args.seconds:
            break
        result = run(make(args.seed, number), args.timeout, keep=args.save)
        counts[result.outcome] += 1
        done += 1
        if result.outcome in ("crash", "hang", "stray file"):
            signatures.setdefault(f"{result.outcome}: {result.where}", []).append(number)
        if sys.stderr.isatty() and done % 100 == 0:
            print(f"\r{done} cases, {dict(counts)}", end="", file=sys.stderr, flush=True)
    elapsed = time.perf_counter() - start
    if sys.stderr.isatty():
        print(file=sys.stderr)
    print(f"{done} {'reader ' if args.reader else ''}cases in {elapsed:.0f} s ({1000 * elapsed / max(done, 1):.1f} "
          f"ms each), seed {args.seed}")
    for outcome in OUTCOMES:
        print(f"  {outcome:<11} {counts[outcome]}")
    for signature, numbers in sorted(signatures.items(), key=lambda item: -len(item[1])):
        print(f"  {len(numbers):>6} x {signature}   (cases {', '.join(map(str, numbers[:5]))})")
    if signatures:
        print(f"failing cases saved in {args.save}; run one again with --case N --seed {args.seed}"
              f"{' --reader' if args.reader else ''}")
    sys.exit(1 if any(counts[o] for o in ("crash", "hang", "stray file")) else 0)


if __name__ == "__main__":
    main()
