"""The coordinator's run loop and its stop rules: :func:`serve` runs a campaign's coordinator to its end.

One thread runs the loop, which owns the SQLite store: it feeds the
inbox (:func:`pump`) through :meth:`coordinator.state.Coordinator.handle` and

* writes the history rows it keeps in batches (every :data:`FLUSH_EVERY_S`, or
  :data:`FLUSH_ROWS` rows), and commits at least every :data:`COMMIT_EVERY_S` (or :data:`COMMIT_ROWS` rows)
  whatever the load (early by as long as its slowest recent message and commit
  took, so that no message started just before the deadline pushes the commit
  past it), with the campaign's elapsed time (``--resume`` carries the time
  rule on from there), and after each commit publishes the signed ``control``
  message (:meth:`coordinator.admission.Admission.control_message`, also sent at every join): the roster, how far each island's history
  is committed (an island waits for that before it leaves) and, at the end,
  the stop order (at each commit it also decides whether to go on following migrant messages:
  :meth:`coordinator.state.Coordinator.review_following`); every :data:`coordinator.thinning.REVIEW_EVERY_S` it measures what storage holds (the time its
  work and the writing of rows took: :meth:`coordinator.thinning.HistoryPolicy.review`)
  and stores the counts of migrant messages superseded in the inbox;
* stops (:func:`check_stop`) by the rules of :class:`island.termination.Termination`
  (a total evaluation budget, a target fitness, a stall, a time limit:
  :meth:`coordinator.state.Coordinator.rule_stop`), when every island has
  finished (or finished or was lost), or when no island has been alive for
  :data:`ORPHAN_S`; then announces the stop and stores the islands' final
  histories (for at most :data:`STOP_GRACE_S`). Ctrl-C (:class:`coordinator.interrupt.CtrlC`)
  stops it the same way, ``interrupted``, waiting at most :data:`INTERRUPT_GRACE_S` for the
  islands' last rows and recording each island run ``stopped`` (by the user); a second Ctrl-C
  leaves at once: the database rolled back to its last commit (nothing half written) and
  marked ``interrupted``, the runs it holds alive recorded ``stopped``. A database that cannot be
  written (locked by another process for :data:`coordinator.store.RUN_LOCK_WAIT_S`,
  full, read-only, deleted) stops the campaign cleanly (:class:`StoreError`): the
  islands are told to stop and the campaign is marked ``interrupted`` where the
  file lets it. Either way the inbox is closed when the loop ends, so that
  nothing arriving on the network keeps the process alive.

What the campaign leaves is :meth:`coordinator.state.Coordinator.outcome`.
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Callable

from coordinator.interrupt import INTERRUPTED, CtrlC
from coordinator.link import Link
from coordinator.members import LEAVE_GRACE_S, STATUS_AFTER, Member
from coordinator.progress import CampaignProgress
from coordinator.state import Coordinator
from coordinator.thinning import REVIEW_EVERY_S
from coordinator.writes import StoreError

ORPHAN_S = 30.0
"""Once islands have joined, a campaign with none alive for this long ends."""
STOP_GRACE_S = 10.0
"""After the stop order, how long to wait for islands' final histories."""
INTERRUPT_GRACE_S = 2.0
"""After Ctrl-C, how long to wait for them (an island's iteration ends well within it; the user may leave sooner)."""
LEFT_AT_ONCE = "interrupted: left at a second Ctrl-C, without waiting for the islands' last rows"
"""The stop reason stored when a second Ctrl-C leaves at once."""
FAULT_ANNOUNCEMENTS = 4
"""After a database fault, how many times (every 0.5 s) the stop order goes out before the coordinator ends."""
COMMIT_EVERY_S = 0.5
MAX_COMMIT_MARGIN_S = 0.3
"""The most a commit is brought forward (the slowest recent message plus the last commit's time)."""
COMMIT_ROWS = 20_000
"""The coordinator commits at least this often, and after this many history rows: what a kill can lose."""
FLUSH_EVERY_S = 0.1
FLUSH_ROWS = 5000
"""History rows (with the island records and thinned stretches) are written in one batch at least this
often, or once this many wait: a row is in the database a tenth of a second after it was handled. Losses
are looked for as often (:meth:`coordinator.members.Membership.settle`)."""
PASS_S = 0.2
"""Longest stretch of message handling between two checks of the stop rules and progress."""
CONTROL_EVERY_S = 1.0
"""The control message goes out after commits that changed something, and at least this often."""


