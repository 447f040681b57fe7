"""Command-line interface: ``biomorph <command>``. A thin layer over the Python API.

Each pillar contributes a sub-command group from ``biomorph/<pillar>/cli.py`` (a
``typer.Typer`` named ``app``) and a demo from ``biomorph/<pillar>/demo.py``
(``run_demo(out_dir) -> list[report.Section]``). Any :class:`BiomorphError` becomes one line
on stderr and exit code 2; Ctrl-C exits with 130 and leaves no partial output.

Every command runs through :func:`_guarded`, which holds the guarantees that do not depend on
the command (README "Guarantees"):

* every int/float option is finite and inside a generic range (ints in ``[0, 2**31-1]``, the
  largest count LAS/PLY/glTF indices hold; floats within ``±1e9``), on top of the option's
  own ``bounded(...)`` range;
* input files (path arguments and path options other than ``--out``/``--output``) must be
  regular files when they exist: named pipes and devices are refused instead of hanging;
* an output that is one of the inputs is refused, and atomic writes onto an input fail;
* an output *folder* (``--out`` without an extension) is locked for the run, and temporary
  files of earlier killed runs in it are removed; appended files are locked per write;
* Ctrl-C anywhere (imports included) prints one line and exits with 130 within a second.
"""

from __future__ import annotations

import os
import signal
import sys


def _entry_point() -> bool:
    """True when this process is the ``biomorph`` executable or ``python -m biomorph.cli``."""
    argv0 = sys.argv[0] if sys.argv else ""
    return os.path.basename(argv0) in ("biomorph", "biomorph.exe") or argv0.endswith(
        os.path.join("biomorph", "cli.py")
    )


def _interrupted_while_starting(signum: int, frame: object) -> None:
    os.write(2, b"interrupted; no partial output was written\n")
    os._exit(130)


def _worker_process() -> bool:
    """True in a process that multiprocessing spawned from the CLI (dask batch workers)."""
    mp = sys.modules.get("multiprocessing")
    if mp is None:
        return False
    current = mp.current_process()  # "_inheriting" while a spawned child imports __main__
    return mp.parent_process() is not None or bool(getattr(current, "_inheriting", False))


if _worker_process():  # the parent handles Ctrl-C and shuts its workers down
    signal.signal(signal.SIGINT, signal.SIG_IGN)
elif _entry_point():  # Ctrl-C during the imports below: one line, no traceback
    signal.signal(signal.SIGINT, _interrupted_while_starting)

import contextlib  # noqa: E402
import functools  # noqa: E402
import typing  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Annotated, Any  # noqa: E402

import typer  # noqa: E402

from biomorph import __version__  # noqa: E402
from biomorph._cli import (  # noqa: E402
    EXIT_INTERRUPTED,
    INTERRUPT_LINE,
    check_value,
    err_console,
    file_lock,
    folder_lock,
    interrupt_guard,
    out_console,
    print_json,
)
from biomorph.errors import BiomorphError, ParameterError, check_regular_file  # noqa: E402
from biomorph.pillars import PILLARS, optional_module  # noqa: E402

try:  # typer >= 0.20 vendors click; older releases use click itself
    from typer._click.exceptions import ClickException as _ClickException
except ImportError:  # pragma: no cover
    from click.exceptions import ClickException as _ClickException


app = typer.Typer(
    name="biomorph",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # plain click help: typer's rich help formatter costs ~0.1 s of start-up (bench/cli.py)
    rich_markup_mode=None,
    help="Skeletons of living things: creatures, trees, motion, leaves.",
)


def _version(value: bool) -> None:
    if value:
        out_console.print(f"biomorph {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version.")
    ] = False,
) -> None:
    """biomorph: generate creatures, skeletonise trees, edit motion, grow leaves."""


