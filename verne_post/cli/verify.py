"""``verne-post verify``: read a G-code program back and check it."""

from __future__ import annotations

import functools
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from ..errors import InputError
from ..machine import load_machine
from .common import (
    AXIS_TOL,
    MAX_MESSAGES,
    TIP_TOL,
    WORK_OFFSET,
    decorated,
    machine_option,
    read_cl,
    reader_option_group,
    setup_file,
    setup_options,
    user_errors,
)
from .main import main

if TYPE_CHECKING:
    from ..verify.verifier import Verification


def print_findings(verification: Verification, max_messages: int) -> None:
    for f in verification.findings[:max_messages]:
        cl = f" (CL {verification.against}:{f.cl_line})" if f.cl_line is not None else ""
        click.echo(f"verne-post: error: {verification.source}:{f.line}: {f.message}{cl}", err=True)
    if len(verification.findings) > max_messages:
        click.echo(f"verne-post: ... and {len(verification.findings) - max_messages} more findings", err=True)


#: The header line the post writes, ``MACHINE shop.yaml (VERNE)`` in any comment style.
_HEADER_MACHINE = re.compile(r"\bMACHINE (\S+) [(\[]")


def _header_machine(text: str) -> str | None:
    """The machine file the program's header names (in its first lines), if any."""
    match = _HEADER_MACHINE.search("\n".join(text[:20_000].splitlines()[:40]))
    return match.group(1) if match else None


@main.command("verify")
@click.argument("program", metavar="PART.nc", type=click.Path(dir_okay=False))
@click.option("--against", "cl_file", type=click.Path(dir_okay=False),
              help="The CL file (APT/CLSF, or a CSV of poses) the program must follow.")
@machine_option
@click.option("--work-offset", nargs=3, type=WORK_OFFSET, default=None,
              help="Part zero X Y Z in the table frame, mm (default: the program header's, else the machine's).")
@click.option("--tol", type=TIP_TOL, default=None,
              help="Tool tip deviation allowed, mm (default: the program header's, else 0.005).")
@click.option("--axis-tol", type=AXIS_TOL, default=None,
              help="Tool axis deviation allowed, degrees (default: the program header's, else 0.05).")
@click.option("--rapid-tol", type=TIP_TOL, default=None,
              help="How far a rapid may leave its CL line (never below it; with --against), or dip below the "
                   "lower of its ends (without), mm (default: the program header's, else 0.5).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), help="Write the findings as JSON.")
@click.option("--quiet", "-q", is_flag=True, help="Nothing on stderr but the findings.")
@click.option("--max-messages", type=MAX_MESSAGES, default=20, show_default=True,
              help="Findings printed before the count.")
@reader_option_group
@functools.partial(decorated, options=setup_options)
@user_errors
def verify_command(program: str, cl_file: str | None, machine_path: str | None,
                   work_offset: tuple[float, float, float] | None, tol: float | None, axis_tol: float | None,
                   rapid_tol: float | None, report_path: str | None, quiet: bool, max_messages: int,
                   stock: tuple[str, ...], fixtures: tuple[str, ...], setup_path: str | None,
                   **reading: Any) -> None:
    """Verify a joint-space G-code program: limits and margins along the motion, bodies that meet
    (the machine's, the tools' and the setup's: --stock, --fixture, --setup as for post), and
    with --against how closely it follows the CL path. Exit 0 if it passes, 3 if not."""
    from ..bodies.world import ProgramBodies
    from ..checks.collision import tool_shapes
    from ..cl.toolpath import ToolChange
    from ..options import PostOptions, setup_of
    from ..output.tables import write_json
    from ..verify.verifier import verify_program

    machine = load_machine(machine_path)
    try:
        text = Path(program).read_text(encoding="utf-8", errors="replace")
    except OSError as error:
        raise InputError(f"cannot read the program: {error.strerror}", program) from None
    against = None if cl_file is None else read_cl(cl_file, **reading)
    # the setup in the part frame, in the CL file's units (mm without one)
    choices = PostOptions(stock=stock, fixtures=fixtures, **setup_file(setup_path))
    setup = setup_of(machine, choices, "mm" if against is None else against.units)
    diameters = {} if against is None else {e.tool: e.diameter for e in against.events if isinstance(e, ToolChange)}
    bodies = ProgramBodies(setup, tool_shapes(machine, diameters))
    try:
        verification = verify_program(text, machine, source=program, against=against, work_offset=work_offset,
                                      tol=tol, axis_tol=axis_tol, rapid_tol=rapid_tol, bodies=bodies)
    except InputError as error:
        named = None if machine_path is not None else _header_machine(text)
        if named is None or named == machine.source:
            raise
        raise InputError(f"{error.reason}; the program's header names the machine file {named}: --machine "
                         f"{named} reads it with that file's controller profile", error.source, error.line) from None
    if report_path:
        write_json(report_path, verification.report())
    if not verification.ok:
        print_findings(verification, max_messages)
        click.echo(f"verne-post: {program}: {len(verification.findings)} finding(s)", err=True)
        sys.exit(3)
    if not quiet:
        click.echo(f"verne-post: {program}: {verification.certificate().lower()} ({verification.blocks} blocks, "
                   f"{verification.samples} poses checked)", err=True)
