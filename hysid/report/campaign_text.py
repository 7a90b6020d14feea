"""The plain text of campaigns: a campaign's summary, its migrations and share, the live progress line, the
answer to Ctrl-C and the screen of ``hysid watch`` (the rest of hysid's text is :mod:`hysid.report.text`)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from hysid.report.records import FitRecord
from hysid.report.text import fit_summary, text_table

if TYPE_CHECKING:
    from coordinator.progress import CampaignProgress
    from hysid.watch import CampaignSnapshot


def migrations_text(m: dict[str, Any]) -> str:
    """A campaign's migrations (its ``migrations`` document) in one phrase, as the summary and the report say them."""
    unfollowed = m.get("unfollowed")
    unlisted = f", {m['unlisted']:,} that waited in vain for the roster to list their run" if m.get("unlisted") else ""
    if not unfollowed:
        return (
            f"{m['messages']} messages ({m['topology']}, every {m['interval']} iterations), "
            f"{m['received']} migrants re-evaluated, {m['taken']} taken in{unlisted}, {m['rejected']} messages rejected"
        )
    return (
        f"{m['messages']:,} messages handled by the coordinator ({m['topology']}, every {m['interval']} iterations) until "
        f"{unfollowed['islands']:,} islands were alive, {unfollowed['after_s']:.0f} s in (it follows those of at most "
        f"{unfollowed['follows_up_to']} islands); by the islands' own counts {m['sent']:,} messages sent, {m['received']:,} "
        f"migrants re-evaluated, {m['taken']:,} taken in{unlisted}; {m['rejected']:,} messages rejected by the coordinator"
    )


def algorithms_text(island: dict[str, Any]) -> str:
    """The algorithms an island run searched with, in order (``GA -> PSO``: its share moved it); a record of an
    earlier hysid knows only its last."""
    return " -> ".join(a.upper() for a in island.get("algorithms") or [island["algo"]])


def island_label(name: str, algos: Sequence[str]) -> str:
    """An island and its algorithms, as the live progress line shows it: ``island-0 (ga -> pso)``."""
    return f"{name} ({' -> '.join(algos)})" if algos else name


def campaign_summary(fit: FitRecord, m: dict[str, Any], stored: dict[str, Any], islands: list[dict[str, Any]]) -> str:
    """The fit summary of a campaign (its ``fit``), then why it stopped, its migrations ``m``, what its database
    ``stored`` and every island."""
    lines = [
        fit_summary(fit, "hysid campaign"),
        f"campaign {fit.settings['campaign']!r}: stopped because {fit.settings['stop_reason']}",
        f"migrations: {migrations_text(m)}",
        stored_line(stored),
    ]
    lines += share_lines(fit.settings, islands)
    for isl in islands:
        lines.append(
            f"  {isl['island']:<12} {algorithms_text(isl):<10} seed {isl['seed']:<4} {isl['status']:<7} best {isl['best_fitness']:.4g} "
            f"after {isl['iterations']} iterations, {isl['evaluations']:,} evaluations" + (f", {isl['thinned']:,} rows thinned" if isl["thinned"] else "")
        )
    return "\n".join(lines)


def stored_line(h: dict[str, Any]) -> str:
    """How much history the coordinator stored, and what it left out when it could not keep up."""
    line = f"history: {h['history_rows']:,} rows stored"
    if h["thinned_rows"]:
        line += (
            f"; {h['thinned_rows']:,} rows thinned while the islands offered more than the coordinator's storage held "
            "(every improvement kept; per island in the islands table)"
        )
    if h["superseded_migrant_messages"]:
        line += f"; {h['superseded_migrant_messages']:,} migrant messages superseded by a newer one of their island before it handled them"
    return line


SHARE_RULES = {
    "staged": "of the exploring algorithm (GA) to the converging one (PSO) after their first migration interval",
    "adaptive": "to the algorithm whose own moves gained more",
}
"""What the moves of each share that moves islands (:mod:`island.share`) follow, as the summary says it."""


def no_moves(share: str, settings: dict[str, Any]) -> str:
    """Why a share that moves islands moved none."""
    interval = (settings.get("migration") or {}).get("interval", 0)
    if not interval:
        return "the islands were isolated (migration interval 0): a share moves islands between rounds of migration"
    if share == "staged":
        return f"no GA island searched its first migration interval ({interval} iterations) before it ended"
    return "each algorithm held its due share of the islands after every round (its gain per island)"


