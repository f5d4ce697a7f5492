"""Drilling cycles (verne_post.cl.cycles) against their documented definitions.

NX: ``nx_simulated`` below is a line-by-line transliteration of NX Post Builder's simulated
cycles (github.com/Unigraphics/PostBuilder, branch PB1980s,
POSTBUILD/pblib/custom_command/pb_cmd_simulated_cycles.tcl: PB_CMD_sim_cycle_drill_move,
_drill_dwell_move, _drill_deep_move, _drill_break_chip_move, _bore_move, _bore_dwell_move,
SIM_RTRCTO), in NX's own variables (rapid_to above the top, feed_to negative below it).
Other families: the peck depths are worked out by hand from the definitions in the tests.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from verne_post.cl.cycles import MAX_PECKS, CycleSpec, approach_moves, cycle_moves, parse_cycle, reactivated
from verne_post.cli import main


def raises(message: str):
    return pytest.raises(ValueError, match=f"^{re.escape(message)}$")


def nx_simulated(kind, rapid_to, feed_to, retract_to, step1=0.0, delay=0.0):
    """Heights along the spindle axis from the hole top, with the move kind, as NX's Tcl moves."""
    out = []

    def sim_rapid(h):
        out.append((h, "rapid"))

    def sim_feed(h):
        out.append((h, "feed"))

    sim_rapid(rapid_to)  # SIM_RAPID_APPROACH mom_cycle_rapid_to_pos (its move along the axis)
    if kind in ("drill", "drill_dwell"):
        sim_feed(feed_to)
        if kind == "drill_dwell":
            out.append((feed_to, "dwell", delay))
        sim_rapid(retract_to)
    elif kind in ("deep", "brkchp"):
        deep_depth = -step1
        rapid_pos = rapid_to
        while feed_to < deep_depth:
            deep_rapto = deep_depth + rapid_to + step1
            if rapid_pos > deep_rapto:
                sim_rapid(deep_rapto)
            sim_feed(deep_depth)
            if kind == "deep":
                sim_rapid(rapid_to)
            deep_depth = deep_depth - step1
        deep_rapto = deep_depth + rapid_to + step1
        if rapid_pos > deep_rapto:
            sim_rapid(deep_rapto)
        sim_feed(feed_to)
        sim_rapid(retract_to)
    elif kind in ("bore", "bore_dwell"):
        sim_feed(feed_to)
        if kind == "bore_dwell":
            out.append((feed_to, "dwell", delay))
        sim_feed(rapid_to)
        if retract_to > rapid_to:  # SIM_RTRCTO
            sim_rapid(retract_to)
    return out


def heights(moves, top, axis):
    """(height along the unit axis, kind, dwell) of each move; asserts every point is on the axis line."""
    a = axis / np.linalg.norm(axis)
    out = []
    for point, kind, dwell in moves:
        d = point - top
        h = float(d @ a)
        np.testing.assert_allclose(d, h * a, atol=1e-9)
        out.append((h, kind, dwell))
    return out


def random_frame(rng):
    axis = rng.normal(size=3)
    return rng.uniform(-200, 200, 3), axis * rng.uniform(0.5, 2.0) / np.linalg.norm(axis)


