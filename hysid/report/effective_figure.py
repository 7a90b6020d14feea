"""The figure of the effective stiffness and equivalent damping at each amplitude and frequency (:mod:`hysid_model.effective`).

Two panels against the excitation frequency, one colour per amplitude level:
(a) k_eff = (F+ - F-) / (2 X0), (b) xi_eq = E_d / (4 pi E_s); the fitted
model's values with a band (or bars, at few frequencies) of one standard
error, and each loop's own as a test reads them off it: the forces at the
ends of its branches and its area (:func:`hysid_model.effective.loop_effective`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.lines import Line2D

from hysid.report.style import figure_legend, frequency_axis, new_figure, save, series_color, styled
from hysid_model.effective import OperatingPoint, loop_effective
from hysid_model.frf import amplitude_levels
from hysid_model.loops import LoopSet
from hysid_model.survey import Survey

FEW = 3
"""Up to this many frequencies per amplitude the model's values are drawn as points with error bars, not lines."""


@styled
def effective_figure(path: Path, loops: LoopSet, survey: Survey, points: Sequence[OperatingPoint]) -> Path:
    """(a) k_eff and (b) xi_eq per amplitude level against frequency: model (lines or points, one standard error) and loops (dots)."""
    levels, index = amplitude_levels(loops.x0)
    k_loop, xi_loop = loop_effective(loops, survey.energy_per_cycle)
    fig = new_figure(3.0)
    axes = fig.subplots(1, 2)
    for ax, q, own, label in (
        (axes[0], "k_eff", k_loop, "(a) effective stiffness $k_{eff}$ (N/m)"),
        (axes[1], "xi_eq", xi_loop, r"(b) equivalent damping ratio $\xi_{eq}$"),
    ):
        for k, level in enumerate(levels):
            color = series_color(k)
            at = [p for p in points if p.x0 == level]
            f = np.array([p.freq_hz for p in at])
            value = np.array([p.values[q] for p in at])
            se = np.nan_to_num(np.array([p.stderr[q] for p in at]))
            if f.size <= FEW:
                ax.errorbar(f, value, yerr=se, color=color, marker="s", markersize=3.5, linestyle="none", capsize=2.0)
            else:
                ax.plot(f, value, color=color, linewidth=1.0)
                ax.fill_between(f, value - se, value + se, color=color, alpha=0.25, linewidth=0)
            m = index == k
            ax.plot(loops.freq_hz[m], own[m], linestyle="none", marker="o", markersize=3.0, markerfacecolor="none", color=color)
        ax.set_title(label)
        ax.set_xlabel("excitation frequency (Hz)")
        frequency_axis(ax, loops.freq_hz)
    handles = [Line2D([], [], color=series_color(k), linewidth=1.0) for k in range(levels.size)]
    labels = [f"X0 = {a * 1e3:.3g} mm" for a in levels]
    handles += [Line2D([], [], color="0.4", marker="s", markersize=3.5), Line2D([], [], linestyle="none", marker="o", markerfacecolor="none", color="0.4")]
    labels += ["fitted model (+- one standard error)", "each loop's own"]
    figure_legend(fig, handles, labels, "outside upper center")
    return save(fig, path)
