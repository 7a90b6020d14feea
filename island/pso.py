"""The thesis' PSO (section 3.2, Figs. 3.11/3.12, PSO program of Appendix A) as an ask/tell optimizer.

Iteration 0 draws ``initial_population`` positions uniformly in the bounds
(Eq. 3.2), evaluates them and keeps the best ``population`` (the swarm) as the particles, with
P = x, zero velocity and Pg the best P. Each iteration moves every particle
with Clerc's constriction (Eq. 3.8, 3.9),

    v = K (v + phi1 r1 (P_i - x) + phi2 r2 (P_g - x)),   x' = x + v,

r1, r2 uniform per dimension. A coordinate whose move would leave the open
bounds stays where it is and its velocity is set to zero (section 5.1). Then
the additional population around Pg (Table 5.1, Eq. 5.1) is evaluated and Pg
updated from it.

* asynchronous (default, Fig. 3.12): particles move one at a time, each with
  the Pg updated by the particles before it in the same iteration, so ``ask``
  returns one particle; the thesis budget is 6000 + 18 x (500 + 15) = 15270;
* ``synchronous=True`` (Fig. 3.11): the whole swarm moves per ``ask`` with the
  Pg of the previous iteration;
* ``neighbourhood="ring"``: P_g of particle i is the best P of itself and its left
  and right neighbours (wrap-around, Fig. 3.10a). The thesis only ran the
  global neighbourhood; with a ring, a better additional candidate becomes the
  personal best of the best particle, so that it reaches the swarm.

Reconstructed from the text (lines missing from the listing's extraction): the
main-loop start (sort the evaluated initial swarm, keep the best ``rempop``,
Pi = positions, Pif = fitness, Pg = best Pi, ``fhv(1) = Pgf``; Fig. 3.12
"P = x; Pg = best_P") and the velocity line's start
``Vi(par,:) = K*(Vi(par,:) + phi1*rand1.*(Pi(par,:) - ipop(par,1:np)) + ...``
with ``rand1``, ``rand2`` drawn per dimension (its visible end uses ``.*``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hysid_model.errors import HysidInputError
from island.addpop import additional_population
from island.population import PopulationOptimizer, array_or_none, check_choice, check_float, load_array
from island.rng import uniform_population

NEIGHBOURHOODS = ("global", "ring")
"""Whose best a particle follows: the swarm's (the thesis) or its ring neighbours' (Fig. 3.10a)."""


def constriction(phi1: float, phi2: float) -> float:
    """Clerc's K = 2 / |2 - phi - sqrt(phi^2 - 4 phi)|, phi = phi1 + phi2 > 4 (Eq. 3.8); 0.7298 for 2.05 + 2.05."""
    phi = phi1 + phi2
    if not phi > 4.0:
        raise HysidInputError(f"PSO options phi1 + phi2 must exceed 4 for the constriction factor (Eq. 3.8), got {phi:g}")
    return 2.0 / abs(2.0 - phi - np.sqrt(phi * phi - 4.0 * phi))


