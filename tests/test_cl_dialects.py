"""CAM dialects: arc direction, helices, frames and records as each CAM system documents them.

The expected geometry is computed here independently of the reader (its own tiny record
scanner and circle maths), from the vendors' documented conventions and the real files in
``tests/data/cl-samples`` (see their SOURCES.md).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from verne_post.cl import read_cl
from verne_post.cl.toolpath import MOTION_KINDS, Coolant, Dwell, ToolChange, Toolpath
from verne_post.errors import InputError

SAMPLES = Path(__file__).resolve().parent / "data" / "cl-samples"
NX_ZLEVEL = SAMPLES / "nx_zlevel_coremill_mm.cls"
MAKINO = SAMPLES / "makino_ffcam_plane1_mm.cldata"
CREO_ROUGH = SAMPLES / "creo8_schruppen_roughing_mm.ncl"
CREO_PROFILE = SAMPLES / "creo8_profilfraesen_mm.ncl"
CREO_THREAD = SAMPLES / "creo_v19_thread_mill_helical_inch.ncl"
CATIA_ISO = SAMPLES / "catia_v5_isoparametric_5axis_mm.aptsource"
CL_SUFFIXES = (".cls", ".ncl", ".cldata", ".aptsource")

NX_HEAD = "TOOL PATH/OP,TOOL,EM10\n$$ centerline data\nUNITS/MM\nFEDRAT/MMPM,100\n"  # NX CLSF (4 lines)
CREO_HEAD = "$$*          Pro/CLfile  Version 8.0 - 8.0.3.0\nUNITS / MM\nFEDRAT / 100.0,  MMPM\n"  # 3 lines
APT_HEAD = "UNITS/MM\nFEDRAT/MMPM,100\n"  # generic APT (2 lines)
ARC = MOTION_KINDS.index("arc")


def read(tmp_path: Path, text: str, **kw: object) -> Toolpath:
    path = tmp_path / "t.cls"
    path.write_text(text)
    return read_cl(path, **kw)  # type: ignore[arg-type]


def refused(tmp_path: Path, text: str, **kw: object) -> InputError:
    path = tmp_path / "t.cls"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        read_cl(path, **kw)  # type: ignore[arg-type]
    assert "\n" not in str(info.value)
    return info.value


def swept(tp: Toolpath, centre: np.ndarray, normal: np.ndarray, mask: np.ndarray) -> float:
    """Signed angle (rad, right-hand about ``normal``) swept by the poses in ``mask`` around ``centre``."""
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)
    d = tp.tip[mask] - centre
    ang = np.unwrap(np.arctan2(d @ w, d @ u))
    return float(ang[-1] - ang[0])


def arc_poses(tp: Toolpath) -> np.ndarray:
    """Mask of the arc poses and the pose each arc starts from."""
    mask = tp.motion == ARC
    mask[np.flatnonzero(mask[1:] & ~mask[:-1])] = True
    return mask


# --------------------------------------------------------------------------- layout


def _relayout(text: str, rng: np.random.Generator, split: bool) -> str:
    """The same records laid out differently, as APT allows: spaces around every comma and slash
    ("spaces can appear anywhere in the record", Vericut's "Supported APT-CLS NC Program Records"),
    CRLF line ends, and, with ``split``, records cut at a comma and continued with '$'."""
    out = []
    for line in text.splitlines():
        head = line.lstrip().upper()
        if "/" not in line or "$" in line or head.startswith(("PPRINT", "PARTNO", "INSERT")):
            out.append(line)
            continue
        word, _, args = line.partition("/")
        parts = args.split(",")
        pads = [" " * int(k) for k in rng.integers(0, 3, 2 * len(parts))]
        args = ",".join(pads[2 * k] + p.strip() + pads[2 * k + 1] for k, p in enumerate(parts))
        line = word + " " * int(rng.integers(0, 3)) + "/" + args
        if split and len(parts) > 2:
            cut = [m.start() for m in re.finditer(",", line)][int(rng.integers(0, len(parts) - 1))]
            line = line[:cut + 1] + "  $\n    " + line[cut + 1:]
        out.append(line)
    return "\r\n".join(out) + "\r\n"


@pytest.mark.parametrize("name", sorted(p.name for p in SAMPLES.iterdir() if p.suffix != ".md"))
@pytest.mark.parametrize("split", [False, True])
def test_real_files_read_the_same_in_another_layout(tmp_path: Path, name: str, split: bool) -> None:
    # the reader's one-line fast route and its general route must agree on the vendors' own files
    original = read_cl(SAMPLES / name)
    text = (SAMPLES / name).read_text(encoding="utf-8", errors="replace")
    relaid = read(tmp_path, _relayout(text, np.random.default_rng(len(name)), split))
    for field in ("tip", "axis", "feed", "rapid", "motion", "tool", "inverse_time"):
        np.testing.assert_array_equal(getattr(relaid, field), getattr(original, field), err_msg=field)
    if not split:
        np.testing.assert_array_equal(relaid.line, original.line)
    assert [type(e).__name__ for e in relaid.events] == [type(e).__name__ for e in original.events]


# --------------------------------------------------------------------------- direction per dialect


def quarter(head: str, axis: str = "0,0,1") -> str:
    return head + f"GOTO/10,0,0\nCIRCLE/0,0,0,{axis},10\nGOTO/0,10,0\n"


def test_nx_arcs_run_clockwise_about_the_axis(tmp_path: Path) -> None:
    # NX CLSF Manager: "i,j,k is the circle or helix axis vector in the MCS (assuming a clockwise
    # direction)": from +X to +Y clockwise about +Z is the 270-degree way through -Y.
    tp = read(tmp_path, quarter(NX_HEAD))
    assert "Siemens NX" in tp.dialect and "clockwise" in tp.dialect
    assert swept(tp, np.zeros(3), np.array([0, 0, 1.0]), np.ones(len(tp), bool)) == pytest.approx(-1.5 * math.pi)
    assert tp.tip[:, 1].min() == pytest.approx(-10, abs=1e-3)
    # the same arc written about -Z is the short way
    tp = read(tmp_path, quarter(NX_HEAD, "0,0,-1"))
    assert swept(tp, np.zeros(3), np.array([0, 0, 1.0]), np.ones(len(tp), bool)) == pytest.approx(0.5 * math.pi)


def test_creo_arcs_run_counter_clockwise(tmp_path: Path) -> None:
    tp = read(tmp_path, quarter(CREO_HEAD).replace("GOTO/", "GOTO / "))
    assert "Creo" in tp.dialect
    assert swept(tp, np.zeros(3), np.array([0, 0, 1.0]), np.ones(len(tp), bool)) == pytest.approx(0.5 * math.pi)


def test_creo_arc_points_listed_after_the_goto_stay_on_the_arc(tmp_path: Path) -> None:
    # PTC Creo help, "CL Output for Circular Interpolation": after CIRCLE, "GOTO / x, y, z" then
    # plain lines "x, y, z", "the points on the arc, the last line specifying the arc end point"
    # (POINTS_&_ARC, or ARC_ONLY with NUMBER_OF_ARC_PTS). Arcs of up to 350 degrees through a few
    # listed points: every pose on the circle, through each point, in order, the whole sweep.
    rng = np.random.default_rng(5)
    lines, cases = CREO_HEAD.rstrip("\n").split("\n"), []
    for _ in range(60):
        c, r = rng.uniform(-50, 50, 3), rng.uniform(1, 40)
        sweep = rng.uniform(0.2, math.radians(350))
        angles = np.sort(rng.uniform(0, sweep, rng.integers(0, 6)))
        angles = np.r_[angles[angles > 1e-3], sweep]
        points = c + r * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(len(angles))])
        start = c + np.array([r, 0, 0])
        lines += [f"GOTO / {start[0]:.10f}, {start[1]:.10f}, {start[2]:.10f}",
                  f"CIRCLE / {c[0]:.10f}, {c[1]:.10f}, {c[2]:.10f},  $", f"0.0, 0.0, 1.0,  {r:.10f}"]
        first = len(lines) + 1
        lines += [("GOTO / " if k == 0 else "        ") + ", ".join(f"{v:.10f}" for v in p)
                  for k, p in enumerate(points)]
        cases.append((c, r, sweep, points, first))
        lines.append(f"GOTO / {start[0]:.10f}, {start[1]:.10f}, {start[2] + 5:.10f}")  # off the arc
    tp = read(tmp_path, "\n".join(lines) + "\n")
    assert tp.warnings == ()
    for c, r, sweep, points, first in cases:
        at = [int(np.flatnonzero(tp.line == first + k)[-1]) for k in range(len(points))]
        begin = at[0] - int(np.sum(tp.line == first))
        mask = np.zeros(len(tp), bool)
        mask[begin:at[-1] + 1] = True
        np.testing.assert_allclose(tp.tip[at], points, atol=1e-9)
        d = tp.tip[mask] - c
        np.testing.assert_allclose(np.hypot(d[:, 0], d[:, 1]), r, rtol=1e-8)
        assert swept(tp, c, np.array([0, 0, 1.0]), mask) == pytest.approx(sweep, abs=1e-8)
        steps = np.diff(np.unwrap(np.arctan2(d[:, 1], d[:, 0])))
        assert np.all(steps > 0)  # counter-clockwise all along
        assert np.max(r * (1 - np.cos(steps / 2))) <= 0.001 * (1 + 1e-9)  # on the arc, not its chords


def test_creo_nurbs_motion_is_its_point_to_point_gotos(tmp_path: Path) -> None:
    # PTC Creo help, "CL Output for NURBS Interpolation": MOVNRB/ON,o,k,w,n,s, knots, control points,
    # then MOVNRB/NEXT and "the actual point-to-point output" as GOTOs, then MOVNRB/OFF
    text = CREO_HEAD + ("GOTO / 0, 0, 0\nMOVNRB / M3AXIS\nMOVNRB / ON, 4, 8, 0, 4, 30.0\n"
                        "MOVNRB / 1, 0, 0, 0, 0, 1, 1, 1, 1\nMOVNRB / 2, 0, 0, 0, 10, 5, 0, $\n20, 5, 0, 30, 0, 0\n"
                        "MOVNRB / NEXT\nGOTO / 10, 3.75, 0\nGOTO / 20, 3.75, 0\nGOTO / 30, 0, 0\nMOVNRB / OFF\n")
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.tip, [[0, 0, 0], [10, 3.75, 0], [20, 3.75, 0], [30, 0, 0]])
    assert tp.warnings == ()


def test_creo_inverse_time_auto_keeps_the_programmed_feed(tmp_path: Path) -> None:
    # PTC Creo help, "Supported CL Data Commands": FEDRAT / INVERS, AUTO "specifies the inverse time
    # feed rate ... for machines with rotary axes", FEDRAT / INVERS, OFF ends it: no value, the
    # post computes inverse time from the feed programmed before
    text = CREO_HEAD + ("GOTO / 0, 0, 10\nFEDRAT / 250.0, MMPM\nFEDRAT / INVERS, AUTO\n"
                        "GOTO / 10, 0, 10, 0, 0.1, 0.99498743710662\nFEDRAT / INVERS, OFF\nGOTO / 20, 0, 10\n")
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.feed, [100, 250, 250])
    assert tp.warnings == () and not tp.inverse_time.any()


def test_nx_origin_is_setup_information_not_a_frame(tmp_path: Path) -> None:
    # NX Post Builder, mom_origin: "the distance from the origin of the MCS to the center of the
    # rotary table"; the GOTO data stay in the MCS
    tp = read(tmp_path, NX_HEAD + "ORIGIN/10,20,30\nGOTO/10,0,0\n")
    np.testing.assert_allclose(tp.tip, [[10, 0, 0]])
    assert len(tp.warnings) == 1 and "ORIGIN read as Siemens NX CLSF's setup information" in tp.warnings[0]
    moved = read(tmp_path, APT_HEAD + "ORIGIN/10,20,30\nGOTO/10,0,0\n", frame="apply")  # a frame elsewhere
    np.testing.assert_allclose(moved.tip, [[20, 20, 30]])


def test_nx_gohome_with_its_own_point_and_dwell_in_revolutions(tmp_path: Path) -> None:
    # NX Post Builder: mom_gohome_pos (GOHOME's own point), mom_delay_revs (a dwell in revolutions)
    text = NX_HEAD + "SPINDL/RPM,1200,CLW\nGOTO/10,0,0\nDELAY/REV,6\nDELAY/2.5\nGOHOME/50,50,200\n"
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.tip, [[10, 0, 0], [50, 50, 200]])
    assert tp.rapid.tolist() == [False, True]
    assert [e.seconds for e in tp.events if isinstance(e, Dwell)] == pytest.approx([0.3, 2.5])
    e = refused(tmp_path, NX_HEAD + "GOTO/10,0,0\nDELAY/REV,6\n")
    assert e.line == 6 and "needs a spindle speed" in e.reason


def test_nx_tool_preselect_operations_and_cycles_as_nx_post_builder_defines_them(tmp_path: Path) -> None:
    # NX Post Builder (ude.cdl, mom_vars_csv.txt): SELECT/TOOL is the tool_preselect event, LOAD/TOOL
    # the change; each TOOL PATH is a path of its own; RTRCTO,AUTO is G98, whose initial level is
    # where the tool was as the cycle began (a FROM before the first load too), kept while it runs;
    # COOLNT/TAP is M8
    text = ("TOOL PATH/DRILL,TOOL,D8\n$$ centerline data\nUNITS/MM\nFROM/0,0,100\nLOAD/TOOL,1\n"
            "SPINDL/RPM,1000,CLW\nCYCLE/DRILL,RAPTO,3,FEDTO,-10,MMPM,250,RTRCTO,AUTO\nGOTO/0,0,0\nSELECT/TOOL,2\n"
            "CYCLE/ON,RTRCTO,10,MANUAL\nGOTO/10,0,0\nCYCLE/ON,RTRCTO,AUTO,MMPR,0.1\nGOTO/20,0,0\n"
            "END-OF-PATH\nTOOL PATH/MILL,TOOL,EM10\nCOOLNT/TAP\nFEDRAT/MMPM,500\nGOTO/30,0,0\nGOTO/40,0,0\n")
    tp = read(tmp_path, text)
    assert tp.warnings == ()
    assert [(c.tool, c.line) for c in tp.events if isinstance(c, ToolChange)] == [(1, 5)]
    assert [e.mode for e in tp.events if isinstance(e, Coolant)] == ["FLOOD"]
    np.testing.assert_allclose(tp.tip[tp.line == 8], [[0, 0, 3], [0, 0, -10], [0, 0, 100]])
    np.testing.assert_allclose(tp.tip[tp.line == 11], [[10, 0, 100], [10, 0, 3], [10, 0, -10], [10, 0, 10]])
    np.testing.assert_allclose(tp.tip[tp.line == 13], [[20, 0, 10], [20, 0, 3], [20, 0, -10], [20, 0, 100]])
    np.testing.assert_allclose(tp.tip[tp.line >= 17], [[30, 0, 0], [40, 0, 0]])  # the cycle ended with its path
    e = refused(tmp_path, NX_HEAD + "CYCLE/DRILL,RAPTO,3,FEDTO,-10,MMPM,250,RTRCTO,AUTO\nGOTO/0,0,0\n")
    assert e.line == 6 and "RTRCTO,AUTO" in e.reason and "no position before it" in e.reason
    e = refused(tmp_path, NX_HEAD + "GOTO/0,0,0\nTHREAD/TURN,1.5\n")
    assert e.line == 6 and "THREAD" in e.reason


def test_length_compensation_is_not_cutter_compensation(tmp_path: Path) -> None:
    tp = read(tmp_path, APT_HEAD + "CUTCOM/ON,LENGTH,3\nGOTO/10,0,0\n")
    assert tp.warnings == ()


AUTODESK_HEAD = "MACHIN/HAAS\nMODE/MILL\nPARTNO/'1001'\nPPRINT/'1001'\nUNITS/MM\nMULTAX/OFF\n"  # 6 lines


def test_autodesk_positional_cycle_point_is_the_hole_bottom(tmp_path: Path) -> None:
    # Autodesk's Common ISO 4343 APT post: onCycle writes CYCLE/DRILL, d, MMPM, f, c, RAPTO, r with
    # c = cycle.clearance (a height) and r = c - cycle.retract; onCyclePoint the hole bottom.
    # Hole tops Z0 and Z-2, bottoms 10 below; clearance plane Z15, retract plane Z5 for both.
    text = AUTODESK_HEAD + ("RAPID\nGOTO/20.0, 0.0, 15.0\nCYCLE/DRILL, 10.0, MMPM, 100.0, 15.0, RAPTO, 10.0\n"
                            "FEDRAT/100.0, MMPM\nGOTO/20.0, 0.0, -10.0\nFEDRAT/100.0, MMPM\nGOTO/40.0, 0.0, -12.0\n"
                            "CYCLE/OFF\n")
    tp = read(tmp_path, text)
    assert "Autodesk" in tp.dialect
    np.testing.assert_allclose(tp.tip[tp.line == 11], [[20, 0, 5], [20, 0, -10], [20, 0, 15]])
    np.testing.assert_allclose(tp.tip[tp.line == 13], [[40, 0, 15], [40, 0, 5], [40, 0, -12], [40, 0, 15]])
    # the same record elsewhere is classic APT: the GOTO is the top, 15 the clearance above it
    classic = read(tmp_path, APT_HEAD + "GOTO/20,0,40\nCYCLE/DRILL,10,MMPM,100,15\nGOTO/20,0,0\nCYCLE/OFF\n")
    np.testing.assert_allclose(classic.tip[classic.line == 5], [[20, 0, 15], [20, 0, -10], [20, 0, 15]])


def test_autodesk_cycles_below_the_work_zero_as_its_post_writes_them(tmp_path: Path) -> None:
    # The same post with the work zero on the stock top and the holes on a step 50 below it:
    # cycle.clearance and cycle.retract are heights in the work frame (c = -35, retract -45, so
    # r = 10), the hole tops at Z-50, the bottoms 12 below. Peck depths count from the top.
    text = AUTODESK_HEAD + ("RAPID\nGOTO/10.0, 10.0, -35.0\nCYCLE/DRILL, 12.0, MMPM, 200.0, -35.0, RAPTO, 10.0\n"
                            "FEDRAT/200.0, MMPM\nGOTO/10.0, 10.0, -62.0\nCYCLE/OFF\n"
                            "CYCLE/DEEP, 12.0, INCR, 5.0, MMPM, 200.0, -35.0, RAPTO, 10.0\n"
                            "FEDRAT/200.0, MMPM\nGOTO/30.0, 10.0, -62.0\nCYCLE/OFF\n")
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.tip[tp.line == 11], [[10, 10, -45], [10, 10, -62], [10, 10, -35]])
    hole, rapid = tp.tip[tp.line == 15], tp.rapid[tp.line == 15]
    np.testing.assert_allclose(hole[:2], [[30, 10, -35], [30, 10, -45]])
    np.testing.assert_allclose(hole[~rapid, 2], [-55, -60, -62])  # pecks of 5 from the top, then the bottom
    assert hole[-1, 2] == pytest.approx(-35)
    # its chip breaking: pecks of 5 from the top, each backing off as far as the approach (5, not
    # RAPTO's 10, the distance between its two planes), and the dwelling period at the bottom
    text = AUTODESK_HEAD + ("RAPID\nGOTO/10.0, 10.0, -35.0\nCYCLE/BRKCHP, 12.0, INCR, 5.0, MMPM, 200.0, -35.0, "
                            "RAPTO, 10.0, DWELL, 0.5\nFEDRAT/200.0, MMPM\nGOTO/10.0, 10.0, -62.0\nCYCLE/OFF\n")
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.tip[tp.line == 11, 2], [-45, -55, -50, -60, -55, -62, -35])
    (dwell,) = [e for e in tp.events if isinstance(e, Dwell)]
    assert dwell.seconds == 0.5 and tp.tip[dwell.index - 1, 2] == pytest.approx(-62)  # standing at the bottom
    # its fine boring (G76) writes the shift after the clearance: refused, naming it
    e = refused(tmp_path, AUTODESK_HEAD + "RAPID\nGOTO/0,0,20\nCYCLE/BORE, 10.0, MMPM, 100.0, 15.0, 0.1, RAPTO, 10.0, "
                "ORIENT, 0\nGOTO/0,0,-10\n")
    assert e.line == 9 and "fine boring with a shift" in e.reason
    # the classic reading still wants a clearance above the hole
    e = refused(tmp_path, APT_HEAD + "GOTO/20,0,40\nCYCLE/DRILL,10,MMPM,100,-15\nGOTO/20,0,0\n")
    assert e.line == 4 and "CLEAR must not be negative" in e.reason


def test_creo_records_as_its_supported_cl_data_commands_define_them(tmp_path: Path) -> None:
    # PTC Creo help, "Supported CL Data Commands" and "CL Output for Holemaking Cycles":
    # FEDRAT units FPM/FPR (feet), COOLNT / type, pressure; CYCLE ... RETURN, 0 "retract to the
    # retract plane"; HEAD for multiple turrets
    text = CREO_HEAD + ("GOTO / 0, 0, 40\nCOOLNT / FLOOD, HIGH\nFEDRAT / 2, FPM\nGOTO / 0, 0, 30\n"
                        "CYCLE / DRILL, DEPTH, 5, MMPM, 80, CLEAR, 2, RETURN, 0\nGOTO / 10, 0, 0\nGOTO / 20, 0, 0\n"
                        "CYCLE / OFF\nHEAD / 1\nHEAD / OFF\n")
    tp = read(tmp_path, text)
    assert tp.warnings == ()
    assert [e.mode for e in tp.events if isinstance(e, Coolant)] == ["FLOOD"]
    assert tp.feed[1] == pytest.approx(2 * 304.8)
    np.testing.assert_allclose(tp.tip[tp.line == 9], [[10, 0, 30], [10, 0, 2], [10, 0, -5], [10, 0, 30]])
    from verne_post.errors import CheckError

    for head in ("HEAD / BOTH", "HEAD / 2, OPTION, 1"):
        with pytest.raises(CheckError) as info:  # a program for another machine: exit 3
            read(tmp_path, CREO_HEAD + f"GOTO / 0, 0, 40\n{head}\nGOTO / 1, 0, 40\n")
        assert info.value.line == 5 and "one spindle" in info.value.reason


def test_arc_direction_override(tmp_path: Path) -> None:
    tp = read(tmp_path, quarter(NX_HEAD), arc_direction="ccw")
    assert swept(tp, np.zeros(3), np.array([0, 0, 1.0]), np.ones(len(tp), bool)) == pytest.approx(0.5 * math.pi)


def test_contradicting_arcs_are_an_error_naming_the_arc(tmp_path: Path) -> None:
    # Written with the ccw convention but claiming to be NX: every tangent move says the other way.
    text = NX_HEAD + "GOTO/-5,-10,0\nGOTO/0,-10,0\nCIRCLE/0,0,0,0,0,1,10\nGOTO/10,0,0\nGOTO/10,5,0\n"
    e = refused(tmp_path, text)
    assert e.line == 7  # the CIRCLE record
    assert "--arc-direction" in e.reason and "clockwise" in e.reason
    # the same file with the direction given is read
    tp = read(tmp_path, text, arc_direction="ccw")
    assert swept(tp, np.zeros(3), np.array([0, 0, 1.0]), arc_poses(tp)) == pytest.approx(0.5 * math.pi)


@pytest.mark.parametrize(("axis", "expected"), [("0,0,1", "counter-clockwise"), ("0,0,-1", "clockwise")])
def test_generic_apt_direction_from_its_tangent_arcs(tmp_path: Path, axis: str, expected: str) -> None:
    # The arc from (0,-10) to (10,0) tangent to the moves around it is the quarter through
    # (7.07,-7.07); its axis decides which reading makes that the arc.
    text = APT_HEAD + "GOTO/-5,-10,0\nGOTO/0,-10,0\nCIRCLE/0,0,0," + axis + ",10\nGOTO/10,0,0\nGOTO/10,5,0\n"
    tp = read(tmp_path, text)
    assert f"arcs {expected}" in tp.dialect and "from the file's tangent arcs" in tp.dialect
    arc = tp.tip[tp.motion == ARC]
    np.testing.assert_allclose(np.linalg.norm(arc[:, :2], axis=1), 10, atol=1e-9)
    assert (arc[:, 0] >= -1e-9).all() and (arc[:, 1] <= 1e-9).all()  # the short way, in the 4th quadrant


def test_generic_apt_without_evidence_warns(tmp_path: Path) -> None:
    tp = read(tmp_path, quarter(APT_HEAD))
    assert any("no tangent move tells the arc direction" in w for w in tp.warnings)


def test_solidworks_cusp_lead_in_does_not_decide_alone(tmp_path: Path) -> None:
    # CL-DIALECTS: a SolidWorks CAM lead-in reverses at the arc start (anti-tangent in, tangent out).
    text = ("PARTNO/X\nTRNTYP/WORLD,0,0,0\nUNITS/MM\nFEDRAT/500,MMPM\nGOTO/80.65,149.0375,-3.\n"
            "GOTO/77.914806,151.4375,-3.\nCIRCLE/75.,150.,-3.,0,0,-1.\nGOTO/78.25,150.,-3.\nGOTO/78.25,111.145664,-3.\n")
    tp = read(tmp_path, text)
    assert "SolidWorks" in tp.dialect
    arc = tp.tip[tp.motion == ARC]
    # counter-clockwise about -Z from angle 23.8 deg to 0 deg: the short clockwise-from-above way
    ang = np.degrees(np.arctan2(arc[:, 1] - 150, arc[:, 0] - 75))
    assert ang[-1] == pytest.approx(0, abs=1e-6) and (np.diff(ang) < 0).all()
    np.testing.assert_allclose(np.hypot(arc[:, 0] - 75, arc[:, 1] - 150), 3.25, atol=1e-6)  # radius from start


# --------------------------------------------------------------------------- helices and other arc forms


def test_nx_times_helix_partial_arc_plus_full_turns(tmp_path: Path) -> None:
    # CL-DIALECTS: NX's TIMES,n sweeps the partial arc plus n - 1 full turns. Clockwise about +Z
    # from +X to -Y is a quarter; with TIMES,3 the sweep is 0.5 pi + 4 pi, descending 9 mm.
    text = NX_HEAD + "GOTO/10,0,0\nCIRCLE/0,0,0,0,0,1,10,0.01,0.5,8,0,TIMES,3\nGOTO/0,-10,-9\n"
    tp = read(tmp_path, text)
    total = swept(tp, np.zeros(3), np.array([0, 0, 1.0]), np.ones(len(tp), bool))
    assert total == pytest.approx(-4.5 * math.pi)
    ang = np.unwrap(np.arctan2(tp.tip[:, 1], tp.tip[:, 0]))
    np.testing.assert_allclose(tp.tip[:, 2], -9 * (ang - ang[0]) / total, atol=1e-9)  # constant pitch
    pitch_angle = math.degrees(math.atan2(9, 10 * 4.5 * math.pi))
    seg = np.diff(tp.tip, axis=0)
    ramp = np.degrees(np.arctan2(-seg[:, 2], np.hypot(seg[:, 0], seg[:, 1])))
    np.testing.assert_allclose(ramp, pitch_angle, atol=0.05)


@pytest.mark.parametrize("times", ["TIMES,0", "TIMES,2.5", "TIMES", "TURNS,2"])
def test_bad_times(tmp_path: Path, times: str) -> None:
    e = refused(tmp_path, NX_HEAD + f"GOTO/10,0,0\nCIRCLE/0,0,0,0,0,1,10,{times}\nGOTO/0,-10,-9\n")
    assert e.line == 6


def test_movarc_angle(tmp_path: Path) -> None:
    # Autodesk HSM's APT post: MOVARC/centre,normal,radius,ANGLE,sweep then the end GOTO.
    text = "$$ HSMWorks\n" + APT_HEAD + "GOTO/10,0,0\nMOVARC/0,0,0,0,0,1,10,ANGLE,450\nGOTO/0,10,-4\n"
    tp = read(tmp_path, text)
    assert swept(tp, np.zeros(3), np.array([0, 0, 1.0]), np.ones(len(tp), bool)) == pytest.approx(2.5 * math.pi)


def test_movarc_angle_that_fits_neither_way_is_refused(tmp_path: Path) -> None:
    text = "$$ HSMWorks\n" + APT_HEAD + "GOTO/10,0,0\nMOVARC/0,0,0,0,0,1,10,ANGLE,45\nGOTO/0,10,0\n"
    e = refused(tmp_path, text)
    assert e.line == 5 and "MOVARC ANGLE 45 does not fit" in e.reason


@pytest.mark.parametrize("seed", range(40))
def test_movarc_direction_is_the_one_its_angle_fits(tmp_path: Path, seed: int) -> None:
    # Autodesk's 2021 APT posts turn the normal for clockwise arcs; the 2011 HSMWorks ones did not,
    # leaving the direction in the (positive) ANGLE alone. Either way the arc is the one of that sweep.
    rng = np.random.default_rng(seed)
    sweep = rng.uniform(5, 355) if seed % 8 else rng.uniform(365, 700)
    clockwise, flipped = bool(seed % 2), bool(seed % 4 > 1)
    phi = math.radians(sweep) * (-1 if clockwise else 1)
    end = [10 * math.cos(phi), 10 * math.sin(phi), -3.0]
    normal = "0,0,-1" if clockwise and flipped else "0,0,1"
    text = ("$$ HSMWorks\n" + APT_HEAD + "GOTO/10,0,0\n"
            f"MOVARC/0,0,0,{normal},10,ANGLE,{sweep:.6f}\nGOTO/{end[0]:.9f},{end[1]:.9f},{end[2]}\n")
    tp = read(tmp_path, text)
    expected = math.radians(sweep) * (-1 if clockwise else 1)
    assert swept(tp, np.zeros(3), np.array([0, 0, 1.0]), np.ones(len(tp), bool)) == pytest.approx(expected, abs=1e-6)


# --------------------------------------------------------------------------- frames


def test_nx_msys_down_is_not_applied(tmp_path: Path) -> None:
    # CL-DIALECTS: MSYS with Z down while every tool axis is (0,0,1): the data are in the MCS.
    text = NX_HEAD + "MSYS/393.0000,-297.5000,3.0000,0,1,0,1,0,0\nGOTO/1,2,3,0,0,1\n"
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.tip[0], [1, 2, 3])
    np.testing.assert_allclose(tp.axis[0], [0, 0, 1])


def test_solidworks_world_data_ignore_csys(tmp_path: Path) -> None:
    text = ("PARTNO/X\nTRNTYP/WORLD,0,0,0\nUNITS/MM\nFEDRAT/500,MMPM\n"
            "CSYS/0,-0.984808,-0.173648,0,1.,0,0,0,0,-0.173648,.984808,0\n"
            "GOTO/-38.637201,-8.8,247.043872,-0.173648,0,.984808\n")
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.axis[0], [-0.173648, 0, 0.984808], atol=1e-6)  # equals CSYS column 3
    np.testing.assert_allclose(tp.tip[0], [-38.637201, -8.8, 247.043872])


# --------------------------------------------------------------------------- other records


def test_permin_feed_in_file_units(tmp_path: Path) -> None:
    tp = read(tmp_path, "UNITS/INCHES\nFEDRAT/PERMIN,10\nGOTO/0,0,0\nGOTO/1,0,0\n")
    np.testing.assert_allclose(tp.feed, 254.0)


def test_cutcom_on_centre_line_data_warns_once(tmp_path: Path) -> None:
    text = NX_HEAD + "CUTCOM/LEFT,XYPLAN\nGOTO/0,0,0\nCUTCOM/OFF\nCUTCOM/RIGHT\nGOTO/1,0,0\n"
    tp = read(tmp_path, text)
    cutcom = [w for w in tp.warnings if "CUTCOM" in w]
    assert len(cutcom) == 1 and ":5:" in cutcom[0] and "2 records like this" in cutcom[0]


def test_cutcom_on_contact_data_is_an_error(tmp_path: Path) -> None:
    text = "$$-> CUTCOM_GEOMETRY_TYPE / OUTPUT_ON_PROFILE\nUNITS/MM\nFEDRAT/100\nCUTCOM/LEFT\nGOTO/0,0,0\n"
    e = refused(tmp_path, text)
    assert e.line == 4 and "contact-point data" in e.reason


def test_creo_comment_continuation_and_ignored_records(tmp_path: Path) -> None:
    text = ("$$*          Pro/CLfile  Version 19.0 - 9738\nPARTNO MFG_TURN_MILL\nMACHIN / MILL, 01\nUNITS / MM\n"
            "LOADTL / 4,  OSETNO,  4 $$-> THREAD TOOL\n$$-> CSYS / 1.0, 0.0, 0.0, 0.0,  $\n"
            "            0.0, 1.0, 0.0, 0.0,  $\n            0.0, 0.0, 1.0, 0.0\n"
            "SETUP/START\nCSI_SET_FLUTE_LENGTH/19.\nSET/MODE,ABSOL\nCYCLE/INIT\nSPINDL / RPM, 400.0,  CLW\n"
            "FEDRAT / 20.0,  MMPM\nGOTO / 0.0, 0.0, 0.0\n")
    tp = read(tmp_path, text)
    assert tp.warnings == ()
    assert tp.part_name == "MFG_TURN_MILL"
    assert len(tp) == 1 and tp.line[0] == 15


def test_warnings_grouped(tmp_path: Path) -> None:
    text = APT_HEAD + "".join(f"FOO/{k}\nGOTO/{k},0,0\n" for k in range(50))
    tp = read(tmp_path, text)
    assert len(tp.warnings) == 1 and "50 records like this" in tp.warnings[0] and ":3:" in tp.warnings[0]


def test_delay_is_a_dwell(tmp_path: Path) -> None:
    tp = read(tmp_path, APT_HEAD + "GOTO/0,0,0\nDELAY/1.5\nGOTO/1,0,0\n")
    (dwell,) = [e for e in tp.events if isinstance(e, Dwell)]
    assert (dwell.seconds, dwell.index, dwell.line) == (1.5, 1, 4)


@pytest.mark.parametrize(
    ("record", "message"),
    [
        ("GOTO/1e400,0,0", "out of range"),
        ("LOADTL/1e20", "tool number"),
        ("FEDRAT/4.9e-324", "feed"),
        ("CIRCLE/0,0,0,0,0,1,1e12", "radius"),
        ("TLDATA/MILL,10,0,-5", "tool length must not be negative"),
        ("SPINDL/RPM,1e300", "spindle speed"),
    ],
)
def test_absurd_numbers_are_input_errors(tmp_path: Path, record: str, message: str) -> None:
    e = refused(tmp_path, APT_HEAD + "GOTO/10,0,0\n" + record + "\nGOTO/0,10,0\n")
    assert e.line == 4 and message in e.reason


# --------------------------------------------------------------------------- the real samples


_REC = re.compile(r"^\s*(GOTO|CIRCLE)\s*/(.*)$")


def scan_arcs(path: Path) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Independent scan: (GOTO line ending the arc, centre, axis, start, end) per CIRCLE, file units."""
    out, last, pending, parts, first = [], None, None, [], 0
    for n, raw in enumerate(path.read_text(errors="replace").replace("\r\n", "\n").split("\n"), 1):
        body = raw.split("$$")[0].rstrip()
        if not parts:
            first = n
        if body.endswith("$"):
            parts.append(body[:-1])
            continue
        m = _REC.match("".join([*parts, body]))
        parts = []
        if not m:
            continue
        vals = [float(v) for v in m.group(2).split(",")[:7] if re.match(r"\s*[-+.\d]", v)]
        if m.group(1) == "CIRCLE":
            pending = vals
            continue
        p = np.array(vals[:3])
        if pending is not None:
            axis = np.array(pending[3:6]) / np.linalg.norm(pending[3:6])
            out.append((first, np.array(pending[:3]), axis, last, p))
            pending = None
        last = p
    return out


def expected_sweep(centre: np.ndarray, n: np.ndarray, start: np.ndarray, end: np.ndarray, cw: bool) -> float:
    """Right-hand signed sweep about n: the arc from start to end going the documented way."""
    d0, d1 = start - centre, end - centre
    d0, d1 = d0 - (d0 @ n) * n, d1 - (d1 @ n) * n
    ccw = math.atan2(float(np.cross(d0, d1) @ n), float(d0 @ d1)) % (2 * math.pi)
    if np.linalg.norm(d1 - d0) < 1e-6 * max(1.0, float(np.linalg.norm(d0))):
        ccw = 2 * math.pi
    return -((2 * math.pi - ccw) % (2 * math.pi) or 2 * math.pi) if cw else (ccw or 2 * math.pi)


@pytest.mark.parametrize(
    ("path", "cw", "scale"),
    [(NX_ZLEVEL, True, 1.0), (MAKINO, True, 1.0), (CREO_ROUGH, False, 1.0), (CREO_PROFILE, False, 1.0),
     (CREO_THREAD, False, 25.4)],
    ids=["nx-zlevel", "makino", "creo-rough", "creo-profile", "creo-thread"],
)
def test_real_sample_arcs_follow_the_documented_direction(path: Path, cw: bool, scale: float) -> None:
    tp = read_cl(path)
    arcs = scan_arcs(path)
    checked = 0
    for line, centre, n, start, end in arcs:
        mask = (tp.line == line) & (tp.motion == ARC)
        if not mask.any():
            continue
        first = int(np.flatnonzero(mask)[0])
        mask[first - 1] = True  # the arc's start pose
        got = swept(tp, centre * scale, n, mask)
        assert got == pytest.approx(expected_sweep(centre, n, start, end, cw), abs=1e-6), line
        checked += 1
    assert checked >= 0.9 * len(arcs)


def test_nx_zlevel_arc_length_and_tangency() -> None:
    # The measurement: 13.9 m of arc under the documented clockwise reading (263 m otherwise).
    tp = read_cl(NX_ZLEVEL)
    seg = np.linalg.norm(np.diff(tp.tip, axis=0), axis=1)
    arc_length = seg[tp.motion[1:] == ARC].sum()
    assert 13_800 < arc_length < 14_000
    # every arc with a tangent move into it is tangent to it: the poses run on without a corner
    into = np.flatnonzero((tp.motion[1:] == ARC) & (tp.motion[:-1] != ARC)) + 1  # first pose of each arc
    before = tp.tip[into - 1] - tp.tip[into - 2]
    after = tp.tip[into] - tp.tip[into - 1]
    cos = np.einsum("ij,ij->i", before, after) / (np.linalg.norm(before, axis=1) * np.linalg.norm(after, axis=1))
    assert np.sum(cos < -0.9) == 0  # never a reversal into an arc


def test_every_real_sample_reads_without_input_error() -> None:
    for path in sorted(SAMPLES.iterdir()):
        if path.suffix in CL_SUFFIXES:
            tp = read_cl(path)
            assert len(tp) > 0 and not any("unknown record" in w for w in tp.warnings), path.name


def test_toolpath_command_writes_what_was_read(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from verne_post.cli import main

    out = tmp_path / "path.csv"
    result = CliRunner().invoke(main, ["toolpath", str(MAKINO), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "Makino FF CAM" in result.output and "clockwise" in result.output
    rows = out.read_text().splitlines()
    assert rows[0] == "x,y,z,i,j,k,feed,motion,line"
    tp = read_cl(MAKINO)
    assert len(rows) == len(tp) + 1
    cells = [r.split(",") for r in rows[1:]]
    np.testing.assert_allclose([[float(c) for c in r[:3]] for r in cells], tp.tip, atol=1e-6)
    assert [r[7] for r in cells] == [MOTION_KINDS[m] for m in tp.motion]
    assert all(r[6] == "" for r, rapid in zip(cells, tp.rapid, strict=True) if rapid)
    # Makino's FEDRAT/PERMIN,141 in a UNITS/MM file: 141 mm/min
    assert any(r[6] == "141" for r in cells)


@pytest.mark.parametrize("name", sorted(p.name for p in SAMPLES.iterdir() if p.suffix in CL_SUFFIXES))
def test_check_on_real_samples_never_bad_input(name: str) -> None:
    """Every real sample is read; `check` ends in 0 or 3 (the part may not fit at offset 0), never 2.

    --tool-length only serves tools whose length the file does not give (Makino's LOAD/TOOL,45).
    """
    from click.testing import CliRunner

    from verne_post.cli import main

    result = CliRunner().invoke(main, ["check", str(SAMPLES / name), "--no-timing", "-q", "--tool-length", "100"])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert result.exit_code in (0, 3), result.output


# --------------------------------------------------------------------------- NX splines through the reader


def test_nx_nurbs_records_read_as_a_curve_from_the_tool_position(tmp_path: Path) -> None:
    from test_cl_spline import curve_at, distance_to_polyline  # the independent Cox-de Boor evaluator

    start = np.array([0.0, 0.0, 10.0])
    control = np.array([[10.0, 20, 10], [30, 25, 12], [45, -5, 10], [60, 10, 9], [80, 0, 10]])
    knots = [0.3, 0.6, 1.0]  # n - 2 values for n = 5 CNTRL records, the last 1 (CL-DIALECTS)
    text = (NX_HEAD + "GOTO/0,0,10\nNURBS/\nKNOT/0.3,0.6\n$$ continued\nKNOT/1.0\n"
            + "".join(f"CNTRL/{x:g},{y:g},{z:g}\n" for x, y, z in control) + "GOTO/80,0,10\nGOTO/90,0,10\n")
    tp = read(tmp_path, text, chordal_tolerance=0.001)
    spline = tp.motion == MOTION_KINDS.index("spline")
    assert (tp.line[spline] == 6).all()
    pts = tp.tip[spline]
    np.testing.assert_allclose(pts[-1], control[-1])  # ends on the last control point
    assert tp.line[-1] == 16 and tp.line[-2] == 6  # the GOTO repeating the end (line 15) adds nothing
    full_knots = np.r_[[0.0] * 4, knots[:-1], [1.0] * 4]
    true = curve_at(full_knots, 3, np.vstack([start, control]), None, np.linspace(0, 1, 20001))
    np.testing.assert_allclose(true[0], start)  # the curve starts where the tool is
    poly = np.vstack([start, pts])
    assert distance_to_polyline(true, poly).max() <= 0.0011


def test_nurbs_with_a_wrong_knot_count_names_its_line(tmp_path: Path) -> None:
    cntrl = "".join(f"CNTRL/{k},{k},{k}\n" for k in range(1, 5))
    text = NX_HEAD + "GOTO/0,0,10\nNURBS/\nKNOT/0.2,0.5,1.0\n" + cntrl + "GOTO/4,4,4\n"
    e = refused(tmp_path, text)
    assert e.line == 6 and "NURBS" in e.reason


@pytest.mark.parametrize(("name", "offset"), [
    ("nx_zlevel_coremill_mm.cls", "0"), ("creo8_schruppen_roughing_mm.ncl", "0"),
    ("makino_ffcam_plane1_mm.cldata", "0"),
    # its deepest GOTO is 4.0313 in (102.4 mm) below part zero; the table's face is 60 mm below the
    # table frame (machines/verne.yaml): part zero 60 mm higher leaves 17.6 mm under the tip
    ("creo_v19_thread_mill_helical_inch.ncl", "60")])
def test_real_samples_post_and_certify(tmp_path: Path, name: str, offset: str) -> None:
    """Posted without timing (durations from the programmed feeds), each program verifies from its text."""
    from click.testing import CliRunner

    from verne_post.cli import main

    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, [str(SAMPLES / name), "-o", str(out), "--no-timing", "-q",
                                       "--tool-length", "100", "--work-offset", "0", "0", offset])
    assert result.exit_code == 0, result.output
    header = out.read_text()[:2000]
    assert "(VERIFIED: MAX TIP DEVIATION" in header and "ALL LIMITS HELD" in header
    assert "(CL DIALECT " in header


# --------------------------------------------------------------------------- Pro/ENGINEER subroutines


def test_defsub_calsub_replays_the_subroutine(tmp_path: Path) -> None:
    # APT subroutines as Pro/ENGINEER writes them: DEFSUB/n ... ENDSUB stores, CALSUB/n runs.
    text = ("$$*          Pro/CLfile  Version 19.0\nPARTNO SUBS\nUNITS / MM\nLOADTL / 1\nFEDRAT / 100,  MMPM\n"
            "DEFSUB / 1\nGODLTA / 0, 0, -5\nGODLTA / 0, 0, 5\nENDSUB\n"
            "GOTO / 0, 0, 10\nCALSUB / 1\nGOTO / 10, 0, 10\nCALSUB / 1\n")
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.tip, [[0, 0, 10], [0, 0, 5], [0, 0, 10], [10, 0, 10], [10, 0, 5], [10, 0, 10]])
    assert tp.line.tolist() == [10, 7, 8, 12, 7, 8]  # the subroutine's poses name its own lines


@pytest.mark.parametrize(
    ("body", "line", "message"),
    [
        ("CALSUB/2\n", 4, "no such subroutine"),
        ("DEFSUB/1\nGOTO/1,0,0\n", 4, "has no ENDSUB"),
        ("ENDSUB\n", 4, "ENDSUB without DEFSUB"),
        ("DEFSUB/1\nDEFSUB/2\nENDSUB\nENDSUB\n", 5, "DEFSUB inside"),
        ("DEFSUB/1\nCALSUB/1\nENDSUB\nCALSUB/1\n", 5, "nested more than"),
    ],
)
def test_bad_subroutines(tmp_path: Path, body: str, line: int, message: str) -> None:
    e = refused(tmp_path, APT_HEAD + "GOTO/0,0,0\n" + body)
    assert e.line == line and message in e.reason


# --------------------------------------------------------------------------- CATIA V5 APT


def _catia_records(text: str) -> list[tuple[str, str]]:
    """An independent scan of CATIA's APT: a line ending in '$' continues on the next, the two
    joined with nothing between them (a number split in two joins into one); '$$' lines are
    comments."""
    out: list[tuple[str, str]] = []
    pending = ""
    for line in text.splitlines():
        if not pending and line.lstrip().startswith("$$"):
            continue
        if line.rstrip().endswith("$"):
            pending += line.rstrip()[:-1]
            continue
        body, pending = pending + line, ""
        word, _, args = body.partition("/")
        out.append((word.strip().upper(), args))
    return out


def test_catia_real_file_reads_as_an_independent_scan_of_it() -> None:
    records = _catia_records(CATIA_ISO.read_text())
    tips, axes, rapid, feeds = [], [], [], []
    next_rapid, feed = False, math.nan
    for word, args in records:
        if word == "RAPID":
            next_rapid = True
        elif word == "FEDRAT":
            feed = float(args.split(",")[0])  # every FEDRAT of the file is 'f,MMPM'
        elif word == "GOTO":
            values = [float(v) for v in args.split(",")]
            tips.append(values[:3])
            axes.append(values[3:])
            rapid.append(next_rapid)
            feeds.append(math.nan if next_rapid else feed)
            next_rapid = False
    tp = read_cl(CATIA_ISO)
    assert len(tp) == len(tips) == 163
    np.testing.assert_allclose(tp.tip, tips, atol=1e-9)
    np.testing.assert_allclose(tp.axis, np.array(axes) / np.linalg.norm(axes, axis=1)[:, None], atol=1e-12)
    np.testing.assert_array_equal(tp.rapid, rapid)
    np.testing.assert_allclose(tp.feed, feeds)
    # tool axes to 140 deg from vertical: normal CAM output (CL-DIALECTS), read as they are
    assert np.degrees(np.arccos(tp.axis[:, 2].min())) > 130


def test_catia_user_typed_pp_words_give_one_grouped_warning() -> None:
    tp = read_cl(CATIA_ISO)
    grouped = [w for w in tp.warnings if "post-processor words in CATIA's output" in w]
    assert len(grouped) == 1
    for word, line in (("SFSDFSDF", 27), ("AICC/ON,10", 40), ("INVERSE/ON", 59)):
        assert f"{word} (line {line})" in grouped[0]
    assert not any("unknown record" in w for w in tp.warnings)


CATIA_HEAD = "$$*CATIA0\n$$ Manufacturing Program.1\nMULTAX\nLOADTL/1\n"  # 4 lines


def test_catia_pp_words_in_a_small_file(tmp_path: Path) -> None:
    text = CATIA_HEAD + "LOOP/START,15\nAICC/ON,10\nqwerty\nFEDRAT/100,MMPM\nGOTO/0,0,0,0,0,1\nLOOP/END\n"
    tp = read(tmp_path, text)
    grouped = [w for w in tp.warnings if "post-processor words" in w]
    assert len(grouped) == 1 and grouped[0].startswith(f"{tmp_path / 't.cls'}:5: 4 post-processor words")
    assert "LOOP/START,15 (line 5), AICC/ON,10 (line 6), QWERTY (line 7), LOOP/END (line 10)" in grouped[0]


def test_a_malformed_spindle_record_replaced_before_any_motion_is_a_warning(tmp_path: Path) -> None:
    from verne_post.cl.toolpath import Spindle

    text = CATIA_HEAD + "SPINDL/900CCLW\nSPINDL/10000,CLW\nFEDRAT/100,MMPM\nGOTO/0,0,0,0,0,1\n"
    tp = read(tmp_path, text)
    [warning] = [w for w in tp.warnings if "is malformed" in w]
    assert warning.startswith(f"{tmp_path / 't.cls'}:5: SPINDL/900CCLW is malformed")
    assert "SPINDL/10000,CLW at line 6 replaces it" in warning
    assert [(e.rpm, e.direction) for e in tp.events if isinstance(e, Spindle)] == [(10000.0, "CW")]


@pytest.mark.parametrize("text", [
    CATIA_HEAD + "SPINDL/900CCLW\nFEDRAT/100,MMPM\nGOTO/0,0,0,0,0,1\nSPINDL/10000,CLW\n",  # motion first
    CATIA_HEAD + "SPINDL/900CCLW\nFEDRAT/100,MMPM\n",  # nothing replaces it
    "UNITS/MM\nFEDRAT/100\nSPINDL/900CCLW\nGOTO/0,0,0\n",  # any dialect
])
def test_a_malformed_spindle_record_still_in_force_at_a_motion_is_an_error(tmp_path: Path, text: str) -> None:
    e = refused(tmp_path, text)
    assert e.line == text.splitlines().index("SPINDL/900CCLW") + 1 and "900CCLW" in e.reason


def test_a_tool_change_ends_a_malformed_spindle_record_before_any_motion(tmp_path: Path) -> None:
    text = CATIA_HEAD + "SPINDL/400CLW\nLOADTL/2\nSPINDL/500,CLW\nFEDRAT/100,MMPM\nGOTO/0,0,0,0,0,1\n"
    tp = read(tmp_path, text)
    [warning] = [w for w in tp.warnings if "is malformed" in w]
    assert warning.startswith(f"{tmp_path / 't.cls'}:5: SPINDL/400CLW is malformed") and "line 6" in warning


# --------------------------------------------------------------------------- programs for other machines


@pytest.mark.parametrize(("text", "line", "what"), [
    # CATIA's mill-turn output: TURRET instead of LOADTL, then MMPR feeds and XZ moves
    (CATIA_HEAD.replace("LOADTL/1", "TURRET/1") + "SPINDL/200,SMM,CLW\nFEDRAT/0.2,MMPR\nGOTO/20,0,5\n", 4, "turning"),
    ("MODE/TURN\nPARTNO/'P1'\nUNITS/MM\nFEDRAT/0.2,MMPR\nGOTO/20,0,5\n", 1, "turning"),  # Autodesk's ISO 4343 post
    (APT_HEAD + "GOTO/0,0,0\nHEAD/2\nGOTO/1,0,0\n", 4, "several heads"),
    (APT_HEAD + "HEAD/BOTH\nGOTO/1,0,0\n", 3, "several heads"),
    # CATIA's Lathe Machining sample: CHANNEL,1 on a multi-turret lathe, TOOLNO/1,TURN, MMPR feeds
    ("$$*CATIA0\nCHANNEL,1\nTOOLNO/1,TURN\nFEDRAT/ 0.4000,MMPR\n", 2, "several"),
    ("$$*CATIA0\nCUTTER/ 1.000000\nTOOLNO/1,TURN\nFEDRAT/ 0.4000,MMPR\nGOTO / 77.0, 0.0, 45.0\n", 3, "turning"),
])
def test_programs_for_another_kind_of_machine_are_refused_as_such(tmp_path: Path, text: str, line: int,
                                                                   what: str) -> None:
    from click.testing import CliRunner

    from verne_post.cli import main
    from verne_post.errors import CheckError

    path = tmp_path / "t.cls"
    path.write_text(text)
    with pytest.raises(CheckError) as info:
        read_cl(path)
    assert info.value.line == line and what in info.value.reason
    for command in (["check"], ["post", "-o", str(tmp_path / "t.nc")]):
        report = tmp_path / f"{command[0]}.json"
        result = CliRunner().invoke(main, [*command, str(path), "-q", "--report", str(report)])
        assert result.exit_code == 3 and result.stderr.startswith(f"verne-post: error: {path}:{line}: ")
        assert len(result.stderr.splitlines()) == 1
        # as for every exit 3, the report says why (and no program is written)
        data = json.loads(report.read_text())
        assert data["ok"] is False and data["source"] == str(path)
        [violation] = data["violations"]
        assert violation["line"] == line and what in violation["message"]
    assert not (tmp_path / "t.nc").exists()


def test_mode_mill_is_read(tmp_path: Path) -> None:
    tp = read(tmp_path, "MODE/MILL\nPARTNO/'P1'\nUNITS/MM\nFEDRAT/100,MMPM\nGOTO/20,0,5\n")
    assert len(tp) == 1 and not tp.warnings


# --------------------------------------------------------------------------- frames by the tool's direction


def _nx_msys_down(axis_k: float) -> str:
    """NX CLSF with MSYS/0,0,0,0,1,0,1,0,0 (X and Y swapped: Z down in the absolute frame) and GOTOs
    whose tool axis is (0,0,axis_k) in the MCS: CL-DIALECTS's two real cases."""
    rows = "".join(f"GOTO/{x:.1f},{0.5 * x:.1f},-5.0,0.0,0.0,{axis_k:.1f}\n" for x in range(10))
    return NX_HEAD + "MSYS/10,20,30,0,1,0,1,0,0\n" + rows  # MSYS on line 5


def test_msys_down_with_axes_up_in_the_mcs_is_read_in_the_mcs(tmp_path: Path) -> None:
    tp = read(tmp_path, _nx_msys_down(1.0))
    np.testing.assert_allclose(tp.axis, np.tile([0.0, 0.0, 1.0], (10, 1)))
    np.testing.assert_allclose(tp.tip[3], [3.0, 1.5, -5.0])
    assert tp.notes == () and not any("frames read as" in w for w in tp.warnings)


def test_msys_down_with_axes_down_in_the_mcs_is_applied(tmp_path: Path) -> None:
    """The variable-contour case: every axis down in the MCS; mapped by MSYS (tip = o + R p,
    R's columns X = (0,1,0), Y = (1,0,0), Z = X x Y = (0,0,-1)) the tool points up."""
    tp = read(tmp_path, _nx_msys_down(-1.0))
    np.testing.assert_allclose(tp.axis, np.tile([0.0, 0.0, 1.0], (10, 1)), atol=1e-12)
    x = 3.0
    np.testing.assert_allclose(tp.tip[3], [10 + 0.5 * x, 20 + x, 30 + 5.0], atol=1e-12)
    [warning] = [w for w in tp.warnings if "frames read as apply" in w]
    assert "--frame local overrides" in warning and "100%" in warning
    assert len(tp.notes) == 1 and tp.notes[0].startswith("FRAMES READ AS APPLY")
    forced = read(tmp_path, _nx_msys_down(-1.0), frame="local")  # --frame is obeyed, and says what would fit
    np.testing.assert_allclose(forced.axis[:, 2], -1.0)
    assert forced.frame_hint == "--frame apply" and any("with --frame apply it points away" in w
                                                          for w in forced.warnings)


def test_a_header_records_the_frame_choice(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from verne_post.cli import main

    path = tmp_path / "down.cls"
    path.write_text(_nx_msys_down(-1.0).replace("TOOL PATH/OP,TOOL,EM10", "TOOL PATH/OP,TOOL,EM10\nLOAD/TOOL,1"))
    out = tmp_path / "down.nc"
    result = CliRunner().invoke(main, [str(path), "-o", str(out), "--work-offset", "auto", "--tool-length", "60",
                                       "--no-timing", "-q"])
    assert result.exit_code == 0, result.stderr
    assert "(CL READING FRAMES READ AS APPLY: THE TOOL AXES POINT AWAY FROM THE TABLE" in out.read_text()


# --------------------------------------------------------------------------- rotary indexing (ROTATE)


def _rx(degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def test_pro_engineer_rotate_indexes_between_subroutine_calls(tmp_path: Path) -> None:
    """As Pro/ENGINEER writes a 4-axis index pattern: the subroutine's points are written in the
    part turned by the table; in the part frame the k-th call's points are R(-t_k) m, t_k the
    angle after k increments of -36 degrees about X."""
    body = "DEFSUB/1\nRAPID\nGOTO / 10, 0, 50, 0, 0, 1\nGOTO / 10, 0, 40\nGOTO / 20, 0, 40\nENDSUB\n"
    calls = "CALSUB/1\n" + "ROTATE / AAXIS, INCR, -36.000000, CCLW\nCALSUB/1\n" * 2
    tp = read(tmp_path, CREO_HEAD + body + calls)
    m = np.array([[10.0, 0, 50], [10, 0, 40], [20, 0, 40]])
    expected = np.vstack([m @ _rx(36.0 * k).T for k in range(3)])
    np.testing.assert_allclose(tp.tip, expected, atol=1e-9)
    np.testing.assert_allclose(tp.axis, np.vstack([np.tile(_rx(36.0 * k) @ [0, 0, 1], (3, 1)) for k in range(3)]),
                               atol=1e-12)
    assert tp.rapid[[0, 3, 6]].all()


def test_rotate_atangl_sets_the_angle_and_clw_only_says_the_way_round(tmp_path: Path) -> None:
    text = APT_HEAD + ("GOTO/0,10,0,0,0,1\nROTATE/AAXIS,ATANGL,90,CLW\nGOTO/0,10,0,0,0,1\n"
                       "ROTATE/AAXIS,INCR,90,CCLW\nGOTO/0,10,0,0,0,1\nROTATE/AAXIS,ATANGL,0\nGOTO/0,10,0,0,0,1\n")
    tp = read(tmp_path, text)
    np.testing.assert_allclose(tp.tip, [[0, 10, 0], [0, 0, -10], [0, -10, 0], [0, 10, 0]], atol=1e-9)
    np.testing.assert_allclose(tp.axis, [[0, 0, 1], [0, 1, 0], [0, 0, -1], [0, 0, 1]], atol=1e-12)


@pytest.mark.parametrize("record", ["ROTATE/AAXIS,ABSOL,90", "ROTATE/90", "ROTATE/AAXIS,BAXIS,90",
                                    "ROTATE/CAXIS,INCR,10,20"])
def test_rotate_forms_not_documented_are_refused(tmp_path: Path, record: str) -> None:
    e = refused(tmp_path, APT_HEAD + f"GOTO/0,0,0\n{record}\nGOTO/0,0,0\n")
    assert e.line == 4 and "only ROTATE/AAXIS|BAXIS|CAXIS" in e.reason


def test_catia_positional_cycle_with_empty_fields_is_refused_with_its_reason(tmp_path: Path) -> None:
    """CATIA's cycle syntax comes from the PP word table of its machine (Dassault, "PP Tables and PP
    Word Syntaxes"), which the APT file does not carry: the continued record (its continuation
    line starting with a comma) is read whole, and refused as what it is, not as a bad number."""
    text = CATIA_HEAD + ("FEDRAT/100,MMPM\nGOTO/0,0,10,0,0,1\nCYCLE/DRILL, 35.000000,,0,0, 1.000000, 1000.000000$\n"
                         ",   70.000000,ON,0,0,0\nGOTO/0,0,0,0,0,1\nCYCLE/OFF\n")
    e = refused(tmp_path, text)
    assert e.line == 7 and "PP word table" in e.reason and "empty field in CYCLE" not in e.reason


def test_a_tool_length_option_the_cl_file_overrides_is_a_warning(tmp_path: Path) -> None:
    """NX's TLDATA gives the length (3 inch): --tool-length 100 is not used, and the run says so
    at the record (the documented precedence: CL file, tool table, --tool-length)."""
    from click.testing import CliRunner

    from verne_post.cli import main

    source = Path(__file__).parent.parent / "examples" / "nx_variable_axis_inch.cls"
    result = CliRunner().invoke(main, ["check", str(source), "--no-timing", "--tool-length", "100"])
    assert result.exit_code == 0, result.output
    tldata = next(i for i, line in enumerate(source.read_text().splitlines(), 1) if line.startswith("TLDATA/"))
    assert (f"verne-post: warning: {source}:{tldata}: --tool-length 100 not used: the CL file gives tool 0 its "
            "length, 76.2 mm") in result.stderr
    quiet = CliRunner().invoke(main, ["check", str(source), "--no-timing", "--tool-length", "76.2"])
    assert "--tool-length" not in quiet.stderr  # the same length: nothing to tell