@pytest.mark.parametrize("seed", range(40))
def test_nx_forms_follow_nx_simulated_cycles(seed: int) -> None:
    rng = np.random.default_rng(seed)
    kind = ["drill", "drill_dwell", "deep", "brkchp", "bore", "bore_dwell"][seed % 6]
    rapid_to = float(rng.choice([0.0, 1.0, 3.0, rng.uniform(0, 5)]))
    feed_to = -float(rng.choice([0.0, 10.0, rng.uniform(0.1, 60)]))
    retract_to = rapid_to + float(rng.choice([0.0, rng.uniform(0, 20)]))
    step = float(rng.choice([5.0, rng.uniform(0.3, 12)]))
    delay = float(rng.uniform(0.1, 3.0))
    toks: list[float | str] = {
        "drill": ["DRILL"],
        "drill_dwell": ["DRILL", "DWELL", delay],
        "deep": ["DRILL", "DEEP", "STEP", step],
        "brkchp": ["DRILL", "BRKCHP", "STEP", step],
        "bore": ["BORE"],
        "bore_dwell": ["BORE", "DWELL", delay],
    }[kind]
    toks = [*toks, "RAPTO", rapid_to, "FEDTO", feed_to, "RTRCTO", retract_to, "MMPM", 250.0]
    spec = parse_cycle(toks)
    assert (spec.feed, spec.feed_unit, spec.depth) == (250.0, "MMPM", -feed_to)
    top, axis = random_frame(rng)
    got = heights(cycle_moves(spec, top, axis), top, axis)

    ref = nx_simulated(kind, rapid_to, feed_to, retract_to, step, delay)
    # NX also makes moves that do not move (some only by rounding: -step + rapid_to + step);
    # the expansion leaves those out.
    expected = [ref[0]]
    for m in ref[1:]:
        if m[1] == "dwell" or abs(m[0] - expected[-1][0]) > 1e-9:
            expected.append(m)
    assert [m[1] for m in got] == [m[1] for m in expected]
    np.testing.assert_allclose([m[0] for m in got], [m[0] for m in expected], atol=1e-9)
    assert [m[2] for m in got if m[1] == "dwell"] == [m[2] for m in expected if m[1] == "dwell"]


def feed_depths(moves, top, axis):
    return [-h for h, kind, _ in heights(moves, top, axis) if kind == "feed"]


def test_solidworks_deep2_first_and_subsequent_pecks() -> None:
    toks = ["DEEP2", "FEDTO", 10.1, "1STPECK", 5.0, "SUBPECK", 2.0, "MMPM", 1097.28, "RAPTO", 3.0, "RTRCTO", 10.0]
    spec = parse_cycle(toks)
    assert (spec.kind, spec.approach, spec.retract) == ("deep", 3.0, 10.0)
    top, axis = np.array([10.0, 20.0, 0.0]), np.array([0.0, 0.0, 1.0])
    moves = cycle_moves(spec, top, axis)
    hs = heights(moves, top, axis)
    # First peck 5, then 2 each, the last one whatever remains: 5, 7, 9, 10.1.
    np.testing.assert_allclose(feed_depths(moves, top, axis), [5.0, 7.0, 9.0, 10.1])
    # Full retract to the approach height after each peck, rapid back to 3 above the last bottom.
    expected = [
        (3.0, "rapid"), (-5.0, "feed"), (3.0, "rapid"), (-2.0, "rapid"), (-7.0, "feed"), (3.0, "rapid"),
        (-4.0, "rapid"), (-9.0, "feed"), (3.0, "rapid"), (-6.0, "rapid"), (-10.1, "feed"), (10.0, "rapid"),
    ]  # fmt: skip
    assert [k for _, k, _ in hs] == [k for _, k in expected]
    np.testing.assert_allclose([h for h, _, _ in hs], [h for h, _ in expected])


def test_solidworks_drill_with_no_dwell() -> None:
    toks = ["DRILL", "FEDTO", 2.75344, "MMPM", 731.52, "RAPTO", 3.0, "RTRCTO", 10.0, "DWELL", 0.0]
    spec = parse_cycle(toks)
    assert spec.dwell == 0.0
    top, axis = np.zeros(3), np.array([0.0, 0.0, 1.0])
    hs = heights(cycle_moves(spec, top, axis), top, axis)
    assert [(h, k) for h, k, _ in hs] == [(3.0, "rapid"), (-2.75344, "feed"), (10.0, "rapid")]


def test_nx_countersink_feeds_to_the_point_itself() -> None:
    spec = parse_cycle(["DRILL", "RAPTO", 3.0, "FEDTO", 0.0, "MMPM", 250.0])
    top, axis = np.array([1.0, 2.0, 3.0]), np.array([0.0, 1.0, 0.0])
    hs = heights(cycle_moves(spec, top, axis), top, axis)
    assert [(h, k) for h, k, _ in hs] == [(3.0, "rapid"), (0.0, "feed"), (3.0, "rapid")]