def share_lines(settings: dict[str, Any], islands: list[dict[str, Any]] | None = None) -> list[str]:
    """How a mixed campaign shared its islands between algorithms, and each move of its share; with the
    ``islands``' records, a move the island's last history does not show (an island of a fixed iteration budget
    may end before the order reaches it) is said to be so."""
    algos = list(dict.fromkeys(settings.get("algos") or []))
    if len(algos) < 2:
        return []
    moves = settings.get("moves") or []
    share = settings.get("share")
    if share not in SHARE_RULES:
        return [f"share: fixed (every island kept its algorithm of {', '.join(a.upper() for a in algos)})"]
    lines = [f"share: {share}, {len(moves)} island move(s) {SHARE_RULES[share]}"]
    if not moves:
        lines.append(f"  none: {no_moves(share, settings)}")
    over = " over the last rounds" if share == "adaptive" else " so far"
    ended_as = {i["island"]: i["algo"] for i in islands or []}
    last = {m["island"]: k for k, m in enumerate(moves)}
    for k, m in enumerate(moves):
        credit = ", ".join(f"{a.upper()} {c:.2g}" for a, c in m["credit"].items())
        unheard = last[m["island"]] == k and ended_as.get(m["island"], m["dst"]) != m["dst"]
        lines.append(
            f"  {m['island']:<12} {m['src'].upper()} -> {m['dst'].upper()} after {m['evaluations']:,} evaluations (orders of magnitude gained by each algorithm's own moves{over}: {credit})"
            + (f"; not followed: the island's last history shows {ended_as[m['island']].upper()}" if unheard else "")
        )
    return lines


def migrant_messages(p: CampaignProgress) -> str:
    """The migrant messages the coordinator handled; once it stopped following them, that the rest go island to island."""
    return f"{p.migrations}" if p.migrations_followed else f"{p.migrations} (then island to island)"


def campaign_progress_line(p: CampaignProgress) -> str:
    """One line of live progress: members, evaluations, global best, migrations, each island's best."""
    alive = sum(s == "alive" for s in p.members.values())
    gone = ", ".join(f"{i} {s}" for i, s in sorted(p.members.items()) if s != "alive")
    islands = "  ".join(f"{island_label(i, v.algos or (v.algo,))}:{v.best:.3g}@{v.iteration}" for i, v in sorted(p.islands.items()))
    return (
        f"[{p.elapsed_s:6.1f} s] members {alive}{f' ({gone})' if gone else ''} | evaluations {p.evaluations:,} | "
        f"best {p.best:.4g} | migrations {migrant_messages(p)}{f' | rejected {p.rejected}' if p.rejected else ''} | {islands}"
    )


def stopping_line(p: CampaignProgress) -> str:
    """What the user reads at once after Ctrl-C in a campaign: how many islands' last rows it waits for, and
    that a second Ctrl-C leaves without them."""
    alive = sum(s == "alive" for s in p.members.values())
    owner = "island's" if alive == 1 else "islands'"
    waits = f"waiting for {alive} {owner} last rows" if alive else "every island's last rows are in; writing the report"
    return f"stopping: {waits} (Ctrl-C again to leave now)"


SPARK = "▁▂▃▄▅▆▇█"


def sparkline(values: Sequence[float]) -> str:
    """A course of best fitness as one block per point, log scale, lowest = shortest block."""
    v = np.log10(np.clip(np.asarray(values, dtype=float), 1e-300, None))
    v = v[np.isfinite(v)]
    if not v.size:
        return ""
    span = float(v.max() - v.min())
    if span < 1e-12:
        return SPARK[0] * v.size
    return "".join(SPARK[int(round((x - v.min()) / span * (len(SPARK) - 1)))] for x in v)


def watch_text(snap: CampaignSnapshot) -> str:
    """The screen of ``hysid watch``: status, global best, one row per island run, membership."""
    p = snap.progress
    why = (snap.stop_reason or "").removeprefix("interrupted: ")
    state = f"{snap.status} ({why})" if snap.status in ("stopped", "interrupted") and why else snap.status
    rejected = f" | rejected messages {p.rejected}" if p.rejected else ""
    best = f"{p.best:.6g} from {snap.best_island}" if np.isfinite(p.best) else "none yet"
    lines = [
        f"campaign {snap.name!r} on {snap.dataset}: {state} after {p.elapsed_s:.1f} s",
        f"global best {best} | evaluations {p.evaluations:,} | migrant messages {migrant_messages(p)}{rejected}",
        "",
    ]
    several = {i["island"] for i in snap.islands if sum(j["island"] == i["island"] for j in snap.islands) > 1}
    rows = [
        [
            f"{i['island']}/{i['run']}" if i["island"] in several else i["island"],
            algorithms_text(i),
            i["status"],
            str(i["iterations"]),
            f"{i['evaluations']:,}",
            f"{i['best_fitness']:.4g}",
            str(i["messages"]),
            f"{i['received']}/{i['taken']}",
            sparkline(i["trend"]),
        ]
        for i in snap.islands
    ]
    headers = ["island", "algo", "status", "iteration", "evaluations", "best", "sent", "received/taken", "best over iterations"]
    lines.append(text_table(headers, rows) if rows else "  no island has reported yet")
    counts = {s: sum(v == s for v in p.members.values()) for s in ("alive", "left", "stopped", "lost", "unknown")}
    latest = ", ".join(f"{island} {event} {time.strftime('%H:%M:%S', time.localtime(t))}" for island, event, t in snap.events)
    stopped = f", {counts['stopped']} stopped by the user" if counts["stopped"] else ""
    unknown = f", {counts['unknown']} unknown (its coordinator gone)" if counts["unknown"] else ""
    lines += [
        "",
        f"members: {counts['alive']} alive, {counts['left']} left{stopped}, {counts['lost']} lost{unknown}" + (f"; latest: {latest}" if latest else ""),
    ]
    return "\n".join(lines)
