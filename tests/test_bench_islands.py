"""The statistics of ``hysid bench islands``: the Wilson interval and the seed-by-seed comparison."""

import math

import numpy as np
import pytest

from hysid.bench.rates import ended_lower, paired, wilson


def test_paired_counts_the_seeds_only_one_campaign_passed_and_tests_them() -> None:
    a = np.array([True] * 30 + [False] * 10 + [True] * 4 + [False] * 6)
    b = np.array([True] * 30 + [True] * 10 + [False] * 4 + [False] * 6)
    p = paired(a, b)
    assert (p["only_a"], p["only_b"]) == (4, 10)
    assert p["difference"] == pytest.approx(-6 / 50)
    low, high = p["difference95"]
    assert low < -6 / 50 < high and high - low == pytest.approx(2 * 1.96 * np.sqrt(14 - 50 * 0.12**2) / 50)
    assert p["sign_test_p"] == pytest.approx(2 * sum(math.comb(14, k) for k in range(5)) / 2**14)


def test_paired_campaigns_that_agree_on_every_seed_do_not_differ() -> None:
    a = np.array([True, False, True])
    p = paired(a, a.copy())
    assert p == {"only_a": 0, "only_b": 0, "difference": 0.0, "difference95": (0.0, 0.0), "sign_test_p": 1.0}


def test_wilson_interval_holds_the_rate_and_stays_in_0_1() -> None:
    assert wilson(0, 20)[0] == 0.0 and 0 < wilson(0, 20)[1] < 0.2
    low, high = wilson(15, 20)
    assert low < 0.75 < high and high <= 1.0


def test_ended_lower_counts_seeds_and_tests_the_log_ratios() -> None:
    rng = np.random.default_rng(0)
    b = 10.0 ** rng.uniform(-7, -4, 40)
    e = ended_lower(b / 10, b)
    assert (e["lower"], e["higher"]) == (40, 0) and e["wilcoxon_p"] < 1e-6
    assert ended_lower(b, b) == {"lower": 0, "higher": 0, "wilcoxon_p": 1.0}