@pytest.mark.parametrize("subtype", ["DEEP", "BRKCHP"])
def test_nx_deep_without_a_step_to_the_point_itself_is_one_feed(subtype: str) -> None:
    """NX's CYCLE/DRILL,DEEP,RAPTO,3,FEDTO,0 (no STEP): Post Builder's simulated deep cycle with
    step1 = 0 feeds once to the point (its peck loop never runs)."""
    spec = parse_cycle(["DRILL", subtype, "RAPTO", 3.0, "FEDTO", 0.0, "MMPM", 250.0])
    top, axis = np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.6, 0.8])
    hs = heights(cycle_moves(spec, top, axis), top, axis)
    expected = nx_simulated(subtype.lower(), 3.0, 0.0, 3.0, step1=0.0)
    assert [(h, k) for h, k, _ in hs] == [(pytest.approx(h), k) for h, k in expected]
    assert [k for _, k in expected] == ["rapid", "feed", "rapid"]


def test_creo_deep_and_peck_table() -> None:
    spec = parse_cycle(["DEEP", "DEPTH", 3.5, "STEP", 1.0, "MMPM", 50.0, "CLEAR", 2.0])
    top, axis = np.zeros(3), np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(feed_depths(cycle_moves(spec, top, axis), top, axis), [1.0, 2.0, 3.0, 3.5])
    # PTC's peck table example: steps .38, .3325, .19, then .095 repeated, depth 1.285409.
    toks = ["DEEP", "DEPTH", 1.285409, "STEP", 0.38, "STEP", 0.3325, "STEP", 0.19, "IPM", 12.0]
    toks += ["STEP", 0.095, "IPM", 12.0, "CLEAR", 1.0]
    spec = parse_cycle(toks)
    expected = [0.38, 0.7125, 0.9025, 0.9975, 1.0925, 1.1875, 1.2825, 1.285409]
    np.testing.assert_allclose(feed_depths(cycle_moves(spec, top, axis), top, axis), expected)
    with raises("CYCLE/DEEP gives a second feed (a peck table with changing feeds is not supported)"):
        parse_cycle([*toks[:-2], "IPM", 10.0, "CLEAR", 1.0])


def test_creo_chip_break_with_back_off() -> None:
    toks = ["BRKCHP", "DEPTH", 4.0, "STEP", 1.5, "MMPM", 80.0, "CLEAR", 2.0, "BACK", 0.25]
    spec = parse_cycle(toks)
    assert spec.chip_break == 0.25
    top, axis = np.zeros(3), np.array([0.0, 0.0, -1.0])
    hs = heights(cycle_moves(spec, top, axis), top, axis)
    expected = [(2.0, "rapid"), (-1.5, "feed"), (-1.25, "rapid"), (-3.0, "feed"), (-2.75, "rapid"), (-4.0, "feed")]
    expected.append((2.0, "rapid"))
    assert [k for _, k, _ in hs] == [k for _, k in expected]
    np.testing.assert_allclose([h for h, _, _ in hs], [h for h, _ in expected])


def test_classic_positional_apt() -> None:
    spec = parse_cycle(["DRILL", 0.5, "IPM", 10.0, 0.1, "RAPTO", 0.05, "DWELL", 1.5])
    assert (spec.depth, spec.feed, spec.feed_unit, spec.approach, spec.retract) == (0.5, 10.0, "IPM", 0.05, 0.1)
    top, axis = np.zeros(3), np.array([0.0, 0.0, 1.0])
    moves = cycle_moves(spec, top, axis)
    dwells = [(m[0], m[2]) for m in moves if m[1] == "dwell"]
    assert len(dwells) == 1 and dwells[0][1] == 1.5
    np.testing.assert_allclose(dwells[0][0], [0.0, 0.0, -0.5])
    assert [m[1] for m in moves] == ["rapid", "feed", "dwell", "rapid"]
    spec = parse_cycle(["DEEP", 2.0, "INCR", 0.5, "IPM", 8.0, 0.1])
    np.testing.assert_allclose(feed_depths(cycle_moves(spec, top, axis), top, axis), [0.5, 1.0, 1.5, 2.0])


