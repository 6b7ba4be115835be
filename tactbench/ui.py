"""The one progress UI: rich bars on a terminal, plain lines in logs, nothing when off.

Library code never draws: it takes a ``progress(done, total, **info)`` callback.
Commands and the runner own a :class:`Progress` and hand out callbacks from it with
:meth:`Progress.callback`.
"""

from __future__ import annotations

import time
from typing import Any, Callable


class Progress:
    """Progress bars on stderr with rich; plain start/finish lines when stderr is not a
    terminal (CI logs, pipes); nothing when disabled."""

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        self._progress = None
        self._console = None
        self._plain: dict[int, tuple[str, float, int | None]] = {}

    def __enter__(self) -> "Progress":
        if not self.enabled:
            return self
        from rich.console import Console

        self._console = Console(stderr=True)
        if self._console.is_terminal:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )
            from rich.progress import Progress as RichProgress

            self._progress = RichProgress(
                TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                TimeElapsedColumn(), TimeRemainingColumn(), TextColumn("{task.fields[info]}"),
                console=self._console, transient=False)
            self._progress.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._progress is not None:
            self._progress.__exit__(*exc)

    def add(self, description: str, total: int | None) -> Any:
        if self._progress is not None:
            return self._progress.add_task(description, total=total, info="")
        if self._console is None:
            return None
        task = len(self._plain)
        self._plain[task] = (description, time.perf_counter(), total)
        self._console.print(f"… {description}", highlight=False)
        return task

    def update(self, task: Any, completed: int, total: int | None = None, info: str = "",
               ) -> None:
        if task is None:
            return
        if self._progress is not None:
            kwargs: dict[str, Any] = {"completed": completed, "info": info}
            if total is not None:
                kwargs["total"] = total
            self._progress.update(task, **kwargs)
            return
        if self._console is None or task not in self._plain:
            return
        description, started, known_total = self._plain[task]
        total = total if total is not None else known_total
        if total is not None and completed >= total:
            del self._plain[task]
            self._console.print(f"✓ {description}: {completed}/{total} in "
                                f"{time.perf_counter() - started:.1f} s {info}", highlight=False)

    def callback(self, description: str, total: int | None = None,
                 ) -> "Callable[..., None] | None":
        """A task as a ``progress(done, total=None, **info)`` callback (None when off).

        The bar appears at the first report, so work that turns out to need none (a cache
        hit, a file that loads at once) leaves no empty bar behind.
        """
        if not self.enabled:
            return None
        task: list[Any] = []

        def report(done: int, total_now: int | None = None, **info: Any) -> None:
            if not task:
                task.append(self.add(description, total_now if total_now is not None
                                     else total))
            text = " ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                            for k, v in info.items())
            self.update(task[0], done, total_now, text)

        return report
