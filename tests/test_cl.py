"""Tests for verne_post.cl: APT/CLSF and CSV readers (real NX samples + synthetic files)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from verne_post.cl import read_cl, read_pose_csv, read_toolpath
from verne_post.errors import InputError
from verne_post.toolpath import Comment, Coolant, Spindle, Stop, ToolChange, Toolpath

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
DATA = Path(__file__).resolve().parent / "data"
VARIABLE_AXIS = EXAMPLES / "nx_variable_axis_inch.cls"
SWARF = EXAMPLES / "nx_swarf_inch_crlf.cls"

MM = "UNITS/MM\nFEDRAT/MMPM,100\n"  # 2-line preamble of most synthetic files


def write(tmp_path: Path, text: str, name: str = "t.cls") -> Path:
    p = tmp_path / name
    p.write_bytes(text.encode())
    return p


def cl(tmp_path: Path, text: str, **kw: object) -> Toolpath:
    return read_cl(write(tmp_path, text), **kw)  # type: ignore[arg-type]


def err(tmp_path: Path, text: str, **kw: object) -> InputError:
    path = write(tmp_path, text)
    with pytest.raises(InputError) as info:
        read_cl(path, **kw)  # type: ignore[arg-type]
    e = info.value
    assert "\n" not in str(e)
    assert e.source == str(path)
    return e


def events(tp: Toolpath, kind: type) -> list:
    return [e for e in tp.events if isinstance(e, kind)]


# --------------------------------------------------------------------------- real NX samples


def raw_gotos(path: Path) -> tuple[list[int], list[list[float]]]:
    """Independent reading of the GOTO lines: (1-based line numbers, numbers)."""
    text = path.read_bytes().decode()
    lines, vals = [], []
    for n, ln in enumerate(text.replace("\r\n", "\n").split("\n"), 1):
        if ln.startswith("GOTO/"):
            lines.append(n)
            vals.append([float(v) for v in ln[5:].split(",")])
    return lines, vals


def msys_origin(path: Path) -> np.ndarray:
    for ln in path.read_text().splitlines():
        if ln.startswith("MSYS/"):
            v = [float(x) for x in ln[5:].split(",")]
            assert v[3:] == [1, 0, 0, 0, 1, 0]  # identity rotation in both samples
            return np.array(v[:3])
    raise AssertionError("no MSYS")


@pytest.mark.parametrize("path", [VARIABLE_AXIS, SWARF], ids=["variable_axis", "swarf"])
def test_real_sample_poses(path: Path) -> None:
    goto_lines, vals = raw_gotos(path)
    tp = read_cl(path)
    assert len(tp) == len(goto_lines)  # 348 / 325 GOTO records
    assert tp.units == "inch"
    assert tp.source == str(path)
    # line numbers point at GOTO lines, in order
    assert tp.line.tolist() == goto_lines
    text_lines = path.read_text().splitlines()
    assert all(text_lines[k - 1].startswith("GOTO") for k in tp.line)
    # inch -> mm; the GOTO data are in NX's MCS (NX CLSF Manager documentation), which MSYS only
    # locates in NX's absolute frame: the numbers are taken as they are. The tool axis is
    # carried over by 3-number GOTOs.
    assert np.any(msys_origin(path) != 0) or path == SWARF
    axis = np.array([0.0, 0.0, 1.0])
    for k, v in enumerate(vals):
        if len(v) == 6:
            axis = np.array(v[3:]) / np.linalg.norm(v[3:])
        np.testing.assert_allclose(tp.tip[k], np.array(v[:3]) * 25.4, atol=1e-9)
        np.testing.assert_allclose(tp.axis[k], axis, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(tp.axis, axis=1), 1.0, atol=1e-12)
    # two RAPID records before the first two GOTOs, then FEDRAT/IPM,10 = 254 mm/min
    assert tp.rapid[:2].all()
    assert np.isnan(tp.feed[:2]).all()
    feed_moves = ~tp.rapid
    np.testing.assert_allclose(tp.feed[feed_moves], 254.0)
    assert not tp.inverse_time.any()
    assert not any("unknown record" in w for w in tp.warnings)


def test_real_sample_counts_match_sources_md() -> None:
    assert len(read_cl(VARIABLE_AXIS)) == 348
    assert len(read_cl(SWARF)) == 325


def test_variable_axis_tool_length_from_tldata() -> None:
    tp = read_cl(VARIABLE_AXIS)
    changes = events(tp, ToolChange)
    assert len(changes) == 1
    assert changes[0].length == pytest.approx(76.2)  # TLDATA length 3.0 in
    assert changes[0].diameter == pytest.approx(25.4)
    assert changes[0].index == 0
    assert changes[0].tool == 0  # the file has no LOAD/TOOL
    assert (tp.tool == 0).all()
    assert any("without a tool load" in w for w in tp.warnings)
    comments = events(tp, Comment)
    assert comments[0].text.startswith("NORM_PART")


def test_swarf_sample_tool_load_and_crlf() -> None:
    assert b"\r\n" in SWARF.read_bytes()
    tp = read_cl(SWARF)
    (change,) = events(tp, ToolChange)
    assert (change.tool, change.adjust, change.index) == (1, 1, 0)
    assert change.length == pytest.approx(101.6)  # TLDATA length 4.0 in
    assert change.diameter == pytest.approx(0.75 * 25.4)
    assert (tp.tool == 1).all()
    assert events(tp, Comment)[0].text.startswith("CONTOUR_PROFILE_CHAMFER")


def test_inch_inferred_from_ipm_with_warning() -> None:
    tp = read_cl(SWARF)
    assert any("inch inferred from IPM" in w for w in tp.warnings)
    assert read_cl(SWARF, units="inch").warnings == ()


# --------------------------------------------------------------------------- realistic fixture


def test_fixture_multi_operation_file() -> None:
    path = DATA / "nx_multi_op_mm.cls"
    tp = read_cl(path)
    assert tp.warnings == ()  # info-listing header/trailer, PAINT, $$ all silent
    assert tp.part_name == "VERNE BRACKET REV B"
    assert tp.units == "mm"
    text_lines = path.read_text().splitlines()
    # FROM before any tool load only sets the start (GOHOME's target); the data are in the MCS
    # (MSYS only says where the MCS sits in NX's absolute frame): the numbers are kept
    assert tp.rapid[0] and tp.line[0] == 20
    np.testing.assert_allclose(tp.tip[0], [-40, 0, 20])
    changes = events(tp, ToolChange)
    assert [(c.tool, c.length, c.diameter, c.adjust) for c in changes] == [(3, 90, 16, 3), (7, 120, 8, 7)]
    assert [c.line for c in changes] == [16, 32]
    # tool array follows the loads
    assert (tp.tool[: changes[1].index] == 3).all()
    assert (tp.tool[changes[1].index :] == 7).all()
    # every pose line starts with a motion record
    assert all(text_lines[k - 1].split("/")[0] in ("GOTO", "FROM", "GOHOME") for k in tp.line)
    # the drilling cycle from Z30, RTRCTO,AUTO: NX's G98, back up to Z30 after each hole (NX Post
    # Builder, mom_cycle_retract_mode); over the second hole across first, then down (NX's
    # SIM_RAPID_APPROACH), never a diagonal descent
    np.testing.assert_allclose(tp.tip[tp.line == 37], [[0, 0, 8], [0, 0, -7], [0, 0, 30]])
    np.testing.assert_allclose(tp.tip[tp.line == 38], [[25, 0, 30], [25, 0, 8], [25, 0, -7], [25, 0, 30]])
    # GOHOME: rapid back to the FROM pose (part frame)
    np.testing.assert_allclose(tp.tip[-1], [0, 0, 250])
    assert tp.rapid[-1]
    assert [e.optional for e in events(tp, Stop)] == [True]
    assert [e.mode for e in events(tp, Coolant)] == ["FLOOD", "OFF"]


# --------------------------------------------------------------------------- GOTO


def test_goto_three_values_carries_axis_initial_z(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "GOTO/1,2,3\nGOTO/4,5,6,0,1,0\nGOTO/7,8,9\n")
    np.testing.assert_allclose(tp.tip, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    np.testing.assert_allclose(tp.axis, [[0, 0, 1], [0, 1, 0], [0, 1, 0]])
    assert tp.line.tolist() == [3, 4, 5]
    np.testing.assert_allclose(tp.feed, 100.0)
    assert not tp.rapid.any()


def test_goto_slightly_non_unit_axis_is_normalised(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "GOTO/0,0,0,0,0,0.99999\nGOTO/0,0,0,0.6,0,0.800004\n")
    np.testing.assert_allclose(np.linalg.norm(tp.axis, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(tp.axis[0], [0, 0, 1])


def test_goto_seven_numbers_is_an_error(tmp_path: Path) -> None:
    e = err(tmp_path, MM + "GOTO/1,2,3,0,0,1,5\n")
    assert (e.reason, e.line) == ("GOTO needs 3 or 6 numbers, got 7", 3)


# --------------------------------------------------------------------------- RAPID / FEDRAT


@pytest.mark.parametrize("rapid", ["RAPID", "RAPID/", "rapid", " RAPID / "])
def test_rapid_applies_to_next_motion_only(tmp_path: Path, rapid: str) -> None:
    tp = cl(tmp_path, MM + f"GOTO/0,0,0\n{rapid}\nPAINT/COLOR,3\nGOTO/1,0,0\nGOTO/2,0,0\n")
    assert tp.rapid.tolist() == [False, True, False]
    assert np.isnan(tp.feed[1]) and tp.feed[2] == 100


@pytest.mark.parametrize(
    ("head", "record", "feed"),
    [
        ("UNITS/MM", "FEDRAT/MMPM,500", 500.0),
        ("UNITS/MM", "FEDRAT/IPM,10", 254.0),
        ("UNITS/MM", "FEDRAT/500,MMPM", 500.0),
        ("UNITS/MM", "FEDRAT/10,IPM", 254.0),
        ("UNITS/MM", "FEDRAT/500", 500.0),
        ("UNITS/INCHES", "FEDRAT/10", 254.0),
        ("UNITS/INCHES", "FEDRAT/MMPM,500", 500.0),
        ("UNITS/MM", "FEDRAT / mmpm , 500.", 500.0),
        ("UNITS/MM\nSPINDL/RPM,1000,CLW", "FEDRAT/MMPR,0.1", 100.0),
        ("UNITS/MM\nSPINDL/RPM,1000,CLW", "FEDRAT/0.1,MMPR", 100.0),
        ("UNITS/MM\nSPINDL/RPM,1000,CLW", "FEDRAT/IPR,0.004", 101.6),
    ],
)
def test_fedrat_variants(tmp_path: Path, head: str, record: str, feed: float) -> None:
    tp = cl(tmp_path, f"{head}\n{record}\nGOTO/0,0,0\n")
    assert tp.feed[0] == pytest.approx(feed)
    assert not tp.inverse_time[0]


def test_fedrat_inverse_time(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "GOTO/0,0,0\nFEDRAT/INVERS,12.5\nGOTO/1,0,0\nFEDRAT/MMPM,300\nGOTO/2,0,0\n")
    assert tp.inverse_time.tolist() == [False, True, False]
    assert tp.feed.tolist() == [100.0, 12.5, 300.0]


def test_per_rev_feed_follows_spindle_speed(tmp_path: Path) -> None:
    text = "UNITS/MM\nSPINDL/RPM,1000,CLW\nFEDRAT/MMPR,0.1\nGOTO/0,0,0\nSPINDL/RPM,2000,CLW\nGOTO/1,0,0\n"
    tp = cl(tmp_path, text)
    assert tp.feed.tolist() == pytest.approx([100.0, 200.0])


def test_per_rev_feed_without_spindle_is_an_error(tmp_path: Path) -> None:
    e = err(tmp_path, "UNITS/MM\nFEDRAT/MMPR,0.1\nGOTO/0,0,0\n")
    assert e.line == 2 and "spindle speed" in e.reason


def test_per_rev_feed_with_spindle_off_is_an_error(tmp_path: Path) -> None:
    text = "UNITS/MM\nSPINDL/RPM,1000\nFEDRAT/MMPR,0.1\nGOTO/0,0,0\nSPINDL/OFF\nGOTO/1,0,0\n"
    e = err(tmp_path, text)
    assert e.line == 6 and "spindle is off" in e.reason


def test_feed_move_before_any_fedrat(tmp_path: Path) -> None:
    e = err(tmp_path, "UNITS/MM\nRAPID\nGOTO/0,0,0\nGOTO/1,0,0\n")
    assert e.line == 4 and e.reason.startswith("feed move before any FEDRAT") and "--feed" in e.reason


def test_feed_option_gives_the_feed_before_the_first_fedrat(tmp_path: Path) -> None:
    """NCL's APT source may have no FEDRAT at all: --feed (mm/min, also for an inch file) is the
    feed of every feed move before the first FEDRAT, and the FEDRAT's own feed follows it."""
    text = "UNITS/INCHES\nGOTO/0,0,0\nGOTO/1,0,0\nRAPID\nGOTO/1,1,0\nGOTO/2,1,0\nFEDRAT/10,IPM\nGOTO/3,1,0\n"
    tp = cl(tmp_path, text, feed=500.0)
    assert np.array_equal(tp.rapid, [False, False, True, False, False])
    np.testing.assert_allclose(tp.feed[[0, 1, 3]], 500.0)
    assert tp.feed[4] == pytest.approx(254.0)
    assert len(tp.notes) == 1 and "FEED 500 MM/MIN FROM --feed FOR THE 3 FEED MOVES" in tp.notes[0]
    assert "CL LINE 2" in tp.notes[0]