def test_feed_and_retract_words() -> None:
    assert parse_cycle(["DRILL", "DEPTH", 5.0, "FEDRAT", 120.0, "CLEAR", 2.0]).feed_unit is None
    spec = parse_cycle(["DRILL", "DEPTH", 5.0, "FEDRAT", "IPM", 12.0, "CLEAR", 2.0])
    assert (spec.feed, spec.feed_unit) == (12.0, "IPM")
    spec = parse_cycle(["DRILL", "DEPTH", 5.0, 0.2, "MMPR", "RAPTO", 2.0, "RTRCTO", "AUTO"])
    assert (spec.feed, spec.feed_unit, spec.retract_auto, spec.retract) == (0.2, "MMPR", True, 2.0)
    assert parse_cycle(["DRILL", "DEPTH", 5.0, "CLEAR", 2.0]).feed is None
    spec = parse_cycle(["DEEP", "DEPTH", 5.0, "STEP", 1.0, "CLEAR", 5.0, "RAPTO", 1.0, "RETURN", 8.0])
    assert (spec.approach, spec.retract) == (1.0, 8.0)


@pytest.mark.parametrize("seed", range(200))
def test_safety_invariants(seed: int) -> None:
    """Every move on the axis; rapids never below the deepest point reached so far; feeds only
    go down to new depth (or out, boring); nothing below the depth; start at approach, end at retract."""
    rng = np.random.default_rng(1000 + seed)
    kind = ["drill", "deep", "brkchp", "bore"][seed % 4]
    depth = float(rng.choice([0.0, rng.uniform(0, 80)]))
    approach = float(rng.uniform(0, 6))
    pecks = tuple(float(x) for x in rng.uniform(0.2, 9, int(rng.integers(1, 4)))) if kind in ("deep", "brkchp") else ()
    spec = CycleSpec(
        kind=kind,
        depth=depth,
        approach=approach,
        retract=approach + float(rng.uniform(0, 10)),
        pecks=pecks,
        chip_break=float(rng.uniform(0.05, 4)) if kind == "brkchp" else None,
        dwell=float(rng.choice([0.0, 1.0])),
    )
    top, axis = random_frame(rng)
    hs = heights(cycle_moves(spec, top, axis), top, axis)
    assert (hs[0][1], hs[-1][1]) == ("rapid", "rapid")
    assert (hs[0][0], hs[-1][0]) == pytest.approx((approach, spec.retract), abs=1e-9)
    deepest = -approach  # depth below the top reached so far (negative: still above)
    prev = approach
    for h, kind_, _ in hs:
        assert h >= -depth - 1e-9
        if kind_ == "rapid":
            assert -h <= max(deepest, 0.0) + 1e-9  # a rapid never enters uncut material
        elif kind_ == "feed":
            assert h < prev or spec.kind == "bore"
        deepest = max(deepest, -h)
        prev = h
    assert deepest == pytest.approx(depth, abs=1e-9)
    assert sum(1 for _, k, _ in hs if k == "dwell") == (1 if spec.dwell else 0)


@pytest.mark.parametrize("seed", range(300))
def test_positioning_over_a_hole_never_descends_while_it_travels(seed: int) -> None:
    # NX's SIM_RAPID_APPROACH: the move along the spindle axis first when it goes up, last when
    # it goes down; each leg purely along or purely across the axis
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    start, target = rng.uniform(-100, 100, 3), rng.uniform(-100, 100, 3)
    if seed % 10 == 0:
        target = start + rng.uniform(-5, 5) * axis  # straight along the axis: one leg
    points = approach_moves(start, target, axis)
    np.testing.assert_allclose(points[-1], target, atol=1e-12)
    legs = np.diff(np.vstack([start, *points]), axis=0)
    assert len(legs) == (1 if seed % 10 == 0 else 2)
    for leg in legs:
        along = leg @ axis
        assert np.linalg.norm(leg - along * axis) < 1e-9 or abs(along) < 1e-9
    heights = [float(p @ axis) for p in [start, *points]]
    if heights[-1] < heights[0]:
        assert heights[-2] == pytest.approx(heights[0], abs=1e-9)  # travelled at the start's height
    else:
        assert heights[1] == pytest.approx(heights[-1], abs=1e-9)  # up first


