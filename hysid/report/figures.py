"""The report figures, after the thesis' Figs. 5.2-5.13 and 6.1.

* :func:`convergence_figure`: best fitness vs iteration, semilog, all runs
  overlaid, one panel per algorithm with matching scales (Figs. 5.6-5.9);
* :func:`loops_figure`: measured vs model loops, rows = amplitudes, columns = a
  few frequencies across the band, the subset named (Figs. 5.10-5.13);
* :func:`residuals_figure`: per-loop RMS residual vs frequency and residual vs
  phase (structure there means physics the model is missing);
* :func:`half_power_figure`: compliance FRF per amplitude with the half-power
  points of Eq. 2.7 (Figs. 2.8, 6.1), measured and model;
* :func:`scatter_figure`: a parameter's results per noise level with its true
  value dashed (Figs. 5.2-5.5);
* :func:`survey_figure`: the equivalent-linear survey of the loops against
  frequency per amplitude (Figs. 4.6-4.8).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.artist import Artist
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FormatStrFormatter, LogLocator, MaxNLocator, NullFormatter

from hysid.report.style import (
    HALF_POWER,
    MODEL,
    PAGE_WIDTH_IN,
    PEAK,
    TRIAL,
    TRUE,
    figure_legend,
    frequency_axis,
    frequency_ticks,
    math_name,
    new_figure,
    save,
    series_color,
    styled,
)
from hysid.report.text import hz_text
from hysid_model.frf import HalfPower, amplitude_levels
from hysid_model.loops import LoopSet
from hysid_model.survey import Survey
from island.run import RunResult

MAX_LOOP_ROWS = 5
LONG_RUN = 40
"""Iterations beyond which the convergence figure puts the iterations on a log scale and draws step lines."""


def _mm(x0: float) -> str:
    return f"{x0 * 1e3:.3g} mm"


@styled
def convergence_figure(path: Path, panels: Sequence[tuple[str, Sequence[RunResult]]], ylabel: str, title: str = "") -> Path:
    """Best fitness per iteration of every run (iteration 0 = initial population), log scale.

    Runs without a history (e.g. a campaign's global best) are left out. A
    star after the last iteration marks the fitness after the least-squares
    polish; when that is far below the search (noiseless data) the axis keeps
    the search readable and the star sits on the bottom edge, labelled with its value.
    """
    n = len(panels)
    fig = new_figure(2.7, PAGE_WIDTH_IN if n > 1 else 4.6)
    axes = fig.subplots(1, n, sharey=True, squeeze=False)[0]
    searched = [h["best_fitness"] for _, runs in panels for r in runs for h in r.history if 0 < h["best_fitness"] < np.inf]
    polished = [r.fitness for _, runs in panels for r in runs if r.polish is not None and 0 < r.fitness < r.search_fitness]
    floor = None
    if searched:
        lowest = min(searched)
        if polished and min(polished) < lowest / 1e3:
            floor = lowest / 10.0  # polish far below the search: keep the search readable, clip the stars
        else:
            floor = min([lowest] + polished) / 1.5
    longest = max((len(r.history) for _, runs in panels for r in runs), default=0)
    many = longest > LONG_RUN
    for ax, (label, runs) in zip(axes, panels):
        last = 0
        clipped = []
        for i, r in enumerate(r for r in runs if r.history):
            it = np.array([h["iteration"] for h in r.history], dtype=float)
            f = np.array([h["best_fitness"] for h in r.history], dtype=float)
            color = series_color(i)
            ax.plot(it + many, f, marker="none" if many else "o", markersize=2.5, color=color, label=r.label, drawstyle="steps-post" if many else "default")
            last = max(last, int(it[-1]))
            if r.polish is not None and 0 < r.fitness < r.search_fitness:
                shown = max(r.fitness, floor * 1.05) if floor else r.fitness
                end = it[-1] + many
                ax.plot([end, end * 1.15 if many else end + 1], [f[-1], shown], linestyle=":", color=color)
                ax.plot(end * 1.15 if many else end + 1, shown, marker="*", markersize=8, color=color, linestyle="none", clip_on=False)
                if shown > r.fitness:
                    clipped.append(r.fitness)
        if clipped and floor:  # clipped only below a floor
            low, high = f"{min(clipped):.2g}", f"{max(clipped):.2g}"
            ax.annotate(
                f"polish: {low}" + (f" to {high}" if high != low else "") + "\n(below the axis)",
                xy=((last + 1) * 1.15 if many else last + 1, floor * 1.05),
                xytext=(-6, 10),
                textcoords="offset points",
                ha="right",
                va="bottom",
                fontsize=7,
            )
        ax.set_yscale("log")
        if floor:
            ax.set_ylim(bottom=floor)
        if many:  # hundreds of iterations: the early descent spread out, each island a step line
            ax.set_xscale("log")
            ax.set_xlabel("iteration + 1 (log scale)")
            ax.set_xlim(0.9, (last + 1) * 1.3)
        else:
            ax.set_xlabel("iteration")
            ax.set_xlim(-0.5, last + 1.5)
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        if label:
            ax.set_title(label)
        handles, labels = ax.get_legend_handles_labels()
        if polished:
            handles.append(Line2D([], [], marker="*", markersize=8, color="0.3", linestyle="none"))
            labels.append("after polish")
        ax.legend(handles, labels, loc="best", ncol=1 if len(labels) <= 5 else 2)
    axes[0].set_ylabel(ylabel)
    if title:
        fig.suptitle(title)
    return save(fig, path)


def _closed(top: np.ndarray, bottom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A loop as one closed curve: loading branch, then the unloading branch backwards."""
    x = np.concatenate([top[:, 0], bottom[::-1, 0], top[:1, 0]])
    f = np.concatenate([top[:, 1], bottom[::-1, 1], top[:1, 1]])
    return x, f


@styled
def loops_figure(path: Path, loops: LoopSet, predicted: np.ndarray, columns: int = 4, title: str = "") -> Path:
    """Measured (dots) and model (line) loops: one row per amplitude, ``columns`` frequencies across the band."""
    return save(draw_loops(loops, predicted, columns, title), path)


def draw_loops(loops: LoopSet, predicted: np.ndarray, columns: int = 4, title: str = "") -> Figure:
    """The figure of :func:`loops_figure` (drawn under its style); the legend sits below the panels, clear of the title,
    and says which of the loops are shown when not all are."""
    levels, index = amplitude_levels(loops.x0)
    rows = np.unique(np.round(np.linspace(0, levels.size - 1, min(levels.size, MAX_LOOP_ROWS))).astype(int))
    shown = 0
    n = loops.n_samples
    fig = new_figure(1.55 * rows.size + 0.45)
    axes = fig.subplots(rows.size, columns, squeeze=False)
    for r, k in enumerate(rows):
        members = np.flatnonzero(index == k)
        members = members[np.argsort(loops.freq_hz[members], kind="stable")]
        picks = members[np.unique(np.round(np.linspace(0, members.size - 1, min(columns, members.size))).astype(int))]
        shown += picks.size
        for c in range(columns):
            ax = axes[r, c]
            if c >= picks.size:
                ax.set_visible(False)
                continue
            j = picks[c]
            model_top = np.column_stack([loops.top[j, :, 0], predicted[j, :n]])
            model_bottom = np.column_stack([loops.bottom[j, :, 0], predicted[j, n:]])
            xt, ft = _closed(loops.top[j], loops.bottom[j])
            xm, fm = _closed(model_top, model_bottom)
            ax.plot(xt * 1e3, ft, linestyle="none", marker=".", markersize=2.0, color=TRIAL)
            ax.plot(xm * 1e3, fm, color=MODEL, linewidth=1.1)
            ax.set_title(hz_text(loops.freq_hz[j]), pad=2)
            if r == rows.size - 1:
                ax.set_xlabel("displacement (mm)")
        axes[r, 0].set_ylabel(f"$X_0$ = {_mm(levels[k])}\nforce (N)")
    handles = [
        Line2D([], [], linestyle="none", marker=".", markersize=6, color=TRIAL),
        Line2D([], [], color=MODEL),
    ]
    labels = ["measured", "model"]
    if shown < loops.n_loops:
        labels[0] = f"measured ({shown} of {loops.n_loops} loops shown: {rows.size} of {levels.size} amplitudes, frequencies across the band)"
    fig.legend(handles, labels, loc="outside lower center", ncol=2)
    if title:
        fig.suptitle(title)
    return fig


def _level_handles(levels: np.ndarray) -> tuple[list[Line2D], list[str]]:
    handles = [Line2D([], [], color=series_color(k), marker="o", markersize=3.5) for k in range(levels.size)]
    return handles, [f"$X_0$ = {_mm(level)}" for level in levels]


@styled
def residuals_figure(path: Path, loops: LoopSet, residuals: np.ndarray, force_amplitude: np.ndarray) -> Path:
    """(a) RMS residual of each loop vs frequency; (b) mean residual vs phase per amplitude (+- 2 standard errors).

    Residuals are in % of each loop's force amplitude |F1|, so loops near and
    far from resonance compare; the known noise sigma is drawn on the same scale.
    """
    levels, index = amplitude_levels(loops.x0)
    rel = residuals / force_amplitude[:, None] * 100.0
    rms = np.sqrt(np.mean(rel**2, axis=1))
    fig = new_figure(2.9)
    ax1, ax2 = fig.subplots(1, 2)
    for k in range(levels.size):
        m = np.flatnonzero(index == k)
        m = m[np.argsort(loops.freq_hz[m], kind="stable")]
        ax1.plot(loops.freq_hz[m], rms[m], marker="o", markersize=2.5, color=series_color(k))
    extra_h, extra_l = [], []
    if loops.has_sigma:
        ax1.plot(loops.freq_hz, loops.sigma / force_amplitude * 100.0, linestyle="none", marker="_", markersize=7, color="0.3")
        extra_h.append(Line2D([], [], linestyle="none", marker="_", markersize=7, color="0.3"))
        extra_l.append(r"noise $\sigma$ (known)")
    positive = rms[rms > 0]
    if positive.size and positive.max() > 10.0 * positive.min():
        ax1.set_yscale("log")
    ax1.set_xlabel("excitation frequency (Hz)")
    ax1.set_ylabel(r"RMS residual (% of $|F_1|$)")
    ax1.set_title("(a) residual of each loop")

    deg = np.degrees(loops.phases())
    deg = np.where(deg >= 270.0, deg - 360.0, deg)
    ax2.axvspan(90.0, 270.0, color="0.93", zorder=0, linewidth=0)
    bins = np.linspace(-90.0, 270.0, 37)
    centres = 0.5 * (bins[1:] + bins[:-1])
    for k in range(levels.size):
        m = index == k
        x, y = deg[m].ravel(), rel[m].ravel()
        which = np.clip(np.digitize(x, bins) - 1, 0, centres.size - 1)
        counts = np.bincount(which, minlength=centres.size)
        has = counts > 1
        mean = np.bincount(which, weights=y, minlength=centres.size)[has] / counts[has]
        var = np.bincount(which, weights=y**2, minlength=centres.size)[has] / counts[has] - mean**2
        se = np.sqrt(np.clip(var, 0.0, None) / (counts[has] - 1))
        ax2.fill_between(centres[has], mean - 2 * se, mean + 2 * se, color=series_color(k), alpha=0.2, linewidth=0)
        ax2.plot(centres[has], mean, color=series_color(k), linewidth=1.2)
    ax2.axhline(0.0, color="0.2", linewidth=0.6)
    ax2.set_xlim(-90.0, 270.0)
    ax2.set_xticks([-90, 0, 90, 180, 270])
    ax2.set_xlabel(r"phase $\omega t$ (deg); shaded: unloading branch")
    ax2.set_ylabel(r"mean residual (% of $|F_1|$)")
    ax2.set_title(r"(b) mean residual vs phase ($\pm 2$ s.e.)")
    handles, labels = _level_handles(levels)
    figure_legend(fig, handles + extra_h, labels + extra_l, "outside upper center")
    return save(fig, path)


@styled
def half_power_figure(
    path: Path,
    loops: LoopSet,
    comp: np.ndarray,
    half_power: Sequence[HalfPower],
    xi_fit: Sequence[float],
    model_curves: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
) -> Path:
    """Compliance |X0/F1| per amplitude (Fig. 6.1): (a) the whole sweep; (b) the resonance with the -3 dB points
    (only (a), saying why, where no amplitude has a half-power estimate).

    ``model_curves`` holds (frequency Hz, compliance m/N) of the fitted model at each level.
    """
    levels, index = amplitude_levels(loops.x0)
    ok = [hp for hp in half_power if hp.ok]
    fig = new_figure(3.3)
    axes = list(fig.subplots(1, 2)) if ok else [fig.subplots(1, 1)]
    for ax in axes:
        for k in range(levels.size):
            m = np.flatnonzero(index == k)
            m = m[np.argsort(loops.freq_hz[m], kind="stable")]
            color = series_color(k)
            ax.plot(loops.freq_hz[m], comp[m] * 1e3, linestyle="none", marker="o", markersize=3.0, color=color)
            if model_curves is not None:
                f, h = model_curves[k]
                ax.plot(f, h * 1e3, color=color, linewidth=1.0)
        ax.set_yscale("log")
        ax.set_xlabel("excitation frequency (Hz)")
        ax.set_ylabel("compliance $|X_0/F_1|$ (mm/N)")
    handles, labels = _level_handles(levels)
    handles += [Line2D([], [], linestyle="none", marker="o", markersize=3.5, color="0.4"), Line2D([], [], color="0.4")]
    labels += ["loops", "fitted model"]
    if not ok:
        axes[0].set_title("compliance over the sweep: no resonance peak with $-3$ dB points on both sides (no Eq. 2.7 estimate)")
        figure_legend(fig, handles, labels, "outside upper center")
        return save(fig, path)
    ax1, ax2 = axes
    width = max(hp.f2_hz - hp.f1_hz for hp in ok)
    lo, hi = min(hp.f1_hz for hp in ok) - 2.5 * width, max(hp.f2_hz for hp in ok) + 2.5 * width
    ax1.set_title("(a) compliance over the sweep")
    for k, hp in enumerate(half_power):
        if not hp.ok:
            continue
        color = series_color(k)
        level = hp.peak_compliance * 1e3 / np.sqrt(2.0)
        ax2.plot([hp.f1_hz, hp.f2_hz], [level, level], color=color, linestyle="--", linewidth=0.9)
        ax2.plot([hp.f1_hz, hp.f2_hz], [level, level], linestyle="none", marker="D", markersize=4.5, color=HALF_POWER, markeredgecolor=color)
        ax2.plot([hp.f_peak_hz], [hp.peak_compliance * 1e3], linestyle="none", marker="v", markersize=6, color=PEAK, markeredgecolor=color)
    ax2.set_xlim(lo, hi)
    in_view = (loops.freq_hz >= lo) & (loops.freq_hz <= hi) & np.isfinite(comp) & (comp > 0)  # a log axis' limits
    if np.any(in_view):
        top = max([hp.peak_compliance for hp in ok] + [float(comp[in_view].max())]) * 1e3
        ax2.set_ylim(float(comp[in_view].min()) * 1e3 / 1.3, top * 1.3)
    ax2.set_title(r"(b) resonance: peak and $-3$ dB points, Eq. 2.7")
    xi_rows = [
        (Line2D([], [], color=series_color(k), marker="s", markersize=4, linestyle="none"), rf"$\xi_{{2.7}}$ = {hp.xi:.5f}, fit {xi_fit[k]:.5f}")
        for k, hp in enumerate(half_power)
        if hp.ok
    ]
    ax2.legend([h for h, _ in xi_rows], [t for _, t in xi_rows], loc="lower center", title="damping ratio at each $X_0$")
    handles += [
        Line2D([], [], linestyle="none", marker="v", markersize=6, color=PEAK),
        Line2D([], [], linestyle="none", marker="D", markersize=4.5, color=HALF_POWER),
    ]
    labels += ["resonance peak", "$-3$ dB points"]
    figure_legend(fig, handles, labels, "outside upper center")
    return save(fig, path)


@styled
def scatter_figure(
    path: Path,
    name: str,
    unit: str,
    true_value: float,
    panels: Sequence[tuple[str, Sequence[tuple[str, dict[int, np.ndarray]]]]],
    cramer_rao: dict[int, float] | None = None,
) -> Path:
    """One parameter's results per noise level (Figs. 5.2-5.5): runs (hollow), mean (filled), range (line).

    Each panel (one per algorithm) holds several series (e.g. published,
    thesis-faithful, hysid defaults) side by side at each noise level; the true
    value is the red dashed line, the grey band true +- the Cramer-Rao bound.
    """
    fig = new_figure(2.9)
    axes = fig.subplots(1, len(panels), sharey=True, squeeze=False)[0]
    noise = sorted({lvl for _, series in panels for _, by_noise in series for lvl in by_noise})
    for ax, (title, series) in zip(axes, panels):
        width = 0.8 / max(len(series), 1)
        if cramer_rao:
            for i, lvl in enumerate(noise):
                bound = cramer_rao.get(lvl, 0.0)
                if bound > 0:
                    ax.fill_between([i - 0.45, i + 0.45], true_value - bound, true_value + bound, color="0.85", linewidth=0)
        ax.axhline(true_value, color=TRUE, linestyle="--", linewidth=1.0)
        for s, (_label, by_noise) in enumerate(series):
            color = series_color(s)
            for i, lvl in enumerate(noise):
                values = np.asarray(by_noise.get(lvl, []), dtype=float)
                if values.size == 0:
                    continue
                x = i + (s - (len(series) - 1) / 2.0) * width
                ax.plot([x, x], [values.min(), values.max()], color=color, linewidth=1.0)
                ax.plot(np.full(values.size, x), values, linestyle="none", marker="o", markersize=3.5, markerfacecolor="none", color=color)
                ax.plot([x], [values.mean()], linestyle="none", marker="o", markersize=5.5, color=color)
        ax.set_xticks(range(len(noise)), [f"{lvl} %" for lvl in noise])
        ax.set_xlim(-0.55, len(noise) - 0.45)
        ax.set_xlabel("noise level")
        ax.set_title(title)
    axes[0].set_ylabel(f"{math_name(name)} ({unit})" if unit and unit != "1" else math_name(name))
    handles: list[Artist] = [Line2D([], [], color=series_color(s), marker="o", markersize=5) for s in range(len(panels[0][1]))]
    labels = [label for label, _ in panels[0][1]]
    handles.append(Line2D([], [], color=TRUE, linestyle="--"))
    labels.append("true value")
    if cramer_rao and any(v > 0 for v in cramer_rao.values()):
        handles.append(Patch(color="0.85"))
        labels.append("true $\\pm$ Cramer-Rao bound")
    figure_legend(fig, handles, labels, "outside lower center")
    return save(fig, path)


@styled
def survey_figure(path: Path, survey: Survey) -> Path:
    """The equivalent-linear survey (Figs. 4.6-4.8): per amplitude level, against frequency, (a) the dynamic
    and storage stiffness, (b) the equivalent viscous damping, (c) the loss factor and (d) the damping ratio
    (or, without a mass, the energy dissipated per cycle); against amplitude, each loop coloured by its
    frequency, (e) the dynamic and secant stiffness and (f) the energy per cycle (a linear specimen: slope 2
    on these log axes; friction: slope 1)."""
    loops = survey.loops
    levels, index = amplitude_levels(loops.x0)
    fig = new_figure(7.0)
    (ax_k, ax_c), (ax_eta, ax_last), (ax_ka, ax_ea) = fig.subplots(3, 2)
    last, last_label = (survey.xi, r"damping ratio $\xi$") if survey.has_mass else (survey.energy_per_cycle, "energy per cycle (J)")
    for k in range(levels.size):
        m = np.flatnonzero(index == k)
        m = m[np.argsort(loops.freq_hz[m], kind="stable")]
        color, f = series_color(k), loops.freq_hz[m]
        ax_k.plot(f, survey.k_dyn[m], marker="o", markersize=3, color=color)
        if survey.has_mass:
            ax_k.plot(f, survey.k_storage[m], marker="s", markersize=3, color=color, linestyle="--", markerfacecolor="none")
        ax_c.plot(f, survey.c_eq[m], marker="o", markersize=3, color=color)
        ax_eta.plot(f, survey.loss_factor[m], marker="o", markersize=3, color=color)
        ax_last.plot(f, last[m], marker="o", markersize=3, color=color)
    ax_k.axhline(0.0, color="0.3", linewidth=0.6)
    ax_k.set_ylabel("stiffness (N/m)")
    ax_k.set_title("(a) dynamic Re($F_1/X_1$)" + (", storage + $m\\omega^2$ (dashed)" if survey.has_mass else ""))
    ax_c.set_ylabel("$c_{eq}$ (N s/m)")
    ax_c.set_title("(b) equivalent viscous damping")
    ax_eta.set_ylabel(r"loss factor $\eta$")
    ax_eta.set_title("(c) loss factor")
    ax_last.set_ylabel(last_label)
    ax_last.set_title("(d) " + ("damping ratio per loop" if survey.has_mass else f"energy per cycle (mass {survey.mass_source.split(':')[0]})"))
    for ax in (ax_k, ax_c, ax_eta, ax_last):
        ax.set_xlabel("excitation frequency (Hz)")
        frequency_axis(ax, loops.freq_hz)
    x_mm = loops.x0 * 1e3
    norm = LogNorm(loops.freq_hz.min(), loops.freq_hz.max()) if loops.freq_hz.max() > loops.freq_hz.min() else None
    dots = ax_ka.scatter(x_mm, survey.k_dyn, c=loops.freq_hz, norm=norm, cmap="viridis", s=14, label="dynamic")
    squares = ax_ka.scatter(x_mm, survey.k_secant, c=loops.freq_hz, norm=norm, cmap="viridis", s=16, marker="s")
    squares.set_edgecolors(squares.to_rgba(loops.freq_hz))
    squares.set_facecolors("none")
    ax_ka.set_ylabel("stiffness (N/m)")
    ax_ka.set_title("(e) dynamic (dots), secant (squares) vs amplitude")
    energy = np.where(survey.energy_per_cycle > 0, survey.energy_per_cycle, np.nan)
    ax_ea.scatter(x_mm, energy, c=loops.freq_hz, norm=norm, cmap="viridis", s=14)
    ax_ea.set_ylabel("energy per cycle (J)")
    ax_ea.set_title("(f) energy dissipated per cycle vs amplitude")
    if np.any(np.isfinite(energy)):
        ax_ea.set_xscale("log")
        ax_ea.set_yscale("log")
        ax_ea.xaxis.set_major_formatter(FormatStrFormatter("%.3g"))
        ax_ea.xaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))  # labelled minor ticks that never collide ("0.60.7")
        ax_ea.xaxis.set_minor_formatter(FormatStrFormatter("%.3g"))
    for ax in (ax_ka, ax_ea):
        ax.set_xlabel("amplitude $X_0$ (mm)")
    bar = fig.colorbar(dots, ax=[ax_ka, ax_ea], label="frequency (Hz)", shrink=0.9)
    bar.set_ticks(frequency_ticks(loops.freq_hz))
    bar.ax.yaxis.set_major_formatter(FormatStrFormatter("%.3g"))
    bar.ax.yaxis.set_minor_formatter(NullFormatter())
    handles, labels = _level_handles(levels)
    figure_legend(fig, handles, labels, "outside upper center")
    return save(fig, path)
