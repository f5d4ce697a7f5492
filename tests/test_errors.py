"""Error messages stay one printable line whatever the input holds."""

from __future__ import annotations

import unicodedata
from pathlib import Path

from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from verne_post.cli import main
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


def test_a_long_reason_keeps_what_to_do() -> None:
    """The remedy ends a message: however long the reason, its end stays (and its start)."""
    reason = ("CYCLE/DRILL: the fields cannot be told apart " + "because of this and that " * 60
              + "; output it as GOTO moves")
    text = str(InputError(reason, "part.aptsource", 9))
    assert text.startswith("part.aptsource:9: CYCLE/DRILL: the fields") and text.endswith("output it as GOTO moves")
    assert len(text.splitlines()) == 1 and len(text) < 1100


def test_the_catia_positional_cycle_refusal_is_whole(tmp_path: Path) -> None:
    """A refusal of a few hundred characters is printed whole, its remedy included."""
    path = tmp_path / "catia.aptsource"
    path.write_text("$$*CATIA0\nPARTNO PART1\nUNITS/MM\nLOADTL/1\nFEDRAT/100,MMPM\nGOTO/0,0,50,0,0,1\n"
                    "CYCLE/DRILL, 35.000000,,0,0, 1.000000, 1000.000000,70.000000,ON,0,0,0\nGOTO/0,0,0,0,0,1\n")
    result = CliRunner().invoke(main, ["check", str(path), "-q"])
    assert result.exit_code == 2 and len(result.stderr.splitlines()) == 1
    assert result.stderr.rstrip().endswith("names them (CYCLE/DRILL,DEPTH,d,CLEAR,c,MMPM,f) or as GOTO moves")