def test_cycle_on_with_changes_replaces_or_adds_values() -> None:
    # NX: CYCLE/ON,FEDTO,-74.5,... after CYCLE/DRILL,DEEP,...
    defined = ["DRILL", "DEEP", "STEP", 20.0, "CLEAR", 3.0, "FEDTO", -72.0, "MMPM", 100.0]
    toks = reactivated(defined, ["FEDTO", -74.5, "RTRCTO", "AUTO"])
    assert toks == ["DRILL", "DEEP", "STEP", 20.0, "CLEAR", 3.0, "FEDTO", -74.5, "MMPM", 100.0, "RTRCTO", "AUTO"]
    spec = parse_cycle(toks)
    assert (spec.depth, spec.retract_auto, spec.pecks) == (74.5, True, (20.0,))
    with raises("CYCLE/ON: expected keyword,value pairs, got 3.0"):
        reactivated(defined, [3.0])
    # a flag word alone; a feed in another unit replaces the old one
    toks = reactivated(defined, ["RTRCTO", 5.0, "MANUAL", "MMPR", 0.2])
    assert toks == ["DRILL", "DEEP", "STEP", 20.0, "CLEAR", 3.0, "FEDTO", -72.0, "MMPR", 0.2, "RTRCTO", 5.0, "MANUAL"]
    assert parse_cycle(["DRILL", "CSINK", "RAPTO", 2.0, "FEDTO", -3.0, "MMPM", 80.0]).depth == 3.0


def test_creo_fixed_format_deep_cycle() -> None:
    # PTC Creo help, "CL Output for Holemaking Cycles", cycle_format fixed: CYCLE / type, z, f, units, t, r, i
    spec = parse_cycle(["DEEP", 5.0, 80.0, "MMPM", 2.0, 1.0])
    assert (spec.depth, spec.feed, spec.feed_unit, spec.approach, spec.pecks) == (5.0, 80.0, "MMPM", 2.0, (1.0,))
    with raises("CYCLE/DRILL: unexpected number 1"):
        parse_cycle(["DRILL", 5.0, 80.0, "MMPM", 2.0, 1.0])


def test_manual_retract_is_the_retract_value() -> None:
    # NX Post Builder, mom_cycle_retract_mode: MANUAL is G99, back to the retract value
    spec = parse_cycle(["DRILL", "RAPTO", 3.0, "FEDTO", -33.0, "RTRCTO", 4.0, "MANUAL", "IPR", 0.25])
    assert (spec.retract, spec.retract_auto, spec.depth) == (4.0, False, 33.0)


TAPPING = "tapping needs the feed synchronised with the spindle, which a joint-space program cannot express"


def tokens(record: str) -> list[float | str]:
    """Tokens of a CYCLE record's arguments as the reader splits them: numbers as float."""
    out: list[float | str] = []
    for word in record.split(","):
        try:
            out.append(float(word))
        except ValueError:
            out.append(word)
    return out


