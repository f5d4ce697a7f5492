"""Programs posted with --no-timing: every feed block's inverse-time F is its duration from the
programmed feed. The controller moves the joints linearly through a block, so the tool tip
follows the forward kinematics of that line, not the chord of the block's ends; its speed
relative to the part is the length of that path over the block's time.

Here the path is measured independently of the post: the G-code is read back, every G93 block
sampled densely along its joint-space line and the tip placed by the forward kinematics. The
NX variable-axis sample passes within 0.3 deg of the table normal at CL line 224, where the
table turns 66 deg over 7.6 mm of tip travel in blocks of 0.015 to 0.03 mm whose tip paths bow
1 to 3.5 um off their chords: 2 to 3.6 % longer than the chords.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from click.testing import CliRunner

import verne_post as vp
from verne_post.cli import main

SAMPLE = Path(__file__).parent / "data" / "cl-samples" / "nx_variable_axis_inch.cls"
FEED = 10.0 * 25.4  # mm/min: the sample's only FEDRAT (IPM 10)
WINDOW = 40  # blocks: the written ends' rounding (1e-4 mm) is then under 0.1 % of a window's path
_WORD = re.compile(r"([XYZACF])(-?\d+(?:\.\d*)?)")


def _feed_blocks(text: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Joints (mm, rad) at every motion block's end, which of them are cutting G93 blocks, their
    F words (1/min), and the tool length (mm) from the TOOL comment."""
    length = float(re.search(r"\(TOOL \d+ LENGTH (\S+)", text).group(1))
    state = dict.fromkeys("XYZACF", np.nan)
    joints, cutting, feed = [], [], []
    inverse = False
    for line in text.splitlines():
        code = line.split("(")[0]
        inverse = (inverse or "G93" in code) and "G94" not in code
        words = dict(_WORD.findall(code))
        if not set(words) & set("XYZAC"):
            continue
        state.update({k: float(v) for k, v in words.items()})
        joints.append([state["X"], state["Y"], state["Z"], np.radians(state["A"]), np.radians(state["C"])])
        cutting.append(inverse and code.startswith("G1") and "RAPID" not in line)
        feed.append(state["F"])
    return np.array(joints), np.array(cutting), np.array(feed), length


def test_untimed_inverse_time_feeds_hold_the_programmed_feed_along_the_tip_path(tmp_path: Path) -> None:
    out = tmp_path / "va.nc"
    result = CliRunner().invoke(main, [str(SAMPLE), "-o", str(out), "--no-timing", "-q"])
    assert result.exit_code == 0, result.output
    joints, cutting, feed, length = _feed_blocks(out.read_text())
    blocks = np.flatnonzero(cutting[1:]) + 1
    s = np.linspace(0.0, 1.0, 33)
    q = joints[blocks - 1, None] + s[None, :, None] * (joints[blocks, None] - joints[blocks - 1, None])
    tip = vp.forward_kinematics(vp.load_machine(), q.reshape(-1, 5), tool_length=length).tip.reshape(len(blocks),
                                                                                                   len(s), 3)
    path = np.linalg.norm(np.diff(tip, axis=1), axis=2).sum(axis=1)  # mm
    minutes = 1.0 / feed[blocks]
    # windows of WINDOW consecutive cutting blocks (a window never spans a move between cuts)
    run = np.r_[0, np.cumsum(np.diff(blocks) != 1)]
    start = np.flatnonzero(run[WINDOW - 1:] == run[:len(run) - WINDOW + 1])
    assert start.size > 5000
    total = np.r_[0.0, np.cumsum(path)]
    time = np.r_[0.0, np.cumsum(minutes)]
    speed = (total[start + WINDOW] - total[start]) / (time[start + WINDOW] - time[start])  # mm/min
    assert speed.max() <= FEED * 1.003, f"tip at {speed.max():.1f} mm/min over {WINDOW} blocks, programmed {FEED}"
