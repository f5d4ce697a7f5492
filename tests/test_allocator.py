"""The command line's allocator settings (verne_post.processes.allocator)."""

from __future__ import annotations

import platform
import sys

from verne_post.processes.allocator import keep_freed_memory


def test_glibc_takes_both_settings_and_others_are_left_alone() -> None:
    glibc = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"
    assert keep_freed_memory() is glibc
