"""What the certified moves between cuts cost in cycle time, against joint-space rapids.

    python -m benchmarks.rapids [FILE ...]

For the examples and the shared real CL samples (or the files given), each placed with
``--work-offset auto`` and a 100 mm tool, prints in one run:

- the baseline: the rapids as they were planned before, one jerk-limited ruckig move in joint
  space from each CL rapid's start to its end (the joints of the CL poses at the same offset),
  which leaves the CAM's straight rapid and can dip below it;
- now: the rapid time of the posted program (the report's ``rapid_time_s``): rapids kept on the
  CAM's line, retract / reorient / approach, home at both ends and the tool-change position;
- their ratio, the cycle time now and how much of it the change added (the feed moves are
  planned as before: the difference in cycle time is the difference in rapid time).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import verne_post as vp
from verne_post.cl import read_toolpath
from verne_post.motion.branch import solve_path
from verne_post.motion.poses import machine_poses
from verne_post.options import PostOptions
from verne_post.pipeline import post
from verne_post.planning.timing import Limits, plan_rapid

ROOT = Path(__file__).resolve().parent.parent
_SAMPLES = sorted(p for p in (ROOT / "tests" / "data" / "cl-samples").iterdir() if p.suffix != ".md")
FILES = [*(p for p in sorted((ROOT / "examples").glob("*.cls")) if p.name not in {s.name for s in _SAMPLES}),
         *_SAMPLES]


def joint_space_rapid_time(machine: vp.Machine, path: Path, offset: tuple[float, float, float]) -> float:
    """Seconds of the program's CL rapids as single ruckig moves in joint space (the old rapids)."""
    poses = machine_poses(read_toolpath(path), machine, work_offset=offset, tool_length=100.0)
    solved = solve_path(machine, poses.tip, poses.axis, poses.sequence, tool_length=poses.tool_length,
                        cone=np.radians(machine.pole.cone))
    joints, limits = solved.result.joints, Limits.from_machine(machine)
    return float(sum(plan_rapid(joints[k - 1], joints[k], limits).duration
                     for k in np.flatnonzero(poses.rapid[1:]) + 1
                     if np.all(np.isfinite(joints[k - 1])) and np.all(np.isfinite(joints[k]))))


def main() -> None:
    machine = vp.load_machine()
    files = [Path(f) for f in sys.argv[1:]] or FILES
    print(f"{'file':36} {'rapids before s':>15} {'rapids now s':>13} {'now/before':>10} {'cycle now s':>12} "
          f"{'added':>7}")
    total_before = total_now = total_cycle = 0.0
    for path in files:
        options = PostOptions(work_offset="auto", tool_length=100.0, workers=1)
        try:
            posted = post(path, machine, options)
        except vp.InputError as error:
            print(f"{path.name:36} not read: {error}")
            continue
        if posted.violations or posted.placement is None:
            print(f"{path.name:36} does not run: {posted.violations[0].message if posted.violations else ''}")
            continue
        timing = posted.report(machine, options)["timing"]
        before = joint_space_rapid_time(machine, path, posted.placement.offset)
        now, cycle = timing["rapid_time_s"], timing["cycle_time_s"]
        total_before, total_now, total_cycle = total_before + before, total_now + now, total_cycle + cycle
        print(f"{path.name:36} {before:15.1f} {now:13.1f} {now / max(before, 1e-9):10.2f} {cycle:12.1f} "
              f"{(now - before) / (cycle - now + before):7.1%}")
    print(f"{'all':36} {total_before:15.1f} {total_now:13.1f} {total_now / max(total_before, 1e-9):10.2f} "
          f"{total_cycle:12.1f} {(total_now - total_before) / (total_cycle - total_now + total_before):7.1%}")


if __name__ == "__main__":
    main()