def test_feed_option_unused_is_said(tmp_path: Path) -> None:
    tp = cl(tmp_path, "UNITS/MM\nFEDRAT/100\nGOTO/0,0,0\nGOTO/1,0,0\n", feed=500.0)
    np.testing.assert_allclose(tp.feed, 100.0)
    assert tp.notes == () and any("--feed 500 not used" in w for w in tp.warnings)


def test_feed_option_out_of_range(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="--feed must be from"):
        cl(tmp_path, "UNITS/MM\nGOTO/0,0,0\n", feed=0.0)


@pytest.mark.parametrize("record", ["FEDRAT/0", "FEDRAT/-5,MMPM", "FEDRAT/MMPM", "FEDRAT/FAST,5", "FEDRAT/1,2"])
def test_bad_fedrat(tmp_path: Path, record: str) -> None:
    assert err(tmp_path, f"UNITS/MM\n{record}\nGOTO/0,0,0\n").line == 2


# --------------------------------------------------------------------------- units


@pytest.mark.parametrize(
    ("record", "units", "scale"),
    [
        ("UNITS/MM", "mm", 1.0),
        ("UNITS/INCHES", "inch", 25.4),
        ("UNIT/INCHES", "inch", 25.4),
        ("units / inch", "inch", 25.4),
    ],
)
def test_units_record(tmp_path: Path, record: str, units: str, scale: float) -> None:
    tp = cl(tmp_path, f"{record}\nFEDRAT/MMPM,100\nGOTO/1,2,3\n")
    assert tp.units == units
    np.testing.assert_allclose(tp.tip[0], np.array([1, 2, 3]) * scale)
    assert tp.warnings == ()


def test_units_inferred_from_ipm_and_mmpm(tmp_path: Path) -> None:
    tp = cl(tmp_path, "RAPID\nGOTO/0,0,1\nFEDRAT/IPM,10\nGOTO/1,0,0\n")
    assert tp.units == "inch"
    np.testing.assert_allclose(tp.tip[1], [25.4, 0, 0])
    assert "t.cls:3: no UNITS record: inch inferred from IPM feed" in tp.warnings[0]
    tp = cl(tmp_path, "FEDRAT/MMPM,100\nGOTO/1,0,0\n")
    assert tp.units == "mm" and tp.tip[0, 0] == 1.0


def test_no_units_defaults_to_mm_with_warning(tmp_path: Path) -> None:
    tp = cl(tmp_path, "FEDRAT/100\nGOTO/1,0,0\n")
    assert tp.units == "mm" and tp.tip[0, 0] == 1.0
    assert any("assuming mm" in w for w in tp.warnings)


def test_units_override_wins(tmp_path: Path) -> None:
    tp = cl(tmp_path, "UNITS/MM\nFEDRAT/100\nGOTO/1,0,0\n", units="inch")
    assert tp.units == "inch"
    np.testing.assert_allclose(tp.tip[0], [25.4, 0, 0])
    assert tp.feed[0] == pytest.approx(2540.0)
    assert any("UNITS/MM ignored" in w for w in tp.warnings)
    tp = cl(tmp_path, "FEDRAT/IPM,10\nGOTO/1,0,0\n", units="mm")
    assert tp.units == "mm" and tp.tip[0, 0] == 1.0 and tp.feed[0] == pytest.approx(254.0)


def test_mixed_units_records_rejected(tmp_path: Path) -> None:
    e = err(tmp_path, "UNITS/MM\nFEDRAT/100\nGOTO/1,0,0\nUNITS/INCHES\nGOTO/2,0,0\n")
    assert e.line == 4 and "mixed units" in e.reason


def test_bad_units_argument(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="units must be"):
        read_cl(write(tmp_path, MM + "GOTO/0,0,0\n"), units="cm")  # type: ignore[arg-type]


# --------------------------------------------------------------------------- MULTAX


TILTED = "MULTAX/ON\nGOTO/0,0,0,0.6,0,0.8\nGOTO/1,0,0\nMULTAX/OFF\nGOTO/2,0,0\n"


def test_multax_off_keeps_the_last_axis_in_catia_apt(tmp_path: Path) -> None:
    # CATIA / DELMIA "APT Format: Syntax of APT Instructions": after MULTAX/OFF "the components of
    # the locked tool axis are the components defined on the last 5-axis position"
    tp = cl(tmp_path, "$$*CATIA0\n" + MM + TILTED)
    np.testing.assert_allclose(tp.axis, [[0.6, 0, 0.8]] * 3)


def test_multax_off_is_the_work_plane_z_in_fusion_apt(tmp_path: Path) -> None:
    # Autodesk's APT posts write MULTAX/OFF only before a section whose tool axis is its Z
    tp = cl(tmp_path, "PPRINT/'Autodesk Fusion'\n" + MM + TILTED)
    np.testing.assert_allclose(tp.axis, [[0.6, 0, 0.8], [0.6, 0, 0.8], [0, 0, 1]])


def test_multax_off_after_a_tilted_axis_is_refused_where_undocumented(tmp_path: Path) -> None:
    e = err(tmp_path, MM + TILTED)
    assert e.line == 7 and "MULTAX/OFF (line 6)" in e.reason and "TLAXIS" in e.reason
    tp = cl(tmp_path, MM + TILTED.replace("MULTAX/OFF\n", "MULTAX/OFF\nTLAXIS/0,0,1\n"))
    np.testing.assert_allclose(tp.axis[-1], [0, 0, 1])
    vertical = cl(tmp_path, MM + "MULTAX/ON\nGOTO/0,0,0,0,0,1\nMULTAX/OFF\nGOTO/2,0,0\n")  # both readings agree
    np.testing.assert_allclose(vertical.axis, [[0, 0, 1]] * 2)


