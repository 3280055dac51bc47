"""Physics of the Anthropomorphic Walker: equations of motion, impact map, integrator, batching."""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from awalker_tracker.model import dynamics
from awalker_tracker.model.walker import WalkerParams, WalkerState, foot_centres, hip_position

PARAMS = WalkerParams()
# a torso with rotational inertia exercises the torso's change of rigid group at the impact
PARAMS_TORSO = WalkerParams(leg_length=1.0, torso_inertia_ratio=0.04, gravity=9.8)


def random_states(rng: np.random.Generator, n: int) -> WalkerState:
    return WalkerState.from_arrays(rng.uniform(-0.5, 0.5, n), rng.uniform(-0.6, 0.6, n),
                                   rng.uniform(-3, 3, n), rng.uniform(-4, 4, n), rng.uniform(-1, 1, n),
                                   rng.integers(0, 2, n))


# ---------------------------------------------------------------------------------------------
# independent derivations with sympy
# ---------------------------------------------------------------------------------------------
def _sympy_lagrangian_accelerations(params: WalkerParams):
    """q'' from Lagrange's equations of three bodies written from the geometry of Fig. 2."""
    t = sp.symbols("t")
    kappa = sp.symbols("kappa")
    p1, p2 = sp.Function("p1")(t), sp.Function("p2")(t)
    R, L, C = params.foot_radius, params.leg_length, params.leg_com
    m_l, m_t, I_l, I_t, g = (params.leg_mass, params.torso_mass, params.leg_inertia, params.torso_inertia,
                             params.gravity)
    foot = sp.Matrix([-R * p1, R])                               # stance foot centre (rolls)
    up = sp.Matrix([-sp.sin(p1), sp.cos(p1)])                    # foot -> hip along the stance leg
    hip = foot + (L - R) * up
    stance_com = foot + (C - R) * up
    swing_com = hip + (L - C) * sp.Matrix([sp.sin(p2), -sp.cos(p2)])
    bodies = [(stance_com, m_l, I_l, p1), (swing_com, m_l, I_l, p2), (hip, m_t, I_t, p1)]
    kinetic = sum(m * (pos.diff(t).T * pos.diff(t))[0] / 2 + inertia * ang.diff(t) ** 2 / 2
                  for pos, m, inertia, ang in bodies)
    potential = sum(m * g * pos[1] for pos, m, _, _ in bodies) + kappa * (p2 - p1) ** 2 / 2
    lag = kinetic - potential
    eqs = [sp.diff(lag.diff(q.diff(t)), t) - lag.diff(q) for q in (p1, p2)]
    a1, a2 = sp.symbols("a1 a2")
    w1, w2, q1, q2 = sp.symbols("w1 w2 q1 q2")
    subs = {p1.diff(t, 2): a1, p2.diff(t, 2): a2}
    eqs = [e.subs(subs).subs({p1.diff(t): w1, p2.diff(t): w2}).subs({p1: q1, p2: q2}) for e in eqs]
    sol = sp.solve(eqs, [a1, a2], dict=True)[0]
    return sp.lambdify((q1, q2, w1, w2, kappa), [sol[a1], sol[a2]], "numpy")


def _sympy_tmt_accelerations(params: WalkerParams):
    """q'' from eq. (17) with k(q) of eq. (16), M of eq. (18) and I1 of eq. (19), taken literally."""
    q1, q2, w1, w2, kappa = sp.symbols("q1 q2 w1 w2 kappa")
    R, L, C = params.foot_radius, params.leg_length, params.leg_com
    m_l, m_t, I_l, I_t, g = (params.leg_mass, params.torso_mass, params.leg_inertia, params.torso_inertia,
                             params.gravity)
    C1 = (C * m_l + L * m_t) / (m_l + m_t)
    m1 = m_l + m_t
    I1 = I_l + I_t + (C1 - C) ** 2 * m_l + (L - C1) ** 2 * m_t
    q = sp.Matrix([q1, q2])
    qd = sp.Matrix([w1, w2])
    k = sp.Matrix([-R * q1 - (C1 - R) * sp.sin(q1), R + (C1 - R) * sp.cos(q1), q1,
                   -R * q1 - (L - R) * sp.sin(q1) + (L - C) * sp.sin(q2),
                   R + (L - R) * sp.cos(q1) - (L - C) * sp.cos(q2), q2])
    T = k.jacobian(q)
    M = sp.diag(m1, m1, I1, m_l, m_l, I_l)
    convective = (T * qd).jacobian(q) * qd                     # "g" of eq. (20)
    gravity = g * sp.Matrix([0, -1, 0, 0, -1, 0])
    f = kappa * sp.Matrix([q2 - q1, q1 - q2])
    lhs = T.T * M * T
    rhs = f + T.T * M * (gravity - convective)
    acc = lhs.LUsolve(rhs)
    return sp.lambdify((q1, q2, w1, w2, kappa), [acc[0], acc[1]], "numpy")


