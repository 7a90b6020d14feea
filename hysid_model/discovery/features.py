"""The candidate library of discovery: families of force shapes of the loops' state, on grids scaled by the data.

A family is a force shape phi(x, v; shape) of the displacement x (m) and the velocity v (m/s), written once as
a numpy expression; a term made of it is ``c * phi`` with c in N. Displacement and velocity enter divided by
reference scales read off the loops (:func:`scales`: the largest amplitude X and the largest velocity amplitude
V, rounded to two digits), so that every coefficient is a force and the formula reads as a law:
``c * np.abs(v / 0.13) ** a * np.sign(v)`` is c (|v| / V)^a sgn(v). The families cover what a missing force
of a vibrating device is made of: powers of |x| and |v| with their signs (odd) or without (even, a
loop that is not point-symmetric), products of x and v (x^2 v, x |v|, ...), one-sided, dead-zone and saturating
springs and a velocity dead zone on a grid of thresholds scaled by the amplitude, saturating or decaying
velocity laws (tanh, 1 - exp, a Gaussian hump) on a grid of velocity scales, and a friction whose normal load
grows with the displacement, |x|^a sgn v and its smooth sign |x|^a tanh(v / u) (wedge dampers, ring and
friction springs, a preloaded joint's load beyond its preload beside a Coulomb term: a = 1; a joint's
micro-slip, a = 2). A shape parameter's grid is
where the sparse selection looks (:mod:`.frols`); its bounds are where the refinement and the whole
model's refit may take it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from types import CodeType

import numpy as np

EXPONENTS = (0.1, 0.2, 0.35, 0.5, 0.75, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0)
"""Exponents the selection tries (1 is a spring's or a dashpot's, which the model has)."""
EXPONENT_BOUNDS = (0.02, 8.0)
THRESHOLDS = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
"""Thresholds the selection tries, as fractions of the reference amplitude X (of V for a velocity's)."""
LOAD_EXPONENTS = tuple(sorted(EXPONENTS + (1.0,)))
"""Exponents of a friction whose normal load grows with the displacement, |x|^a sgn v (1 is a wedge's, no spring's)."""
SMOOTH_LOAD_EXPONENTS = (0.5, 1.0, 2.0, 3.0)
"""The same for its smooth-sign variant (with a velocity scale each: a coarser grid, the refinement takes it on)."""
VELOCITY_SCALES = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0)
"""Velocity scales of the saturating and decaying laws the selection tries, as fractions of V (from 0.02 on,
the displacement scales of a saturating spring, as fractions of X)."""


@dataclass(frozen=True)
class Shape:
    """A shape parameter of a family: its symbol in the expression, its unit, its bounds and grid in SI units."""

    symbol: str
    unit: str
    bounds: tuple[float, float]
    grid: tuple[float, ...]
    words: str


@dataclass(frozen=True)
class Family:
    """A force shape phi(x, v; shape): ``expression`` and ``notation`` are templates whose fields are the
    shape symbols (see :meth:`render`)."""

    key: str
    expression: str
    """numpy expression in x and v; ``{a}``-style fields for the shape parameters."""
    notation: str
    """The same in plain notation."""
    shapes: tuple[Shape, ...]

    def render(self, values: dict[str, str], plain: bool = False) -> str:
        """The expression (``plain``: the notation) with every shape symbol replaced by ``values[symbol]`` (a
        name or a number, as text)."""
        return (self.notation if plain else self.expression).format(**{s.symbol: values[s.symbol] for s in self.shapes})

    def grid(self) -> list[dict[str, float]]:
        """Every combination of the shape parameters' grids (one empty shape for a family without any)."""
        combos: list[dict[str, float]] = [{}]
        for s in self.shapes:
            combos = [{**c, s.symbol: float(g)} for c in combos for g in s.grid]
        return combos

    def evaluate(self, x: np.ndarray, v: np.ndarray, shape: dict[str, float]) -> np.ndarray:
        """phi at ``x``, ``v`` (any broadcastable shapes) for one ``shape``."""
        code = compiled(self.render({s.symbol: s.symbol for s in self.shapes}))
        with np.errstate(all="ignore"):
            return np.asarray(eval(code, {"np": np}, {"x": x, "v": v, **shape}), dtype=float)


@lru_cache(maxsize=256)
def compiled(expression: str) -> CodeType:
    """``expression`` compiled once (the refinement evaluates a family many times)."""
    return compile(expression, "<candidate force>", "eval")


def rounded(value: float) -> float:
    """``value`` to two significant digits (a reference scale that reads well in a formula)."""
    return float(f"{value:.2g}")


def scales(x0: np.ndarray, omega: np.ndarray) -> tuple[float, float]:
    """The reference displacement X (m) and velocity V (m/s): the largest amplitude and velocity amplitude of
    the loops, to two digits."""
    return rounded(float(np.max(x0))), rounded(float(np.max(x0 * omega)))


def _exponent(symbol: str = "a") -> Shape:
    return Shape(symbol, "1", EXPONENT_BOUNDS, EXPONENTS, "exponent")


