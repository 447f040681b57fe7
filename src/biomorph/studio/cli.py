"""``biomorph studio``: start the browser studio (registered on the root CLI)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

#: seconds the studio waits for its web server's teardown after Ctrl-C: well inside the
#: interrupt guard's grace (``biomorph._cli.INTERRUPT_GRACE``, 0.5 s), after which the
#: guard itself exits with 130; idle the teardown takes 0.1-0.2 s, 0.25-0.35 s with the
#: cores busy
STOP_WAIT = 0.3


def studio(
    host: Annotated[
        str,
        typer.Option(
            "--host",
            help="Interface to bind. Loopback by default; "
            "anything else exposes the studio and the data folder "
            "to the network.",
        ),
    ] = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", help="TCP port (0 picks a free one).")] = 8080,
    data: Annotated[
        Path,
        typer.Option(
            "--data",
            help="Folder files are opened from and saved to (nothing outside it is reachable).",
        ),
    ] = Path("."),
    max_upload_mb: Annotated[
        float, typer.Option("--max-upload-mb", help="Largest accepted upload.")
    ] = 64.0,
    token: Annotated[
        str | None,
        typer.Option(
            "--token",
            help="Require this secret (at least 8 characters) on every request; the "
            "printed URL carries it. Use it behind a tunnel or on a shared "
            "machine.",
        ),
    ] = None,
    shared: Annotated[
        bool,
        typer.Option(
            "--shared",
            help="One session for every page (all pages see and move the same "
            "controls) instead of one per page.",
        ),
    ] = False,
) -> None:
    """Open the four pillars in the browser: creature, motion, tree, leaf (plus files).

    Example: biomorph studio --data ./my-data --port 8080   (then open the printed URL)
    """
    from biomorph.errors import ParameterError
    from biomorph.studio.server import StudioApp

    if not 0 <= port <= 65535:
        raise ParameterError(f"--port {port} is outside 0..65535")
    if max_upload_mb <= 0:
        raise ParameterError(f"--max-upload-mb must be positive, got {max_upload_mb}")
    app = StudioApp(
        data,
        host=host,
        port=port,
        max_upload_bytes=int(max_upload_mb * 1e6),
        token=token,
        shared=shared,
    )
    try:
        url = app.start()
    except OSError as exc:
        raise ParameterError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from exc
    typer.echo(f"biomorph studio: open {url}  (data folder {app.sandbox.root}; Ctrl-C stops)")
    if host not in ("127.0.0.1", "localhost", "::1"):
        typer.echo(f"warning: listening on {host}, not only this machine", err=True)
    try:
        app.wait()
    except KeyboardInterrupt:
        typer.echo("stopping the studio")
    finally:
        # within Ctrl-C's grace: the server's teardown may take longer under load
        app.stop(timeout=STOP_WAIT)


def register(app: typer.Typer) -> None:
    """Add the ``studio`` command to the root ``biomorph`` app."""
    app.command("studio")(studio)
