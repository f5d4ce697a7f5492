"""The command group: ``verne-post FILE ...`` posts; every other command is a module of this package."""

from __future__ import annotations

import sys
import warnings
from typing import Any

import click

from ..errors import one_line
from ..processes.allocator import keep_freed_memory


class _DefaultToPost(click.Group):
    """``verne-post FILE ...`` runs the ``post`` command; named subcommands work as usual."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if args and args[0] not in self.commands and args[0] not in ("--help", "-h", "--version"):
            args = ["post", *args]
        return super().parse_args(ctx, _auto_offset(args))

    def main(self, *args: Any, **kwargs: Any) -> Any:
        """Command-line mistakes as one line (``verne-post: error: ...``), exit code 2.

        Python warnings (e.g. numpy's on NaN arithmetic in rejected input) are not shown: every
        line on stderr is one of verne-post's own messages.
        """
        keep_freed_memory()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return super().main(*args, standalone_mode=False, **kwargs)
        except click.ClickException as error:
            click.echo(f"verne-post: error: {one_line(error.format_message())}", err=True)
            sys.exit(error.exit_code)
        except click.Abort:
            click.echo("verne-post: aborted", err=True)
            sys.exit(1)


def _auto_offset(args: list[str]) -> list[str]:
    """``--work-offset auto`` (three numbers otherwise) becomes the hidden flag ``--auto-offset``."""
    out: list[str] = []
    for arg in args:
        if arg.lower() == "auto" and out and out[-1] == "--work-offset":
            out[-1] = "--auto-offset"
        elif arg.lower() == "--work-offset=auto":
            out.append("--auto-offset")
        else:
            out.append(arg)
    return out




def _print_version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    """--version: the version and which kinematics route runs (compiled numba loops or numpy)."""
    if not value or ctx.resilient_parsing:
        return
    from ..kinematics.kernels import route
    from ..version import __version__

    click.echo(f"verne-post, version {__version__}\nkinematics: {route()}")
    ctx.exit()


@click.group(cls=_DefaultToPost, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--version", is_flag=True, expose_value=False, is_eager=True, callback=_print_version,
              help="Show the version and the kinematics route (numba or numpy), then exit.")
def main() -> None:
    """Postprocessor for the VERNE 5-axis machine: CL data to joint-space G-code.

    \b
    verne-post part.cls -o part.nc        postprocess (same as 'verne-post post ...')
    verne-post check part.cls             everything but writing the program
    verne-post verify part.nc [--against part.cls]   check a G-code program
    verne-post batch DIR -o OUTDIR        many files at once (local processes or Dask)
    verne-post place part.cls             where to clamp the part (work offset and room)
    verne-post workspace -o ws.png        map of the tool-tip workspace for a tool axis
    verne-post toolpath part.cls          the toolpath as the reader understood it (CSV)
    verne-post ik / fk ...                kinematics of single poses or CSV files
    verne-post calibrate meas.csv -o my.yaml   identify geometry and joint zeros from measured tips
    """