def test_every_motion_that_carries_the_axis_refuses_it_undecided(tmp_path: Path) -> None:
    for motion in ("NURBS/\nKNOT/1.0\nCNTRL/1,2,0\nCNTRL/3,2,0\nCNTRL/4,0,0\nGOTO/9,9,9", "CLEARP/50\nRETRCT",
                   "INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/0,0,0,1),ON,(LINE/0,0,0,0,1,0)", "GODLTA/5"):
        e = err(tmp_path, MM + TILTED.replace("GOTO/2,0,0\n", motion + "\n"))
        assert "MULTAX/OFF (line 6)" in e.reason
    # GOHOME to a FROM pose sets the axis again
    head = "UNITS/MM\nFEDRAT/MMPM,100\nFROM/0,0,100\nLOADTL/1\n"
    text = head + TILTED.replace("GOTO/2,0,0\n", "GOHOME\nGOTO/5,5,5\n")
    np.testing.assert_allclose(cl(tmp_path, text).axis[-1], [0, 0, 1])


def test_bare_multax_is_multax_on(tmp_path: Path) -> None:
    # CATIA's APT format lists MULTAX and MULTAX/ON as one statement; NCL reads a bare MULTAX as ON
    tp = cl(tmp_path, MM + "MULTAX\nGOTO/0,0,0,0.6,0,0.8\n")
    np.testing.assert_allclose(tp.axis, [[0.6, 0, 0.8]])


def test_multax_off_rejects_tool_axis(tmp_path: Path) -> None:
    e = err(tmp_path, MM + "MULTAX/OFF\nGOTO/0,0,0,1,0,0\n")
    assert e.line == 4 and "MULTAX/OFF" in e.reason


# --------------------------------------------------------------------------- MSYS / CSYS


