"""SMC with look-ahead: exact answers from a Kalman filter, unbiased resampling, ancestry."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from awalker_tracker.inference.smc import (
    AncestryHistory, ParticleFilter, SMCConfig, effective_sample_size, map_trajectory,
    normalize_log_weights, resample)


@dataclass
class ScalarStates:
    x: np.ndarray            # (N,)
    path: np.ndarray         # (N, frames so far): every value this particle's lineage took

    def take(self, idx: np.ndarray) -> "ScalarStates":
        return ScalarStates(self.x[idx], self.path[idx])


@dataclass
class LinearGaussian:
    """x_t = a x_{t-1} + N(0, q); z_t = x_t + N(0, r); x_0 ~ N(m0, p0)."""

    a: float = 0.95
    q: float = 0.3
    r: float = 0.05
    m0: float = 1.0
    p0: float = 2.0

    def initial(self, n, rng):
        x = self.m0 + np.sqrt(self.p0) * rng.standard_normal(n)
        return ScalarStates(x, x[:, None].copy())

    def transition(self, states, rng):
        x = self.a * states.x + np.sqrt(self.q) * rng.standard_normal(states.x.shape)
        return ScalarStates(x, np.concatenate([states.path, x[:, None]], axis=1)), {"moved": True}

    def log_likelihood(self, prev_states, states, z):
        return -0.5 * (z - states.x) ** 2 / self.r

    def simulate(self, frames, rng):
        x = self.m0 + np.sqrt(self.p0) * rng.standard_normal()
        zs = []
        for _ in range(frames):
            zs.append(x + np.sqrt(self.r) * rng.standard_normal())
            x = self.a * x + np.sqrt(self.q) * rng.standard_normal()
        return np.array(zs)

    def kalman(self, zs):
        """Filtering means and variances p(x_t | z_0..t)."""
        means, variances = [], []
        m, p = self.m0, self.p0
        for t, z in enumerate(zs):
            if t > 0:
                m, p = self.a * m, self.a**2 * p + self.q
            gain = p / (p + self.r)
            m, p = m + gain * (z - m), (1 - gain) * p
            means.append(m)
            variances.append(p)
        return np.array(means), np.array(variances)

    def kalman_log_evidence(self, zs):
        """log p(z_0..T) of ``log_likelihood`` (which leaves out log N's constant -log(2 pi r) / 2)."""
        total, m, p = 0.0, self.m0, self.p0
        for t, z in enumerate(zs):
            if t > 0:
                m, p = self.a * m, self.a**2 * p + self.q
            s = p + self.r           # predictive variance of z_t
            total += -0.5 * np.log(2 * np.pi * s) - 0.5 * (z - m) ** 2 / s + 0.5 * np.log(2 * np.pi * self.r)
            gain = p / s
            m, p = m + gain * (z - m), (1 - gain) * p
        return total


def _weighted_moments(step):
    w = step.weights
    mean = np.sum(w * step.states.x)
    return mean, np.sum(w * (step.states.x - mean) ** 2)


@pytest.mark.parametrize("lookahead,scheme", [(0, "systematic"), (3, "systematic"),
                                              (3, "stratified"), (3, "multinomial")])
def test_filter_matches_kalman(lookahead, scheme):
    model = LinearGaussian()
    zs = model.simulate(25, np.random.default_rng(1))
    kal_mean, kal_var = model.kalman(zs)
    pf = ParticleFilter(model, SMCConfig(num_particles=20000, lookahead=lookahead, resampling=scheme, seed=3))
    steps = pf.run(zs)
    assert [s.frame for s in steps] == list(range(len(zs)))
    assert pf.num_resamples > 0          # the resampling path is exercised
    for step, m, v in zip(steps, kal_mean, kal_var):
        mean, var = _weighted_moments(step)
        tolerance = 5.0 * np.sqrt(v / step.effective_sample_size) + 1e-3
        assert abs(mean - m) < tolerance, (step.frame, mean, m)
        # relative error of a weighted variance ~ sqrt(2 / N_eff)
        assert abs(var - v) < (5.0 * np.sqrt(2.0 / step.effective_sample_size) + 0.05) * v, (step.frame, var, v)


@pytest.mark.parametrize("lookahead", [0, 3])
def test_log_evidence_matches_kalman(lookahead):
    """The frames' log_evidence, log sum_j w_{t-1,j} p(z_t | s_t^j), add up to log p(z_0..T), with or
    without look-ahead resampling (its re-weighting keeps S_{t-1} properly weighted)."""
    model = LinearGaussian()
    zs = model.simulate(25, np.random.default_rng(1))
    pf = ParticleFilter(model, SMCConfig(num_particles=20000, lookahead=lookahead, seed=4))
    steps = pf.run(zs)
    assert pf.num_resamples > 0
    estimate = sum(s.log_evidence for s in steps)
    exact = model.kalman_log_evidence(zs)
    # measured over seeds 0-4: within 0.05-0.55 nats over the 25 frames; the same sum with the frame's own
    # weights w_t in place of w_{t-1} is 30 nats off
    assert estimate == pytest.approx(exact, abs=1.0)
    wrong = sum(float(np.log(np.sum(np.exp(s.log_weights + s.log_likelihood)))) for s in steps)
    assert abs(wrong - exact) > 10.0


def test_lookahead_lags_by_tau_and_resamples_less():
    model = LinearGaussian(r=0.02)
    zs = model.simulate(40, np.random.default_rng(5))
    pf = ParticleFilter(model, SMCConfig(num_particles=2000, lookahead=3, seed=0))
    outputs = [len(pf.push(z)) for z in zs]
    assert outputs[:3] == [0, 0, 0] and all(n == 1 for n in outputs[3:])
    assert [s.frame for s in pf.finish()] == [37, 38, 39]
    plain = ParticleFilter(model, SMCConfig(num_particles=2000, lookahead=0, seed=0))
    plain.run(zs)
    # Look-ahead weights are peakier than one frame's, but resampling with w_hat keeps it well defined.
    assert 0 < pf.num_resamples <= len(zs)
    assert plain.num_resamples > 0


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "multinomial"])
def test_resampling_is_unbiased(scheme):
    rng = np.random.default_rng(0)
    weights = rng.random(12) ** 3
    weights /= weights.sum()
    n, trials = 12, 4000
    counts = np.zeros(12)
    for _ in range(trials):
        idx = resample(weights, rng, scheme)
        assert idx.shape == (n,) and np.all(np.diff(idx) >= 0)
        counts += np.bincount(idx, minlength=12)
        if scheme == "systematic":   # low variance: each count is floor or ceil of N w
            c = np.bincount(idx, minlength=12)
            assert np.all(c >= np.floor(n * weights) - 1e-9) and np.all(c <= np.ceil(n * weights) + 1e-9)
    mean_counts = counts / trials
    # multinomial count variance is N w (1 - w); the others are lower
    std_error = np.sqrt(n * weights * (1 - weights) / trials)
    assert np.all(np.abs(mean_counts - n * weights) < 5 * std_error + 1e-3)


