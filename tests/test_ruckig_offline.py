"""ruckig plans the rapids offline only.

The community build of ruckig (the one on PyPI) sends any trajectory with intermediate
waypoints to a remote service (its C++ cloud client); verne-post must never use that API. Its
C++ client opens its sockets below Python, so a Python-level socket patch cannot see it: the
inputs handed to ruckig are checked, and the whole command is traced at the system-call level.
"""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

import verne_post.planning.timing
from verne_post.cli import main

ROOT = Path(__file__).resolve().parent.parent
PART = ROOT / "tests" / "data" / "nx_multi_op_mm.cls"  # real NX sample with rapids between its operations


def _no_network(*args: Any, **kwargs: Any) -> Any:
    raise AssertionError(f"network access while posting: {args!r}")


def test_rapids_give_ruckig_no_waypoints_and_python_opens_no_socket(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    real = verne_post.planning.timing.Ruckig
    made: list[Any] = []
    inputs: list[Any] = []

    class Spy:
        def __init__(self, *args: Any) -> None:
            self.inner = real(*args)
            made.append(self.inner)

        def calculate(self, inp: Any, *args: Any) -> Any:
            inputs.append(inp)
            return self.inner.calculate(inp, *args)

    monkeypatch.setattr(verne_post.planning.timing, "Ruckig", Spy)
    for name in ("socket", "create_connection", "getaddrinfo"):
        monkeypatch.setattr(socket, name, _no_network)
    # in one process: the spy sees every rapid planned (helper processes are traced below)
    result = CliRunner().invoke(main, [str(PART), "-o", str(tmp_path / "part.nc"), "--quiet", "--workers", "1"])
    assert result.exit_code == 0, result.output
    assert inputs  # the rapids went through the spy: a moved seam fails here, not silently
    assert all(list(inp.intermediate_positions) == [] for inp in inputs)
    # Made with no room for waypoints, ruckig refuses them itself instead of calling the service.
    assert all(r.max_number_of_waypoints == 0 for r in made)


def _internet_sockets(tmp_path: Path, command: list[str]) -> tuple[int, list[str]]:
    """Run ``command`` under strace (with its children); its exit code and every AF_INET/AF_INET6
    socket it created."""
    trace = tmp_path / "trace.txt"
    process = subprocess.run(["strace", "-f", "--seccomp-bpf", "-e", "trace=socket", "-o", str(trace), *command],
                             capture_output=True, text=True, timeout=300, check=False)
    return process.returncode, [line for line in trace.read_text().splitlines() if "AF_INET" in line]


def test_posting_a_program_with_rapids_opens_no_internet_socket(tmp_path: Path) -> None:
    # strace must see a socket when there is one, or this test could not fail.
    code, sockets = _internet_sockets(tmp_path, [sys.executable, "-c", "import socket; socket.socket().close()"])
    assert code == 0 and sockets
    code, sockets = _internet_sockets(tmp_path, [sys.executable, "-m", "verne_post", str(PART), "-o",
                                                 str(tmp_path / "part.nc"), "--quiet"])
    assert code == 0 and (tmp_path / "part.nc").exists()
    assert sockets == []


def test_nothing_sets_ruckig_waypoints() -> None:
    offending = [str(path.relative_to(ROOT)) for path in (ROOT / "verne_post").rglob("*.py")
                 if "intermediate_positions" in path.read_text(encoding="utf-8")]
    assert offending == []
