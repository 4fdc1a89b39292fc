"""A study's progress on stderr: a rich progress bar on a terminal, else a line
"<label>: <done>/<total> runs" at most every 10 s and at the end (a log gets a few lines, not a
bar redrawn in place). `RowProgress(..., enabled=False)` shows nothing."""

from __future__ import annotations

import sys
import time
from types import TracebackType
from typing import Any

LINE_EVERY_S = 10.0  # without a terminal: one line at most this often (and the last one)


class RowProgress:
    """`with RowProgress(label, total) as p: ... p.advance(done)` (runs finished so far)."""

    def __init__(self, label: str, total: int, enabled: bool = True):
        self.label, self.total, self.enabled = label, total, enabled
        self.tty = enabled and sys.stderr.isatty()
        self.last = time.monotonic()
        self._bar: Any = None  # a rich.progress.Progress on a terminal
        self._task: Any = None

    def __enter__(self) -> RowProgress:
        if self.tty:
            # lazy: rich.progress (~20 ms), which `swarm --help` must not pay
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self._bar = Progress(
                TextColumn(self.label),
                BarColumn(),
                MofNCompleteColumn(),
                TimeRemainingColumn(),
                transient=True,
                console=Console(stderr=True),
            )
            self._bar.__enter__()
            self._task = self._bar.add_task(self.label, total=self.total)
        return self

    def advance(self, done: int) -> None:
        if not self.enabled:
            return
        if self._bar is not None and self._task is not None:
            self._bar.update(self._task, completed=done)
        elif time.monotonic() - self.last > LINE_EVERY_S or done == self.total:
            self.last = time.monotonic()
            print(f"{self.label}: {done}/{self.total} runs", file=sys.stderr, flush=True)

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        if self._bar is not None:
            self._bar.__exit__(kind, value, tb)
