"""The additional population (island.addpop): Eq. 5.1 sizes, Table 5.1 combinations, bounded Gaussian steps."""

from __future__ import annotations

import numpy as np
import pytest

from island.addpop import additional_population, addpop_masks, addpop_size

TABLE_5_1 = [  # mutated parameters p1..p4 for L = 3, in the thesis' order
    "X...",
    ".X..",
    "..X.",
    "...X",
    "XX..",
    "X.X.",
    "X..X",
    ".XX.",
    ".X.X",
    "..XX",
    "XXX.",
    "XX.X",
    "X.XX",
    ".XXX",
]


def test_size_follows_eq_5_1():
    assert addpop_size(4, 4) == 15
    assert addpop_size(4, 3) == 14
    assert addpop_size(5, 2) == 5 + 10
    assert addpop_size(10, 3) == 10 + 45 + 120
    assert addpop_size(3, 4) == 2**3 - 1  # a level above D mutates every combination
    assert addpop_size(4, 0) == 0


def test_masks_are_the_rows_of_table_5_1():
    expected = np.array([[c == "X" for c in row] for row in TABLE_5_1])
    assert np.array_equal(addpop_masks(4, 3), expected)
    assert np.array_equal(addpop_masks(4, 4), np.vstack([expected, np.ones((1, 4), dtype=bool)]))
    assert addpop_masks(6, 3).shape == (addpop_size(6, 3), 6)


def test_each_row_changes_exactly_its_combination_of_genes():
    bounds = np.tile([-1.0, 1.0], (4, 1))
    best = np.zeros(4)
    pop = additional_population(best, bounds, np.random.default_rng(0), amount=1e-3, level=4)
    assert pop.shape == (15, 4)
    assert np.array_equal(pop != best, addpop_masks(4, 4))


def test_steps_are_gaussian_with_amount_times_the_range():
    bounds = np.array([[0.0, 10.0]])
    rng = np.random.default_rng(1)
    steps = np.array([additional_population(np.array([5.0]), bounds, rng, amount=0.01, level=1)[0, 0] - 5.0 for _ in range(4000)])
    assert steps.std() == pytest.approx(0.01 * 10.0, rel=0.05)
    assert abs(steps.mean()) < 0.01


def test_out_of_bounds_values_are_rejected_and_unchanged_rows_redrawn():
    bounds = np.array([[0.0, 1.0], [0.0, 1.0]])
    best = np.array([0.999, 0.5])
    pop = additional_population(best, bounds, np.random.default_rng(2), amount=0.2, level=2)
    assert np.all((pop > 0) & (pop < 1))
    # with a huge step every mutation leaves the bounds: each row would equal the best and is redrawn uniformly
    many = np.vstack([additional_population(best, bounds, np.random.default_rng(s), amount=1e6, level=2) for s in range(200)])
    assert np.all(many != best)
    assert np.all((many >= 0) & (many <= 1))
    assert many.mean(axis=0) == pytest.approx([0.5, 0.5], abs=0.05)