@pytest.mark.parametrize(
    ("record", "message"),
    [
        ("TAP,FEDTO,-10,RAPTO,3", f"CYCLE/TAP: {TAPPING}"),
        ("DRILL,TAP,FEDTO,-10", f"CYCLE/DRILL,TAP: {TAPPING}"),
        (
            "BORE,DRAG,FEDTO,-10,RAPTO,3",
            "CYCLE/BORE,DRAG: boring with the spindle stopped before the retract (DRAG) cannot be expressed as moves",
        ),
        ("BORE,BACK,FEDTO,-10,RAPTO,3", "CYCLE/BORE,BACK: back boring needs spindle orientation and a shift (BACK)"),
        ("SPOT,DEPTH,1", "CYCLE/SPOT is not a known cycle"),
        ("3,DRILL", "CYCLE needs a cycle type (e.g. CYCLE/DRILL)"),
        ("DRILL,RAPTO,3,FEDTO,-1,PECKS,2", "CYCLE/DRILL: unknown word 'PECKS'"),
        ("DRILL,DEPTH,-2,CLEAR,1", "CYCLE/DRILL depth must not be negative, got -2"),
        ("DRILL,DEPTH,2,FEDTO,-2,CLEAR,1", "CYCLE/DRILL gives both DEPTH and FEDTO"),
        ("DRILL,RAPTO,3", "CYCLE/DRILL has no depth (give DEPTH,d or FEDTO,d)"),
        ("DRILL,FEDTO,-3,MMPM,100", "CYCLE/DRILL has no clearance: give CLEAR,c or RAPTO,r"),
        ("DRILL,FEDTO,-3,RAPTO,-1", "CYCLE/DRILL RAPTO must not be negative, got -1"),
        ("DRILL,FEDTO,-3,RAPTO,1,RAPTO,2", "CYCLE/DRILL: RAPTO given twice"),
        ("DRILL,FEDTO,-3,RAPTO,1,RTRCTO,AUTO,RTRCTO,5", "CYCLE/DRILL: RTRCTO given twice"),
        ("DRILL,FEDTO,-3,RAPTO,MMPM,100", "CYCLE/DRILL: RAPTO needs a number"),
        ("DRILL,DEEP,FEDTO,-30,RAPTO,3", "CYCLE/DRILL,DEEP pecks to 30 below the point but gives no peck depth "
                                         "(STEP, INCR or 1STPECK): NX's own cycle pecks by the step and never gets "
                                         "below the point without one"),
        ("DRILL,FEDTO,-30,RAPTO,3,STEP,5", "CYCLE/DRILL does not peck but gives peck depths"),
        ("DEEP,FEDTO,-30,RAPTO,3,STEP,0", "CYCLE/DEEP peck depths must be positive, got 0"),
        ("DEEP2,FEDTO,9,1STPECK,3,STEP,1,RAPTO,3", "CYCLE/DEEP2 gives both STEP/INCR and 1STPECK/SUBPECK"),
        (
            "BRKCHP,DEPTH,9,STEP,1,CLEAR,2,DWELL,0.5",
            "CYCLE/BRKCHP with DWELL is ambiguous (a dwell at every peck or at the bottom)",
        ),
        (
            "BRKCHP,DEPTH,9,STEP,1,CLEAR,2,REV,2",
            "CYCLE/BRKCHP: chip breaking by spindle revolutions (REV) is not supported",
        ),
        ("DRILL,DEPTH,9,CLEAR,2,BACK,0.5", "CYCLE/DRILL: BACK (chip-break back-off) belongs to BRKCHP only"),
        ("DRILL,DEPTH,9,CLEAR,2,7", "CYCLE/DRILL: unexpected number 7"),
        ("DRILL,DEPTH,9,CLEAR,2,MMPM,0", "CYCLE/DRILL feed must be positive, got 0"),
        ("OFF", "CYCLE/OFF: CYCLE/ON and CYCLE/OFF are not cycle definitions"),
    ],
)
def test_rejections(record: str, message: str) -> None:
    with raises(message):
        parse_cycle(tokens(record))


def test_bounded_pecks_and_bad_axis() -> None:
    spec = parse_cycle(["DEEP", "DEPTH", 1000.0, "STEP", 0.001, "CLEAR", 1.0])
    with raises(f"a hole 1000 deep in pecks of 0.001 needs more than {MAX_PECKS} pecks: check the depth and the peck "
                "depth"):
        cycle_moves(spec, np.zeros(3), np.array([0.0, 0.0, 1.0]))
    spec = parse_cycle(["DRILL", "DEPTH", 1.0, "CLEAR", 1.0])
    with raises("cycle needs a finite hole top and a non-zero tool axis"):
        cycle_moves(spec, np.zeros(3), np.zeros(3))


def test_a_hole_of_too_many_pecks_is_an_error_at_its_cycle_record(tmp_path: Path) -> None:
    """A fuzzed DEEP cycle, 1000 mm in pecks of 1 micrometre: one line at the CYCLE record, exit 2."""
    path = tmp_path / "pecks.cls"
    path.write_text("PARTNO/PECKS\nUNITS/MM\nLOADTL/1\nFEDRAT/MMPM,100\nGOTO/0,0,50,0,0,1\n"
                    "CYCLE/DEEP,DEPTH,1000,STEP,0.001,CLEAR,1\nGOTO/10,10,0,0,0,1\nCYCLE/OFF\nFINI\n")
    result = CliRunner().invoke(main, ["check", str(path), "-q", "--no-timing"])
    assert result.exit_code == 2
    assert result.output == (f"verne-post: error: {path}:6: CYCLE/DEEP: a hole 1000 deep in pecks of 0.001 needs "
                             f"more than {MAX_PECKS} pecks: check the depth and the peck depth\n")
