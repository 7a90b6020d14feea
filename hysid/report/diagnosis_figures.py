"""The diagnosis report's figures: the gap after each step, the residual map, and loops before and after."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np
from matplotlib.colors import LogNorm

from hysid.diagnose.metrics import GapMetrics, loop_whitened_rms
from hysid.report.style import MODEL, PAGE_WIDTH_IN, TRIAL, frequency_axis, new_figure, save, series_color, styled
from hysid_model.frf import amplitude_levels

if TYPE_CHECKING:
    from hysid.diagnose.selection import Diagnosis

START = "#999999"
"""The start model in loop plots (grey, dashed)."""


@styled
def gap_figure(path: Path, labels: Sequence[str], metrics: Sequence[GapMetrics]) -> Path:
    """Whitened RMS (and its cross-validated value) and the loop/energy errors after each step."""
    fig = new_figure(2.6)
    left, right = fig.subplots(1, 2)
    x = np.arange(len(metrics))
    left.semilogy(x, [m.whitened_rms for m in metrics], "o-", color=MODEL, label="fit")
    cv = [m.cv_whitened_rms for m in metrics]
    if all(c is not None for c in cv):
        left.semilogy(x, cv, "s--", color=TRIAL, label="leave-one-frequency-out")
    left.axhline(1.0, color="k", lw=0.8, ls=":", label="noise floor")
    left.set_ylabel("whitened residual RMS")
    left.legend()
    right.plot(x, [m.nrmse_pct for m in metrics], "o-", color=series_color(2), label="loop NRMSE")
    right.plot(x, [m.energy_error_pct for m in metrics], "s-", color=series_color(3), label="energy per cycle")
    right.set_ylabel("error (%)")
    right.set_ylim(bottom=0)
    right.legend()
    for ax in (left, right):
        ax.set_xticks(x, [label.split(": ")[-1] if i == 0 else label for i, label in enumerate(labels)], rotation=20, ha="right")
    return save(fig, path)


@styled
def residual_map_figure(path: Path, diagnosis: "Diagnosis") -> Path:
    """Per-loop whitened RMS over frequency x amplitude, start model vs final model, one colour scale."""
    h = diagnosis.harmonics
    before, after = loop_whitened_rms(diagnosis.start, h), loop_whitened_rms(diagnosis.final, h)
    norm = LogNorm(vmin=max(min(before.min(), after.min()), 0.1), vmax=max(before.max(), after.max(), 10.0))
    fig = new_figure(2.7)
    axes = fig.subplots(1, 2, sharex=True, sharey=True)
    for ax, values, title in ((axes[0], before, f"before: {diagnosis.start.spec}"), (axes[1], after, f"after: {diagnosis.final.spec}")):
        art = ax.scatter(h.loops.freq_hz, h.loops.x0 * 1e3, c=values, s=60, marker="s", cmap="viridis", norm=norm, edgecolors="none")
        ax.set_title(title, fontsize=7.5)
        ax.set_xlabel("frequency (Hz)")
        frequency_axis(ax, h.loops.freq_hz.min(), h.loops.freq_hz.max())
    axes[0].set_ylabel("amplitude X0 (mm)")
    fig.colorbar(art, ax=axes, label="whitened RMS per loop (1 = noise)")
    return save(fig, path)


def chosen_loops(diagnosis: "Diagnosis", per_level: int = 2) -> list[int]:
    """Per amplitude level, the loop the start model misses most and the one at the median frequency."""
    h = diagnosis.harmonics
    levels, index = amplitude_levels(h.loops.x0)
    worst = loop_whitened_rms(diagnosis.start, h)
    out: list[int] = []
    for level in range(levels.size):
        members = np.flatnonzero(index == level)
        picks = [members[np.argmax(worst[members])], members[np.argsort(h.loops.freq_hz[members])[members.size // 2]]]
        out += [int(p) for p in dict.fromkeys(picks)][:per_level]
    return out[:6]


@styled
def loops_figure(path: Path, diagnosis: "Diagnosis") -> Path:
    """Measured loops with the start and the final model's branches."""
    h = diagnosis.harmonics
    picks = chosen_loops(diagnosis)
    cols = min(3, len(picks))
    rows = -(-len(picks) // cols)
    fig = new_figure(2.1 * rows, PAGE_WIDTH_IN)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).reshape(-1)
    n = h.loops.n_samples
    start = diagnosis.start.objective.objective.predict(diagnosis.start.theta)[0]
    final = diagnosis.final.objective.objective.predict(diagnosis.final.theta)[0]
    for ax, j in zip(axes, picks):
        x = np.concatenate([h.loops.top[j, :, 0], h.loops.bottom[j, :, 0]]) * 1e3
        ax.plot(x, h.loops.forces()[j], ".", ms=2.0, color=TRIAL, label="measured")
        for force, color, style, label in ((start, START, "--", "start model"), (final, MODEL, "-", "final model")):
            ax.plot(x[:n], force[j, :n], style, color=color, lw=1.0, label=label)
            ax.plot(x[n:], force[j, n:], style, color=color, lw=1.0)
        ax.set_title(f"{h.loops.freq_hz[j]:.4g} Hz, X0 = {h.loops.x0[j] * 1e3:.3g} mm", fontsize=7.5)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("F (N)")
    for ax in axes[len(picks):]:
        ax.set_visible(False)
    axes[0].legend(loc="best")
    return save(fig, path)