def check_stop(c: Coordinator) -> str | None:
    reason = c.rule_stop()
    if reason:
        return reason
    alive = c.membership.any_alive()
    finished = bool(c.islands) and all(v.final for v in c.islands.values()) and not alive
    enough = len({island for island, _ in c.islands} | set(c.members)) >= c.config.min_islands
    if finished and (enough or c.resumed):
        return "every island finished"
    if (
        not alive
        and enough
        and any(v.final for v in c.islands.values())
        and all(v.final or c.members.get(island, Member("lost")).status == "lost" or c.current.get(island) != run for (island, run), v in c.islands.items())
    ):
        return "every island finished or was lost"
    idle_since = c.membership.idle_since
    if not alive and idle_since is not None and time.monotonic() - idle_since >= ORPHAN_S:
        return f"no island alive for {ORPHAN_S:g} s"
    return None


def commit(c: Coordinator, link: Link, *, announce: bool = False) -> None:
    """Commit (with the summary of rejects not recorded one by one), then publish the control
    message if something changed, every :data:`CONTROL_EVERY_S`, or with ``announce``. Only
    committed rows are ever reported to islands as stored."""
    dropped = c.inbox.take_dropped()
    if dropped:
        c.rejected += sum(dropped.values())
        c.rejected_backlog["overflow"] += sum(dropped.values())
    for reason, n in c.rejected_backlog.items():
        c.store.add_rejected(c.name, "*", reason, f"{n} rejected messages not recorded one by one (a flood)", 0, n)
    c.rejected_backlog.clear()
    superseded = c.inbox.take_superseded()
    if superseded:
        c.store.add_superseded(c.name, superseded)
        c.superseded += sum(superseded.values())
    began = time.monotonic()
    c.review_following(link)
    c.consider_migrants(link)
    c.busy_s += time.monotonic() - began
    flush(c)
    started = time.monotonic()
    c.store.commit(c.name, c.elapsed())
    c.committed_at, c.rows_since_commit = time.monotonic(), 0
    c.commit_s, c.slowest_item_s = c.committed_at - started, c.slowest_item_s / 2
    c.busy_s += c.commit_s
    if c.committed_at - c.window_at >= REVIEW_EVERY_S:
        c.policy.review(c.committed_at - c.window_at, c.busy_s, c.writing_s, c.written)
        c.window_at, c.busy_s, c.writing_s, c.written = c.committed_at, 0.0, 0.0, 0
    changed = c.changed or c.membership.events != c.announced_events
    if c.runs and (announce or changed or c.committed_at - c.control_at >= CONTROL_EVERY_S):
        c.announce(link, c.stop_reason)


def flush(c: Coordinator) -> None:
    """Write the queued history rows (and island records, thinned stretches), timing it."""
    began = time.monotonic()
    c.written += c.store.flush()
    spent = time.monotonic() - began
    c.writing_s += spent
    c.busy_s += spent
    c.flushed_at = time.monotonic()


def pump(c: Coordinator, link: Link, seconds: float, first_wait: float = 0.05) -> int:
    """Handle what arrives for up to ``seconds`` (waiting up to ``first_wait`` for the first item),
    committing whenever :data:`COMMIT_EVERY_S` or :data:`COMMIT_ROWS` is reached, and at the end;
    returns the items handled."""
    deadline = time.monotonic() + seconds
    handled = 0
    wait = first_wait
    while True:
        item = c.inbox.get(timeout=wait)
        if item is not None:
            began = time.monotonic()
            c.handle(link, item)
            spent = time.monotonic() - began
            c.slowest_item_s = max(c.slowest_item_s, spent)
            c.busy_s += spent
            handled += 1
        now = time.monotonic()
        done = item is None or now >= deadline
        margin = min(MAX_COMMIT_MARGIN_S, c.slowest_item_s + c.commit_s)
        due = done or now - c.committed_at >= COMMIT_EVERY_S - margin or c.rows_since_commit >= COMMIT_ROWS
        if due or now - c.flushed_at >= FLUSH_EVERY_S or c.store.pending_rows >= FLUSH_ROWS:
            c.membership.settle(c.inbox.holds if c.stop_reason is not None else None)  # stopping: final histories may wait
            if due:
                commit(c, link)
            else:
                flush(c)
        if done:
            return handled
        wait = 0.0


def serve(
    c: Coordinator,
    link: Link,
    on_progress: Callable[[CampaignProgress], None] | None = None,
    *,
    extra_stop: Callable[[], str | None] | None = None,
    progress_every_s: float = 1.0,
) -> str:
    """Run until a stop rule, ``extra_stop()`` or Ctrl-C; announce the stop, collect final histories; returns the reason.

    ``on_progress`` is called every ``progress_every_s``, at each membership event, at once when the campaign
    starts to stop (its :attr:`CampaignProgress.stopping` says why) and at the end. A second Ctrl-C raises
    ``KeyboardInterrupt`` at once (see the module docstring). A database that cannot be written ends the
    campaign: islands are told to stop, the campaign is marked ``interrupted`` if the file lets us, and
    :class:`StoreError` says what happened.
    """
    try:
        with CtrlC(c.membership.stopped_by_user) as ctrl_c:  # goodbyes handled from the key on record "stopped"
            return _serve(c, link, on_progress, extra_stop, progress_every_s, ctrl_c)
    finally:
        c.inbox.close()


