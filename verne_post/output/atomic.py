"""The one writer of every output file: a failed or killed run leaves no partial file, no stray
temporary, and never clobbers a good file.

- A regular (or new) file is written to a temporary in its folder, which takes its place only
  once complete. On Linux the temporary has no name while it is written (``O_TMPFILE``): if the
  process dies, even by SIGKILL, the kernel frees it. Complete, it is linked (``linkat``)
  straight to a new output, or to ``.NAME.verne-PID-XXXX.tmp`` renamed at once over an existing one.
- Where ``O_TMPFILE`` is not available the temporary is named from the start: SIGTERM, SIGINT
  and SIGHUP remove it before the process ends, and a later write of the same output removes
  the temporaries of processes that no longer exist (killed by SIGKILL).
- An output that exists and is not a regular file (``/dev/null``, a FIFO, a terminal) is written
  into, never replaced; a symbolic link is written through to the file it names.
- Any ``OSError`` (missing or read-only folder, full disk) is raised as one :class:`OutputError`
  naming the output.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import signal
import stat
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from ..errors import OutputError

#: Middle of every temporary's name: ``.{output name}.verne-{pid}-{random}.tmp``.
TEMP_TAG = ".verne-"

#: Signals on which a named temporary is removed before the process ends.
CLEANUP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGINT", "SIGHUP") if hasattr(signal, name))

#: Write unnamed temporaries (Linux ``O_TMPFILE``, linked through ``/proc/self/fd``); where
#: False, or where the file system refuses them, temporaries are named from the start.
use_tmpfile = hasattr(os, "O_TMPFILE") and os.path.isdir("/proc/self/fd")

# Named temporaries of this process that exist right now, (folder fd, name): the signal
# handler removes them.
_pending: set[tuple[int, str]] = set()


def check_writable(path: str | os.PathLike[str]) -> None:
    """Raise :class:`OutputError` now if ``path`` obviously cannot be written (missing folder, a
    folder in its place), so that a long run does not fail only at its end."""
    target = _resolved(path)
    folder = target.parent
    if target.is_dir():
        raise OutputError("is a directory", str(path))
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist"
        raise OutputError(f"cannot write: folder {str(folder)!r} {what}", str(path))
    if not _is_special(target) and not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write: folder {str(folder)!r} is not writable", str(path))


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], newline: str | None = "\n", binary: bool = False
                 ) -> Iterator[IO[Any]]:
    """A text handle (ASCII; bytes with ``binary``) whose content becomes ``path`` when the block
    ends without error.

    The file is flushed to disk before it appears and keeps the permissions of the file it
    replaces (or the usual ones for a new file). On any error ``path`` is left as it was and no
    temporary remains; ``OSError`` is raised as :class:`OutputError`.
    """
    target = _resolved(path)
    try:
        if _is_special(target):
            with (open(target, "wb") if binary else open(target, "w", encoding="ascii", newline=newline)) as handle:
                yield handle
        else:
            with _replacing(target, newline, binary) as handle:
                yield handle
    except OSError as exc:
        raise OutputError(f"cannot write: {exc.strerror or exc}", str(path)) from None


def _resolved(path: str | os.PathLike[str]) -> Path:
    """``path`` with symbolic links followed: a link is written through, not replaced."""
    return Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)


def _is_special(target: Path) -> bool:
    """True for an existing file that is neither a regular file nor a folder."""
    try:
        mode = os.stat(target).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


@contextlib.contextmanager
def _replacing(target: Path, newline: str | None, binary: bool) -> Iterator[IO[Any]]:
    """Write a temporary in ``target``'s folder; it replaces ``target`` when the block succeeds."""
    folder_fd = os.open(target.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    fd = named = None
    try:
        with _removing_on_signal():
            _remove_stale(folder_fd, target.name)
            mode = _mode_for(target)
            fd = _unnamed(folder_fd) if use_tmpfile else None
            if fd is None:
                named = _named(folder_fd, target.name)
                fd = os.open(named, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600, dir_fd=folder_fd)
            with (os.fdopen(fd, "wb", closefd=False) if binary
                  else os.fdopen(fd, "w", encoding="ascii", newline=newline, closefd=False)) as handle:
                yield handle
            os.fchmod(fd, mode)
            os.fsync(fd)
            if named is None:
                try:  # a new output: its name appears with the whole content, nothing else ever
                    os.link(f"/proc/self/fd/{fd}", target.name, dst_dir_fd=folder_fd, follow_symlinks=True)
                    return
                except FileExistsError:
                    named = _named(folder_fd, target.name)
                    os.link(f"/proc/self/fd/{fd}", named, dst_dir_fd=folder_fd, follow_symlinks=True)
            os.replace(named, target.name, src_dir_fd=folder_fd, dst_dir_fd=folder_fd)
            _pending.discard((folder_fd, named))
            named = None
    finally:
        if named is not None:
            with contextlib.suppress(OSError):
                os.unlink(named, dir_fd=folder_fd)
            _pending.discard((folder_fd, named))
        if fd is not None:
            os.close(fd)
        os.close(folder_fd)


def _unnamed(folder_fd: int) -> int | None:
    """A nameless file in the folder (``O_TMPFILE``), or None where the file system has none."""
    try:
        return os.open(".", os.O_TMPFILE | os.O_WRONLY, 0o600, dir_fd=folder_fd)
    except OSError as exc:
        if exc.errno in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL):
            return None
        raise


def _named(folder_fd: int, name: str) -> str:
    """A fresh temporary name for output ``name``, registered for removal on a signal."""
    temporary = f".{name}{TEMP_TAG}{os.getpid()}-{secrets.token_hex(4)}.tmp"
    _pending.add((folder_fd, temporary))
    return temporary


def _mode_for(target: Path) -> int:
    """Permissions of the file being replaced, else the usual ones of a new file."""
    try:
        return os.stat(target).st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _remove_stale(folder_fd: int, name: str) -> None:
    """Remove temporaries of output ``name`` left by processes that no longer run."""
    prefix = f".{name}{TEMP_TAG}"
    with contextlib.suppress(OSError), os.scandir(folder_fd) as entries:
        for entry in entries:
            if not (entry.name.startswith(prefix) and entry.name.endswith(".tmp")):
                continue
            pid = entry.name[len(prefix):].split("-")[0]
            if pid.isdigit() and not _running(int(pid)):
                with contextlib.suppress(OSError):
                    os.unlink(entry.name, dir_fd=folder_fd)


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


@contextlib.contextmanager
def _removing_on_signal() -> Iterator[None]:
    """While the block runs, SIGTERM/SIGINT/SIGHUP first remove the named temporaries, then act
    as before (by default: end the process)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in CLEANUP_SIGNALS}

    def handler(signum: int, frame: Any) -> None:
        for folder_fd, name in list(_pending):
            with contextlib.suppress(OSError):
                os.unlink(name, dir_fd=folder_fd)
        signal.signal(signum, previous[signum] or signal.SIG_DFL)
        os.kill(os.getpid(), signum)

    caught = [s for s, h in previous.items() if h is not signal.SIG_IGN]
    for s in caught:
        signal.signal(s, handler)
    try:
        yield
    finally:
        for s in caught:
            signal.signal(s, previous[s] or signal.SIG_DFL)
