"""Stochastic control prior (Sec. 4.2): Rao-Blackwellised kappa_bar, Gamma iota at the strike, stability."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from awalker_tracker.model import control, gaits
from awalker_tracker.model.walker import WalkerParams

PARAMS = WalkerParams()


@pytest.fixture(scope="module")
def table() -> gaits.GaitTable:
    return gaits.GaitTable.load()


@pytest.fixture(scope="module")
def prior(table: gaits.GaitTable) -> control.ControlPrior:
    return control.ControlPrior.from_gait_table(table)


def test_defaults_are_the_papers(prior: control.ControlPrior, table: gaits.GaitTable) -> None:
    assert (prior.beta, prior.mu_kappa, prior.kappa_bar_variance, prior.kappa_noise_variance) == (0.85, 0.7, 0.5, 1.0)
    assert prior.impulse_variance == pytest.approx(0.05**2)
    coef, _ = gaits.fit_impulse_mean(table)
    np.testing.assert_allclose(prior.impulse_mean_coefficients, coef)
    # units check: mu_kappa lies inside the stiffness of human gaits in the table (~0.74 at 5 km/h, 0.7 m)
    assert abs(table.lookup(5 / 3.6, 0.7)[2] - prior.mu_kappa) < 0.1
    with pytest.raises(ValueError):
        control.ControlPrior(beta=1.5)


def test_gamma_impulse_has_the_fitted_mean_and_paper_variance(prior: control.ControlPrior) -> None:
    rng = np.random.default_rng(0)
    w1, w2 = np.full(200_000, -1.9), np.full(200_000, -1.3)
    draws = prior.sample_impulse(rng, w1, w2)
    mean = prior.impulse_mean(-1.9, -1.3)
    assert np.all(draws > 0)
    assert draws.mean() == pytest.approx(mean, rel=2e-3)
    assert draws.var() == pytest.approx(0.05**2, rel=2e-2)


def _start(prior, table, n, rng, speed=5 / 3.6, step=0.7):
    walkers = gaits.gait_initial_state(PARAMS, np.full(n, speed), np.full(n, step), table=table)
    _, _, kappa, iota = table.lookup(speed, step)
    return walkers, control.initial_control(prior, n, rng, stiffness=kappa, toe_off_impulse=iota)


def test_kappa_draws_and_rao_blackwell_update(prior: control.ControlPrior, table: gaits.GaitTable) -> None:
    rng = np.random.default_rng(1)
    n = 20_000
    walkers, ctrl = _start(prior, table, n, rng)
    m0, v0 = ctrl.stiffness_mean_mean.copy(), ctrl.stiffness_mean_variance.copy()
    walkers, ctrl1, ev = control.sample_transition(PARAMS, prior, walkers, ctrl, 1 / 30, rng)
    assert not ev.heel_strike.any()           # first frame of a stride
    kappa = ctrl1.stiffness
    # predictive law of kappa_t: N(m, v + sigma_kappa^2)
    assert kappa.mean() == pytest.approx(m0[0], abs=0.03)
    assert kappa.var() == pytest.approx(v0[0] + prior.kappa_noise_variance, rel=0.03)
    # scalar Kalman update of the kappa_bar belief, particle by particle
    var = 1.0 / (1.0 / v0 + 1.0 / prior.kappa_noise_variance)
    np.testing.assert_allclose(ctrl1.stiffness_mean_variance, var)
    np.testing.assert_allclose(ctrl1.stiffness_mean_mean, var * (m0 / v0 + kappa / prior.kappa_noise_variance))


def test_stride_update_at_heel_strike(table: gaits.GaitTable) -> None:
    """With tiny noise, walkers strike; at the strike the belief goes through eq. (5) and iota = mu(q'-)."""
    quiet = dataclasses.replace(control.ControlPrior.from_gait_table(table), kappa_noise_variance=1e-10,
                                kappa_bar_variance=1e-10,
                                impulse_variance=1e-12)
    rng = np.random.default_rng(2)
    walkers, ctrl = _start(quiet, table, 5, rng)
    for _ in range(30):
        before = ctrl.copy()
        walkers, ctrl, ev = control.sample_transition(PARAMS, quiet, walkers, ctrl, 1 / 30, rng)
        if ev.heel_strike.any():
            break
    assert ev.heel_strike.all()
    m_post = before.stiffness_mean_mean  # tiny-noise draws leave the mean where it was
    v_post = 1.0 / (1.0 / before.stiffness_mean_variance + 1.0 / quiet.kappa_noise_variance)
    keep = 1 - quiet.beta
    np.testing.assert_allclose(ctrl.stiffness_mean_mean, quiet.beta * quiet.mu_kappa + keep * m_post, atol=1e-6)
    np.testing.assert_allclose(ctrl.stiffness_mean_variance, keep**2 * v_post + quiet.kappa_bar_variance, rtol=1e-9)
    pre = ev.pre_strike_rates
    np.testing.assert_allclose(ctrl.toe_off_impulse, quiet.impulse_mean(pre[:, 0], pre[:, 1]), rtol=1e-4)
    np.testing.assert_allclose(ev.toe_off_impulse, ctrl.toe_off_impulse)
    np.testing.assert_allclose(ctrl.time_since_strike, (1 - ev.strike_fraction) / 30)


def test_take_and_copy(prior: control.ControlPrior, table: gaits.GaitTable) -> None:
    rng = np.random.default_rng(3)
    _, ctrl = _start(prior, table, 4, rng)
    ctrl.stiffness[:] = [1.0, 2.0, 3.0, 4.0]
    picked = ctrl.take(np.array([3, 3, 0]))
    assert picked.stiffness.tolist() == [4.0, 4.0, 1.0] and len(picked) == 3
    dup = ctrl.copy()
    dup.stiffness[0] = -1
    assert ctrl.stiffness[0] == 1.0


def test_noise_free_prior_keeps_walking_at_the_gait(table: gaits.GaitTable) -> None:
    """Control: without noise, walkers from the 4 km/h, 0.6 m gait take 20 regular steps, none falls."""
    _, _, kappa, iota = table.lookup(4 / 3.6, 0.6)
    still = dataclasses.replace(control.ControlPrior.from_gait_table(table), mu_kappa=float(kappa),
                                kappa_noise_variance=1e-12, kappa_bar_variance=1e-12, impulse_variance=1e-12,
                                impulse_mean_coefficients=(float(iota), 0.0, 0.0, 0.0))
    rng = np.random.default_rng(4)
    walkers, ctrl = _start(still, table, 50, rng, 4 / 3.6, 0.6)
    steps = np.zeros(50, int)
    for _ in range(400):
        walkers, ctrl, ev = control.sample_transition(PARAMS, still, walkers, ctrl, 1 / 30, rng)
        assert not ev.fallen.any()
        steps += ev.heel_strike
        if steps.min() >= 20:
            break
    assert steps.min() >= 20


def test_paper_prior_spreads_gaits_and_its_fall_rate_is_measured(prior: control.ControlPrior,
                                                                 table: gaits.GaitTable) -> None:
    """The paper's noise levels: walkers leave the start gait quickly and many fall (see the report).

    Asserted: fallen walkers are frozen and flagged (never NaN), and sampled gaits do spread.
    """
    rng = np.random.default_rng(5)
    n = 300
    walkers, ctrl = _start(prior, table, n, rng)
    fallen = np.zeros(n, bool)
    for _ in range(60):
        walkers, ctrl, ev = control.sample_transition(PARAMS, prior, walkers, ctrl, 1 / 30, rng)
        fallen |= ev.fallen
        assert np.all(np.isfinite(walkers.stance_angle)) and np.all(np.isfinite(ctrl.stiffness_mean_mean))
    assert ctrl.stiffness_mean_mean.std() > 0.1
    assert 0.0 < fallen.mean() <= 1.0


def test_prior_walk_statistics(prior: control.ControlPrior, table: gaits.GaitTable) -> None:
    _, _, kappa, iota = table.lookup(4 / 3.6, 0.6)
    still = dataclasses.replace(prior, mu_kappa=float(kappa), kappa_noise_variance=1e-12, kappa_bar_variance=1e-12,
                                impulse_variance=1e-12, impulse_mean_coefficients=(float(iota), 0.0, 0.0, 0.0))
    quiet = control.prior_walk_statistics(PARAMS, still, table, 4 / 3.6, 0.6, n=20, steps=8)
    assert quiet["fraction_fallen"] == 0.0 and quiet["median_strikes_before_fall"] is None
    assert quiet["step_length_percentiles_m"]["50"] == pytest.approx(0.6, abs=2e-3)
    assert quiet["speed_percentiles_kmh"]["50"] == pytest.approx(4.0, abs=0.02)
    noisy = control.prior_walk_statistics(PARAMS, prior, table, 5 / 3.6, 0.7, n=100, steps=8)
    assert 0.0 < noisy["fraction_fallen"] <= 1.0
    spread = noisy["step_length_percentiles_m"]
    assert spread["95"] - spread["5"] > 0.1
    assert np.isfinite(noisy["log_step_length_vs_log_speed_slope"])