def rot_z(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_msys_rotated_frame(tmp_path: Path) -> None:
    # CL frame: origin (10, 20, 30), X = part +Y, Y = part -X (90 deg about Z)
    tp = cl(tmp_path, MM + "MSYS/10,20,30,0,1,0,-1,0,0\nGOTO/1,2,3,1,0,0\nGOTO/0,0,0\n", frame="apply")
    np.testing.assert_allclose(tp.tip[0], [10 - 2, 20 + 1, 30 + 3])
    np.testing.assert_allclose(tp.axis[0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(tp.tip[1], [10, 20, 30])
    np.testing.assert_allclose(tp.axis[1], [0, 1, 0], atol=1e-15)  # axis carried in CL numbers


def test_catia_origin_with_x_and_z_axes(tmp_path: Path) -> None:
    # CATIA's NC axis, ORIGIN/x,y,z,xx,xy,xz,zx,zy,zz: here X = part +Y, Z = part +Z, so Y = part -X
    tp = cl(tmp_path, MM + "ORIGIN/10,20,30,0,1,0,0,0,1\nGOTO/1,2,3,1,0,0\n", frame="apply")
    np.testing.assert_allclose(tp.tip[0], [10 - 2, 20 + 1, 30 + 3])
    np.testing.assert_allclose(tp.axis[0], [0, 1, 0], atol=1e-15)
    e = err(tmp_path, MM + "ORIGIN/0,0,0,1,0,0,0.1,0,0.995\nGOTO/0,0,0\n")
    assert e.line == 3 and "not orthogonal" in e.reason


def test_msys_tilted_frame_with_rounded_axes(tmp_path: Path) -> None:
    # X tilted 30 deg about Y, written with 7 decimals as NX does: orthonormalised
    tp = cl(tmp_path, MM + "MSYS/0,0,0,0.8660254,0.0000000,-0.5000000,0.0000000,1.0000000,0.0000000\nGOTO/0,0,0\n",
            frame="apply")
    np.testing.assert_allclose(tp.axis[0], [0.5, 0, 0.8660254], atol=1e-7)


def test_msys_inch_origin_and_reset(tmp_path: Path) -> None:
    text = "UNITS/INCHES\nFEDRAT/10\nMSYS/1,0,0,1,0,0,0,1,0\nGOTO/1,0,0\nMSYS/0,0,0,1,0,0,0,1,0\nGOTO/1,0,0\n"
    np.testing.assert_allclose(cl(tmp_path, text, frame="apply").tip[:, 0], [50.8, 25.4])
    # NX reading: each GOTO in its own MCS; the second MCS brought into the first one's frame
    tp = cl(tmp_path, text)
    np.testing.assert_allclose(tp.tip[:, 0], [25.4, 0.0])
    assert any("2 different machine coordinate systems" in w for w in tp.warnings)


def test_csys_matrix(tmp_path: Path) -> None:
    R = rot_z(90.0)
    t = [5.0, 6.0, 7.0]
    m = np.column_stack([R, t]).ravel()
    tp = cl(tmp_path, MM + "CSYS/" + ",".join(f"{v:.10f}" for v in m) + "\nGOTO/1,0,0,1,0,0\n", frame="apply")
    np.testing.assert_allclose(tp.tip[0], [5, 7, 7], atol=1e-9)
    np.testing.assert_allclose(tp.axis[0], [0, 1, 0], atol=1e-9)


@pytest.mark.parametrize(
    ("record", "message"),
    [
        ("MSYS/0,0,0,1,0,0,0.1,0.995,0", "not orthogonal"),
        ("MSYS/0,0,0,1,0,0,0,0,0", "zero length"),
        ("MSYS/0,0,0,2,0,0,0,1,0", "not unit"),
        ("MSYS/0,0,0,1,0,0", "MSYS needs 9 numbers"),
        ("CSYS/1,0,0,0,0,1,0,0,0,0,-1,0", "right-handed"),
        ("CSYS/1,0,0,0,0,1,0,0", "CSYS needs 12 numbers"),
    ],
)
def test_bad_frames_rejected(tmp_path: Path, record: str, message: str) -> None:
    e = err(tmp_path, MM + record + "\nGOTO/0,0,0\n")
    assert e.line == 3 and message in e.reason


def test_msys_property_random_frames(tmp_path: Path) -> None:
    """1000 random orthonormal frames: output == origin + R p and R a (one file, one pose each)."""
    rng = np.random.default_rng(20240611)
    n = 1000
    lines = ["UNITS/MM", "FEDRAT/MMPM,100"]
    expected_tip, expected_axis = [], []
    for _ in range(n):
        q, r = np.linalg.qr(rng.normal(size=(3, 3)))
        R = q * np.sign(np.diag(r))
        if np.linalg.det(R) < 0:
            R[:, 2] *= -1
        o = rng.uniform(-1000, 1000, 3)
        p = rng.uniform(-500, 500, 3)
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        lines.append("MSYS/" + ",".join(repr(float(v)) for v in (*o, *R[:, 0], *R[:, 1])))
        lines.append("GOTO/" + ",".join(repr(float(v)) for v in (*p, *a)))
        expected_tip.append(o + R @ p)
        expected_axis.append(R @ a)
    tp = cl(tmp_path, "\n".join(lines) + "\n", frame="apply")
    assert len(tp) == n
    np.testing.assert_allclose(tp.tip, expected_tip, atol=1e-9)
    np.testing.assert_allclose(tp.axis, expected_axis, atol=1e-12)
    # the MCS reading: every pose brought into the first frame, R0^T (o + R p - o0)
    local = cl(tmp_path, "\n".join(lines) + "\n")
    R0 = np.array([[float(v) for v in lines[2][5:].split(",")][3:6], [float(v) for v in lines[2][5:].split(",")][6:9]])
    o0 = np.array([float(v) for v in lines[2][5:].split(",")][:3])
    R0 = np.column_stack([R0[0], R0[1], np.cross(R0[0], R0[1])])
    np.testing.assert_allclose(local.tip, (np.array(expected_tip) - o0) @ R0, atol=1e-8)
    np.testing.assert_allclose(local.axis, np.array(expected_axis) @ R0, atol=1e-12)


# --------------------------------------------------------------------------- tools


def test_tool_change_merge_nx_order(tmp_path: Path) -> None:
    text = (
        MM
        + "TOOL PATH/OP1,TOOL,EM10\n"  # 3
        + "TLDATA/MILL,10,0,75,0,0\n"  # 4: before the load
        + "LOAD/TOOL,3,ADJUST,3\n"  # 5
        + "SPINDL/RPM,5000,CLW\n"  # 6
        + "GOTO/0,0,0\n"  # 7
        + "TOOL PATH/OP2,TOOL,EM6\n"  # 8
        + "LOAD/TOOL,4\n"  # 9
        + "TLDATA/MILL,6,0,60,0,0\n"  # 10: after the load
        + "GOTO/1,0,0\n"  # 11
    )
    tp = cl(tmp_path, text)
    changes = events(tp, ToolChange)
    assert changes == [
        ToolChange(index=0, line=5, tool=3, length=75.0, diameter=10.0, adjust=3),
        ToolChange(index=1, line=9, tool=4, length=60.0, diameter=6.0, adjust=None),
    ]
    assert tp.tool.tolist() == [3, 4]
    kinds = [type(e).__name__ for e in tp.events]
    assert kinds == ["Comment", "ToolChange", "Spindle", "Comment", "ToolChange"]
    assert [c.text for c in events(tp, Comment)] == ["OP1 (tool EM10)", "OP2 (tool EM6)"]
    assert tp.warnings == ()


def test_tldata_inch_length_converted(tmp_path: Path) -> None:
    tp = cl(tmp_path, "UNITS/INCHES\nFEDRAT/10\nLOAD/TOOL,2\nTLDATA/MILL,0.5,0,3.0\nGOTO/0,0,0\n")
    (change,) = events(tp, ToolChange)
    assert change.length == pytest.approx(76.2) and change.diameter == pytest.approx(12.7)


def test_loadtl_select_cutter(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "LOADTL/5,LENGTH,80\nCUTTER/12,1\nGOTO/0,0,0\nSELECT/TOOL,7\nGOTO/1,0,0\n")
    changes = events(tp, ToolChange)
    assert [(c.tool, c.length, c.diameter, c.index) for c in changes] == [(5, 80.0, 12.0, 0), (7, None, None, 1)]
    assert tp.tool.tolist() == [5, 7]


def test_select_after_load_is_a_preselection(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "LOADTL/1\nSELECT/TOOL,2\nGOTO/0,0,0\n")
    assert [c.tool for c in events(tp, ToolChange)] == [1]
    assert tp.tool.tolist() == [1]


def test_tool_zero_before_first_load_and_events_index(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "GOTO/0,0,0\nGOTO/1,0,0\nLOAD/TOOL,9\nGOTO/2,0,0\nSTOP\n")
    assert tp.tool.tolist() == [0, 0, 9]
    (change,) = events(tp, ToolChange)
    assert change.index == 2
    (stop,) = events(tp, Stop)
    assert stop.index == 3 and not stop.optional  # after the last motion: index N


def test_cutter_alone_gives_tool_zero_change_with_warning(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "CUTTER/8\nGOTO/0,0,0\n")
    (change,) = events(tp, ToolChange)
    assert (change.tool, change.diameter, change.length) == (0, 8.0, None)
    assert any("without a tool load" in w for w in tp.warnings)


def test_bad_tool_number(tmp_path: Path) -> None:
    e = err(tmp_path, MM + "LOAD/TOOL,2.5\nGOTO/0,0,0\n")
    assert e.line == 3 and "tool number" in e.reason


# --------------------------------------------------------------------------- spindle / coolant


@pytest.mark.parametrize(
    ("record", "rpm", "direction"),
    [
        ("SPINDL/RPM,1200,CLW", 1200.0, "CW"),
        ("SPINDL/1200,RPM,CCLW", 1200.0, "CCW"),
        ("SPINDL/RPM,800", 800.0, "CW"),
        ("spindl / rpm , 950. , cclw", 950.0, "CCW"),
    ],
)
def test_spindle_records(tmp_path: Path, record: str, rpm: float, direction: str) -> None:
    tp = cl(tmp_path, MM + record + "\nGOTO/0,0,0\n")
    assert events(tp, Spindle) == [Spindle(index=0, line=3, rpm=rpm, direction=direction)]  # type: ignore[arg-type]


def test_spindle_off_and_on_reuses_last(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "SPINDL/RPM,3000,CCLW\nGOTO/0,0,0\nSPINDL/OFF\nSPINDL/ON\nGOTO/1,0,0\n")
    got = [(s.rpm, s.direction, s.index) for s in events(tp, Spindle)]
    assert got == [(3000.0, "CCW", 0), (0.0, "OFF", 1), (3000.0, "CCW", 1)]


@pytest.mark.parametrize(
    ("record", "message"),
    [("SPINDL/ON", "without a previous"), ("SPINDL/SFM,300", "surface speed"), ("SPINDL/RPM,-5", "positive")],
)
def test_bad_spindle(tmp_path: Path, record: str, message: str) -> None:
    e = err(tmp_path, MM + record + "\nGOTO/0,0,0\n")
    assert e.line == 3 and message in e.reason


@pytest.mark.parametrize("mode", ["ON", "OFF", "FLOOD", "MIST", "THRU"])
def test_coolant_modes(tmp_path: Path, mode: str) -> None:
    tp = cl(tmp_path, MM + f"COOLNT/{mode}\nGOTO/0,0,0\n")
    assert events(tp, Coolant) == [Coolant(index=0, line=3, mode=mode)]  # type: ignore[arg-type]


def test_unknown_coolant_mode_warns(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "COOLNT/AIR\nGOTO/0,0,0\n")
    assert events(tp, Coolant) == []
    assert any(":3: COOLNT/AIR" in w for w in tp.warnings)


# --------------------------------------------------------------------------- CIRCLE


def circle_file(axis: str, end: str, start: str = "10,0,0", extra: str = "", rec_axis: str = "") -> str:
    return MM + f"GOTO/{start}{rec_axis}\nCIRCLE/0,0,0,{axis},10{extra}\nGOTO/{end}\n"


def check_on_circle_and_sagitta(tp: Toolpath, r: float, tol: float) -> None:
    xy = tp.tip[:, :2]
    np.testing.assert_allclose(np.linalg.norm(xy, axis=1), r, atol=1e-9)
    mid = 0.5 * (xy[1:] + xy[:-1])
    sagitta = r - np.linalg.norm(mid, axis=1)
    assert sagitta.max() <= tol * (1 + 1e-9)
    assert sagitta.max() > tol / 4  # not grossly over-sampled


def test_circle_quarter_ccw(tmp_path: Path) -> None:
    tp = cl(tmp_path, circle_file("0,0,1", "0,10,0"))
    assert len(tp) > 3  # never a single chord
    check_on_circle_and_sagitta(tp, 10.0, 0.001)
    ang = np.arctan2(tp.tip[:, 1], tp.tip[:, 0])
    assert np.all(np.diff(ang) > 0)  # counter-clockwise about +Z
    assert ang[-1] == pytest.approx(math.pi / 2)
    assert (tp.line[1:] == 5).all() and tp.line[0] == 3  # arc poses carry the end GOTO's line
    np.testing.assert_allclose(tp.tip[-1], [0, 10, 0])
    assert (tp.feed == 100).all()


def test_circle_negative_axis_goes_the_long_way(tmp_path: Path) -> None:
    tp = cl(tmp_path, circle_file("0,0,-1", "0,10,0"))
    check_on_circle_and_sagitta(tp, 10.0, 0.001)
    ang = np.unwrap(np.arctan2(tp.tip[:, 1], tp.tip[:, 0]))
    assert np.all(np.diff(ang) < 0)  # clockwise seen from +Z = CCW about -Z
    assert ang[-1] - ang[0] == pytest.approx(-1.5 * math.pi)
    assert tp.tip[:, 1].min() == pytest.approx(-10.0, abs=0.01)  # passes through (0,-10)


def test_circle_nx_eleven_values_and_tolerance(tmp_path: Path) -> None:
    coarse = cl(tmp_path, circle_file("0,0,1", "-10,0,0", extra=",0.01,0.5,8,0"), chordal_tolerance=0.05)
    fine = cl(tmp_path, circle_file("0,0,1", "-10,0,0", extra=",0.01,0.5,8,0"), chordal_tolerance=0.001)
    check_on_circle_and_sagitta(coarse, 10.0, 0.05)
    check_on_circle_and_sagitta(fine, 10.0, 0.001)
    assert len(fine) > len(coarse)
    assert (coarse.tip[1:-1, 1] > 0).all()  # half circle through +Y


def test_circle_full_and_helical(tmp_path: Path) -> None:
    tp = cl(tmp_path, circle_file("0,0,1", "10,0,0"))
    ang = np.unwrap(np.arctan2(tp.tip[:, 1], tp.tip[:, 0]))
    assert ang[-1] - ang[0] == pytest.approx(2 * math.pi)
    tp = cl(tmp_path, circle_file("0,0,1", "-10,0,5"))
    ang = np.arctan2(tp.tip[:, 1], tp.tip[:, 0])
    np.testing.assert_allclose(tp.tip[1:, 2], 5 * ang[1:] / math.pi, atol=1e-9)  # z linear in angle


def test_circle_in_tilted_plane_and_inch(tmp_path: Path) -> None:
    # circle about +X through (0,1,0) -> (0,0,1), inch: radius 1 in, tolerance in mm
    text = "UNITS/INCHES\nFEDRAT/10\nGOTO/0,1,0\nCIRCLE/0,0,0,1,0,0,1\nGOTO/0,0,1\n"
    tp = cl(tmp_path, text, chordal_tolerance=0.002)
    yz = tp.tip[:, 1:]
    np.testing.assert_allclose(np.linalg.norm(yz, axis=1), 25.4, atol=1e-9)
    np.testing.assert_allclose(tp.tip[:, 0], 0, atol=1e-12)
    sag = 25.4 - np.linalg.norm(0.5 * (yz[1:] + yz[:-1]), axis=1)
    assert sag.max() <= 0.002 * (1 + 1e-9)
    assert np.all(np.diff(np.arctan2(yz[:, 1], yz[:, 0])) > 0)  # y -> z is CCW about +X


def test_circle_axis_slerp(tmp_path: Path) -> None:
    s = math.sin(math.radians(30))
    c = math.cos(math.radians(30))
    text = MM + f"GOTO/10,0,0,0,0,1\nCIRCLE/0,0,0,0,0,1,10\nGOTO/0,10,0,{s},0,{c}\n"
    tp = cl(tmp_path, text)
    np.testing.assert_allclose(np.linalg.norm(tp.axis, axis=1), 1.0, atol=1e-12)
    tilt = np.degrees(np.arccos(np.clip(tp.axis[:, 2], -1, 1)))
    assert np.all(np.diff(tilt) > 0)
    np.testing.assert_allclose(tilt[[0, -1]], [0, 30], atol=1e-9)
    np.testing.assert_allclose(np.diff(tilt), np.diff(tilt)[0], atol=1e-9)  # constant angular rate
    assert (tp.axis[:, 1] == 0).all()


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        (MM + "GOTO/12,0,0\nCIRCLE/0,0,0,0,0,1,10\nGOTO/0,10,0\n", 4, "arc start point"),
        (MM + "GOTO/10,0,0\nCIRCLE/0,0,0,0,0,1,10\nGOTO/0,11,0\n", 5, "arc end point"),
        (MM + "GOTO/10,0,0\nCIRCLE/0,0,0,0,0,0,10\nGOTO/0,10,0\n", 4, "circle axis has zero or absurd length"),
        (MM + "GOTO/10,0,0\nCIRCLE/0,0,0,0,0\nGOTO/0,10,0\n", 4, "CIRCLE needs 6 to 11 numbers"),
        (MM + "GOTO/10,0,0\nCIRCLE/0,0,0,0,0,1,10\n", 4, "not followed by the GOTO"),
        (MM + "GOTO/10,0,0\nCIRCLE/0,0,0,0,0,1,10\nGOHOME\n", 5, "must be followed by a GOTO"),
        (MM + "CIRCLE/0,0,0,0,0,1,10\nGOTO/0,10,0\n", 3, "no current position"),
    ],
)
def test_bad_circles(tmp_path: Path, text: str, line: int, message: str) -> None:
    e = err(tmp_path, text)
    assert e.line == line and message in e.reason


# --------------------------------------------------------------------------- APT arcs: INDIRV, TLON,GOFWD


def _fmt(v: np.ndarray | list[float]) -> str:
    return ",".join(f"{x:.12f}" for x in v)


def test_gofwd_runs_on_the_circle_to_the_crossing_of_the_check_line(tmp_path: Path) -> None:
    # Creo's CIRC_INTERPOLATION APT_FORMAT and CATIA's default circle output. Each case is built
    # from its answer: a sweep, and a check line through that end point, either through the centre
    # (its other crossing half a turn away, so the end is the 1st crossing below half a turn and
    # the 2nd above it, as CATIA's "ON,2,INTOF" full circles are) or a chord at a random angle.
    rng = np.random.default_rng(11)
    lines, cases = MM.rstrip("\n").split("\n"), []
    for k in range(200):
        axis = np.array([0.0, 0.0, 1.0]) if k % 2 else _unit(rng.normal(size=3) + np.array([0, 0, 3.0]))
        c, r = rng.uniform(-100, 100, 3), rng.uniform(0.5, 80)
        u = _unit(np.cross(axis, rng.normal(size=3)))
        sense = 1.0 if rng.random() < 0.5 else -1.0
        w = sense * np.cross(axis, u)  # the way the tool goes at the start
        height = rng.uniform(-20, 20)
        start = c + height * axis + r * u
        sweep = rng.uniform(0.05, 2 * np.pi - 0.05) if k % 5 else 2 * np.pi
        end = c + height * axis + r * (np.cos(sweep) * u + np.sin(sweep) * w)
        radial = _unit(end - c - height * axis)
        if k % 3 == 0 and k % 5:  # a chord through the end: its other end E + t d, t = -2 (E - centre) . d
            tangent = np.cos(sweep) * w - np.sin(sweep) * u
            d = _unit(tangent + rng.uniform(-2, 2) * radial)
            other = (end - 2 * ((end - c - height * axis) @ d) * d) - c - height * axis
            other_angle = np.arctan2(other @ w, other @ u) % (2 * np.pi)
            a, b = end - rng.uniform(1, 9) * d, end + rng.uniform(1, 9) * d
            crossing = 1 if other_angle > sweep or other_angle < 1e-6 else 2
        else:
            a, b = end - rng.uniform(0.1, 2) * r * radial, end + rng.uniform(0.1, 2) * r * radial
            crossing = 1 if sweep < np.pi else 2
        a, b = a + rng.uniform(-5, 5) * axis, b + rng.uniform(-5, 5) * axis  # the line is a plane along the axis
        circle = f"{_fmt(c)},{r:.12f}" if k % 2 else f"{_fmt(c)},{_fmt(axis)},{r:.12f}"
        intof = "" if crossing == 1 and k % 4 else f"{crossing},INTOF,"
        direction = _unit(w + rng.uniform(-0.5, 0.5) * u)  # INDIRV need only point the way round
        lines += [f"GOTO/{_fmt(start)},{_fmt(axis)}", f"INDIRV/{_fmt(direction)}",
                  f"TLON, GOFWD / (CIRCLE / {circle}), ON, {intof}(LINE / {_fmt(a)},{_fmt(b)})"]
        cases.append((start, end, c, axis, r, sweep, sense, len(lines)))
    tp = cl(tmp_path, "\n".join(lines) + "\n")
    assert tp.warnings == ()
    first = np.flatnonzero(np.isin(tp.line, [n - 2 for *_, n in cases]))
    for start_index, (start, end, c, axis, r, sweep, sense, line) in zip(first, cases, strict=True):
        stop = start_index + 1 + np.flatnonzero(tp.line[start_index + 1:] == line)
        assert len(stop) and stop[0] == start_index + 1 and np.all(np.diff(stop) == 1)
        path = tp.tip[np.r_[start_index, stop]]
        np.testing.assert_allclose(path[0], start, atol=1e-9)
        np.testing.assert_allclose(path[-1], end, atol=1e-8)
        rel = path - c
        along = rel @ axis
        radial = rel - along[:, None] * axis
        np.testing.assert_allclose(along, along[0], atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(radial, axis=1), r, rtol=1e-9)
        turns = np.einsum("ij,j->i", np.cross(radial[:-1], radial[1:]), axis) * sense
        angles = np.arctan2(turns, np.einsum("ij,ij->i", radial[:-1], radial[1:]))
        assert np.all(angles > 0) and abs(angles.sum() - sweep) < 1e-8
        sagitta = r * (1 - np.cos(angles / 2))
        assert sagitta.max() <= 0.001 * (1 + 1e-9)  # the default chordal tolerance, mm
        np.testing.assert_allclose(tp.axis[stop], np.broadcast_to(axis, (len(stop), 3)), atol=1e-12)


@pytest.mark.parametrize(
    ("records", "message"),
    [
        ("INDIRV/0,1,0\nTLLFT,GOFWD/(CIRCLE/0,0,0,10),ON,(LINE/0,0,0,1,0,0)", "only TLON,GOFWD"),
        ("INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/0,0,0,10),TO,(LINE/0,0,0,1,0,0)", "only ON"),
        ("INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/0,0,0,12),ON,(LINE/0,0,0,1,0,0)", "starts 10 from the circle's axis"),
        ("INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/0,0,0,10),ON,(LINE/20,0,0,20,1,0)", "does not cross the circle"),
        ("INDIRV/1,0,0\nTLON,GOFWD/(CIRCLE/0,0,0,10),ON,(LINE/0,0,0,1,0,0)", "does not point along the circle"),
        ("INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/0,0,0,1,0,0,10),ON,(LINE/0,0,0,1,0,0)", "axis is not the tool axis"),
        ("INDIRV/0,1,0\nTLON,GOFWD/(PLANE/0,0,1,0),ON,(LINE/0,0,0,1,0,0)", "only the form"),
        ("GOTO/10,0,0\nTLON,GOFWD/(CIRCLE/0,0,0,10),ON,(LINE/0,0,0,0,10,0)", "has no length to give its direction"),
        ("INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/10,0,0,0.001),ON,(LINE/0,0,0,0,10,0)", "from the circle's axis"),
    ],
)
def test_gofwd_that_cannot_be_honoured_is_refused(tmp_path: Path, records: str, message: str) -> None:
    e = err(tmp_path, MM + "GOTO/10,0,0\n" + records + "\n")
    assert e.line == 5 and message in e.reason


@pytest.mark.parametrize("side", [1, -1])
def test_gofwd_to_a_rounded_tangent_exit_line_ends_at_the_tangent_point(tmp_path: Path, side: int) -> None:
    # the exit line tangent at 135 degrees on either side of the centre, its points rounded to 5
    # decimals (as CATIA prints): one crossing, at the tangent point, not two rounding apart
    e = np.array([math.cos(math.radians(135)), math.sin(math.radians(135))]) * 10
    t = np.array([-e[1], e[0]]) / 10
    a, b = (e + 3 * t) * side, (e - 4 * t) * side
    line = f"{a[0]:.5f},{a[1]:.5f},0,{b[0]:.5f},{b[1]:.5f},0"
    tp = cl(tmp_path, MM + f"GOTO/10,0,0\nINDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/0,0,0,10),ON,(LINE/{line})\n")
    np.testing.assert_allclose(tp.tip[-1, :2], e * side, atol=1e-5)


def test_gofwd_without_indirv_goes_on_the_way_it_was_going(tmp_path: Path) -> None:
    # APT: no INDIRV, the motion keeps the direction of the move before it (here +Y at (10, 0))
    tp = cl(tmp_path, MM + "GOTO/10,-5,0\nGOTO/10,0,0\nTLON,GOFWD/(CIRCLE/0,0,0,10),ON,(LINE/0,0,0,0,1,0)\n")
    np.testing.assert_allclose(tp.tip[-1], [0, 10, 0], atol=1e-12)


# --------------------------------------------------------------------------- FROM / GOHOME


def test_from_first_pose_rapid_and_gohome(tmp_path: Path) -> None:
    text = "UNITS/MM\nLOADTL/1\nFROM/0,0,200\nFEDRAT/MMPM,100\nGOTO/10,0,0,1,0,0\nGOHOME\n"
    tp = cl(tmp_path, text)
    np.testing.assert_allclose(tp.tip, [[0, 0, 200], [10, 0, 0], [0, 0, 200]])
    np.testing.assert_allclose(tp.axis[2], [0, 0, 1])
    assert tp.rapid.tolist() == [True, False, True]
    assert tp.line.tolist() == [3, 5, 6]


def test_from_before_any_tool_load_only_sets_the_start(tmp_path: Path) -> None:
    # Makino FF CAM writes FROM before the first tool load: no tool length could place that pose.
    text = "UNITS/MM\nFROM/0,0,200\nLOADTL/1\nFEDRAT/MMPM,100\nGOTO/10,0,0\nGOHOME\n"
    tp = cl(tmp_path, text)
    np.testing.assert_allclose(tp.tip, [[10, 0, 0], [0, 0, 200]])
    assert tp.line.tolist() == [5, 6]


def test_gohome_without_from(tmp_path: Path) -> None:
    # the machine's home is unknown here: as the program's last motion (Autodesk's posts end with
    # it) the program ends before it, with a warning; with motion after it, refused at the GOHOME
    tp = cl(tmp_path, MM + "GOTO/0,0,0\nGOHOME\nCOOLNT/OFF\nEND\nFINI\n")
    assert len(tp) == 1 and any(":4: GOHOME without a FROM position" in w for w in tp.warnings)
    for after in ("GOTO/1,0,0", "GOTO/1,0,0\nGOTO/2,0,0", "CIRCLE/0,0,0,0,0,1,1\nGOTO/0,1,0", "RAPID\nGOTO/5,5,5"):
        e = err(tmp_path, MM + "GOTO/1,0,0\nGOHOME\n" + after + "\n")
        assert e.line == 4 and e.reason.startswith("GOHOME without a FROM position") and "motion after it" in e.reason


def test_godlta_and_tlaxis(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "TLAXIS/1,0,0\nGOTO/0,0,0\nGODLTA/5\nGODLTA/0,1,0\n")
    np.testing.assert_allclose(tp.tip, [[0, 0, 0], [5, 0, 0], [5, 1, 0]])
    np.testing.assert_allclose(tp.axis, [[1, 0, 0]] * 3)


# --------------------------------------------------------------------------- CLEARP / CLRSRF / RETRCT


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def test_retrct_withdraws_along_the_tool_axis_onto_the_clearance_plane(tmp_path: Path) -> None:
    # ICAM's APT vocabulary: RETRCT moves the tip along the current tool axis until it rests on the
    # plane of the last CLEARP / CLRSRF. Checked as a property of each result, not by the formula:
    # on the plane, along +axis from the point before, a rapid, carrying the RETRCT's line.
    rng = np.random.default_rng(7)
    lines, cases = MM.rstrip("\n").split("\n"), []
    for k in range(300):
        tip = rng.uniform(-200, 200, 3)
        axis = _unit(rng.normal(size=3) + np.array([0, 0, 2.0]))
        normal = _unit(rng.normal(size=3))
        if abs(normal @ axis) < 0.2:
            normal = _unit(normal + 2 * axis)
        if normal @ axis < 0:
            normal = -normal
        distance = normal @ tip + rng.uniform(0.5, 150) * (normal @ axis)
        scale = rng.uniform(0.2, 5)  # CLEARP's a,b,c need not be unit: the plane is a·x = d
        a, b, c, d = (*(scale * normal), scale * distance)
        form = ("CLEARP/{:.12f},{:.12f},{:.12f},{:.12f}", "CLRSRF/{:.12f},{:.12f},{:.12f},{:.12f}",
                "CLRSRF/NORMAL,{:.12f},{:.12f},{:.12f},{:.12f}")[k % 3]
        lines += [f"GOTO/{tip[0]:.12f},{tip[1]:.12f},{tip[2]:.12f},{axis[0]:.15f},{axis[1]:.15f},{axis[2]:.15f}",
                  form.format(a, b, c, d), "RETRCT"]
        cases.append((tip, axis, normal, distance, len(lines)))
    tp = cl(tmp_path, "\n".join(lines) + "\n")
    assert len(tp) == 2 * len(cases) and tp.warnings == ()
    for n, (tip, axis, normal, distance, line) in enumerate(cases):
        before, after = tp.tip[2 * n], tp.tip[2 * n + 1]
        np.testing.assert_allclose(before, tip, atol=1e-9)
        assert abs(normal @ after - distance) < 1e-8
        move = after - before
        assert move @ axis > 0.4 and np.linalg.norm(np.cross(move, axis)) < 1e-8
        assert tp.rapid[2 * n + 1] and not tp.rapid[2 * n] and tp.line[2 * n + 1] == line
        np.testing.assert_allclose(tp.axis[2 * n + 1], axis, atol=1e-12)


@pytest.mark.parametrize(
    ("record", "end"),
    [
        ("CLEARP/50", [10 + 0.6 * 62.5, 0, 50]),  # the plane z = 50, reached along (0.6, 0, 0.8)
        ("CLEARP/XYPLAN,50", [10 + 0.6 * 62.5, 0, 50]),
        ("CLEARP/YZPLAN,40", [40, 0, 0.8 * 50]),  # x = 40
        ("CLEARP/ZXPLAN,-5", None),  # y = -5: parallel to the axis
        ("CLRSRF/0,0,100", [10 + 0.6 * 74, 0, 0.8 * 74]),  # through the point, normal to the axis
    ],
)
def test_clearance_plane_forms(tmp_path: Path, record: str, end: list[float] | None) -> None:
    text = MM + f"GOTO/10,0,0,0.6,0,0.8\n{record}\nRETRCT\n"
    if end is None:
        e = err(tmp_path, text)
        assert e.line == 5 and "parallel to the clearance plane of line 4" in e.reason
        return
    tp = cl(tmp_path, text)
    np.testing.assert_allclose(tp.tip[-1], end, atol=1e-12)


@pytest.mark.parametrize(
    ("records", "message", "line"),
    [
        ("RETRCT", "RETRCT without a clearance plane", 4),
        ("CLEARP/XYPLAN,50\nCLEARP/NOMORE\nRETRCT", "RETRCT without a clearance plane", 6),
        ("CLRSRF/0,0,0,0,0,1,20\nRETRCT", "clearance surface of line 4, a form not supported", 5),
        ("CLRSRF/NORMAL,10\nRETRCT", "clearance surface of line 4, a form not supported", 5),
        ("CLEARP/0,0,0,5\nRETRCT", "clearance surface of line 4, a form not supported", 5),
        ("CLRSRF/(PLANE/0,0,1,50)\nRETRCT", "clearance surface of line 4, a form not supported", 5),
    ],
)
def test_retrct_that_cannot_be_honoured_is_refused(tmp_path: Path, records: str, message: str, line: int) -> None:
    # a skipped retract leaves the next move to run from the cut through the part
    e = err(tmp_path, MM + "GOTO/0,0,0\n" + records + "\nGOTO/50,0,50\n")
    assert message in e.reason and e.line == line


def test_clearance_records_in_any_form_change_nothing_until_a_retract(tmp_path: Path) -> None:
    for record in ("CLRSRF/(PLANE/0,0,1,50)", "CLRSRF/NORMAL,0,0,0,5", "CLEARP/ON", "CLRSRF/0,0,0,0,0,1,20"):
        tp = cl(tmp_path, MM + f"GOTO/0,0,0\n{record}\nGOTO/1,0,0\n")
        np.testing.assert_allclose(tp.tip, [[0, 0, 0], [1, 0, 0]])
        assert tp.warnings == ()


def test_a_motion_after_a_spline_that_is_not_a_goto_ends_the_spline_end_repeat(tmp_path: Path) -> None:
    # after a NURBS, a GOTO repeating its end adds nothing; a retract, a GOHOME or an arc in between
    # means the GOTO back down to that point is a move of its own
    spline = "NURBS/\nKNOT/1.0\nCNTRL/1,2,0\nCNTRL/3,2,0\nCNTRL/4,0,0\n"
    arc = "INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/0,0,0,4),ON,(LINE/0,0,0,0,1,0)"
    for between in ("CLEARP/50\nRETRCT", "GOHOME/4,0,50", arc):
        tp = cl(tmp_path, MM + "GOTO/0,0,0\n" + spline + between + "\nGOTO/4,0,0\nGOTO/10,0,0\n")
        np.testing.assert_allclose(tp.tip[-2:], [[4, 0, 0], [10, 0, 0]])


def test_retrct_from_above_the_plane_does_not_move_down(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "GOTO/0,0,80\nCLEARP/XYPLAN,50\nRETRCT\nGOTO/5,0,80\n")
    np.testing.assert_allclose(tp.tip, [[0, 0, 80], [5, 0, 80]])
    assert any(":5: RETRCT: the tool is already at or beyond the clearance plane of line 4" in w for w in tp.warnings)


def test_clearance_plane_stays_where_it_was_defined_when_the_frame_changes(tmp_path: Path) -> None:
    # the plane is the part's z = 50; the GOTO is in an MCS shifted by (0, 0, 30) and rotated about Z
    text = MM + "CLEARP/XYPLAN,50\nMSYS/0,0,30,0,1,0,-1,0,0\nGOTO/1,2,3\nRETRCT\n"
    tp = cl(tmp_path, text, frame="apply")
    np.testing.assert_allclose(tp.tip, [[-2, 1, 33], [-2, 1, 50]], atol=1e-12)


# --------------------------------------------------------------------------- text records, ignored records


def test_partno_pprint_insert_stop(tmp_path: Path) -> None:
    text = MM + "PARTNO/BRACKET $$ 7\nPPRINT/ HELLO, WORLD $ \nINSERT/M08\nSTOP\nOPSTOP\nGOTO/0,0,0\n"
    tp = cl(tmp_path, text)
    assert tp.part_name == "BRACKET $$ 7"  # text records are literal
    assert [c.text for c in events(tp, Comment)] == ["HELLO, WORLD $", "M08"]
    assert [s.optional for s in events(tp, Stop)] == [False, True]
    assert any(":5: INSERT/M08: not executed" in w for w in tp.warnings)


def test_display_records_ignored_silently(tmp_path: Path) -> None:
    text = MM + (
        "PAINT/COLOR,4\nDISPLY/ON\nPEN/1\nAUTOPS\nCLRSRF/NORMAL,10\nOPERATION/ROUGH\nGOTO/0,0,0\nEND-OF-PATH\nEND\n"
    )
    tp = cl(tmp_path, text)
    assert tp.warnings == () and len(tp) == 1


def test_fini_stops_parsing(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "GOTO/0,0,0\nFINI\nGOTO/1,2\ngarbage?!\n")
    assert len(tp) == 1 and tp.warnings == ()


def test_unknown_record_warning(tmp_path: Path) -> None:
    path = write(tmp_path, MM + "GOTO/0,0,0\nFOOBAR/1,2\nWIDGET\nGOTO/1,0,0\n")
    tp = read_cl(path)
    assert len(tp) == 2
    assert tp.warnings == (f"{path}:4: unknown record 'FOOBAR' ignored", f"{path}:5: unknown record 'WIDGET' ignored")


def test_tracut_is_read_as_information_with_a_warning(tmp_path: Path) -> None:
    tp = cl(tmp_path, MM + "TRACUT/1,0,0,5,0,1,0,0,0,0,1,0\nGOTO/1,2,3\nTRACUT/NOMORE\nGOTO/0,0,0\n")
    np.testing.assert_allclose(tp.tip, [[1, 2, 3], [0, 0, 0]])
    assert len(tp.warnings) == 1 and ":3: TRACUT read as information" in tp.warnings[0]
    assert "(2 records like this" in tp.warnings[0]


@pytest.mark.parametrize(
    ("record", "message"),
    [("TRANS/1,2,3", "TRANS"), ("GOFWD/S1", "GOFWD"), ("INDEX/1", "INDEX"), ("MOVE/1,2,3", "MOVE"),
     ("CONT/1,2,3", "CONT"), ("TLON,GOTO/1,2,3", "TLON,GOTO"), ("ARC/0,0,0,0,0,1,5,5,0,0", "ARC"),
     ("ROTATE/AAXIS,ABSOL,90,CLW", "ROTATE"), ("MCS/1,0,0,0,1,0,0,0,1,0,0,0", "MCS (a work-plane frame")],
)
def test_geometry_changing_records_rejected(tmp_path: Path, record: str, message: str) -> None:
    e = err(tmp_path, MM + record + "\nGOTO/0,0,0\n")
    assert e.line == 3 and message in e.reason


def test_cutcom_off_is_harmless(tmp_path: Path) -> None:
    assert cl(tmp_path, MM + "CUTCOM/OFF\nGOTO/0,0,0\n").warnings == ()


# --------------------------------------------------------------------------- lexical details


def test_comments_continuation_whitespace_case_numbers(tmp_path: Path) -> None:
    text = (
        "$$ header comment\n"  # 1
        "units / mm\n"  # 2
        "fedrat / mmpm , 100 $$ trailing\n"  # 3
        "goto / 25. , .984808 , -.5\n"  # 4
        "GOTO/1e-3, 1.E+02 ,\t-2.5E-1 $$ comment\n"  # 5
        "GOTO/1.0,$\n"  # 6
        "   2.0,$   $$ note\n"  # 7
        "\n"  # 8: blank line inside a continued record is skipped
        "3.0\n"  # 9
        "  GOTO/4,5,6\n"  # 10
    )
    tp = cl(tmp_path, text)
    np.testing.assert_allclose(tp.tip, [[25, 0.984808, -0.5], [0.001, 100, -0.25], [1, 2, 3], [4, 5, 6]])
    assert tp.line.tolist() == [4, 5, 6, 10]
    assert tp.warnings == ()


def test_crlf_and_cr_line_endings(tmp_path: Path) -> None:
    for eol in ("\r\n", "\r"):
        tp = cl(tmp_path, (MM + "GOTO/0,0,0\nJUNK\nGOTO/1,0,0\n").replace("\n", eol))
        assert tp.line.tolist() == [3, 5]
        assert any(":4: unknown record 'JUNK'" in w for w in tp.warnings)


def test_nx_information_listing_header_and_trailer(tmp_path: Path) -> None:
    header = (
        "==============================================================\n"
        "Information listing created by :  jdoe\n"
        "Date                           :  Mon Feb 03 10:00:00 2020\n"
        "Current work part              :  C:/parts/model1.prt\n"
        "Node name                      :  pc-123\n"
        "==============================================================\n"
    )
    tp = cl(tmp_path, header + MM + "GOTO/0,0,0\nEND-OF-PATH\nTool Path Listing has 12 lines.")
    assert tp.warnings == () and tp.line.tolist() == [9]
    # the header patterns are only skipped before the first record
    tp = cl(tmp_path, MM + "GOTO/0,0,0\nNode name : pc-123\n")
    assert any("unknown record 'NODE NAME : PC-123'" in w for w in tp.warnings)


# --------------------------------------------------------------------------- CYCLE


def drill_file(cycle: str, head: str = "UNITS/MM", top: str = "20,100,10") -> str:
    return (
        f"{head}\nSPINDL/RPM,1000,CLW\nFEDRAT/MMPM,500\nRAPID\nGOTO/0,0,50\n"
        f"{cycle}\nGOTO/{top}\nGOTO/30,100,10\nCYCLE/OFF\nGOTO/30,100,50\n"
    )


@pytest.mark.parametrize(
    "cycle",
    [
        "CYCLE/DRILL,RAPTO,3.0000,FEDTO,-10.0000,RTRCTO,AUTO,MMPM,250.0000",  # NX
        "CYCLE/DRILL,10,FEDRAT,MMPM,250,CLEAR,3",
        "CYCLE/DRILL,DEPTH,10,FEDRAT,250,RAPTO,3",
        "CYCLE/DRILL,10,MMPM,250,3",  # classic APT: depth, unit, feed, clearance
        "CYCLE/DRILL, FEDTO, 10, MMPM, 250, CLEAR, 3",  # Fusion-style
        "CYCLE/DRILL,DEPTH,10,PERMIN,250,RAPTO,3",  # per minute in the file's units, as FEDRAT/PERMIN
    ],
)
def test_drill_cycle_expanded(tmp_path: Path, cycle: str) -> None:
    # over the first hole across first, then down (NX's SIM_RAPID_APPROACH); RTRCTO,AUTO is G98,
    # back to the level where the cycle began (Z50), the others retract to the clearance (Z13)
    tp = cl(tmp_path, drill_file(cycle))
    up = 50 if "AUTO" in cycle else 13
    across = [[30, 100, 50]] if up == 50 else []
    np.testing.assert_allclose(
        tp.tip,
        [[0, 0, 50], [20, 100, 50], [20, 100, 13], [20, 100, 0], [20, 100, up], *across, [30, 100, 13],
         [30, 100, 0], [30, 100, up], [30, 100, 50]],
    )  # fmt: skip
    rapid = [True, True, True, False, True, *[True] * len(across), True, False, True, False]
    assert tp.rapid.tolist() == rapid
    np.testing.assert_allclose(tp.feed[~tp.rapid], [250, 250, 500])
    assert tp.line.tolist() == [5, 7, 7, 7, 7, *[8] * len(across), 8, 8, 8, 10]


def test_drill_cycle_inch_classic_and_tilted_axis(tmp_path: Path) -> None:
    text = "UNITS/INCHES\nFEDRAT/IPM,10\nGOTO/0,0,2,0.6,0,0.8\nCYCLE/DRILL,.5,20.,IPM,.1\nGOTO/1,0,0\nCYCLE/OFF\n"
    tp = cl(tmp_path, text)
    a = np.array([0.6, 0, 0.8])
    top = np.array([25.4, 0, 0])
    # from (0,0,2) down to the approach point: across the axis first, then along it
    approach = top + 2.54 * a
    across = approach - ((approach - [0, 0, 50.8]) @ a) * a
    np.testing.assert_allclose(tp.tip[1:], [across, approach, top - 12.7 * a, approach], atol=1e-12)
    assert tp.feed[3] == pytest.approx(508.0)


def test_drill_cycle_on_reuses_last(tmp_path: Path) -> None:
    text = MM + "CYCLE/DRILL,5,MMPM,50,2\nGOTO/0,0,0\nCYCLE/OFF\nGOTO/9,9,9\nCYCLE/ON\nGOTO/1,0,0\nCYCLE/OFF\n"
    tp = cl(tmp_path, text)
    np.testing.assert_allclose(tp.tip[tp.line == 8], [[1, 0, 9], [1, 0, 2], [1, 0, -5], [1, 0, 2]])


def test_cycle_on_with_a_new_depth_drills_to_it(tmp_path: Path) -> None:
    text = MM + ("GOTO/0,0,20\nCYCLE/DRILL,RAPTO,3,FEDTO,-10,MMPM,50\nGOTO/0,0,0\nCYCLE/OFF\nGOTO/9,0,20\n"
                 "CYCLE/ON,FEDTO,-4,RTRCTO,AUTO\nGOTO/9,0,0\nCYCLE/OFF\n")
    tp = cl(tmp_path, text)
    np.testing.assert_allclose(tp.tip[tp.line == 5], [[0, 0, 3], [0, 0, -10], [0, 0, 3]])
    np.testing.assert_allclose(tp.tip[tp.line == 9], [[9, 0, 3], [9, 0, -4], [9, 0, 20]])


@pytest.mark.parametrize(
    ("cycle", "message"),
    [
        ("CYCLE/TAP,10,MMPR,1.5,3", "tapping"),
        ("CYCLE/DRILL,RAPTO,3,FEDTO,-10,STEP,2", "does not peck"),
        ("CYCLE/DRILL,10,MMPM,250", "clearance"),
        ("CYCLE/DRILL,CLEAR,3,MMPM,250", "depth"),
        ("CYCLE/WHIRL,1", "not a known cycle"),
    ],
)
def test_unsupported_cycles_rejected(tmp_path: Path, cycle: str, message: str) -> None:
    e = err(tmp_path, drill_file(cycle))
    assert e.line == 6 and message in e.reason


def test_solidworks_peck_cycle_expanded_with_dwell_and_cycle_ending_at_tool_change(tmp_path: Path) -> None:
    # CL-DIALECTS: SolidWorks CAM writes CYCLE/INIT, then DEEP2 with 1STPECK/SUBPECK; a cycle may stay
    # active into the next tool's operation without CYCLE/OFF.
    text = ("UNITS/MM\nFEDRAT/MMPM,500\nCYCLE/INIT\n"
            "CYCLE/DEEP2,FEDTO,10.1,1STPECK,5.,SUBPECK,2.,MMPM,1097.28,RAPTO,3.,RTRCTO,10.\nGOTO/0,0,0\n"
            "CYCLE/DRILL,FEDTO,2.75344,MMPM,731.52,RAPTO,3.,RTRCTO,10.,DWELL,1.5\nGOTO/20,0,0\n"
            "LOADTL/2\nGOTO/40,0,5\n")
    tp = cl(tmp_path, text)
    hole = tp.tip[tp.line == 5]
    feeds = hole[~tp.rapid[tp.line == 5]]
    # the bottoms of the pecks: 5, 7, 9, 10.1 mm deep (first peck 5, then 2 each, last one short)
    np.testing.assert_allclose(sorted(set(np.round(-feeds[:, 2], 9)) & {5.0, 7.0, 9.0, 10.1}), [5, 7, 9, 10.1])
    assert -hole[:, 2].max() <= -3 and hole[:, 2].min() == pytest.approx(-10.1)
    np.testing.assert_allclose(tp.feed[(tp.line == 5) & ~tp.rapid], 1097.28)
    dwell = [e for e in tp.events if type(e).__name__ == "Dwell"]
    assert [(d.seconds, d.line) for d in dwell] == [(1.5, 7)]
    assert tp.line[-1] == 9 and tp.tip[-1].tolist() == [40, 0, 5]  # after the tool change: a plain move

# --------------------------------------------------------------------------- malformed input


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        ("GOTO/1,2", "GOTO needs 3 or 6 numbers, got 2"),
        ("GOTO/", "GOTO needs 3 or 6 numbers, got 0"),
        ("GOTO/1.2x3,0,0", "'1.2x3' is not a number"),
        ("GOTO/1,2,abc", "'abc' is not a number"),
        ("GOTO/1_0,2,3", "'1_0' is not a number"),
        ("GOTO/1,,3", "empty field in GOTO"),
        ("GOTO/nan,2,3", "NaN in GOTO"),
        ("GOTO/1,2,3,0,NaN,1", "NaN in GOTO"),
        ("GOTO/inf,2,3", "infinite value in GOTO"),
        ("GOTO/1,2,3,0,0,-Infinity", "infinite value in GOTO"),
        ("GOTO/1,2,3,0,0,0", "tool axis has zero length"),
        ("GOTO/1,2,3,0,0,5", "tool axis has length 5, expected a unit vector"),
        ("FROM/1,2", "FROM needs 3 or 6 numbers, got 2"),
        ("GOTO/1e300,0,0", "coordinate out of range in GOTO (|value| > 1e+07)"),
    ],
)
def test_malformed_goto(tmp_path: Path, body: str, reason: str) -> None:
    e = err(tmp_path, MM + "GOTO/0,0,0\n" + body + "\nGOTO/1,1,1\n")
    assert (e.reason, e.line) == (reason, 4)
    assert str(e) == f"{e.source}:4: {reason}"


