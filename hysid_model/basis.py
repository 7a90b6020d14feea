"""Basis functions ('features') of the steady-state force on the branch samples.

Under the prescribed displacement x = X0 sin(wt) (Eq. 4.5) every memoryless
force term is a function of the phase wt and of the branch (loading or
unloading). A model's force on a loop is then a sum of coefficients times these
features, F = sum_m a_m(theta, X0, w) * phi_m(wt), which is what makes the
objective a closed form (no time integration, cf. Eq. 4.6 and 4.10).

Feature names: ``s<k>`` = sin(k wt), ``c<k>`` = cos(k wt) for harmonic order k,
``sgn`` = sign(x') (+1 on the loading, -1 on the unloading branch; Eq. 2.5).
"""

from __future__ import annotations

import re

import numpy as np

_HARMONIC = re.compile(r"^([sc])([1-9][0-9]*)$")


def feature_values(name: str, phase: np.ndarray, n_top: int) -> np.ndarray:
    """Values of feature ``name`` at ``phase`` (shape ``(L, 2n)``, top branch first)."""
    if name == "sgn":
        out = -np.ones_like(phase)
        out[:, :n_top] = 1.0
        return out
    if name == "dc":
        return np.ones_like(phase)
    match = _HARMONIC.match(name)
    if match is None:
        raise ValueError(f"unknown basis feature {name!r}")
    order = int(match.group(2))
    return np.sin(order * phase) if match.group(1) == "s" else np.cos(order * phase)


def design_matrix(names: list[str], phase: np.ndarray, n_top: int) -> np.ndarray:
    """Stack features into ``(L, 2n, M)``."""
    return np.stack([feature_values(name, phase, n_top) for name in names], axis=-1)


def harmonic_names(max_order: int, include_dc: bool = True) -> list[str]:
    names = ["dc"] if include_dc else []
    for k in range(1, max_order + 1):
        names += [f"s{k}", f"c{k}"]
    return names
