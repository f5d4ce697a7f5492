"""Run LinuxCNC's standalone G-code interpreter ``rs274`` on a file and read back what it did.

Used by the tests and the benchmark to check the G-code writer against a real interpreter; not
part of the user-facing pipeline. Independent of the rest of the package (numpy + stdlib only).

The interpreter comes with Debian's ``linuxcnc-uspace`` package::

    apt-get install -y --no-install-recommends linuxcnc-uspace

It is run in batch mode, ``rs274 -g -t TOOLTABLE FILE OUTFILE``, and prints one "canonical
machining function" call per line into OUTFILE, for example::

        23 N..... STRAIGHT_TRAVERSE(10.0000, 20.0000, 30.0000, 10.0000, 0.0000, 400.0000)
        27 N10    STRAIGHT_FEED(11.0000, 20.0000, 30.0000, 11.0000, 0.0000, 410.0000)

(positions X Y Z A B C in program units, mm and degrees here, printed with 4 decimals). Errors go
to stderr as the message followed by the offending line, and the exit status is then 1.

In inverse-time mode (G93) the interpreter does not report the F word: it reports
``SET_FEED_RATE(max(0.1, L * F))`` before each G1, where L is the XYZ length of the move, or the
ABC length (degrees) if X, Y and Z do not change. :func:`inverse_time_rate` reproduces that.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "FEED_INVERSE_TIME",
    "FEED_UNITS_PER_MINUTE",
    "FEED_UNITS_PER_REV",
    "INSTALL_HINT",
    "Rs274Error",
    "Rs274NotFoundError",
    "Rs274Result",
    "find_rs274",
    "inverse_time_rate",
    "parse_canon",
    "run_rs274",
]

#: Feed modes reported in :attr:`Rs274Result.feed_modes`.
FEED_UNITS_PER_MINUTE = 0  # G94
FEED_INVERSE_TIME = 1  # G93
FEED_UNITS_PER_REV = 2  # G95

INSTALL_HINT = (
    "LinuxCNC's standalone G-code interpreter 'rs274' is not installed: install it with "
    "'apt-get install -y --no-install-recommends linuxcnc-uspace' (Debian 12), "
    "or set RS274=/path/to/rs274"
)

_DEFAULT_TIMEOUT_S = 600.0

# "   27 N.....  STRAIGHT_FEED(...)" or "    8 N20    STRAIGHT_TRAVERSE(...)": sequence number,
# block number (N word or dots), canonical call name and its arguments.
_CANON_LINE = re.compile(r"^\s*\d+\s+N(?:\.+|-?\d+)\s*([A-Z_][A-Z0-9_]*)\((.*)\)\s*$")

_FEED_MODE_COMMENTS = {
    "interpreter: feed mode set to units per minute": FEED_UNITS_PER_MINUTE,
    "interpreter: feed mode set to inverse time": FEED_INVERSE_TIME,
    "interpreter: feed mode set to units per revolution": FEED_UNITS_PER_REV,
}


class Rs274Error(RuntimeError):
    """The interpreter rejected the program, or could not be run."""

    def __init__(self, message: str, errors: list[str] | None = None) -> None:
        super().__init__(message)
        self.errors = list(errors or [])


class Rs274NotFoundError(Rs274Error, FileNotFoundError):
    """No ``rs274`` executable was found."""


@dataclass(frozen=True)
class Rs274Result:
    """What the interpreter did with a program.

    - ``moves`` (M, 6): end position X Y Z A B C of every STRAIGHT_TRAVERSE / STRAIGHT_FEED, in
      program units (mm, degrees), as printed by the interpreter (4 decimals).
    - ``kinds`` (M,) int8: 0 traverse (G0), 1 feed (G1).
    - ``feed_modes`` (M,) int8: feed mode in force at each move, :data:`FEED_UNITS_PER_MINUTE`,
      :data:`FEED_INVERSE_TIME` or :data:`FEED_UNITS_PER_REV` (meaningless on traverses).
    - ``feed_rates`` (M,): last ``SET_FEED_RATE`` value before each move (for G93 moves that is
      ``max(0.1, L * F)``, see :func:`inverse_time_rate`; meaningless on traverses).
    - ``errors``: error lines from the interpreter (empty unless ``check=False``).
    - ``calls``: every canonical call in order as ``(name, arguments)`` strings.
    - ``stdout``: what the interpreter printed on stdout (``(PRINT,...)`` comments).
    """

    moves: np.ndarray
    kinds: np.ndarray
    feed_modes: np.ndarray
    feed_rates: np.ndarray
    errors: list[str] = field(default_factory=list)
    calls: list[tuple[str, str]] = field(default_factory=list)
    stdout: str = ""

    def named(self, name: str) -> list[str]:
        """Arguments of every call named ``name`` (e.g. ``"SELECT_TOOL"``), in order."""
        return [args for n, args in self.calls if n == name]


def find_rs274() -> str | None:
    """Path of the ``rs274`` executable: ``$RS274`` if set, else ``rs274`` on PATH, else None."""
    env = os.environ.get("RS274")
    if env:
        return env if os.path.isfile(env) and os.access(env, os.X_OK) else None
    found = shutil.which("rs274")
    if found:
        return found
    for candidate in ("/usr/bin/rs274", "/usr/local/bin/rs274"):
        if os.path.isfile(candidate) and os.access(candidate, os.X_OK):
            return candidate
    return None


def inverse_time_rate(start: np.ndarray, end: np.ndarray, f_word: np.ndarray | float) -> np.ndarray:
    """The feed rate rs274 reports for a G93 move from ``start`` to ``end`` (X Y Z A B C, mm/deg).

    ``max(0.1, L * F)`` with L the XYZ distance, or the ABC distance when X, Y and Z are all
    unchanged (exact float comparison, as the interpreter does). Shapes broadcast over leading axes.
    """
    start = np.asarray(start, dtype=float)
    end = np.asarray(end, dtype=float)
    d = end - start
    linear = np.sqrt(np.sum(d[..., :3] ** 2, axis=-1))
    angular = np.sqrt(np.sum(d[..., 3:6] ** 2, axis=-1))
    xyz_moves = np.any(d[..., :3] != 0.0, axis=-1)
    length = np.where(xyz_moves, linear, angular)
    return np.maximum(0.1, length * np.asarray(f_word, dtype=float))


def parse_canon(lines: Iterable[str]) -> Rs274Result:
    """Parse the canonical output of ``rs274`` (the OUTFILE) into moves and feed state.

    ``errors`` of the result is left empty: errors are on the interpreter's stderr.
    """
    moves: list[list[float]] = []
    kinds: list[int] = []
    modes: list[int] = []
    rates: list[float] = []
    calls: list[tuple[str, str]] = []
    mode = FEED_UNITS_PER_MINUTE
    rate = 0.0
    for raw in lines:
        match = _CANON_LINE.match(raw)
        if match is None:
            continue
        name, args = match.group(1), match.group(2)
        calls.append((name, args))
        if name == "STRAIGHT_TRAVERSE" or name == "STRAIGHT_FEED":
            values = [float(v) for v in args.split(",")]
            if len(values) < 6:
                raise Rs274Error(f"unexpected rs274 output line: {raw.rstrip()}")
            moves.append(values[:6])
            kinds.append(0 if name == "STRAIGHT_TRAVERSE" else 1)
            modes.append(mode)
            rates.append(rate)
        elif name == "SET_FEED_RATE":
            rate = float(args)
        elif name == "COMMENT":
            text = args.strip().strip('"')
            mode = _FEED_MODE_COMMENTS.get(text, mode)
        elif name == "SET_FEED_MODE":
            # SET_FEED_MODE(spindle, 1) is per revolution; (spindle, 0) is printed for both G93
            # and G94, which only the interpreter's COMMENT tells apart.
            parts = [p.strip() for p in args.split(",")]
            if parts and parts[-1] == "1":
                mode = FEED_UNITS_PER_REV
    return Rs274Result(
        moves=np.asarray(moves, dtype=float).reshape(-1, 6),
        kinds=np.asarray(kinds, dtype=np.int8),
        feed_modes=np.asarray(modes, dtype=np.int8),
        feed_rates=np.asarray(rates, dtype=float),
        calls=calls,
    )


def _write_tool_table(path: Path, tool_numbers: Iterable[int]) -> None:
    """Tool table with one pocket per tool: ``T<n> P<pocket> Z0 D0`` (tool 0 = no tool, skipped)."""
    tools = sorted({int(t) for t in tool_numbers})
    if tools and tools[0] < 0:
        raise ValueError(f"negative tool number {tools[0]}")
    rows = [
        f"T{t} P{pocket} Z0 D0 ;verne_post test tool"
        for pocket, t in enumerate((t for t in tools if t != 0), start=1)
    ]
    path.write_text("".join(r + "\n" for r in rows), encoding="ascii")


def _environment(executable: str) -> dict[str, str]:
    """Environment for the interpreter; finds the libraries of an unpacked (not installed) .deb."""
    env = dict(os.environ)
    libdir = Path(executable).resolve().parent.parent / "lib"
    if (libdir / "librs274.so.0").exists() and str(libdir) not in ("/usr/lib", "/lib"):
        env["LD_LIBRARY_PATH"] = os.pathsep.join(
            p for p in (str(libdir), env.get("LD_LIBRARY_PATH", "")) if p
        )
    return env


def run_rs274(
    path: str | os.PathLike[str],
    *,
    tool_numbers: Iterable[int],
    timeout: float = _DEFAULT_TIMEOUT_S,
    check: bool = True,
    require_program_end: bool = True,
    executable: str | None = None,
) -> Rs274Result:
    """Interpret the G-code file ``path`` with ``rs274`` and return its moves and feed state.

    ``tool_numbers``: every tool the program loads (a tool table with them is written). The
    interpreter runs in a temporary directory with ``timeout`` seconds. With ``check`` (default),
    raises :class:`Rs274Error` if the interpreter reported any error (stderr message or non-zero
    exit status), or, with ``require_program_end``, if it never reached M2/M30 (a ``%`` line in
    the middle silently ends the program). Raises :class:`Rs274NotFoundError` if no interpreter
    is installed.
    """
    exe = executable or find_rs274()
    if exe is None:
        raise Rs274NotFoundError(INSTALL_HINT)
    source = Path(path).resolve()
    if not source.is_file():
        raise FileNotFoundError(f"no such G-code file: {source}")
    with tempfile.TemporaryDirectory(prefix="verne_rs274_") as tmp:
        work = Path(tmp)
        table = work / "tools.tbl"
        canon = work / "canon.txt"
        _write_tool_table(table, tool_numbers)
        try:
            proc = subprocess.run(
                [exe, "-g", "-t", str(table), str(source), str(canon)],
                cwd=work,
                env=_environment(exe),
                stdin=subprocess.DEVNULL,
                capture_output=True,
                text=True,
                errors="replace",
                timeout=timeout,
                check=False,
            )
        except subprocess.TimeoutExpired as exc:
            raise Rs274Error(f"rs274 did not finish {source} within {timeout:g} s") from exc
        except OSError as exc:
            raise Rs274NotFoundError(f"cannot run {exe}: {exc}. {INSTALL_HINT}") from exc
        if canon.exists():
            with canon.open(encoding="utf-8", errors="replace") as fh:
                result = parse_canon(fh)
        else:
            result = parse_canon(())
    # stderr: "executing" (batch mode banner), then per error the message and the offending line.
    errors = [ln for ln in proc.stderr.splitlines() if ln.strip() and ln.strip() != "executing"]
    if proc.returncode != 0 and not errors:
        errors.append(f"rs274 exited with status {proc.returncode}")
    if require_program_end and not errors and not any(n == "PROGRAM_END" for n, _ in result.calls):
        errors.append("program ended without reaching M2/M30 (no PROGRAM_END reported)")
    result = Rs274Result(
        moves=result.moves,
        kinds=result.kinds,
        feed_modes=result.feed_modes,
        feed_rates=result.feed_rates,
        errors=errors,
        calls=result.calls,
        stdout=proc.stdout,
    )
    if check and errors:
        raise Rs274Error(f"rs274 rejected {source}: " + " | ".join(errors), errors)
    return result
