"""Reusable GUI pieces of the tabs: a data-folder file picker and an export button row."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from biomorph.errors import InputError
from biomorph.studio.base import StudioTab, plain

NO_FILE = "(none in the data folder)"


class FilePicker:
    """Dropdown of data-folder files with given extensions, Open/Refresh, and an upload.

    ``on_open(path)`` runs inside the tab's error-capturing :meth:`StudioTab.run`.
    """

    def __init__(
        self,
        tab: StudioTab,
        label: str,
        extensions: Sequence[str],
        on_open: Callable[[Path], Any],
        upload_label: str | None = None,
    ) -> None:
        self.tab = tab
        self.extensions = tuple(e.lower() for e in extensions)
        self.on_open = on_open
        gui = tab.gui
        self.dropdown = gui.add_dropdown(
            label,
            options=self.options(),
            hint=f"Files ({' '.join(self.extensions)}) in the data folder.",
        )
        self.buttons = gui.add_button_group("", ("Open", "Refresh"))
        self.buttons.on_click(self._clicked)
        self.upload = tab.app.add_upload(
            tab, upload_label or f"Upload {label.lower()}", self._uploaded, self.extensions
        )

    def options(self) -> tuple[str, ...]:
        files = self.tab.app.sandbox.list_files(self.extensions)
        return tuple(files) if files else (NO_FILE,)

    def refresh(self) -> None:
        self.dropdown.options = self.options()

    def _clicked(self, event: Any) -> None:
        if event.target.value == "Refresh":
            self.tab.run("refresh", self.refresh, timed=False, show=False)
        else:
            self.tab.run("open", self.open_selected, timed=False, heavy=True)

    def open_selected(self) -> Any:
        name = self.dropdown.value
        if name == NO_FILE:
            raise InputError("no file chosen: put one in the data folder or upload it")
        path = self.tab.app.sandbox.resolve(name)
        self.tab.set_status(f"Reading {plain(name)} ({path.stat().st_size / 1e6:.1f} MB) …")
        return self.on_open(path)

    def _uploaded(self, path: Path) -> Any:
        result = self.on_open(path)
        self.refresh()
        self.dropdown.value = self.tab.app.sandbox.relative(path)
        return result


class ExportRow:
    """One button per export format; each writes ``exports/<stem>.<ext>`` via ``writers``,
    with a list saying what each file holds (``contents``, format -> one line)."""

    def __init__(
        self,
        tab: StudioTab,
        stem: Callable[[], str],
        writers: dict[str, Callable[[Path], Any]],
        label: str = "Export",
        contents: dict[str, str] | None = None,
    ) -> None:
        self.tab = tab
        self.stem = stem
        self.writers = writers
        self.buttons = tab.gui.add_button_group(label, tuple(writers))
        self.buttons.on_click(self._clicked)
        if contents:
            lines = "\n".join(f"* **{fmt}**: {text}" for fmt, text in contents.items())
            tab.gui.add_markdown(
                f"Written to `exports/` in the data folder and offered as a download:\n\n{lines}"
            )
        self.last_path: Path | None = None

    def _clicked(self, event: Any) -> None:
        fmt = event.target.value
        self.tab.run(f"export {fmt}", lambda: self.export(fmt), timed=False, show=False)

    def export(self, fmt: str) -> Path:
        """Write the current state in format ``fmt`` (a key of ``writers``)."""
        name = f"{self.stem()}.{fmt.lower()}"
        self.last_path = self.tab.app.export(self.tab, name, self.writers[fmt])
        return self.last_path
