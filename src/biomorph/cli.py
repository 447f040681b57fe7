"""Command-line interface: ``biomorph <command>``. A thin layer over the Python API.

Each pillar contributes a sub-command group from ``biomorph/<pillar>/cli.py`` (a
``typer.Typer`` named ``app``) and a demo from ``biomorph/<pillar>/demo.py``
(``run_demo(out_dir) -> list[report.Section]``). Any :class:`BiomorphError` becomes one line
on stderr and exit code 2; Ctrl-C exits with 130 and leaves no partial output.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from biomorph import __version__
from biomorph._cli import err_console, out_console, print_json
from biomorph.errors import BiomorphError
from biomorph.pillars import PILLARS, optional_module

try:  # typer >= 0.20 vendors click; older releases use click itself
    from typer._click.exceptions import ClickException as _ClickException
except ImportError:  # pragma: no cover
    from click.exceptions import ClickException as _ClickException


app = typer.Typer(name="biomorph", no_args_is_help=True, add_completion=False,
                  pretty_exceptions_enable=False,
                  help="Skeletons of living things: creatures, trees, motion, leaves.")


def _version(value: bool) -> None:
    if value:
        out_console.print(f"biomorph {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: Annotated[bool, typer.Option("--version", callback=_version,
                                                is_eager=True, help="Print the version.")] = False
          ) -> None:
    """biomorph: generate creatures, skeletonise trees, edit motion, grow leaves."""


@app.command()
def info(path: Annotated[Path, typer.Argument(help="Any file biomorph reads.")],
         as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False
         ) -> None:
    """Say what a file holds: point clouds, BVH/HTR motion, skeleton PLY/MTG, meshes.

    Example: biomorph info scan.laz --json
    """
    from biomorph.inspect import describe

    summary = describe(path)
    if as_json:
        print_json(summary)
        return
    from rich.table import Table

    table = Table(title=str(path), show_header=False)
    for k, v in summary.items():
        table.add_row(str(k), str(v))
    out_console.print(table)


@app.command()
def render(path: Annotated[Path, typer.Argument(help="Cloud, skeleton, motion or mesh file.")],
           output: Annotated[Path, typer.Option("-o", "--output", help="PNG to write.")] =
           Path("preview.png"),
           up: Annotated[str | None, typer.Option(
               "--up", help="Vertical axis: z (trees, leaves) or y (creatures, motion); "
                            "default by file type.")] = None,
           ) -> None:
    """Render a PNG preview (three orthographic views + perspective).

    Example: biomorph render skeleton.ply -o preview.png
    """
    from biomorph.render import render_file

    out = render_file(path, output, up=up)
    out_console.print(f"wrote {out}")


@app.command()
def demo(out: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("demo-out"),
         only: Annotated[list[str] | None, typer.Option("--only",
                                                        help="Run only these pillars.")] = None
         ) -> None:
    """Run every pillar on built-in data and write OUT/report.html with pictures.

    Example: biomorph demo --out demo-out
    """
    from biomorph.demo import run_demo

    report = run_demo(out, only=only)
    out_console.print(f"wrote {report}")


def _add_pillar_apps() -> None:
    for pillar in PILLARS:
        mod = optional_module(pillar, "cli")
        if mod is not None:
            app.add_typer(mod.app, name=pillar)
    studio = optional_module("studio", "cli")
    if studio is not None:
        studio.register(app)


_add_pillar_apps()


def run(argv: list[str] | None = None) -> int:
    """Run the CLI on ``argv``; return the exit code (0 ok, 2 bad input/usage, 130 Ctrl-C)."""
    try:
        result = app(args=argv, prog_name="biomorph", standalone_mode=False)
    except BiomorphError as exc:
        err_console.print(f"[bold red]error:[/] {exc}", markup=True, highlight=False)
        return 2
    except typer.Exit as exc:
        return int(exc.exit_code or 0)
    except _ClickException as exc:
        exc.show()
        return 2 if exc.exit_code == 2 else int(exc.exit_code)
    except (KeyboardInterrupt, typer.Abort):
        err_console.print("interrupted; no partial output was written")
        return 130
    except OSError as exc:  # unreadable/unwritable paths, full disk
        err_console.print(f"[bold red]error:[/] {exc.strerror or exc}: "
                          f"{exc.filename or ''}".rstrip(": "))
        return 2
    return int(result) if isinstance(result, int) else 0


def main() -> None:
    sys.exit(run(sys.argv[1:]))


if __name__ == "__main__":
    main()