def test_weight_helpers():
    assert effective_sample_size(np.zeros(50)) == pytest.approx(50)
    assert effective_sample_size(np.array([0.0, -np.inf, -np.inf])) == pytest.approx(1)
    assert np.allclose(np.exp(normalize_log_weights(np.full(4, -np.inf))), 0.25)
    lw = normalize_log_weights(np.array([1000.0, 1000.0 + np.log(3.0)]))
    assert np.allclose(np.exp(lw), [0.25, 0.75])
    with pytest.raises(ValueError):
        normalize_log_weights(np.array([0.0, np.nan]))
    with pytest.raises(ValueError):
        SMCConfig(resampling="bogus")
    with pytest.raises(ValueError):
        SMCConfig(trust=1.5)


@pytest.mark.parametrize("prune_every", [0, 4])
def test_ancestry_reconstructs_lineages(prune_every):
    """The lineage rebuilt from per-frame ancestry equals the path each particle carried itself."""
    model = LinearGaussian(r=0.01)
    zs = model.simulate(30, np.random.default_rng(2))
    pf = ParticleFilter(model, SMCConfig(num_particles=500, lookahead=2, seed=7))
    history = AncestryHistory(prune_every=prune_every)
    steps = pf.run(zs)
    for step in steps:
        history.append(None if step.frame == 0 else step.ancestors, {"x": step.states.x})
    assert pf.num_resamples > 3
    final = steps[-1]
    for index in [final.best_index, 0, 499]:
        assert np.array_equal(history.trajectory(index)["x"], final.states.path[index])
    assert np.array_equal(map_trajectory(history, final.log_weights)["x"], final.states.path[final.best_index])
    if prune_every:
        history.prune()
        assert history.stored_particles() < 500 * 30 / 3   # the ancestry tree coalesces
        for index in [final.best_index, 123]:
            assert np.array_equal(history.trajectory(index)["x"], final.states.path[index])


def test_bad_likelihood_is_reported():
    class Broken(LinearGaussian):
        def log_likelihood(self, prev_states, states, z):
            return np.full(3, np.nan)

    with pytest.raises(ValueError, match="shape"):
        ParticleFilter(Broken(), SMCConfig(num_particles=10, lookahead=0)).push(0.0)


@dataclass
class CopiedStates(ScalarStates):
    continues: np.ndarray | None = None      # the row each particle continues (smc module doc)

    def take(self, idx: np.ndarray) -> "CopiedStates":
        return CopiedStates(self.x[idx], self.path[idx])


class Rejuvenating(LinearGaussian):
    """Copies random particles over other random ones every third frame, saying which row each copy continues."""

    def initial(self, n, rng):
        s = super().initial(n, rng)
        return CopiedStates(s.x, s.path)

    def transition(self, states, rng):
        s, info = super().transition(states, rng)
        return CopiedStates(s.x, s.path), info

    def rejuvenate(self, frame, log_weights, parent, states, obs, rng):
        if parent is None or frame % 3:
            return states
        rows = rng.choice(len(states.x), size=60, replace=False)
        sources = rng.choice(len(states.x), size=rows.size)
        x, path = states.x.copy(), states.path.copy()
        x[rows], path[rows] = x[sources], path[sources]
        continues = np.arange(len(x))
        continues[rows] = sources
        return CopiedStates(x, path, continues)


