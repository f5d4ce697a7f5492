"""Output files: complete or absent, never a stray temporary, never a replaced device; file-system
failures are one line naming the path (exit 2, no traceback)."""

from __future__ import annotations

import contextlib
import os
import signal
import stat
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from verne_post.errors import OutputError
from verne_post.output import atomic
from verne_post.output.atomic import atomic_write

ROOT = Path(__file__).parent.parent
PART = ROOT / "tests" / "data" / "nx_multi_op_mm.cls"
HEADER = "PARTNO/TEST\nUNITS/MM\nMULTAX/ON\nTLDATA/MILL,10,0,80,0,0\nLOAD/TOOL,1\nFEDRAT/MMPM,1000\n"
GOOD = "GOTO/0,0,50,0,0,1\nGOTO/10,0,50,0.1,0,0.995\nGOTO/20,5,50,0,0,1\nFINI\n"
BAD = "GOTO/0,0,50,0,0,1\nRAPID\nGOTO/3000,0,50,0,0,1\nFINI\n"


@pytest.fixture(params=[True, False], ids=["O_TMPFILE", "named-temporary"])
def tmpfile_mode(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> bool:
    """Run the test with unnamed temporaries (Linux) and with the named fallback."""
    monkeypatch.setattr(atomic, "use_tmpfile", request.param)
    return request.param


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_new_file_has_the_content_and_usual_permissions(tmp_path: Path, tmpfile_mode: bool) -> None:
    with atomic_write(tmp_path / "out.nc") as handle:
        handle.write("G0 X1\n")
    assert (tmp_path / "out.nc").read_text() == "G0 X1\n"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE((tmp_path / "out.nc").stat().st_mode) == 0o666 & ~umask
    assert _names(tmp_path) == ["out.nc"]


def test_replacing_keeps_permissions(tmp_path: Path, tmpfile_mode: bool) -> None:
    target = tmp_path / "out.nc"
    target.write_text("old\n")
    target.chmod(0o640)
    with atomic_write(target) as handle:
        handle.write("new\n")
    assert target.read_text() == "new\n" and stat.S_IMODE(target.stat().st_mode) == 0o640
    assert _names(tmp_path) == ["out.nc"]


def test_failure_midway_leaves_nothing(tmp_path: Path, tmpfile_mode: bool) -> None:
    target = tmp_path / "out.nc"
    for before in (None, "precious\n"):
        if before:
            target.write_text(before)
        with pytest.raises(OutputError, match=r"out\.nc: cannot write: No space left on device$"), \
                atomic_write(target) as handle:
            handle.write("partial\n")
            raise OSError(28, os.strerror(28))
        assert _names(tmp_path) == (["out.nc"] if before else [])
        if before:
            assert target.read_text() == before


def test_symbolic_link_is_written_through(tmp_path: Path, tmpfile_mode: bool) -> None:
    (tmp_path / "real.nc").write_text("old\n")
    (tmp_path / "link.nc").symlink_to("real.nc")
    with atomic_write(tmp_path / "link.nc") as handle:
        handle.write("new\n")
    assert (tmp_path / "link.nc").is_symlink() and (tmp_path / "real.nc").read_text() == "new\n"


def test_fifo_is_written_into_not_replaced(tmp_path: Path, tmpfile_mode: bool) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received: list[str] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_text()))
    reader.start()
    with atomic_write(fifo) as handle:
        handle.write("G0 X1\n")
    reader.join(10)
    assert received == ["G0 X1\n"] and stat.S_ISFIFO(fifo.stat().st_mode)
    assert _names(tmp_path) == ["pipe"]


