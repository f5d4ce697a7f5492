"""Error messages stay one printable line whatever the input holds."""

from __future__ import annotations

import unicodedata

from hypothesis import given
from hypothesis import strategies as st

from verne_post.errors import MAX_TOKEN_CHARS, InputError, one_line, quote

LINE_BREAKS = "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"


def _printable(text: str) -> bool:
    return not any(unicodedata.category(ch) in ("Cc", "Zl", "Zp", "Cf", "Cs", "Co", "Cn") for ch in text)


@given(st.text(), st.text(), st.integers(1, 10**6))
def test_every_error_is_one_printable_line(token: str, source: str, line: int) -> None:
    text = str(InputError(f"'{token}' is not a number", source, line))
    assert len(text.splitlines()) <= 1 and not any(ch in text for ch in LINE_BREAKS)
    assert _printable(text)


def test_long_token_is_cut() -> None:
    text = str(InputError(f"'{'7' * 5000}' is not a number", "part.cls", 12))
    assert text.startswith("part.cls:12: '777") and text.endswith("...' is not a number")
    assert len(text) < len("part.cls:12: ") + MAX_TOKEN_CHARS + len("'' is not a number") + 1


def test_control_characters_are_escaped_not_dropped() -> None:
    assert one_line("bad 'a\nb\x1b[2J'") == "bad 'a\\x0ab\\x1b[2J'"
    assert one_line("x\u2028y") == "x\\u2028y"
    assert quote("\r" * 100).count("\\x0d") < MAX_TOKEN_CHARS // 4 + 1


def test_apostrophes_are_not_quotes() -> None:
    message = "pose is out of the machine's reach; the part's " + "x" * 60
    assert one_line(message) == message