@pytest.mark.parametrize("params", [PARAMS, PARAMS_TORSO])
def test_accelerations_match_sympy_lagrangian_and_tmt(params: WalkerParams) -> None:
    rng = np.random.default_rng(1)
    state = random_states(rng, 200)
    kappa = rng.uniform(-1, 12, 200)
    ours = dynamics.accelerations(params, state, kappa)
    for derive in (_sympy_lagrangian_accelerations, _sympy_tmt_accelerations):
        ref = np.array(derive(params)(state.stance_angle, state.swing_angle, state.stance_rate,
                                      state.swing_rate, kappa)).T
        np.testing.assert_allclose(ours, ref, rtol=1e-10, atol=1e-10)


def test_mass_matrix_is_body_jacobian_product() -> None:
    rng = np.random.default_rng(2)
    state = random_states(rng, 50)
    jac = dynamics.body_jacobians(PARAMS_TORSO, state.stance_angle, state.swing_angle)
    masses = np.array([[PARAMS_TORSO.leg_mass] * 2 + [PARAMS_TORSO.leg_inertia]] * 2
                      + [[PARAMS_TORSO.torso_mass] * 2 + [PARAMS_TORSO.torso_inertia]])
    product = np.einsum("nbik,bi,nbil->nkl", jac, masses, jac)
    np.testing.assert_allclose(product, dynamics.mass_matrix(PARAMS_TORSO, state.stance_angle, state.swing_angle),
                               rtol=1e-12, atol=1e-14)


# ---------------------------------------------------------------------------------------------
# energy and integrator accuracy
# ---------------------------------------------------------------------------------------------
def test_energy_conserved_between_impacts() -> None:
    """Total energy drifts < 1e-6 of the kinetic energy over 0.3 s (10 frames at 30 Hz, 4 sub-steps).

    Justification of the bound: RK4's energy error per unit time scales as omega (h omega)^4 with
    h = 1/120 s and omega <= ~8 rad/s (pendulum and spring frequencies for kappa <= 1.5 here),
    i.e. ~2e-5 per second relative as a crude worst case; 1e-6 over 0.3 s leaves the margin we
    measure (~1e-9) yet catches any wrong force term (which gives drifts of 1e-2 and more).
    """
    rng = np.random.default_rng(3)
    n = 400
    state = WalkerState.from_arrays(rng.uniform(0.2, 0.4, n), rng.uniform(-0.4, -0.2, n),
                                    rng.uniform(-2.0, -1.2, n), rng.uniform(-1.5, 1.5, n))
    kappa = rng.uniform(0.0, 1.5, n)
    e0 = dynamics.total_energy(PARAMS, state, kappa)
    ke = dynamics.kinetic_energy(PARAMS, state)
    struck = np.zeros(n, bool)
    for _ in range(10):
        state, events = dynamics.advance(PARAMS, state, kappa, 0.0, 1.0 / 30.0)
        struck |= events.heel_strike | events.fallen
    ok = ~struck
    assert ok.sum() > 300
    drift = np.abs(dynamics.total_energy(PARAMS, state, kappa) - e0)[ok] / ke[ok]
    assert drift.max() < 1e-6


def test_energy_not_conserved_with_wrong_forces_detected() -> None:
    """Guard for the test above: the same check fails if the spring energy is left out."""
    state = WalkerState.from_arrays(0.3, -0.3, -1.6, 0.5)
    e0 = dynamics.kinetic_energy(PARAMS, state) + dynamics.potential_energy(PARAMS, state, 0.0)
    state2, _ = dynamics.advance(PARAMS, state, 1.5, 0.0, 0.1)
    e1 = dynamics.kinetic_energy(PARAMS, state2) + dynamics.potential_energy(PARAMS, state2, 0.0)
    assert abs(e1 - e0)[0] / dynamics.kinetic_energy(PARAMS, state)[0] > 1e-3


def test_rk4_error_shrinks_16x_when_halving_the_step() -> None:
    state = WalkerState.from_arrays([0.3, 0.25], [-0.3, -0.1], [-1.6, -1.2], [0.4, 1.5])
    kappa = np.array([0.8, 3.0])
    duration = 0.24

    def run(substeps: int) -> np.ndarray:
        s, events = dynamics.advance(PARAMS, state, kappa, 0.0, duration, substeps=substeps)
        assert not events.heel_strike.any()
        return np.stack([s.stance_angle, s.swing_angle, s.stance_rate, s.swing_rate], 1)

    reference = run(512)
    errors = [np.abs(run(n) - reference).max() for n in (4, 8, 16)]
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    for r in ratios:
        assert 11.0 < r < 22.0, (errors, ratios)


# ---------------------------------------------------------------------------------------------
# impact map
# ---------------------------------------------------------------------------------------------
def _bodies(params: WalkerParams, p_st, p_sw, w_st, w_sw):
    """Positions, velocities, masses, inertias and rates of (stance leg, swing leg, torso), by hand."""
    R, L, C = params.foot_radius, params.leg_length, params.leg_com
    foot = np.stack([-R * p_st, np.full_like(p_st, R)], -1)
    foot_v = np.stack([-R * w_st, np.zeros_like(p_st)], -1)
    up = np.stack([-np.sin(p_st), np.cos(p_st)], -1)
    up_v = np.stack([-np.cos(p_st), -np.sin(p_st)], -1) * w_st[:, None]
    hip, hip_v = foot + (L - R) * up, foot_v + (L - R) * up_v
    st, st_v = foot + (C - R) * up, foot_v + (C - R) * up_v
    down = np.stack([np.sin(p_sw), -np.cos(p_sw)], -1)
    down_v = np.stack([np.cos(p_sw), np.sin(p_sw)], -1) * w_sw[:, None]
    sw, sw_v = hip + (L - C) * down, hip_v + (L - C) * down_v
    return [(st, st_v, params.leg_mass, params.leg_inertia, w_st),
            (sw, sw_v, params.leg_mass, params.leg_inertia, w_sw),
            (hip, hip_v, params.torso_mass, params.torso_inertia, w_st)], hip


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _angular_momentum(bodies, point):
    return sum(m * _cross(pos - point, vel) + inertia * w for pos, vel, m, inertia, w in bodies)


def _pre_impact_states(rng, n):
    a = rng.uniform(0.15, 0.5, n)
    return WalkerState.from_arrays(-a, a, rng.uniform(-2.5, -0.8, n), rng.uniform(-2.5, 1.0, n),
                                   rng.uniform(-2, 2, n), rng.integers(0, 2, n))


@pytest.mark.parametrize("params", [PARAMS, PARAMS_TORSO])
def test_impact_without_toe_off_conserves_angular_momenta(params: WalkerParams) -> None:
    rng = np.random.default_rng(4)
    pre = _pre_impact_states(rng, 300)
    post = dynamics.heel_strike(params, pre, 0.0)
    # frames: pre-impact coordinates relative to the old rolling origin; post relative to the new one
    bodies_pre, hip_pre = _bodies(params, pre.stance_angle, pre.swing_angle, pre.stance_rate, pre.swing_rate)
    bodies_post, hip_post = _bodies(params, post.stance_angle, post.swing_angle, post.stance_rate, post.swing_rate)
    shift = (post.contact_origin - pre.contact_origin)[:, None] * np.array([1.0, 0.0])
    np.testing.assert_allclose(hip_post + shift, hip_pre, atol=1e-12)   # same configuration
    contact = np.stack([-params.foot_radius * post.stance_angle, np.zeros(len(pre))], -1)  # post frame
    # whole walker about the new contact point
    h_pre = _angular_momentum(bodies_pre, contact + shift)
    h_post = _angular_momentum(bodies_post, contact)
    np.testing.assert_allclose(h_post, h_pre, rtol=1e-10, atol=1e-12)
    # trailing leg (old stance = new swing) about the hip
    trailing_pre = _angular_momentum([bodies_pre[0]], hip_pre)
    trailing_post = _angular_momentum([bodies_post[1]], hip_post)
    np.testing.assert_allclose(trailing_post, trailing_pre, rtol=1e-10, atol=1e-12)
    # inelastic: kinetic energy never increases
    ke_pre, ke_post = dynamics.kinetic_energy(params, pre), dynamics.kinetic_energy(params, post)
    assert np.all(ke_post <= ke_pre + 1e-12)
    assert np.mean(ke_post < ke_pre - 1e-6) > 0.9


def test_impact_swaps_legs_and_moves_origin_to_the_swing_foot() -> None:
    rng = np.random.default_rng(5)
    pre = _pre_impact_states(rng, 50)
    post = dynamics.heel_strike(PARAMS, pre, rng.uniform(0, 0.5, 50))
    np.testing.assert_array_equal(post.stance_angle, pre.swing_angle)
    np.testing.assert_array_equal(post.swing_angle, pre.stance_angle)
    np.testing.assert_array_equal(post.stance_leg, 1 - pre.stance_leg)
    (_, _), (swing_x, _) = foot_centres(PARAMS, pre)
    new_contact = post.contact_origin - PARAMS.foot_radius * post.stance_angle
    np.testing.assert_allclose(new_contact, swing_x, atol=1e-12)
    a = pre.swing_angle
    np.testing.assert_allclose(post.contact_origin - pre.contact_origin,
                               2 * (PARAMS.foot_radius * a + (PARAMS.leg_length - PARAMS.foot_radius) * np.sin(a)))
    np.testing.assert_allclose(hip_position(PARAMS, post)[0], hip_position(PARAMS, pre)[0], atol=1e-12)


def test_toe_off_adds_momentum_along_the_stance_leg() -> None:
    """With iota the generalised impulse is J_hip^T iota e: check via the hip velocity change."""
    rng = np.random.default_rng(6)
    pre = _pre_impact_states(rng, 100)
    iota = rng.uniform(0.05, 0.6, 100)
    passive = dynamics.heel_strike(PARAMS, pre, 0.0)
    pushed = dynamics.heel_strike(PARAMS, pre, iota)
    # momentum about the new contact point grows by the moment of the push (applied at the hip)
    bodies_a, hip = _bodies(PARAMS, passive.stance_angle, passive.swing_angle, passive.stance_rate, passive.swing_rate)
    bodies_b, _ = _bodies(PARAMS, pushed.stance_angle, pushed.swing_angle, pushed.stance_rate, pushed.swing_rate)
    contact = np.stack([-PARAMS.foot_radius * passive.stance_angle, np.zeros(100)], -1)
    push = iota[:, None] * np.stack([-np.sin(pre.stance_angle), np.cos(pre.stance_angle)], -1)
    expected = _cross(hip - contact, push)
    np.testing.assert_allclose(_angular_momentum(bodies_b, contact) - _angular_momentum(bodies_a, contact),
                               expected, rtol=1e-9, atol=1e-12)
    # forward walking (phi1' < 0) is sped up, and the push does positive work
    assert np.all(pushed.stance_rate < passive.stance_rate)
    assert np.all(dynamics.kinetic_energy(PARAMS, pushed) > dynamics.kinetic_energy(PARAMS, passive))


# ---------------------------------------------------------------------------------------------
# batched stepping, strike location, falls
# ---------------------------------------------------------------------------------------------
def walking_states(rng: np.random.Generator, n: int) -> WalkerState:
    """Perturbations of the 5 km/h, 0.7 m cyclic gait (a = 0.39 rad, rates -1.91, -1.30 rad/s)."""
    a = rng.uniform(0.37, 0.41, n)
    return WalkerState.from_arrays(a, -a, rng.uniform(-1.95, -1.85, n), rng.uniform(-1.35, -1.25, n),
                                   rng.uniform(-1, 1, n), rng.integers(0, 2, n))


def test_batched_step_equals_single_steps() -> None:
    rng = np.random.default_rng(7)
    n = 40
    state = walking_states(rng, n)
    kappa, iota = rng.uniform(0.6, 0.9, n), rng.uniform(0.35, 0.45, n)
    batch, tss = state, np.zeros(n)
    singles = [state.take(np.array([i])) for i in range(n)]
    single_tss = [np.zeros(1) for _ in range(n)]
    strikes = 0
    for _ in range(30):
        batch, ev = dynamics.advance(PARAMS, batch, kappa, iota, 1 / 30, time_since_strike=tss)
        tss = ev.time_since_strike
        strikes += ev.heel_strike.sum()
        for i in range(n):
            singles[i], sev = dynamics.advance(PARAMS, singles[i], kappa[i], iota[i], 1 / 30,
                                               time_since_strike=single_tss[i])
            single_tss[i] = sev.time_since_strike
            assert sev.heel_strike[0] == ev.heel_strike[i]
            assert sev.strike_fraction[0] == pytest.approx(ev.strike_fraction[i], abs=1e-12)
    assert strikes >= n  # every walker struck at least once in one second
    for name in ("stance_angle", "swing_angle", "stance_rate", "swing_rate", "contact_origin", "stance_leg"):
        np.testing.assert_allclose(getattr(batch, name), np.concatenate([getattr(s, name) for s in singles]),
                                   rtol=1e-12, atol=1e-12)


def test_strike_located_inside_the_frame() -> None:
    """Strike time from 30 Hz frames (4 sub-steps) matches a fine-step simulation to < 1e-6 s."""
    rng = np.random.default_rng(8)
    n = 30
    state = walking_states(rng, n)
    kappa, iota = rng.uniform(0.6, 0.9, n), 0.4
    _, fine_times, _ = dynamics.simulate_to_strike(PARAMS, state, kappa, iota, step=1 / 4000)
    strike_time = np.full(n, np.nan)
    s = state
    for frame in range(40):
        s, ev = dynamics.advance(PARAMS, s, kappa, iota, 1 / 30)
        first = ev.heel_strike & np.isnan(strike_time)
        strike_time[first] = (frame + ev.strike_fraction[first]) / 30
    assert np.all(np.isfinite(fine_times))
    np.testing.assert_allclose(strike_time, fine_times, atol=1e-6)


def test_fallen_walkers_flagged_and_frozen() -> None:
    # 0: falls backwards (rate pushes the stance leg forward past horizontal); 1: walks; 2: no strike too long
    a = 0.39608  # the 5 km/h, 0.7 m cyclic gait for walker 1 (see test_cyclic_gaits.py)
    state = WalkerState.from_arrays([0.3, a, 0.1], [-0.3, -a, -0.1], [12.0, -1.9093, -0.001], [0.0, -1.3005, 0.0])
    tss = np.array([0.0, 0.0, 1.99])
    fallen_ever = np.zeros(3, bool)
    for _ in range(30):
        before = state.copy()
        state, ev = dynamics.advance(PARAMS, state, 0.749, 0.398, 1 / 30, time_since_strike=tss)
        tss = ev.time_since_strike
        assert np.all(np.isfinite(state.stance_angle)) and np.all(np.isfinite(state.swing_rate))
        for i in np.flatnonzero(ev.fallen):
            assert state.stance_angle[i] == before.stance_angle[i] and state.stance_rate[i] == before.stance_rate[i]
            assert not ev.heel_strike[i]
        fallen_ever |= ev.fallen
    assert fallen_ever.tolist() == [True, False, True]


# ---------------------------------------------------------------------------------------------
# compiled kernels against straightforward references
# ---------------------------------------------------------------------------------------------
def test_compiled_integration_matches_an_adaptive_reference() -> None:
    """advance's RK4 kernel against scipy's DOP853 on eq. (17) (accelerations: checked with sympy above)."""
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(11)
    n = 12
    state = random_states(rng, n)
    state = WalkerState.from_arrays(0.5 * state.stance_angle, 0.5 * state.swing_angle, state.stance_rate,
                                    state.swing_rate)
    kappa = rng.uniform(0.0, 2.0, n)
    duration = 0.05
    ours, events = dynamics.advance(PARAMS, state, kappa, 0.0, duration, substeps=32)
    for i in np.flatnonzero(~events.heel_strike & ~events.fallen):
        def rhs(_t, y, i=i):
            s = WalkerState.from_arrays(*y)
            return np.concatenate([y[2:], dynamics.accelerations(PARAMS, s, kappa[i])[0]])
        y0 = [state.stance_angle[i], state.swing_angle[i], state.stance_rate[i], state.swing_rate[i]]
        ref = solve_ivp(rhs, (0.0, duration), y0, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
        got = [ours.stance_angle[i], ours.swing_angle[i], ours.stance_rate[i], ours.swing_rate[i]]
        np.testing.assert_allclose(got, ref, atol=1e-8)


def _reference_impact_rates(params: WalkerParams, pre: WalkerState, iota: np.ndarray) -> np.ndarray:
    """The impact map written with the body Jacobians and a linear solve (module docstring of dynamics)."""
    p1, p2 = pre.stance_angle, pre.swing_angle
    masses = np.array([[params.leg_mass] * 2 + [params.leg_inertia]] * 2
                      + [[params.torso_mass] * 2 + [params.torso_inertia]])
    pre_vel = dynamics.body_jacobians(params, p1, p2) @ np.stack([pre.stance_rate, pre.swing_rate], -1)[:, None, :, None]
    post_jac = dynamics.body_jacobians(params, p2, p1)          # new stance (= old swing), new swing, torso
    momentum = masses[None] * pre_vel[..., 0][:, [1, 0, 2]]
    rhs = np.einsum("nbik,nbi->nk", post_jac, momentum)
    push = iota[:, None] * np.stack([-np.sin(p1), np.cos(p1)], -1)
    rhs = rhs + np.einsum("nik,ni->nk", post_jac[:, 2, :2, :], push)
    return np.linalg.solve(dynamics.mass_matrix(params, p2, p1), rhs[..., None])[..., 0]


@pytest.mark.parametrize("params", [PARAMS, PARAMS_TORSO])
def test_compiled_impact_matches_the_jacobian_form(params: WalkerParams) -> None:
    rng = np.random.default_rng(12)
    pre = _pre_impact_states(rng, 200)
    iota = rng.uniform(0.0, 0.6, 200)
    post = dynamics.heel_strike(params, pre, iota)
    np.testing.assert_allclose(np.stack([post.stance_rate, post.swing_rate], -1),
                               _reference_impact_rates(params, pre, iota), rtol=1e-11, atol=1e-12)


def test_a_stance_leg_leaning_beyond_any_step_counts_as_fallen() -> None:
    """fallen_mask: a stance leg leaning past MAX_STANCE_LEAN (0.9 rad) is a fall, forwards or backwards,
    while every step the gait table solves (up to 1.2 m, for this leg length) strikes well within it."""
    from awalker_tracker.model.cyclic_gaits import double_support_angle

    lean = dynamics.MAX_STANCE_LEAN
    state = WalkerState.from_arrays([lean + 0.02, -lean - 0.02, lean - 0.02, 0.3], [-0.3, 0.3, -0.3, -0.3],
                                    [0.0, 0.0, 0.0, -1.0], [0.0, 0.0, 0.0, 1.0])
    assert dynamics.fallen_mask(PARAMS, state).tolist() == [True, True, False, False]
    assert float(double_support_angle(PARAMS, 1.2)) < lean - 0.1


def test_step_events_take_rows_of_every_field():
    """``StepEvents.take``: the events of the walkers asked for, every field cut alike (the adaptive particle
    count keeps a subset of a frame's particles with their events)."""
    from dataclasses import fields

    n = 5
    events = dynamics.StepEvents(
        heel_strike=np.array([True, False, True, False, False]), strike_fraction=np.arange(n) / 10,
        strike_position=np.arange(n) + 0.5, fallen=np.array([False, False, False, True, False]),
        time_since_strike=np.arange(n) * 0.1, toe_off_impulse=np.arange(n) * 0.01,
        pre_strike_rates=np.arange(2 * n, dtype=float).reshape(n, 2))
    rows = np.array([3, 0, 3])
    taken = events.take(rows)
    for f in fields(events):
        assert np.array_equal(getattr(taken, f.name), getattr(events, f.name)[rows]), f.name