def test_ancestry_follows_the_rows_a_rejuvenation_copies():
    """A copied particle continues its source's lineage: the lineage rebuilt from the ancestry still equals the
    path each particle carried (without ``continues`` it would be the overwritten row's)."""
    model = Rejuvenating(r=0.01)
    zs = model.simulate(24, np.random.default_rng(3))
    pf = ParticleFilter(model, SMCConfig(num_particles=200, lookahead=2, seed=5))
    history = AncestryHistory(prune_every=0)
    steps = pf.run(zs)
    for step in steps:
        history.append(None if step.frame == 0 else step.ancestors, {"x": step.states.x})
    final = steps[-1]
    for index in range(0, 200, 7):
        assert np.array_equal(history.trajectory(index)["x"], final.states.path[index])


def test_kld_particle_count_is_fox_bound():
    """n = chi^2_{k-1, 1-delta} / (2 eps), the Wilson-Hilferty approximation within 1 % for k >= 10; one bin 1."""
    from scipy.stats import chi2

    from awalker_tracker.inference.smc import kld_particle_count

    assert kld_particle_count(1, 0.05, 0.99) == 1
    for bins in (10, 50, 300, 3000):
        exact = chi2.ppf(0.99, bins - 1) / (2 * 0.05)
        assert kld_particle_count(bins, 0.05, 0.99) == pytest.approx(exact, rel=0.01)
    assert kld_particle_count(300, 0.02, 0.99) > kld_particle_count(300, 0.05, 0.99)   # tighter: more particles


@dataclass
class BinnedLinearGaussian(LinearGaussian):
    """``LinearGaussian`` with histogram bins of ``width`` over x, for the adaptive particle count."""

    width: float = 0.05

    def bin_keys(self, states):
        return np.floor(states.x / self.width).astype(np.int64)


def test_adaptive_count_follows_the_predicted_spread_and_stays_exact():
    """KLD-sampling: a walk whose moves are small (q) is followed with fewer particles than one whose moves are
    large, never fewer than min_particles nor more than num_particles, and the filter still matches the Kalman
    filter in mean, variance and evidence."""
    counts = {}
    for q, r in ((0.003, 0.002), (0.3, 0.2)):
        model = BinnedLinearGaussian(q=q, r=r)
        zs = model.simulate(30, np.random.default_rng(2))
        pf = ParticleFilter(model, SMCConfig(num_particles=20000, min_particles=500, seed=5))
        steps = pf.run(zs)
        sizes = [len(s.states.x) for s in steps]
        assert pf.num_resamples > 0 and min(sizes) >= 500 and max(sizes) <= 20000
        assert all(len(s.log_weights) == len(s.ancestors) == n for s, n in zip(steps, sizes))
        counts[q] = np.median(sizes[5:])
        kal_mean, kal_var = model.kalman(zs)
        for step, m, v in zip(steps, kal_mean, kal_var):
            mean, var = _weighted_moments(step)
            assert abs(mean - m) < 5.0 * np.sqrt(v / step.effective_sample_size) + 1e-3, (q, step.frame)
            assert abs(var - v) < (5.0 * np.sqrt(2.0 / step.effective_sample_size) + 0.05) * v, (q, step.frame)
        # 500-1300 particles: measured within 2.3 nats over the 30 frames at filter seeds 0-3
        assert sum(s.log_evidence for s in steps) == pytest.approx(model.kalman_log_evidence(zs), abs=4.0)
    # measured: a median of 500 particles (the floor) against 1277
    assert counts[0.003] < 0.5 * counts[0.3]


def test_adaptive_count_at_its_ceiling_changes_nothing():
    """min_particles = num_particles: the same filter, bit for bit, as a fixed count (no second draw)."""
    model = BinnedLinearGaussian(width=1e-6)
    zs = model.simulate(20, np.random.default_rng(3))
    fixed = ParticleFilter(model, SMCConfig(num_particles=3000, seed=1)).run(zs)
    capped = ParticleFilter(model, SMCConfig(num_particles=3000, min_particles=3000, seed=1)).run(zs)
    assert all(np.array_equal(a.log_weights, b.log_weights) and np.array_equal(a.states.x, b.states.x)
               for a, b in zip(fixed, capped))


def test_adaptive_count_needs_bins_and_a_valid_floor():
    with pytest.raises(ValueError, match="bin_keys"):
        ParticleFilter(LinearGaussian(), SMCConfig(num_particles=1000, min_particles=100))
    with pytest.raises(ValueError, match="min_particles must lie in 0-num_particles"):
        SMCConfig(num_particles=1000, min_particles=2000)
    with pytest.raises(ValueError, match="kld_error"):
        SMCConfig(kld_error=0.0)
    with pytest.raises(ValueError, match="kld_quantile"):
        SMCConfig(kld_quantile=1.0)
