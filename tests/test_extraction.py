"""Loop extraction from raw records (hysid_model.extraction) against loops with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from hysid_model.extraction import centre_branches, extract_loop, loop_from_branches

FREQ = 7.3
X0 = 2e-3
SIGMA = 2.0
PHASE = 0.5  # rad: first harmonic of the smooth force leads x by 0.5 rad


def smooth_force(theta: np.ndarray, loading: np.ndarray | float) -> np.ndarray:
    return 400.0 * np.sin(theta + PHASE) + 60.0 * np.sin(3 * theta + 0.2)


def friction_force(theta: np.ndarray, loading: np.ndarray | float) -> np.ndarray:
    """Stiffness plus Coulomb friction: a 300 N jump at each reversal."""
    return 100.0 * np.sin(theta) + 150.0 * np.where(np.asarray(loading) > 0, 1.0, -1.0)


def record(force_of, seed: int, *, fs: float = 5000.0, cycles: float = 14, ramp: float = 2.0, transient: float = 80.0, sigma: float = SIGMA):
    """A shaker record: amplitude ramps up over ``ramp`` cycles, a decaying 23 Hz force transient, noise on F and x."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(cycles / FREQ * fs)) / fs
    theta = 2 * np.pi * FREQ * t + 0.7
    envelope = np.clip(FREQ * t / ramp, 0.0, 1.0) if ramp > 0 else np.ones_like(t)
    x = 3e-4 + X0 * envelope * np.sin(theta) + 1e-6 * rng.standard_normal(t.size)
    force = 25.0 + envelope * force_of(theta, np.cos(theta)) + transient * np.exp(-t / 0.05) * np.sin(2 * np.pi * 23 * t)
    return t, x, force + sigma * rng.standard_normal(t.size)


def branch_errors(loop, force_of) -> np.ndarray:
    theta = np.arcsin(np.clip(loop.top[:, 0] / loop.x0, -1, 1))
    return np.concatenate([loop.top[:, 1] - force_of(theta, 1.0), loop.bottom[:, 1] - force_of(np.pi - theta, -1.0)])


def test_recovers_a_known_noisy_loop_after_a_transient():
    t, x, force = record(smooth_force, seed=1)
    loop = extract_loop(t, x, force, source="synthetic", nominal_freq_hz=FREQ)
    assert abs(loop.x0 / X0 - 1) < 1e-3
    assert abs(loop.freq_hz / FREQ - 1) < 1e-5
    assert abs(loop.phase_deg - np.degrees(PHASE)) < 0.2
    assert abs(loop.x_offset - 3e-4) < 1e-6
    assert abs(loop.force_mean - 25.0) < 0.2
    assert loop.window_s[0] >= 2 / FREQ - 1e-9  # the ramp (2 cycles) is not used
    assert loop.cycles >= 10  # ... but every steady cycle after it is
    assert abs(loop.sigma_raw / SIGMA - 1) < 0.1
    z = branch_errors(loop, smooth_force) / loop.sigma
    assert np.abs(z).max() < 4.5
    assert 0.7 < np.mean(z**2) < 1.3
    assert loop.top.shape == loop.bottom.shape == (100, 2)
    np.testing.assert_allclose(loop.top[:, 0], np.linspace(-loop.x0, loop.x0, 100))


def test_sigma_is_the_noise_of_the_stored_branch_samples():
    """Pooled over seeds, (branch - truth) / sigma has unit variance: sigma is per stored sample, not per raw sample."""
    z, ratio = [], []
    for seed in range(6):
        t, x, force = record(smooth_force, seed=100 + seed, ramp=0.0, transient=0.0)
        loop = extract_loop(t, x, force, source="synthetic")
        z.append(branch_errors(loop, smooth_force) / loop.sigma)
        ratio.append(loop.sigma * np.sqrt(loop.samples_per_point) / loop.sigma_raw)
    z = np.concatenate(z)
    assert 0.85 < np.mean(z**2) < 1.15
    assert abs(np.mean(z)) < 0.1
    np.testing.assert_allclose(ratio, 1.0, atol=0.05)  # sigma = sigma_raw / sqrt(m)


def test_smooth_loop_without_noise_is_unbiased():
    t, x, force = record(smooth_force, seed=2, sigma=0.0, transient=0.0)
    loop = extract_loop(t, x, force, source="synthetic")
    err = branch_errors(loop, smooth_force)
    assert np.abs(err).max() < 1e-3 * 400.0  # curvature bias of the local fits, at the reversal samples
    assert np.abs(err[1:99]).max() < 2e-4 * 400.0


def test_friction_jump_at_the_reversals_stays_sharp():
    t, x, force = record(friction_force, seed=3, sigma=1.0, transient=0.0)
    loop = extract_loop(t, x, force, source="synthetic")
    tol = 4.5 * loop.sigma
    assert abs(loop.top[-1, 1] - 250.0) < tol  # loading branch arrives at +X0 with +friction
    assert abs(loop.bottom[-1, 1] - (-50.0)) < tol  # unloading leaves +X0 with -friction: a 300 N jump
    assert abs(loop.bottom[0, 1] - (-250.0)) < tol
    assert abs(loop.top[0, 1] - 50.0) < tol
    assert np.abs(branch_errors(loop, friction_force) / loop.sigma).max() < 4.5