@app.command()
def info(
    path: Annotated[Path, typer.Argument(help="Any file biomorph reads.")],
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
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
def render(
    path: Annotated[Path, typer.Argument(help="Cloud, skeleton, motion or mesh file.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="PNG to write.")] = Path(
        "preview.png"
    ),
    up: Annotated[
        str | None,
        typer.Option(
            "--up",
            help="Vertical axis: z (trees, leaves) or y (creatures, motion); default by file type.",
        ),
    ] = None,
) -> None:
    """Render a PNG preview (three orthographic views + perspective).

    Example: biomorph render skeleton.ply -o preview.png
    """
    from biomorph.inspect import render_file

    out = render_file(path, output, up=up)
    out_console.print(f"wrote {out}")


@app.command()
def demo(
    out: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("demo-out"),
    only: Annotated[
        list[str] | None, typer.Option("--only", help="Run only these pillars.")
    ] = None,
) -> None:
    """Run every pillar on built-in data and write OUT/report.html with pictures.

    Example: biomorph demo --out demo-out
    """
    from biomorph.demo import run_demo

    report = run_demo(out, only=only)
    out_console.print(f"wrote {report}")


#: pillar groups already added to :data:`app` (``"studio"`` included)
_ADDED: set[str] = set()
#: the root's own commands: running one of them needs no pillar group
_ROOT_COMMANDS = frozenset({"info", "render", "demo"})


def _add_pillar_apps(only: str | None = None) -> None:
    """Add the pillar groups (and the studio) to :data:`app`; ``only`` adds just that one.

    ``biomorph motion info FILE`` then imports and builds one pillar's CLI, not four (about
    0.1 s of a call); ``--help`` and anything else get them all.
    """
    for pillar in PILLARS:
        if (only is None or only == pillar) and pillar not in _ADDED:
            mod = optional_module(pillar, "cli")
            _ADDED.add(pillar)
            if mod is not None:
                mod.app.rich_markup_mode = None  # plain click help, as for the root (fast start)
                app.add_typer(mod.app, name=pillar)
    if (only is None or only == "studio") and "studio" not in _ADDED:
        _ADDED.add("studio")
        studio = optional_module("studio", "cli")
        if studio is not None:
            studio.register(app)


def full_app() -> typer.Typer:
    """:data:`app` with every pillar group and the studio added (for tools and tests that
    walk the whole command tree; ``biomorph`` itself adds only the group a call runs)."""
    _add_pillar_apps()
    return app


def _selected_group(argv: list[str]) -> str | None:
    """The one group ``argv`` runs (a pillar, ``"studio"``, or ``""`` for a root command),
    or ``None`` when it needs every group (no command, a root option such as ``--help``
    first, a typo)."""
    if not argv or argv[0].startswith("-"):
        return None
    first = argv[0]
    if first in PILLARS or first == "studio":
        return first
    return "" if first in _ROOT_COMMANDS else None


#: generic ranges of every numeric option (on top of each option's own ``bounded`` range):
#: counts, seeds and indices fit int32 (LAS/PLY/glTF index limits); no length, time, angle
#: or factor a user means is beyond 1e9 of its unit
INT_RANGE = (0, 2**31 - 1)
FLOAT_ABS_MAX = 1e9
#: option names that name outputs (never inputs)
OUTPUT_PARAMS = frozenset({"out", "output", "out_dir", "plot", "preview"})
#: (command path, parameter) of files a command appends to: locked for the run
APPENDED = {("creature", "annotate"): "out"}


def _get(params: dict[str, Any], name: str, default: float) -> float:
    value = params.get(name)
    return default if value is None else float(value)


#: working-memory estimates (bytes) of the requests whose size is an option, checked against
#: the available memory before the command runs. Per-unit figures are peak RSS growth
#: measured with ``/usr/bin/time -f %M`` between two sizes of the same command (tree synth
#: 50k -> 400k points: 508 B/point; leaf canopy 20 -> 200 plants of 6 leaves x 20
#: triangles: ~1 kB per triangle) or, where not measured, the arrays the command holds
#: (leaf mesh: 3 int64 indices + ~0.5 vertex of position/normal/uv per triangle, x2 for the
#: writer's copy = 200 B; leaf grow: one 60-sample leaf mesh per frame and leaf = 10 kB).
MEMORY: dict[tuple[str, ...], tuple[str, Callable[[dict[str, Any]], float]]] = {
    ("tree", "synth"): ("points", lambda p: _get(p, "points", 0) * 508),
    ("leaf", "canopy"): (
        "plants",
        lambda p: _get(p, "plants", 20) * _get(p, "leaves", 6) * _get(p, "triangles", 20) * 1000,
    ),
    ("leaf", "mesh"): ("triangles", lambda p: _get(p, "triangles", 0) * 200),
    ("leaf", "grow"): (
        "frames",
        lambda p: _get(p, "frames", 24) * (_get(p, "leaves", 8) if p.get("plant") else 1) * 10_000,
    ),
}


def _check_memory(cmd_path: tuple[str, ...], params: dict[str, Any]) -> None:
    entry = MEMORY.get(cmd_path)
    if entry is None:
        return
    name, estimate = entry
    from biomorph._cli import check_memory

    what = " ".join(("biomorph", *cmd_path))
    if params.get(name) is not None:
        what += f" --{name.replace('_', '-')} {params[name]}"
    check_memory(what, estimate(params))


def _numeric_kind(annotation: Any) -> str | None:
    """``"int"``/``"float"`` for an option annotated with int/float (optional or a list)."""
    if annotation in (int, float):
        return annotation.__name__
    for arg in typing.get_args(annotation):
        kind = _numeric_kind(arg)
        if kind:
            return kind
    return None


def _path_like(annotation: Any) -> bool:
    if annotation is Path:
        return True
    return any(_path_like(a) for a in typing.get_args(annotation))


def _check_numbers(command: Any, params: dict[str, Any]) -> None:
    for p in command.params:
        descriptor = getattr(p, "type_descriptor", None)
        kind = _numeric_kind(getattr(descriptor, "annotation", None))
        value = params.get(p.name)
        if kind is None or value is None:
            continue
        name = p.opts[-1] if p.opts else p.name
        for v in value if isinstance(value, list | tuple) else (value,):
            if kind == "int":
                check_value(name, v, *INT_RANGE)
            else:
                check_value(name, v, -FLOAT_ABS_MAX, FLOAT_ABS_MAX)


def _paths(command: Any, params: dict[str, Any]) -> tuple[list[Path], dict[str, Path]]:
    """(input paths, {param name: output path}) of one invocation."""
    inputs: list[Path] = []
    outputs: dict[str, Path] = {}
    for p in command.params:
        descriptor = getattr(p, "type_descriptor", None)
        value = params.get(p.name)
        if value is None or not _path_like(getattr(descriptor, "annotation", None)):
            continue
        values = [Path(v) for v in (value if isinstance(value, list | tuple) else [value])]
        if p.name in OUTPUT_PARAMS:
            outputs[p.name] = values[0]
        else:
            inputs.extend(values)
    return inputs, outputs


def _check_paths(
    cmd_path: tuple[str, ...], command: Any, params: dict[str, Any]
) -> tuple[list[Path], Path | None, Path | None]:
    """Refuse non-regular inputs and outputs that are inputs; return (inputs, output folder
    to lock, appended file to lock)."""
    inputs, outputs = _paths(command, params)
    for p in inputs:
        if os.path.lexists(p) and not p.is_dir():
            check_regular_file(p)
    real_inputs = {os.path.realpath(p): p for p in inputs}
    appended = APPENDED.get(cmd_path)
    append_file = None
    folder = None
    for name, out in outputs.items():
        opt = "--" + name.replace("_", "-")
        if name == appended:
            append_file = out
            continue
        if os.path.realpath(out) in real_inputs:
            raise ParameterError(
                f"{opt} {out}: is also an input of this command and would "
                "be overwritten; choose another output"
            )
        if name == "out" and (out.is_dir() or not out.suffix):
            folder = out  # an input inside it is protected: atomic writes refuse to replace it
    return inputs, folder, append_file


def _guarded(
    cmd_path: tuple[str, ...], command: Any, callback: Callable[..., Any]
) -> Callable[..., Any]:
    @functools.wraps(callback)
    def wrapper(**params: Any) -> Any:
        from biomorph.io.atomic import protect, unprotect

        _check_numbers(command, params)
        _check_memory(cmd_path, params)
        inputs, folder, append_file = _check_paths(cmd_path, command, params)
        protect(inputs)
        try:
            return _call(callback, params, append_file, folder)
        except UnicodeDecodeError as exc:
            raise _not_utf8(inputs, exc) from None
        finally:
            unprotect(inputs)

    return wrapper


def _not_utf8(inputs: list[Path], exc: UnicodeDecodeError) -> BiomorphError:
    """The input a UnicodeDecodeError came from, as a FormatError naming file and byte."""
    from biomorph.errors import FormatError

    for p in inputs:
        try:
            data = p.read_bytes() if p.is_file() and p.stat().st_size < 2**28 else b""
            data.decode("utf-8")
        except UnicodeDecodeError as bad:
            line = data.count(b"\n", 0, bad.start) + 1
            return FormatError(
                p,
                f"byte 0x{data[bad.start]:02x} at offset {bad.start} is not "
                "UTF-8; expected UTF-8 text (re-save the file as UTF-8)",
                line=line,
            )
        except OSError:
            continue
    return FormatError(
        None, f"a text input is not UTF-8 ({exc.reason} at byte {exc.start}); expected UTF-8 text"
    )


def _call(
    callback: Callable[..., Any],
    params: dict[str, Any],
    append_file: Path | None,
    folder: Path | None,
) -> Any:
    """Run the command holding the lock of the file it appends to or of its output folder."""
    if append_file is not None:
        import hashlib
        import tempfile

        digest = hashlib.sha1(os.path.realpath(append_file).encode()).hexdigest()
        lock = Path(tempfile.gettempdir(), "biomorph-locks", f"{digest[:16]}.lock")
        with file_lock(lock, what=f"{append_file} (appended by another run)"):
            return callback(**params)
    if folder is not None:
        with folder_lock(folder):
            return callback(**params)
    return callback(**params)


def _wrap_commands(group: Any, path: tuple[str, ...] = ()) -> None:
    for name, sub in getattr(group, "commands", {}).items():
        if hasattr(sub, "commands"):
            _wrap_commands(sub, path + (name,))
        elif sub.callback is not None and not getattr(sub.callback, "_biomorph_guarded", False):
            sub.callback = _guarded(path + (name,), sub, sub.callback)
            sub.callback._biomorph_guarded = True  # type: ignore[attr-defined]


@functools.cache
def _command(group: str | None = None) -> Any:
    """The click command tree of :data:`app` with ``group``'s commands (all when ``None``,
    see :func:`_selected_group`), every command wrapped by :func:`_guarded`."""
    if group != "":
        _add_pillar_apps(group)
    command = typer.main.get_command(app)
    _wrap_commands(command)
    return command


def _one_line(exc: Any) -> str:
    """A click usage error as one line naming the command and the problem."""
    message = " ".join(exc.format_message().split())
    ctx = getattr(exc, "ctx", None)
    where = ctx.command_path if ctx is not None else "biomorph"
    return f"{where}: {message} (see {where} --help)"


def _error(message: str) -> None:
    """Print ``error: message`` on stderr as one line (the message is not rich markup)."""
    from rich.markup import escape

    err_console.print(
        f"[bold red]error:[/] {escape(' '.join(message.split()))}", markup=True, highlight=False
    )


def run(argv: list[str] | None = None) -> int:
    """Run the CLI on ``argv``; return the exit code (0 ok, 2 bad input/usage, 130 Ctrl-C).

    Warnings raised while a command runs (numpy's RuntimeWarnings on a bad file, library
    deprecations) are held back: a failing command prints only its one error line, a
    succeeding one prints each distinct warning once, after its output.
    """
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        code = _run(argv)
    if code in (0, 1):
        seen = set()
        for w in caught:
            text = f"warning: {' '.join(str(w.message).split())}"
            if text not in seen:
                seen.add(text)
                err_console.print(text, markup=False, highlight=False)
    return code


def _run(argv: list[str] | None) -> int:
    with interrupt_guard() as interrupted:
        try:
            args = sys.argv[1:] if argv is None else list(argv)
            command = _command(_selected_group(args))
            result = command.main(args=args, prog_name="biomorph", standalone_mode=False)
        except BiomorphError as exc:
            _error(str(exc))
            return 2
        except typer.Exit as exc:
            code = int(exc.exit_code or 0)
            if code == EXIT_INTERRUPTED and interrupted():
                err_console.print(INTERRUPT_LINE)
            return code
        except _ClickException as exc:
            if exc.exit_code == 2:
                _error(_one_line(exc))
                return 2
            exc.show()
            return int(exc.exit_code)
        except (KeyboardInterrupt, typer.Abort):
            err_console.print(INTERRUPT_LINE)
            return EXIT_INTERRUPTED
        except OSError as exc:  # unreadable/unwritable paths, full disk
            where = os.fspath(exc.filename) if exc.filename else ""
            _error(f"{where + ': ' if where else ''}{exc.strerror or exc}")
            return 2
        except MemoryError:
            _error("out of memory; the request is larger than this machine's memory")
            return 2
        except Exception as exc:  # a bug, not bad input: one line, exit 1, traceback on demand
            if interrupted():
                # raised because Ctrl-C cut something short (an import half done leaves a
                # module that fails the next import): the interruption, not a bug
                err_console.print(INTERRUPT_LINE)
                return EXIT_INTERRUPTED
            if os.environ.get("BIOMORPH_DEBUG"):
                raise
            _error(
                f"internal error ({type(exc).__name__}: {exc}); this is a bug in biomorph "
                "- run again with BIOMORPH_DEBUG=1 for the traceback and report it"
            )
            return 1
        if result == EXIT_INTERRUPTED and interrupted():
            err_console.print(INTERRUPT_LINE)
    return int(result) if isinstance(result, int) else 0


def main() -> None:
    code = run(sys.argv[1:])
    if code == EXIT_INTERRUPTED:  # skip the interpreter's slow teardown after Ctrl-C
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    main()
