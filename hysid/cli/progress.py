"""Progress of a long command on stderr: a bar with an ETA on a terminal (rich), plain lines otherwise.

On a terminal, :class:`Progress` draws one bar (done/total, elapsed, time
left, and a short status such as the best fitness) that redraws in place. When
stderr is not a terminal (a log file, a pipe, a batch job) it writes one plain
line at each tenth of the work, so a log stays short and still tells how far
a run got. With ``enabled=False`` (``--json``, ``--quiet``) it shows nothing.
The work is counted in the library's own units: fit iterations, reproduction
runs, diagnosis fits, island iterations.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from types import TracebackType
from typing import TYPE_CHECKING, TextIO

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.progress import Progress as RichProgress

from coordinator.interrupt import INTERRUPTED
from hysid.report.campaign_text import campaign_progress_line, migrant_messages, stopping_line
from island.termination import Termination

if TYPE_CHECKING:
    from coordinator.progress import CampaignProgress

PLAIN_STEPS = 10
"""Plain lines per run of work when stderr is not a terminal (one at each tenth)."""


def clock(seconds: float) -> str:
    """``1:02:03`` or ``2:03``."""
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class Progress:
    """Progress of ``total`` units of work called ``label``; use as a context manager."""

    def __init__(self, label: str, total: float, *, enabled: bool = True, stream: TextIO | None = None) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled
        self.terminal = enabled and self.stream.isatty()
        self.label = label
        self.total = max(float(total), 1.0)
        self.done = 0.0
        self.started = time.monotonic()
        self.shown_step = 0
        self.bar: RichProgress | None = None
        if self.terminal:
            self.bar = RichProgress(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TaskProgressColumn(),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                TextColumn("{task.fields[status]}"),
                console=Console(file=self.stream),
                transient=True,
            )
            self.task = self.bar.add_task(label, total=self.total, status="")

    def __enter__(self) -> Progress:
        if self.bar is not None:
            self.bar.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        if self.bar is not None:
            self.bar.stop()

    def update(self, done: float, status: str = "", total: float | None = None) -> None:
        """``done`` units of work so far (of ``total`` if the total changed), with a short ``status``."""
        if total is not None:
            self.total = max(float(total), 1.0)
        self.done = min(float(done), self.total)
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(self.task, completed=self.done, total=self.total, status=status)
            return
        step = int(PLAIN_STEPS * self.done / self.total)
        if step > self.shown_step:
            self.shown_step = step
            print(self.line(status), file=self.stream, flush=True)

    def say(self, line: str) -> None:
        """``line`` on its own, above the bar on a terminal (also when the bar is off)."""
        if self.bar is not None:
            self.bar.console.print(line, markup=False, highlight=False, soft_wrap=True)
        else:
            print(line, file=self.stream, flush=True)

    def advance(self, status: str = "", by: float = 1.0) -> None:
        """One more unit (or ``by``) of work done."""
        self.update(self.done + by, status)

    def line(self, status: str = "") -> str:
        """The plain progress line: ``fitting: 40% (8/19), 0:03 elapsed, about 0:05 left; <status>``."""
        elapsed = time.monotonic() - self.started
        left = elapsed * (self.total - self.done) / self.done if self.done > 0 else float("nan")
        eta = f", about {clock(left)} left" if self.done < self.total and left == left else ""
        return f"{self.label}: {100 * self.done / self.total:.0f}% ({self.done:.0f}/{self.total:.0f}), {clock(elapsed)} elapsed{eta}" + (
            f"; {status}" if status else ""
        )


def campaign_done(p: CampaignProgress, islands: int, iterations: int | None, termination: Termination) -> float:
    """How far a campaign is, in island iterations of ``islands x iterations`` (in percent when islands
    search until the stop order, ``iterations`` None): the furthest of the islands' own budgets and the
    stop rules that can be measured in advance (evaluation budget, time limit)."""
    total = islands * iterations if iterations else 100
    fractions = [sum(min(v.iteration, iterations) for v in p.islands.values()) / total] if iterations else []
    if termination.budget:
        fractions.append(p.evaluations / termination.budget)
    if termination.time_limit_s:
        fractions.append(p.elapsed_s / termination.time_limit_s)
    return min(max(fractions, default=0.0), 1.0) * total


def campaign_status(p: CampaignProgress) -> str:
    """The short status next to a campaign's bar: global best, members, migrations."""
    alive = sum(s == "alive" for s in p.members.values())
    return f"best {p.best:.4g} | members {alive} | migrations {migrant_messages(p)}" + (f" | rejected {p.rejected}" if p.rejected else "")


def campaign_reporter(bar: Progress, islands: int, iterations: int | None, termination: Termination) -> Callable[[CampaignProgress], None]:
    """The coordinator's progress callback for ``bar``: the bar on a terminal, else one line per
    report (:func:`hysid.report.campaign_text.campaign_progress_line`); with the bar off (``--quiet``, ``--json``)
    only the answer to Ctrl-C (:func:`announcing_stop`)."""

    def report(p: CampaignProgress) -> None:
        if not bar.enabled:
            return
        if bar.terminal:
            bar.update(campaign_done(p, islands, iterations, termination), campaign_status(p))
        else:
            print(campaign_progress_line(p), file=bar.stream, flush=True)

    return announcing_stop(report, bar.say)


def announcing_stop(report: Callable[[CampaignProgress], None] | None, say: Callable[[str], None]) -> Callable[[CampaignProgress], None]:
    """``report`` (a progress callback, or None) that first says, once, what the campaign does after Ctrl-C
    (:func:`hysid.report.campaign_text.stopping_line`, a line handed to ``say``): a user's key is answered whatever
    ``--quiet`` says."""
    said = False

    def on_progress(p: CampaignProgress) -> None:
        nonlocal said
        if p.stopping == INTERRUPTED and not said:
            said = True
            say(f"hysid: {stopping_line(p)}")
        if report is not None:
            report(p)

    return on_progress