def _serve(
    c: Coordinator,
    link: Link,
    on_progress: Callable[[CampaignProgress], None] | None,
    extra_stop: Callable[[], str | None] | None,
    progress_every_s: float,
    ctrl_c: CtrlC,
) -> str:
    last, shown_events = 0.0, -1
    fault: StoreError | None = None
    try:
        while c.stop_reason is None:
            pump(c, link, PASS_S)
            c.stop_reason = INTERRUPTED if ctrl_c.asked else check_stop(c) or (extra_stop() if extra_stop is not None else None)
            if c.stop_reason is None and on_progress is not None and (time.monotonic() - last >= progress_every_s or c.membership.events != shown_events):
                on_progress(c.progress())
                last, shown_events = time.monotonic(), c.membership.events
    except KeyboardInterrupt:  # Ctrl-C where CtrlC could not take SIGINT over stops the campaign as one it took
        if ctrl_c.asked:  # the second: leave at once
            _leave_now(c)
            raise
        c.stop_reason = INTERRUPTED
    except StoreError as exc:
        fault, c.stop_reason = exc, INTERRUPTED
    try:
        if fault is None:
            by_user = c.stop_reason == INTERRUPTED
            if by_user:
                c.membership.stopped_by_user()
            c.store.set_status(c.name, "stopping", c.stop_reason)
            if on_progress is not None:
                on_progress(c.progress())
            _stop_islands(c, link, INTERRUPT_GRACE_S if by_user else STOP_GRACE_S)
            if by_user:
                c.membership.stopped_by_user(give_up=True)
    except StoreError as exc:
        fault = exc
    except KeyboardInterrupt:  # Ctrl-C while the islands' last rows come: leave at once
        _leave_now(c)
        raise
    if fault is not None:
        raise _interrupted(c, link, fault)
    c.store.set_status(c.name, "stopped", c.stop_reason)
    if on_progress is not None:
        on_progress(c.progress())
    return c.stop_reason


def _stop_islands(c: Coordinator, link: Link, grace_s: float) -> None:
    """Announce the stop until every island left (at most ``grace_s``), storing their
    final histories and confirming them."""
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline and c.membership.any_alive():
        commit(c, link, announce=True)
        pump(c, link, min(0.5, max(deadline - time.monotonic(), 0.0)))
    pump(c, link, LEAVE_GRACE_S, first_wait=LEAVE_GRACE_S)


def _leave_now(c: Coordinator) -> None:
    """A second Ctrl-C: the database back at its last commit (a batch the key cut short is not half
    written; only committed rows were ever confirmed to islands), every run it holds alive recorded
    ``stopped``, the campaign marked interrupted (:data:`LEFT_AT_ONCE`); a file that will not take
    it keeps what was committed."""
    c.stop_reason = INTERRUPTED
    c.store.rollback()
    try:
        last = {island: event for island, event, _ in c.store.members(c.name)}
        for island, event in last.items():
            if STATUS_AFTER[event] == "alive":
                c.store.member_event(c.name, island, "stopped")
        c.store.set_status(c.name, INTERRUPTED, LEFT_AT_ONCE)
    except (StoreError, sqlite3.Error):
        c.store.rollback()


def _interrupted(c: Coordinator, link: Link, fault: StoreError) -> StoreError:
    """After a database fault: tell the islands to stop (reporting only rows really committed),
    mark the campaign interrupted if the file lets us."""
    c.inbox.close()
    c.store.rollback()
    c.store.release_reserve()
    c.gaps.forget()
    try:
        for _ in range(FAULT_ANNOUNCEMENTS):
            if c.runs:
                c.announce(link, f"interrupted: {fault.detail}")
            time.sleep(0.5)
    except sqlite3.Error:
        pass  # the file cannot even be read: islands end on their own after their wait
    try:
        c.store.check_file()
    except StoreError:
        return StoreError(f"campaign {c.name!r} stopped: {fault.detail}; what it recorded went with the file (nothing to resume)")
    try:
        c.store.set_status(c.name, "interrupted", f"interrupted: {fault.detail}")
        marked = "it is marked interrupted"
    except StoreError as exc:
        marked = f"it could not be marked interrupted ({exc.detail.rsplit(': ', 1)[-1]})"
    return StoreError(f"campaign {c.name!r} stopped: {fault.detail}; what was committed before is kept and {marked} (--resume carries on)")