def bounded_move(x: np.ndarray, v: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x' = x + v where strictly inside the bounds; elsewhere the coordinate stays and its velocity becomes 0."""
    moved = x + v
    inside = (moved > bounds[:, 0]) & (moved < bounds[:, 1])
    return np.where(inside, moved, x), np.where(inside, v, 0.0)


class PSO(PopulationOptimizer):
    """Constricted PSO of the thesis (section 3.2, Figs. 3.11/3.12, Eq. 3.9); every setting an option with the
    thesis value as default (section 5.1), ``redraw_limit`` as :class:`island.population.PopulationOptimizer` says."""

    name = "PSO"

    def __init__(
        self,
        bounds: np.ndarray,
        seed: int,
        *,
        phi1: float = 2.05,
        phi2: float = 2.05,
        synchronous: bool = False,
        neighbourhood: str = "global",
        **shared: Any,
    ) -> None:
        """``shared``: the options every algorithm has (:class:`island.population.PopulationOptimizer`)."""
        super().__init__(bounds, seed, **shared)
        self.phi1 = check_float(self.name, "phi1", phi1, 0.0)
        self.phi2 = check_float(self.name, "phi2", phi2, 0.0)
        self.K = constriction(self.phi1, self.phi2)
        if not isinstance(synchronous, (bool, np.bool_)):
            raise HysidInputError(f"PSO option synchronous must be true or false, got {synchronous!r}")
        self.synchronous = bool(synchronous)
        self.neighbourhood = check_choice(self.name, "neighbourhood", neighbourhood, NEIGHBOURHOODS)
        self.x: np.ndarray | None = None
        """Particle positions ``(S, D)``; None before the initial swarm is evaluated."""
        self.v: np.ndarray | None = None
        self.P: np.ndarray | None = None
        self.Pf: np.ndarray | None = None
        self.Pg: np.ndarray | None = None
        self.Pgf = np.inf
        self._particle = 0
        """Next particle to move (asynchronous mode)."""
        self._moved = False
        """All particles moved in this iteration; the additional population is next."""

    def _settings(self) -> dict[str, Any]:
        return self._settings_with({"phi1": self.phi1, "phi2": self.phi2, "synchronous": self.synchronous, "neighbourhood": self.neighbourhood})

    # --- moves ---------------------------------------------------------------------
    def _movers(self) -> slice:
        """The particles of the next move: all (synchronous) or the next one (asynchronous)."""
        return slice(0, self.population) if self.synchronous else slice(self._particle, self._particle + 1)

    def _social(self, movers: slice) -> np.ndarray:
        """The P_g the movers follow: the global best, or each one's ring-neighbourhood best P."""
        assert self.P is not None and self.Pf is not None and self.Pg is not None  # set by the initial swarm
        if self.neighbourhood == "global":
            return self.Pg
        ring = (np.arange(movers.start, movers.stop)[:, None] + np.array([-1, 0, 1])) % self.population
        return self.P[ring[np.arange(ring.shape[0]), np.argmin(self.Pf[ring], axis=1)]]

    def _move(self, movers: slice) -> np.ndarray:
        """Eq. 3.9 and the bounded position update for the movers; returns their new positions."""
        assert self.x is not None and self.v is not None and self.P is not None and self.Pf is not None and self.Pg is not None  # set by the initial swarm
        x = self.x[movers]
        r = self.rng.random((2,) + x.shape)
        v = self.K * (self.v[movers] + self.phi1 * r[0] * (self.P[movers] - x) + self.phi2 * r[1] * (self._social(movers) - x))
        new_x, self.v[movers] = bounded_move(x, v, self.bounds)
        return new_x

    def _next_batch(self) -> tuple[str, np.ndarray]:
        if self.P is None:
            return "initial", uniform_population(self.rng, self.bounds, self.initial_population)
        assert self.Pg is not None  # set with P
        if self._moved:
            return "addpop", additional_population(self.Pg, self.bounds, self.rng, amount=self.addpop_amount, level=self.addpop_level)
        return "move", self._move(self._movers())

    # --- results -------------------------------------------------------------------
    def _finish(self, kind: str, x: np.ndarray, f: np.ndarray) -> None:
        if kind == "initial":
            keep = np.argsort(f, kind="stable")[: self.population]
            self._adopt(x[keep], f[keep])
            self.history.append(self.Pgf)
        elif kind == "addpop":
            assert self.P is not None and self.Pf is not None  # set by the initial swarm
            j = int(np.argmin(f))
            if f[j] < self.Pgf:
                self.Pg, self.Pgf = x[j].copy(), float(f[j])
                if self.neighbourhood == "ring":
                    b = int(np.argmin(self.Pf))
                    self.P[b], self.Pf[b] = self.Pg, self.Pgf
            self._moved = False
            self._complete_iteration(self.Pgf)
        else:
            self._moved_to(self._movers(), x, f)

    def _adopt(self, x: np.ndarray, f: np.ndarray) -> None:
        """Particles at the candidates, each its own personal best, at rest (P = x, v = 0; Fig. 3.12)."""
        self.x, self.P, self.Pf = x.copy(), x.copy(), f.copy()
        self.v = np.zeros_like(self.x)
        self.Pg, self.Pgf = self.P[0].copy(), float(self.Pf[0])
        self._particle, self._moved = 0, False

    def _moved_to(self, movers: slice, x: np.ndarray, f: np.ndarray) -> None:
        """New positions and fitness of the movers: personal bests, then Pg (Figs. 3.11/3.12)."""
        assert self.x is not None and self.v is not None and self.P is not None and self.Pf is not None and self.Pg is not None  # set by the initial swarm
        self.x[movers] = x
        better = np.flatnonzero(f < self.Pf[movers])
        if better.size:
            idx = movers.start + better
            self.P[idx], self.Pf[idx] = x[better], f[better]
            j = better[np.argmin(f[better])]
            if f[j] < self.Pgf:
                self._gained(self.Pgf, float(f[j]))
                self.Pg, self.Pgf = x[j].copy(), float(f[j])
        self._particle = movers.stop % self.population
        if self._particle == 0:
            if self.addpop_number:
                self._moved = True
            else:
                self._complete_iteration(self.Pgf)

    def _take(self, x: np.ndarray, f: float) -> bool:
        """A migrant becomes the worst particle's position and personal best, with zero velocity."""
        assert self.x is not None and self.v is not None and self.P is not None and self.Pf is not None and self.Pg is not None  # set by the initial swarm
        w = int(np.argmax(self.Pf))
        if not f < self.Pf[w]:
            return False
        self.x[w], self.P[w], self.Pf[w], self.v[w] = x, x, f, 0.0
        if f < self.Pgf:
            self.Pg, self.Pgf = x.copy(), f
        return True

    def _known(self) -> tuple[np.ndarray, np.ndarray]:
        assert self.P is not None and self.Pf is not None and self.Pg is not None  # set by the initial swarm
        others = ~np.all(self.Pg == self.P, axis=1)
        return np.vstack([self.Pg, self.P[others]]), np.concatenate([[self.Pgf], self.Pf[others]])

    def _state(self) -> dict[str, Any]:
        return {
            "x": array_or_none(self.x),
            "v": array_or_none(self.v),
            "P": array_or_none(self.P),
            "Pf": array_or_none(self.Pf),
            "Pg": array_or_none(self.Pg),
            "Pgf": self.Pgf,
            "particle": self._particle,
            "moved": self._moved,
        }

    def _load(self, state: dict[str, Any]) -> None:
        self.x = load_array(state["x"], self.dim)
        self.v = load_array(state["v"], self.dim)
        self.P = load_array(state["P"], self.dim)
        self.Pf = load_array(state["Pf"])
        self.Pg = load_array(state["Pg"])
        self.Pgf = float(state["Pgf"])
        self._particle = int(state["particle"])
        self._moved = bool(state["moved"])
