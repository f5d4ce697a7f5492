"""``verne-post toolpath``: the toolpath as the reader understood it (CSV)."""

from __future__ import annotations

from typing import Any

import click
import numpy as np

from .common import read_cl, reader_option_group, user_errors
from .kinematics import write_csv
from .main import main


@main.command("toolpath")
@click.argument("cl_file", metavar="PART.cls", type=click.Path(dir_okay=False))
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Output CSV (default: stdout).")
@click.option("--quiet", "-q", is_flag=True, help="No dialect line and no warnings on stderr.")
@reader_option_group
@user_errors
def toolpath_command(cl_file: str, output: str | None, quiet: bool, **reading: Any) -> None:
    """Write the toolpath exactly as the reader understood it, as CSV.

    Columns x,y,z (tool tip, mm, part frame), i,j,k (unit tool axis), feed (mm/min; empty on
    rapids, 1/min on inverse-time moves), motion (feed, rapid, arc, spline, cycle), line (CL
    line). Arcs, helices, splines and cycles are expanded. The dialect and the conventions used
    go to stderr, to compare with the CAM system's own display.
    """
    from ..cl.toolpath import MOTION_KINDS

    tp = read_cl(cl_file, **reading)
    if not quiet:
        click.echo(f"verne-post: {cl_file}: {tp.dialect}; {len(tp)} poses, source units {tp.units}", err=True)
        for warning in tp.warnings:
            click.echo(f"verne-post: warning: {warning}", err=True)
    motion = tp.motion if tp.motion is not None else np.where(tp.rapid, 1, 0)
    feed = np.char.mod("%.6g", tp.feed)
    feed[~np.isfinite(tp.feed)] = ""
    table = {"x": tp.tip[:, 0], "y": tp.tip[:, 1], "z": tp.tip[:, 2], "i": tp.axis[:, 0], "j": tp.axis[:, 1],
             "k": tp.axis[:, 2], "feed": feed, "motion": np.array(MOTION_KINDS)[motion], "line": tp.line}
    write_csv(table, output, {"x": "%.6f", "y": "%.6f", "z": "%.6f", "i": "%.9f", "j": "%.9f", "k": "%.9f",
                               "feed": "%s", "motion": "%s", "line": "%d"})
