"""Write-then-rename output: a failed run leaves no partial file and never clobbers a good one."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], newline: str | None = "\n", binary: bool = False
                 ) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path`` for ASCII text (or bytes with ``binary``); on
    success it replaces ``path``.

    The file is flushed to disk before the rename and keeps the permissions of the file it
    replaces (or the usual ones for a new file). On any error the temporary file is removed
    and ``path`` is left as it was.
    """
    target = Path(path)
    fd, temporary = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with (os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="ascii", newline=newline)) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        try:
            mode = target.stat().st_mode & 0o7777
        except FileNotFoundError:
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o666 & ~umask
        os.chmod(temporary, mode)
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise
