"""The diagnosis report's figures: the gap after each step, the residual map, and loops before and after."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from hysid.report.records import DiagnosisCurves, ProposedForce
from hysid.report.style import MODEL, PAGE_WIDTH_IN, TRIAL, frequency_axis, new_figure, save, series_color, styled
from hysid.report.text import hz_text
from hysid_model.frf import amplitude_levels
from hysid_model.loops import LoopSet

START = "#999999"
"""The start model in loop plots (grey, dashed)."""


@styled
def gap_figure(path: Path, labels: Sequence[str], metrics: Sequence[dict[str, Any]]) -> Path:
    """Whitened RMS (and its cross-validated value) and the loop/energy errors after each step (the diagnosis
    document's ``gap`` entries)."""
    fig = new_figure(2.6)
    left, right = fig.subplots(1, 2)
    x = np.arange(len(metrics))
    left.semilogy(x, [m["whitened_rms"] for m in metrics], "o-", color=MODEL, label="fit")
    cv = [m["cv_whitened_rms"] for m in metrics]
    if all(c is not None for c in cv):
        left.semilogy(x, cv, "s--", color=TRIAL, label="leave-one-frequency-out")
    left.axhline(1.0, color="k", lw=0.8, ls=":", label="noise floor")
    left.set_ylabel("whitened residual RMS")
    left.legend()
    right.plot(x, [m["loop_nrmse_pct"] for m in metrics], "o-", color=series_color(2), label="loop NRMSE")
    right.plot(x, [m["energy_error_pct"] for m in metrics], "s-", color=series_color(3), label="energy per cycle")
    right.set_ylabel("error (%)")
    right.set_ylim(bottom=0)
    right.legend()
    for ax in (left, right):
        ax.set_xticks(x, [label.split(": ")[-1] if i == 0 else label for i, label in enumerate(labels)], rotation=20, ha="right")
    return save(fig, path)


@styled
def residual_map_figure(path: Path, loops: LoopSet, curves: DiagnosisCurves, start: str, final: str) -> Path:
    """Per-loop whitened RMS over frequency x amplitude, start model vs final model (their specs), one colour scale."""
    before, after = curves.start_rms, curves.final_rms
    norm = LogNorm(vmin=max(min(before.min(), after.min()), 0.1), vmax=max(before.max(), after.max(), 10.0))
    fig = new_figure(2.7)
    axes = fig.subplots(1, 2, sharex=True, sharey=True)
    for ax, values, title in ((axes[0], before, f"before: {start}"), (axes[1], after, f"after: {final}")):
        art = ax.scatter(loops.freq_hz, loops.x0 * 1e3, c=values, s=60, marker="s", cmap="viridis", norm=norm, edgecolors="none")
        ax.set_title(title, fontsize=7.5)
        ax.set_xlabel("frequency (Hz)")
        frequency_axis(ax, loops.freq_hz)
    axes[0].set_ylabel("amplitude X0 (mm)")
    fig.colorbar(art, ax=axes, label="whitened RMS per loop (1 = noise)")
    return save(fig, path)


LOOP_CHOICE = ("worst fit at the start", "median frequency")
"""What the diagnosis' loop figure shows of each amplitude, left to right."""
MAX_LEVELS = 3


def chosen_loops(loops: LoopSet, worst: np.ndarray) -> list[list[int]]:
    """Per amplitude level (at most :data:`MAX_LEVELS`, spread over the levels with two loops or more if
    there are any): the loop the start model misses most and the one at the median frequency (the next
    worst if that is the same loop)."""
    _, index = amplitude_levels(loops.x0)
    sizes = np.bincount(index)
    candidates = np.flatnonzero(sizes > 1) if np.any(sizes > 1) else np.arange(sizes.size)
    shown = candidates[np.unique(np.round(np.linspace(0, candidates.size - 1, min(candidates.size, MAX_LEVELS))).astype(int))]
    out = []
    for level in shown:
        members = np.flatnonzero(index == level)
        ranked = members[np.argsort(-worst[members], kind="stable")]
        median = members[np.argsort(loops.freq_hz[members], kind="stable")[members.size // 2]]
        picks = [int(ranked[0])] + ([int(median if median != ranked[0] else ranked[1])] if members.size > 1 else [])
        out.append(picks)
    return out


@styled
def loops_figure(path: Path, loops: LoopSet, curves: DiagnosisCurves) -> Path:
    """Measured loops with the start and the final model's branches (:func:`draw_loops`)."""
    return save(draw_loops(loops, curves), path)


def draw_loops(loops: LoopSet, curves: DiagnosisCurves) -> Figure:
    """One row per amplitude, the loops of :data:`LOOP_CHOICE` as columns (titled so), the legend below the panels."""
    rows = chosen_loops(loops, curves.start_rms)
    cols = max(len(r) for r in rows)
    fig = new_figure(1.9 * len(rows) + 0.5, PAGE_WIDTH_IN * (0.5 + 0.25 * cols))
    axes = fig.subplots(len(rows), cols, squeeze=False)
    n = loops.n_samples
    start, final = curves.start_force, curves.final_force
    for r, picks in enumerate(rows):
        for c in range(cols):
            ax = axes[r, c]
            if c >= len(picks):
                ax.set_visible(False)
                continue
            j = picks[c]
            x = np.concatenate([loops.top[j, :, 0], loops.bottom[j, :, 0]]) * 1e3
            ax.plot(x, loops.forces()[j], ".", ms=2.0, color=TRIAL)
            for force, color, style in ((start, START, "--"), (final, MODEL, "-")):
                ax.plot(x[:n], force[j, :n], style, color=color, lw=1.0)
                ax.plot(x[n:], force[j, n:], style, color=color, lw=1.0)
            ax.set_title(f"{LOOP_CHOICE[c]}: {hz_text(loops.freq_hz[j])}, X0 = {loops.x0[j] * 1e3:.3g} mm", fontsize=7.5)
            ax.set_xlabel("x (mm)")
            ax.set_ylabel("F (N)")
    handles = [Line2D([], [], ls="none", marker=".", ms=5, color=TRIAL), Line2D([], [], ls="--", color=START), Line2D([], [], color=MODEL)]
    fig.legend(handles, ["measured", "start model", "final model"], loc="outside lower center", ncol=3)
    return fig


@styled
def proposed_force_figure(path: Path, loops: LoopSet, proposed: ProposedForce) -> Path:
    """The proposed force against displacement (left) and velocity (right), each loop a line, with what the
    final model leaves of the measured force without it as points."""
    x, v, force, left_over = proposed.x, proposed.v, proposed.force, proposed.left_over
    kept = loops.kept()
    fig = new_figure(2.8)
    axes = fig.subplots(1, 2, sharey=True)
    n = loops.n_samples
    for ax, state, label in ((axes[0], x * 1e3, "x (mm)"), (axes[1], v, "v (m/s)")):
        for j in range(loops.n_loops):
            ax.plot(state[j][kept[j]], left_over[j][kept[j]], ".", ms=1.5, color=TRIAL, alpha=0.5)
            for branch in (slice(0, n), slice(n, 2 * n)):  # each branch in its own order: no line across the loop
                ax.plot(state[j][branch], force[j][branch], "-", color=MODEL, lw=0.9)
        ax.set_xlabel(label)
    axes[0].set_ylabel("F (N)")
    fig.suptitle(f"{proposed.name}: {proposed.notation}", fontsize=8)
    return save(fig, path)
