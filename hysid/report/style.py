"""One figure style for every hysid report: sizes for a printed page, colour-blind-safe colours.

Figures are built on :class:`matplotlib.figure.Figure` directly (no pyplot, no
GUI backend, no global state) inside :func:`styled`, and saved as PNG at
:data:`DPI`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal, ParamSpec, TypeVar

import matplotlib as mpl
import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.ticker import FixedLocator, FormatStrFormatter, LogLocator, NullFormatter

DPI = 200
PAGE_WIDTH_IN = 7.0
"""Full text width of a two-column journal page."""

RC: dict[str, Any] = {
    "font.family": "DejaVu Sans",
    "font.size": 8.5,
    "axes.titlesize": 8.5,
    "axes.labelsize": 8.5,
    "legend.fontsize": 7.5,
    "xtick.labelsize": 7.5,
    "ytick.labelsize": 7.5,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.5,
    "axes.linewidth": 0.7,
    "lines.linewidth": 1.2,
    "lines.markersize": 4.0,
    "legend.frameon": False,
    "mathtext.fontset": "dejavusans",
    "savefig.dpi": DPI,
}
"""No ``savefig.bbox = "tight"``: constrained layout already fits the panels, titles and outside legends to the
figure, and a figure keeps the size it was made at (a page's width, :data:`PAGE_WIDTH_IN`)."""

TRIAL = "#0072B2"
"""Measured data: blue, as the thesis' loop plots (the thesis' 'trial')."""
MODEL = "#D55E00"
"""Model: vermilion."""
TRUE = "#CC0000"
"""True value (the thesis' red dotted line)."""
PEAK = "#CC79A7"
"""Resonance peak markers (magenta in Fig. 6.1)."""
HALF_POWER = "#56B4E9"
"""-3 dB markers (cyan in Fig. 6.1)."""
SERIES = ("#0072B2", "#D55E00", "#009E73", "#E69F00", "#CC79A7", "#56B4E9", "#F0E442", "#000000")
"""Okabe-Ito palette for amplitudes, runs and settings."""

MATH = {
    "xi0": r"$\xi_0$",
    "S_xi": r"$S_\xi$",
    "w0": r"$\omega_0$",
    "S_w": r"$S_\omega$",
    "meq": r"$M_{eq}$",
}
"""Parameter names as the thesis typesets them."""

P = ParamSpec("P")
R = TypeVar("R")


def series_color(i: int) -> str:
    return SERIES[i % len(SERIES)]


def math_name(name: str) -> str:
    return MATH.get(name, name.replace("_", r"\_"))


def styled(func: Callable[P, R]) -> Callable[P, R]:
    """Run a figure builder under :data:`RC` (rc parameters are read when artists are made and saved)."""

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with mpl.rc_context(RC):  # type: ignore[arg-type]  # matplotlib's stubs want literal rc keys; RC's are checked by matplotlib when set
            return func(*args, **kwargs)

    return wrapper


def frequency_ticks(freq_hz: np.ndarray, most: int = 8) -> list[float]:
    """Ticks of a log frequency axis that always mark the lowest and the highest frequency measured:
    every measured frequency when there are at most ``most``, else 1-2-5 steps between the two ends."""
    measured = np.unique(np.round(freq_hz, 6))
    if measured.size <= most:
        return measured.tolist()
    low, high = measured[0], measured[-1]
    inner = [t for t in LogLocator(subs=(1.0, 2.0, 5.0)).tick_values(low, high) if low * 1.3 < t < high / 1.3]
    return [float(low), *inner, float(high)]


def frequency_axis(ax: Axes, freq_hz: np.ndarray) -> None:
    """A frequency axis: logarithmic, ticked at :func:`frequency_ticks`, when the band spans more than a factor 4."""
    if freq_hz.max() > 4 * freq_hz.min():
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(FixedLocator(frequency_ticks(freq_hz)))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%.3g"))
        ax.xaxis.set_minor_formatter(NullFormatter())


def new_figure(height_in: float, width_in: float = PAGE_WIDTH_IN) -> Figure:
    """A figure of ``width_in`` x ``height_in`` inches at :data:`DPI`, the resolution it is saved at: text is
    measured for the layout (and :func:`figure_legend`) as it will be drawn, not at another resolution's hinting."""
    return Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")


LEGEND_SHARE = 0.98
"""The most of the figure's width a figure legend's row may take (constrained layout's pads stay clear)."""


def figure_legend(fig: Figure, handles: Sequence[Artist], labels: Sequence[str], loc: Literal["outside upper center", "outside lower center"]) -> Legend:
    """The figure's legend (``loc``: one of constrained layout's ``"outside ..."`` places) in as few rows as fit the
    figure's width: every entry on one row where they fit, else the fewest rows of balanced length."""
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)  # Agg: the PNG writer's
    renderer = canvas.get_renderer()
    n = len(labels)
    for rows in range(1, n + 1):
        legend = fig.legend(handles, labels, loc=loc, ncol=math.ceil(n / rows))
        if rows == n or legend.get_window_extent(renderer).width <= LEGEND_SHARE * fig.bbox.width:
            return legend
        legend.remove()
    raise ValueError("a legend needs at least one entry")


def save(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, format="png")
    return path
