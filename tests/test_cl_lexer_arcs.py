"""The reader's pure stages alone: the lexer of logical records and the arc expander."""

from __future__ import annotations

import math

import numpy as np
import pytest

from verne_post.cl.arcs import MAX_ARC_POINTS, arc_points, arc_sweep, tangent_votes
from verne_post.cl.lexer import Record, records, split_lines


def lex(text: str) -> list[Record]:
    return list(records(split_lines(text)))


def test_continuations_comments_and_line_numbers() -> None:
    text = "GOTO/1,2,3\nCIRCLE / 0,0,0,  $\n\n$$ inside\n0,0,1, 5 $$ tail\nRAPID\nTOOL   PATH/OP1,TOOL,T\n"
    assert lex(text) == [
        Record("GOTO", "1,2,3", 1),
        Record("CIRCLE", " 0,0,0,  0,0,1, 5", 2),
        Record("RAPID", "", 6),
        Record("TOOL PATH", "OP1,TOOL,T", 7),
    ]


def test_creo_comment_runs_onto_plain_lines_of_numbers() -> None:
    text = ("$$-> CSYS / 1.0, 0.0, 0.0, 0.0,  $\n            0.0, 1.0, 0.0, 0.0,  $\n"
            "            0.0, 0.0, 1.0, 0.0\nSPINDL / RPM, 100,  CLW\n")
    assert lex(text) == [Record("SPINDL", " RPM, 100,  CLW", 4)]


def test_comment_ending_in_dollar_does_not_swallow_a_record() -> None:
    assert lex("$$ price in $\nGOTO/1,2,3\n") == [Record("GOTO", "1,2,3", 2)]


def test_plain_lines_of_numbers_after_a_goto_are_its_points() -> None:
    # PTC Creo help, "CL Output for Circular Interpolation": GOTO / x, y, z then lines x, y, z
    text = "GOTO / 1, 2, 3\n 4.5, -5, 6E1\n\n$$ c\n7,8,9,0,0,1\nSPINDL/100\n1,2,3\nGOTO/1,1,1\n+.5,2.,3\n"
    assert lex(text) == [
        Record("GOTO", " 1, 2, 3", 1),
        Record("GOTO", "4.5, -5, 6E1", 2, follows_goto=True),
        Record("GOTO", "7,8,9,0,0,1", 5, follows_goto=True),
        Record("SPINDL", "100", 6),
        Record("1,2,3", "", 7),  # not after a GOTO: left for the reader to call unknown
        Record("GOTO", "1,1,1", 8),
        Record("GOTO", "+.5,2.,3", 9, follows_goto=True),
    ]
    assert all(r.follows_goto == (r.line in (2, 5, 9)) for r in lex(text))


def test_text_records_are_literal() -> None:
    assert lex("PARTNO MFG_TURN_MILL\nPPRINT/ A $$ B $\nINSERT/M08\n") == [
        Record("PARTNO", "MFG_TURN_MILL", 1), Record("PPRINT", "A $$ B $", 2), Record("INSERT", "M08", 3)]


def test_nx_listing_header_with_tabs_and_trailer() -> None:
    text = ("=====\nInformation listing created by :\tjdoe\nDate\t\t: Mon Feb 03 2020\nNode name\t: pc-1\n=====\n"
            "GOTO/0,0,0\nTool Path Listing has 12 lines.\n")
    assert lex(text) == [Record("GOTO", "0,0,0", 6)]


def test_unfinished_continuation_is_reported() -> None:
    assert lex("GOTO/1,2,$\n")[-1] == Record("$", "", 1)


def test_crlf_and_cr_line_ends() -> None:
    assert split_lines("A\r\nB\rC\n") == ["A", "B", "C"]


# --------------------------------------------------------------------------- arcs


def random_arc(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    c = rng.uniform(-100, 100, 3)
    u = np.cross(n, rng.normal(size=3))
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    r = rng.uniform(0.5, 200)
    phi = rng.uniform(0.05, 2 * math.pi - 0.05)
    dh = rng.uniform(-20, 20)
    start = c + r * u
    end = c + r * (math.cos(phi) * u + math.sin(phi) * w) + dh * n
    return c, n, r, phi, dh, start, end


def test_random_arcs_and_helices_on_the_curve_within_tolerance() -> None:
    rng = np.random.default_rng(7)
    for _ in range(2000):
        c, n, r, phi, dh, start, end = random_arc(rng)
        direction = "ccw" if rng.random() < 0.5 else "cw"
        turns = int(rng.integers(1, 4))
        sweep = arc_sweep(c, n, start, end, direction, turns)
        expected = (phi if direction == "ccw" else 2 * math.pi - phi) + 2 * math.pi * (turns - 1)
        assert sweep == pytest.approx(expected, abs=1e-9)
        tol = 10 ** rng.uniform(-4, -1)
        points, t = arc_points(c, n, start, end, sweep, direction, tol)
        np.testing.assert_allclose(points[-1], end, atol=1e-12)
        d = points - c
        h = d @ n
        radial = np.linalg.norm(d - h[:, None] * n, axis=1)
        np.testing.assert_allclose(radial, r, atol=1e-9 * max(1, r))
        np.testing.assert_allclose(h, t * dh, atol=1e-9)  # height linear in the swept angle
        chord_mid = 0.5 * (np.vstack([start, points[:-1]]) + points)
        dm = chord_mid - c
        sagitta = r - np.linalg.norm(dm - (dm @ n)[:, None] * n, axis=1)
        assert sagitta.max() <= tol * (1 + 1e-6)
        # the direction: the first step turns the right way about n
        step = np.cross(start - c, points[0] - c) @ n
        assert (step > 0) == (direction == "ccw")


def test_huge_arc_at_tiny_tolerance_is_refused() -> None:
    c, n = np.zeros(3), np.array([0.0, 0.0, 1.0])
    start, end = np.array([1e7, 0, 0]), np.array([0, 1e7, 0])
    with pytest.raises(ValueError, match="points at the chordal tolerance"):
        arc_points(c, n, start, end, 2 * math.pi * 100, "ccw", 1e-6)
    assert MAX_ARC_POINTS <= 1_000_000


def test_tangent_votes() -> None:
    c = np.zeros((1, 3))
    n = np.array([[0.0, 0.0, 1.0]])
    start, end = np.array([[10.0, 0, 0]]), np.array([[0.0, 10, 0]])
    # moving +Y into (10,0) and -X out of (0,10): counter-clockwise about +Z on both sides
    ccw, cw = tangent_votes(np.array([[10.0, -5, 0]]), start, end, np.array([[-5.0, 10, 0]]), c, n)
    assert (ccw[0], cw[0]) == (2, 0)
    ccw, cw = tangent_votes(np.array([[10.0, 5, 0]]), start, end, np.array([[5.0, 10, 0]]), c, n)
    assert (ccw[0], cw[0]) == (0, 2)
    ccw, cw = tangent_votes(np.full((1, 3), np.nan), start, end, np.array([[0.0, 20, 0]]), c, n)
    assert (ccw[0], cw[0]) == (0, 0)  # no neighbour before, a radial move after: no evidence