def test_character_device_is_written_into_not_replaced(tmp_path: Path) -> None:
    """A null device made for the test, and the system's /dev/null through the CLI."""
    device = tmp_path / "null"
    os.mknod(device, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    with atomic_write(device) as handle:
        handle.write("G0 X1\n")
    assert stat.S_ISCHR(device.stat().st_mode) and _names(tmp_path) == ["null"]
    before = os.stat("/dev/null")
    result = _post(tmp_path, HEADER + GOOD, "-o", "/dev/null", "--report", "/dev/null", "--no-timing")
    assert result.returncode == 0, result.stderr
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and (after.st_ino, after.st_rdev) == (before.st_ino, before.st_rdev)


def _post(tmp_path: Path, content: str, *args: str) -> subprocess.CompletedProcess[str]:
    (tmp_path / "part.cls").write_text(content)
    return subprocess.run([sys.executable, "-m", "verne_post", "part.cls", *args], capture_output=True, text=True,
                          cwd=tmp_path)


def _one_line_error(result: subprocess.CompletedProcess[str], *words: str) -> None:
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and result.stderr.startswith("verne-post: error: ")
    for word in words:
        assert word in result.stderr


@pytest.mark.parametrize(("option", "path", "reason"), [
    ("-o", "missing/part.nc", "folder 'missing' does not exist"),
    ("--report", "missing/r.json", "folder 'missing' does not exist"),
    ("-o", "part.cls/part.nc", "'part.cls' is not a folder"),
    ("-o", "/sys/verne-post-test.nc", "cannot write"),  # sysfs refuses new files, also to root
    ("-o", "/dev/full", "No space left on device"),  # a full disk
    ("--report", "/dev/full", "No space left on device"),
])
def test_unwritable_outputs_are_one_line(tmp_path: Path, option: str, path: str, reason: str) -> None:
    args = [option, path] if option == "-o" else ["-o", "part.nc", option, path]
    result = _post(tmp_path, HEADER + GOOD, *args, "--no-timing", "--quiet")
    _one_line_error(result, f"error: {path}: ", reason)
    assert _names(tmp_path) == ["part.cls"]


def test_report_failure_still_prints_the_violations(tmp_path: Path) -> None:
    result = _post(tmp_path, HEADER + BAD, "--report", "/dev/full")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "part.cls:9: pose is out of the machine's reach" in result.stderr
    assert "/dev/full: cannot write: No space left on device" in result.stderr.splitlines()[-1]


def test_output_may_not_be_the_input(tmp_path: Path) -> None:
    result = _post(tmp_path, HEADER + GOOD, "-o", "part.cls")
    _one_line_error(result, "part.cls", "the input")
    assert (tmp_path / "part.cls").read_text() == HEADER + GOOD


# A process that writes part of an output and waits to be killed.
_WRITER = textwrap.dedent("""
    import sys, time
    from verne_post.output import atomic
    atomic.use_tmpfile = sys.argv[2] == "1"
    with atomic.atomic_write(sys.argv[1]) as handle:
        handle.write("partial\\n" * 10000)
        handle.flush()
        print("writing", flush=True)
        time.sleep(60)
""")


def _killed_writer(target: Path, use_tmpfile: bool, signum: int) -> int:
    process = subprocess.Popen([sys.executable, "-c", _WRITER, str(target), str(int(use_tmpfile))],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert process.stdout is not None and process.stdout.readline() == "writing\n"
    process.send_signal(signum)
    return process.wait(30)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
@pytest.mark.parametrize("use_tmpfile", [True, False], ids=["O_TMPFILE", "named-temporary"])
def test_signal_removes_the_temporary(tmp_path: Path, use_tmpfile: bool, signum: int) -> None:
    (tmp_path / "out.nc").write_text("precious\n")
    assert _killed_writer(tmp_path / "out.nc", use_tmpfile, signum) != 0
    assert _names(tmp_path) == ["out.nc"] and (tmp_path / "out.nc").read_text() == "precious\n"


def test_sigkill_leaves_nothing_with_o_tmpfile(tmp_path: Path) -> None:
    assert _killed_writer(tmp_path / "out.nc", True, signal.SIGKILL) == -signal.SIGKILL
    assert _names(tmp_path) == []


def test_stale_temporary_of_a_killed_run_is_removed_by_the_next(tmp_path: Path, tmpfile_mode: bool) -> None:
    assert _killed_writer(tmp_path / "out.nc", False, signal.SIGKILL) == -signal.SIGKILL
    stale = _names(tmp_path)
    assert len(stale) == 1 and stale[0].startswith(".out.nc" + atomic.TEMP_TAG)
    (tmp_path / f".out.nc{atomic.TEMP_TAG}{os.getpid()}-0000.tmp").write_text("a running process's\n")
    (tmp_path / ".other.nc.verne-1-0000.tmp").write_text("another output's\n")
    with atomic_write(tmp_path / "out.nc") as handle:
        handle.write("done\n")
    assert _names(tmp_path) == sorted([f".out.nc{atomic.TEMP_TAG}{os.getpid()}-0000.tmp",
                                       ".other.nc.verne-1-0000.tmp", "out.nc"])


def _writing(pid: int, folder: Path) -> bool:
    """True once process ``pid`` has a file other than the input open in ``folder`` (a named or
    unnamed temporary)."""
    with contextlib.suppress(OSError):
        for fd in os.listdir(f"/proc/{pid}/fd"):
            with contextlib.suppress(OSError):
                name = os.readlink(f"/proc/{pid}/fd/{fd}")
                if name.startswith(f"{folder}/") and name != f"{folder}/part.cls":
                    return True
    return False


@pytest.mark.parametrize("use_tmpfile", [True, False], ids=["O_TMPFILE", "named-temporary"])
def test_cli_killed_while_writing_leaves_no_file(tmp_path: Path, use_tmpfile: bool) -> None:
    """SIGTERM to verne-post while it writes a large timed CSV: nothing but the input remains."""
    (tmp_path / "part.cls").write_bytes(PART.read_bytes())
    code = (f"from verne_post import cli; from verne_post.output import atomic; atomic.use_tmpfile = {use_tmpfile}; "
            "cli.main()")
    process = subprocess.Popen([sys.executable, "-c", code, "part.cls", "-o", "part.csv", "--period", "0.0001",
                                "--tool-length", "50", "--quiet"], cwd=tmp_path.resolve())
    while not _writing(process.pid, tmp_path.resolve()) and process.poll() is None:
        time.sleep(0.002)
    process.send_signal(signal.SIGTERM)
    assert process.wait(60) == -signal.SIGTERM
    assert _names(tmp_path) == ["part.cls"]