def library(x_ref: float, v_ref: float) -> list[Family]:
    """The candidate families for loops of reference amplitude ``x_ref`` (m) and velocity ``v_ref`` (m/s)."""
    X, V = repr(x_ref), repr(v_ref)
    offset = Shape("g", "m", (-x_ref, x_ref), tuple(x_ref * f for f in (-0.8, -0.6, -0.4, -0.2, 0.0, 0.2, 0.4, 0.6, 0.8)), "offset")
    gap = Shape("g", "m", (0.0, x_ref), tuple(x_ref * f for f in THRESHOLDS), "threshold")
    v_gap = Shape("u", "m/s", (0.0, v_ref), tuple(v_ref * f for f in THRESHOLDS), "velocity threshold")
    x_scale = Shape("g", "m", (1e-3 * x_ref, 10.0 * x_ref), tuple(x_ref * f for f in VELOCITY_SCALES[2:]), "displacement scale")
    v_scale = Shape("u", "m/s", (1e-4 * v_ref, 10.0 * v_ref), tuple(v_ref * f for f in VELOCITY_SCALES), "velocity scale")
    load = Shape("a", "1", EXPONENT_BOUNDS, LOAD_EXPONENTS, "exponent")
    smooth_load = Shape("a", "1", EXPONENT_BOUNDS, SMOOTH_LOAD_EXPONENTS, "exponent")
    families = [
        Family("velocity_sign", "np.sign(v)", "sgn(v)", ()),
        Family("velocity_power", f"np.abs(v / {V}) ** {{a}} * np.sign(v)", f"(|v| / {V} m/s)^{{a}} sgn(v)", (_exponent(),)),
        Family("velocity_power_even", f"np.abs(v / {V}) ** {{a}}", f"(|v| / {V} m/s)^{{a}}", (_exponent(),)),
        Family("displacement_power", f"np.abs(x / {X}) ** {{a}} * np.sign(x)", f"(|x| / {X} m)^{{a}} sgn(x)", (_exponent(),)),
        Family("displacement_power_even", f"np.abs(x / {X}) ** {{a}}", f"(|x| / {X} m)^{{a}}", (_exponent(),)),
        Family("x2_v", f"(x / {X}) ** 2 * (v / {V})", f"(x / {X} m)^2 (v / {V} m/s)", ()),
        Family("x_absv", f"(x / {X}) * np.abs(v / {V})", f"(x / {X} m) |v / {V} m/s|", ()),
        Family("absx_v", f"np.abs(x / {X}) * (v / {V})", f"|x / {X} m| (v / {V} m/s)", ()),
        Family("x_v", f"(x / {X}) * (v / {V})", f"(x / {X} m) (v / {V} m/s)", ()),
        Family("x_v2", f"(x / {X}) * (v / {V}) ** 2", f"(x / {X} m) (v / {V} m/s)^2", ()),
        Family("dead_zone", f"np.maximum(np.abs(x) - {{g}}, 0.0) * np.sign(x) / {X}", f"(|x| - {{g}} m)+ sgn(x) / {X} m", (gap,)),
        Family("one_sided", f"np.maximum(x - {{g}}, 0.0) / {X}", f"(x - {{g}} m)+ / {X} m", (offset,)),
        Family("tanh_displacement", "np.tanh(x / {g})", "tanh(x / {g} m)", (x_scale,)),
        Family("velocity_dead_zone", f"np.maximum(np.abs(v) - {{u}}, 0.0) * np.sign(v) / {V}", f"(|v| - {{u}} m/s)+ sgn(v) / {V} m/s", (v_gap,)),
        Family("tanh_velocity", "np.tanh(v / {u})", "tanh(v / {u} m/s)", (v_scale,)),
        Family("exp_saturation", "-np.expm1(-np.abs(v) / {u}) * np.sign(v)", "(1 - exp(-|v| / {u} m/s)) sgn(v)", (v_scale,)),
        Family("gaussian_velocity", "np.exp(-(v / {u}) ** 2) * np.sign(v)", "exp(-(v / {u} m/s)^2) sgn(v)", (v_scale,)),
        Family("load_friction", f"np.abs(x / {X}) ** {{a}} * np.sign(v)", f"(|x| / {X} m)^{{a}} sgn(v)", (load,)),
        Family("smooth_load_friction", f"np.abs(x / {X}) ** {{a}} * np.tanh(v / {{u}})", f"(|x| / {X} m)^{{a}} tanh(v / {{u}} m/s)", (smooth_load, v_scale)),
    ]
    return families


def columns(
    families: list[Family], x: np.ndarray, v: np.ndarray, grid_x: np.ndarray, grid_v: np.ndarray
) -> tuple[list[tuple[int, dict[str, float]]], np.ndarray]:
    """Every family at every shape of its grid, as a force at the samples ``x``, ``v`` ``(L, N)`` less its cycle
    mean over the uniform phases ``grid_x``, ``grid_v`` (as a term's force enters a model): the index of
    ``(family, shape)`` of each column, and the columns ``(K, L, N)``."""
    index, out = [], []
    for i, family in enumerate(families):
        for shape in family.grid():
            f = family.evaluate(x, v, shape) - family.evaluate(grid_x, grid_v, shape).mean(axis=-1, keepdims=True)
            if np.all(np.isfinite(f)):
                index.append((i, shape))
                out.append(f)
    return index, np.array(out)