def test_given_window_uses_all_its_whole_cycles():
    """A tapered sine as in the ARTS records: 7 periods, constant over [2/f, 5/f]."""
    f, fs = 0.5, 1024.0
    t = np.arange(int(7 / f * fs) + 1) / fs
    envelope = np.clip(np.minimum(f * t / 2, (7 - f * t) / 2), 0, 1)
    theta = 2 * np.pi * f * t
    x = 0.0127 * envelope * np.sin(theta)
    force = envelope * (9000 * np.sign(np.cos(theta)) + 2000 * np.sin(theta)) + 30 * np.random.default_rng(4).standard_normal(t.size)
    given = extract_loop(t, x, force, source="tapered", nominal_freq_hz=f, steady_window=(4.0, 10.0))
    auto = extract_loop(t, x, force, source="tapered", nominal_freq_hz=f)
    assert given.cycles == auto.cycles == 3
    assert abs(given.x0 / 0.0127 - 1) < 1e-3
    assert abs(auto.window_s[0] - 4.0) < 2 / fs and abs(auto.window_s[1] - 10.0) < 2 / fs


def test_sample_rate_locked_to_the_frequency_gives_unbiased_branches_and_the_raw_noise():
    """256 samples per period: every cycle samples the same phases, too few for windows h wide at 100 points per
    branch; the windows widen until their samples determine a quadratic, and overlap. The branches stay unbiased,
    and the loop's sigma counts the samples the windows share: the values scatter less than it (z rms below 1),
    and it is within 30 % of the sigma of the same record at a rate not locked to the excitation."""
    f = 2.0
    loops = []
    for fs in (512.0, 512.0 * 1.0131):
        rng = np.random.default_rng(5)
        t = np.arange(int(12 / f * fs)) / fs
        theta = 2 * np.pi * f * t
        force = smooth_force(theta, np.cos(theta)) + SIGMA * rng.standard_normal(t.size)
        loop = extract_loop(t, X0 * np.sin(theta), force, source="locked")
        z = branch_errors(loop, smooth_force) / loop.sigma
        assert loop.force_harmonics is None and np.abs(z).max() < 4.5 and np.sqrt(np.mean(z**2)) < 1.1
        assert abs(loop.sigma_raw / SIGMA - 1) < 0.1
        loops.append(loop)
    locked, free = loops
    assert locked.window_overlap > 2.0 and abs(locked.sigma / free.sigma - 1) < 0.3


@pytest.mark.parametrize("per_cycle", [32, 20, 10])
def test_few_samples_per_cycle_locked_or_not_give_the_loop_of_a_band_limited_force(per_cycle):
    """32 samples per cycle (an 800 Hz test at 25.6 kHz), 20 and 10: locked to the excitation, the branches are
    the force's harmonics; a little off, local windows where they find enough phases, harmonics where not;
    either way unbiased within the loop's sigma (harmonic values share their noise, so they scatter less)."""
    f = 10.0
    for fs in (per_cycle * f, per_cycle * f * 1.0037):
        rng = np.random.default_rng(per_cycle)
        t = np.arange(int(30 / f * fs)) / fs
        theta = 2 * np.pi * f * t
        force = 3.0 * np.cos(theta + 0.2) + 0.5 * np.sin(3 * theta) + 0.01 * rng.standard_normal(t.size)
        loop = extract_loop(t, 1e-3 * np.sin(theta), force, source="sparse.csv")
        if fs == per_cycle * f:
            assert loop.force_harmonics is not None and loop.force_harmonics <= (per_cycle - 1) // 2
        truth = lambda ph: 3.0 * np.cos(ph + 0.2) + 0.5 * np.sin(3 * ph)
        z = branch_errors(loop, lambda th, _c: truth(th)) / loop.sigma  # noqa: B023 (called within this iteration)
        assert np.abs(z).max() < 5.0 and np.sqrt(np.mean(z**2)) < 1.5, (fs, loop.force_harmonics, np.abs(z).max())
        assert abs(loop.sigma_raw / 0.01 - 1) < 0.1


def test_raw_branches_are_centred_resampled_and_oriented():
    """Like PrepareExpData: branches handed over swapped and off-centre come back as loading/unloading on the grid."""
    theta = np.linspace(-np.pi / 2, np.pi / 2, 37)
    x = 1e-3 * np.sin(theta)
    loading = np.column_stack([x + 2e-4, 3.0 * np.sin(theta + 0.3) + 7.0])
    unloading = np.column_stack([x[::-1] + 2e-4, 3.0 * np.sin(np.pi - theta[::-1] + 0.3) + 7.0])
    x0, top, bottom = loop_from_branches(unloading, loading, 50, "swapped.mat")
    assert x0 == pytest.approx(1e-3)
    np.testing.assert_allclose(top[:, 0], np.linspace(-1e-3, 1e-3, 50))
    assert np.all(top[1:-1, 1] > bottom[1:-1, 1])  # the loading branch carries the larger force
    centred_top, centred_bottom = centre_branches(top, bottom)
    both = np.concatenate([centred_top, centred_bottom])
    np.testing.assert_allclose(both.max(axis=0), -both.min(axis=0), atol=1e-12)
