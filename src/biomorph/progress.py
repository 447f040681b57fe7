"""Progress bars for long work (rich), shown on stderr and hidden when not interactive."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

T = TypeVar("T")

_console = Console(stderr=True)


def _make(enabled: bool | None) -> Progress:
    show = sys.stderr.isatty() if enabled is None else enabled
    return Progress(
        SpinnerColumn(),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=_console,
        transient=True,
        disable=not show,
    )


@contextlib.contextmanager
def task(
    description: str, total: float | None = None, enabled: bool | None = None
) -> Iterator[Callable[..., None]]:
    """Context manager yielding ``advance(n=1, description=None)`` for a progress bar.

    Ctrl-C propagates as ``KeyboardInterrupt``; the CLI turns it into a clean exit (130)
    and atomic writers leave no partial files.
    """
    with _make(enabled) as progress:
        tid = progress.add_task(description, total=total)

        def advance(n: float = 1, description: str | None = None) -> None:
            if description is not None:
                progress.update(tid, description=description)
            progress.advance(tid, n)

        yield advance


def track(
    items: Iterable[T], description: str, total: int | None = None, enabled: bool | None = None
) -> Iterator[T]:
    """Iterate over ``items`` with a progress bar."""
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    with task(description, total, enabled) as advance:
        for item in items:
            yield item
            advance()