def test_first_error_wins_over_later_ones(tmp_path: Path) -> None:
    e = err(tmp_path, MM + "GOTO/0,0,nan\nGOTO/1,2\n")
    assert (e.reason, e.line) == ("NaN in GOTO", 3)


@pytest.mark.parametrize("text", ["", "\n\n", "$$ only a comment\nUNITS/MM\nFEDRAT/100\nEND-OF-PATH\n"])
def test_no_motion(tmp_path: Path, text: str) -> None:
    e = err(tmp_path, text)
    assert (e.reason, e.line) == ("no motion records in file", None)


@pytest.mark.parametrize(
    "data",
    [b"GOTO/1,2,3\n\x00\x01\x02binary", b"\x81\x8d\x8f\x90\x9d GOTO", b"\x7fELF\x02\x01\x01\x03\x04"],
)
def test_binary_file_rejected(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "b.cls"
    path.write_bytes(data)
    with pytest.raises(InputError) as info:
        read_cl(path)
    assert info.value.reason.startswith("not a text CL file")


def test_unbalanced_continuation_at_eof(tmp_path: Path) -> None:
    e = err(tmp_path, MM + "GOTO/0,0,0\nGOTO/1,2,$\n$$ comment\n")
    assert e.line == 4 and "continuation" in e.reason


def test_missing_file() -> None:
    with pytest.raises(InputError, match="file not found"):
        read_cl("/nonexistent/x.cls")


def test_bad_chordal_tolerance(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="chordal tolerance"):
        cl(tmp_path, MM + "GOTO/0,0,0\n", chordal_tolerance=0.0)


def test_utf8_bom_and_cp1252_comment(tmp_path: Path) -> None:
    path = tmp_path / "w.cls"
    path.write_bytes(b"\xef\xbb\xbfUNITS/MM\nFEDRAT/100\nPPRINT/\xc3\x98 8 mm\nGOTO/0,0,0\n")
    assert events(read_cl(path), Comment)[0].text == "\u00d8 8 mm"
    path.write_bytes(b"UNITS/MM\nFEDRAT/100\nPPRINT/\xd8 8 mm\nGOTO/0,0,0\n")
    assert events(read_cl(path), Comment)[0].text == "\u00d8 8 mm"
    path.write_bytes("UNITS/MM\r\nFEDRAT/100\r\nPPRINT/\u00d8 8 mm\r\nGOTO/0,0,0\r\n".encode("utf-16"))
    tp = read_cl(path)
    assert events(tp, Comment)[0].text == "\u00d8 8 mm" and tp.line.tolist() == [4]


# --------------------------------------------------------------------------- CSV


def test_csv_any_order_case_whitespace(tmp_path: Path) -> None:
    path = write(tmp_path, " K , x,Y ,z,i,J, Feed \n1,1,2,3,0,0,500\n\n# note\n0,4,5,6,0,1,\n", "p.csv")
    tp = read_pose_csv(path)
    np.testing.assert_allclose(tp.tip, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_allclose(tp.axis, [[0, 0, 1], [0, 1, 0]])
    assert tp.feed[0] == 500 and np.isnan(tp.feed[1])
    assert tp.line.tolist() == [2, 5]
    assert not tp.rapid.any() and not tp.inverse_time.any() and (tp.tool == 0).all()
    assert tp.units == "mm" and tp.events == ()


def test_csv_without_feed_and_inch(tmp_path: Path) -> None:
    path = write(tmp_path, "x,y,z,i,j,k\n1,0,0,0,0,1.0e-0\n", "p.csv")
    tp = read_pose_csv(path, units="inch")
    np.testing.assert_allclose(tp.tip, [[25.4, 0, 0]])
    assert np.isnan(tp.feed).all() and tp.units == "inch"


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("x,y,z,i,j\n1,2,3,0,0\n", 1, "lacks column(s) k"),
        ("x,y,z,i,j,k,speed\n", 1, "unknown column 'speed'"),
        ("x,y,z,i,j,k,x\n", 1, "appears twice"),
        ("x,y,z,i,j,k\n1,2,3,0,0\n", 2, "row has 5 fields"),
        ("x,y,z,i,j,k\n1,2,3,0,0,1\n1,2,3q,0,0,1\n", 3, "'3q' is not a number"),
        ("x,y,z,i,j,k\n1,2,nan,0,0,1\n", 2, "'nan' is not a finite number"),
        ("x,y,z,i,j,k\n1,2,3,0,0,0\n", 2, "tool axis has zero length"),
        ("x,y,z,i,j,k,feed\n1,2,3,0,0,1,-3\n", 2, "feed must be positive"),
        ("x,y,z,i,j,k\n", None, "no poses in file"),
    ],
)
def test_csv_errors(tmp_path: Path, text: str, line: int | None, message: str) -> None:
    path = write(tmp_path, text, "p.csv")
    with pytest.raises(InputError) as info:
        read_pose_csv(path)
    assert info.value.line == line and message in info.value.reason


def test_read_toolpath_dispatch(tmp_path: Path) -> None:
    csv = write(tmp_path, "x,y,z,i,j,k\n1,2,3,0,0,1\n", "poses.CSV")
    assert read_toolpath(csv).rapid.tolist() == [False]
    assert len(read_toolpath(csv, units="mm", chordal_tolerance=0.01)) == 1
    clf = write(tmp_path, MM + "RAPID\nGOTO/1,2,3\n", "prog.cls")
    assert read_toolpath(clf, units="mm").rapid.tolist() == [True]
    assert len(read_toolpath(VARIABLE_AXIS)) == 348
