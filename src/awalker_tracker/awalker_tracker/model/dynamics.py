"""Anthropomorphic Walker dynamics: equations of motion, heel strike with toe-off, batched RK4.

Paper Sec. 4.1 and Appendices A-B, in the conventions of :mod:`walker` (SI, per unit body mass).

Equations of motion (eq. 1 / 17). With a = L - R (foot centre to hip), c = C - R (foot centre
to leg centre of mass) and b = L - C (hip to leg centre of mass), the kinetic energy of the
three bodies (stance leg, swing leg, torso point at the hip rotating with the stance leg) is
1/2 q'^T M(q) q' with

    M11 = A + B cos(phi1),   A = m_l (R^2 + c^2) + (m_l + m_t)(R^2 + a^2) + I_l + I_t,
                             B = 2 R (m_l c + (m_l + m_t) a)
    M12 = -m_l b (R cos(phi2) + a cos(phi1 - phi2))
    M22 = m_l b^2 + I_l,

which is T^T M T of eq. (17) (same bodies, T = dk/dq of eq. 16). The convective term of (17)
and gravity give, per unit mass,

    M q'' = [ B/2 sin(phi1) phi1'^2 - m_l b phi2'^2 (R sin(phi2) - a sin(phi1 - phi2)) + G1 sin(phi1)
              + kappa (phi2 - phi1),
              -m_l b a sin(phi1 - phi2) phi1'^2 - G2 sin(phi2) - kappa (phi2 - phi1) ]

with G1 = g (m_l c + (m_l + m_t) a) and G2 = g m_l b. test_walker_dynamics.py re-derives this
with a sympy Lagrangian and with the TMT form of eq. (17).

Heel strike (eq. 2, 21-26, re-derived). The printed eq. (22) pairs the bodies of k+ with the
wrong masses, and the torso changes rigid group at the impact, so the map is written over
three bodies (old stance leg, old swing leg, torso) whose pre-impact velocities V- are known:
the post-impact generalised velocities q'+ (new coordinates: phi1+ = phi2-, phi2+ = phi1-)
satisfy, for every virtual velocity allowed after the impact (new foot rolling, hip joint intact),

    sum_b J+_b^T M_b (J+_b q'+ - V-_b) = J+_hip^T (iota e),   e = (-sin phi1-, cos phi1-),

i.e. M(q+) q'+ = sum_b J+_b^T M_b V-_b + J+_hip^T iota e. The toe-off impulse iota (m/s per
unit mass) acts along the old stance leg (paper eq. 23); every point of that leg's axis has the
same velocity along the axis, so only its magnitude and direction matter. With iota = 0 the
virtual velocity (1, 1) is a rotation about the new contact point and (0, 1) a rotation of the
trailing leg about the hip: their angular momenta are conserved and kinetic energy cannot grow.

Integration: fixed-step RK4 with ``substeps`` sub-steps per frame; a heel strike (zero crossing
of phi1 + phi2 going down with phi1 < 0) is located inside the sub-step by Newton iteration on
the fraction of the sub-step, the impact applied there, and the rest of the sub-step integrated
from the post-impact state. At most one heel strike per walker per call: a step of the walker
lasts > 0.3 s, far longer than a 1/30 s or 1/60 s frame.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .walker import WalkerParams, WalkerState

#: Walkers are flagged fallen when no heel strike happened for this long (s).
MAX_STRIKE_INTERVAL = 2.0
#: Largest RK4 sub-step (s) used when ``substeps`` is not given: 4 sub-steps per 1/30 s frame.
DEFAULT_MAX_SUBSTEP = 1.0 / 120.0


@dataclass(frozen=True)
class _Consts:
    """Per-parameter constants of the equations of motion (see module docstring)."""

    R: float
    a: float
    c: float
    b: float
    A: float
    B: float
    mlb: float
    M22: float
    G1: float
    G2: float
    g: float
    m_l: float
    m_t: float
    I_l: float
    I_t: float


_CONSTS_CACHE: dict[WalkerParams, _Consts] = {}


def _consts(params: WalkerParams) -> _Consts:
    cached = _CONSTS_CACHE.get(params)
    if cached is not None:
        return cached
    R, L, C = params.foot_radius, params.leg_length, params.leg_com
    m_l, m_t, I_l, I_t, g = params.leg_mass, params.torso_mass, params.leg_inertia, params.torso_inertia, params.gravity
    a, c, b = L - R, C - R, L - C
    m1 = m_l + m_t
    consts = _Consts(
        R=R, a=a, c=c, b=b,
        A=m_l * (R * R + c * c) + m1 * (R * R + a * a) + I_l + I_t,
        B=2.0 * R * (m_l * c + m1 * a),
        mlb=m_l * b,
        M22=m_l * b * b + I_l,
        G1=g * (m_l * c + m1 * a),
        G2=g * m_l * b,
        g=g, m_l=m_l, m_t=m_t, I_l=I_l, I_t=I_t,
    )
    _CONSTS_CACHE[params] = consts
    return consts


def _acc(k: _Consts, p1: np.ndarray, p2: np.ndarray, w1: np.ndarray, w2: np.ndarray,
         kappa: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """q'' (rad/s^2) of eq. (17) on raw arrays."""
    return _acc_trig(k, np.sin(p1), np.cos(p1), np.sin(p2), np.cos(p2), p2 - p1, w1, w2, kappa)


def _acc_trig(k: _Consts, s1, c1, s2, c2, gap, w1, w2, kappa) -> tuple[np.ndarray, np.ndarray]:
    """q'' from sin/cos of phi1, phi2 and gap = phi2 - phi1; the hot loop of the tracker."""
    sd = s1 * c2 - c1 * s2                 # sin(phi1 - phi2)
    cd = c1 * c2 + s1 * s2                 # cos(phi1 - phi2)
    m11 = k.A + k.B * c1
    m12 = -k.mlb * (k.R * c2 + k.a * cd)
    spring = kappa * gap
    w1sq = w1 * w1
    r1 = (0.5 * k.B * w1sq + k.G1) * s1 - k.mlb * (w2 * w2) * (k.R * s2 - k.a * sd) + spring
    r2 = -k.mlb * k.a * sd * w1sq - k.G2 * s2 - spring
    inv_det = 1.0 / (m11 * k.M22 - m12 * m12)
    return (k.M22 * r1 - m12 * r2) * inv_det, (m11 * r2 - m12 * r1) * inv_det


def _rotate(s: np.ndarray, c: np.ndarray, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sin, cos) of angle + delta from (sin, cos) of angle, with Taylor series for delta.

    RK4 stage angles differ from the sub-step's start by |delta| = |h phi'| (< 0.1 rad when walking
    at h = 1/120 s); the series to delta^10 is exact to < 1e-15 there (< 3e-8 even at |delta| = 1)
    and is ~20x cheaper than numpy's sin/cos on the stage angles.
    """
    d2 = delta * delta
    sin_d = delta * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0 * (1.0 - d2 / 72.0 * (1.0 - d2 / 110.0)))))
    cos_d = 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0 * (1.0 - d2 / 56.0 * (1.0 - d2 / 90.0))))
    return s * cos_d + c * sin_d, c * cos_d - s * sin_d


def mass_matrix(params: WalkerParams, stance_angle: np.ndarray, swing_angle: np.ndarray) -> np.ndarray:
    """Generalised mass matrix M(q) = T^T M T (m^2 per unit mass), shape (N, 2, 2)."""
    k = _consts(params)
    p1, p2 = np.asarray(stance_angle, float), np.asarray(swing_angle, float)
    m11 = k.A + k.B * np.cos(p1)
    m12 = -k.mlb * (k.R * np.cos(p2) + k.a * np.cos(p1 - p2))
    m22 = np.full_like(m11, k.M22)
    return np.stack([np.stack([m11, m12], -1), np.stack([m12, m22], -1)], -2)


def accelerations(params: WalkerParams, state: WalkerState, stiffness: np.ndarray | float) -> np.ndarray:
    """Angular accelerations (phi1'', phi2'') in rad/s^2 of eq. (17), shape (N, 2).

    ``stiffness`` kappa: hip spring stiffness, N m/rad per kg, scalar or (N,).
    """
    a1, a2 = _acc(_consts(params), state.stance_angle, state.swing_angle, state.stance_rate,
                  state.swing_rate, np.asarray(stiffness, float))
    return np.stack([a1, a2], axis=1)


def potential_energy(params: WalkerParams, state: WalkerState, stiffness: np.ndarray | float) -> np.ndarray:
    """Gravitational (ground = 0) plus spring energy, J/kg, shape (N,)."""
    k = _consts(params)
    p1, p2 = state.stance_angle, state.swing_angle
    height = (k.m_l * (k.R + k.c * np.cos(p1)) + k.m_t * (k.R + k.a * np.cos(p1))
              + k.m_l * (k.R + k.a * np.cos(p1) - k.b * np.cos(p2)))
    return k.g * height + 0.5 * np.asarray(stiffness, float) * (p2 - p1) ** 2


def kinetic_energy(params: WalkerParams, state: WalkerState) -> np.ndarray:
    """1/2 q'^T M(q) q' (J/kg), shape (N,)."""
    k = _consts(params)
    p1, p2, w1, w2 = state.stance_angle, state.swing_angle, state.stance_rate, state.swing_rate
    m11 = k.A + k.B * np.cos(p1)
    m12 = -k.mlb * (k.R * np.cos(p2) + k.a * np.cos(p1 - p2))
    return 0.5 * (m11 * w1 * w1 + 2.0 * m12 * w1 * w2 + k.M22 * w2 * w2)


def total_energy(params: WalkerParams, state: WalkerState, stiffness: np.ndarray | float) -> np.ndarray:
    """Kinetic + gravitational + kappa/2 (phi2 - phi1)^2, J/kg, shape (N,)."""
    return kinetic_energy(params, state) + potential_energy(params, state, stiffness)


def body_jacobians(params: WalkerParams, stance_angle: np.ndarray, swing_angle: np.ndarray) -> np.ndarray:
    """Velocity Jacobians of the three bodies w.r.t. (phi1', phi2'), shape (N, 3, 3, 2).

    Bodies (axis 1): stance leg centre of mass, swing leg centre of mass, torso (at the hip,
    rotating with the stance leg). Components (axis 2): x', y' (m/s), angular rate (rad/s).
    """
    k = _consts(params)
    p1 = np.atleast_1d(np.asarray(stance_angle, float))
    p2 = np.atleast_1d(np.asarray(swing_angle, float))
    zero, one = np.zeros_like(p1), np.ones_like(p1)
    hip_dx, hip_dy = -(k.R + k.a * np.cos(p1)), -k.a * np.sin(p1)
    stance = [[-(k.R + k.c * np.cos(p1)), zero], [-k.c * np.sin(p1), zero], [one, zero]]
    swing = [[hip_dx, k.b * np.cos(p2)], [hip_dy, k.b * np.sin(p2)], [zero, one]]
    torso = [[hip_dx, zero], [hip_dy, zero], [one, zero]]
    return np.moveaxis(np.array([stance, swing, torso], dtype=float), -1, 0)


def _body_masses(params: WalkerParams) -> np.ndarray:
    """diag(M_b) per body (stance leg, swing leg, torso), shape (3, 3)."""
    k = _consts(params)
    return np.array([[k.m_l, k.m_l, k.I_l], [k.m_l, k.m_l, k.I_l], [k.m_t, k.m_t, k.I_t]])


def _impact_rates(params: WalkerParams, p1: np.ndarray, p2: np.ndarray, w1: np.ndarray, w2: np.ndarray,
                  iota: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Post-impact (new stance, new swing) rates from pre-impact angles/rates and toe-off iota."""
    masses = _body_masses(params)
    pre_jac = body_jacobians(params, p1, p2)                    # bodies: old stance, old swing, torso
    pre_vel = pre_jac @ np.stack([w1, w2], -1)[:, None, :, None]  # (N, 3, 3, 1)
    post_jac = body_jacobians(params, p2, p1)                   # bodies: new stance (= old swing), new swing, torso
    pre_matched = pre_vel[..., 0][:, [1, 0, 2]]                 # reorder to the post-impact bodies
    momentum = masses[None] * pre_matched                       # (N, 3, 3)
    rhs = np.einsum("nbik,nbi->nk", post_jac, momentum)
    # toe-off impulse along the old stance leg, applied through the hip (torso row of post_jac)
    push = iota[:, None] * np.stack([-np.sin(p1), np.cos(p1)], -1)
    rhs = rhs + np.einsum("nik,ni->nk", post_jac[:, 2, :2, :], push)
    rates = np.linalg.solve(mass_matrix(params, p2, p1), rhs[..., None])[..., 0]
    return rates[:, 0], rates[:, 1]


def heel_strike(params: WalkerParams, state: WalkerState, toe_off_impulse: np.ndarray | float) -> WalkerState:
    """Impact map at heel strike: toe-off, inelastic collision, leg swap (paper eq. 2, App. B).

    ``state`` is the pre-impact state (phi1 + phi2 = 0, phi1 < 0 for a regular strike);
    ``toe_off_impulse`` iota in m/s (impulse per unit mass), scalar or (N,). Returns the
    post-impact state: angles and rates swapped to the new stance/swing legs, ``stance_leg``
    flipped and ``contact_origin`` moved to where the new stance foot rolls from, so that the
    new contact point is the old swing foot's lowest point.
    """
    p1, p2 = state.stance_angle, state.swing_angle
    iota = np.broadcast_to(np.asarray(toe_off_impulse, float), p1.shape)
    w1n, w2n = _impact_rates(params, p1, p2, state.stance_rate, state.swing_rate, iota)
    k = _consts(params)
    # new contact x = hip x + (L-R) sin phi2 = origin - R phi1 - a sin phi1 + a sin phi2; new origin = contact + R phi2
    new_origin = state.contact_origin - k.R * p1 - k.a * np.sin(p1) + k.a * np.sin(p2) + k.R * p2
    return WalkerState(
        stance_angle=p2.copy(), swing_angle=p1.copy(), stance_rate=w1n, swing_rate=w2n,
        contact_origin=new_origin, stance_leg=(1 - state.stance_leg).astype(np.int8),
    )


def impulse_for_stance_rate(params: WalkerParams, pre_state: WalkerState,
                            stance_rate: np.ndarray | float) -> np.ndarray:
    """Toe-off iota (m/s) that gives the new stance leg the rate ``stance_rate`` (rad/s) after the impact.

    ``pre_state``: walkers just before their heel strike. The post-impact rates are affine in iota
    (the impulse enters the momentum balance linearly), so two impacts (iota = 0 and 1) give it.
    May be negative when even iota = 0 leaves the new stance leg faster than asked.
    """
    p1, p2, w1, w2 = pre_state.stance_angle, pre_state.swing_angle, pre_state.stance_rate, pre_state.swing_rate
    zero, _ = _impact_rates(params, p1, p2, w1, w2, np.zeros_like(p1))
    one, _ = _impact_rates(params, p1, p2, w1, w2, np.ones_like(p1))
    return (np.asarray(stance_rate, float) - zero) / (one - zero)


@dataclass
class StepEvents:
    """What happened to each of N walkers during one :func:`advance` call."""

    heel_strike: np.ndarray        # (N,) bool: a heel strike happened in this frame
    strike_fraction: np.ndarray    # (N,) float in [0, 1): when, as a fraction of the frame (0 if none)
    strike_position: np.ndarray    # (N,) float: sagittal x (m) of the new contact point (NaN if none)
    fallen: np.ndarray             # (N,) bool: walker fell (state frozen at the frame start)
    time_since_strike: np.ndarray  # (N,) s since the last heel strike, at the end of the frame
    toe_off_impulse: np.ndarray    # (N,) iota (m/s) applied at the strike (NaN if none)
    pre_strike_rates: np.ndarray   # (N, 2) (phi1', phi2') just before the strike (NaN if none)


#: iota given as a function of (walker indices, pre-impact states of those walkers) -> iota (m/s)
ImpulseSampler = Callable[[np.ndarray, WalkerState], np.ndarray]


def _rk4(k: _Consts, p1, p2, w1, w2, kappa, h):
    """One classical RK4 step of size h (scalar or array) for the raw state arrays.

    Stage angles are q + delta; their sines/cosines come from the step start's by :func:`_rotate`.
    Both angles (and rates) are stacked in (2, N) arrays so that each numpy call serves both
    legs (the arrays are small: the cost is mostly per call). Returns rows of (2, N) arrays.
    """
    q = np.stack(np.broadcast_arrays(p1, p2))          # (phi1, phi2)
    w = np.stack(np.broadcast_arrays(w1, w2))          # (phi1', phi2')
    sin, cos = np.sin(q), np.cos(q)
    gap = q[1] - q[0]
    hh = 0.5 * h
    a = np.stack(_acc_trig(k, sin[0], cos[0], sin[1], cos[1], gap, w[0], w[1], kappa))
    # stage 2: q + h/2 q'
    d = hh * w
    s_, c_ = _rotate(sin, cos, d)
    v = w + hh * a
    b = np.stack(_acc_trig(k, s_[0], c_[0], s_[1], c_[1], gap + (d[1] - d[0]), v[0], v[1], kappa))
    # stage 3: q + h/2 (q' + h/2 a)
    e = hh * v
    s_, c_ = _rotate(sin, cos, e)
    u = w + hh * b
    g = np.stack(_acc_trig(k, s_[0], c_[0], s_[1], c_[1], gap + (e[1] - e[0]), u[0], u[1], kappa))
    # stage 4: q + h (q' + h/2 b)
    f = h * u
    s_, c_ = _rotate(sin, cos, f)
    z = w + h * g
    j = np.stack(_acc_trig(k, s_[0], c_[0], s_[1], c_[1], gap + (f[1] - f[0]), z[0], z[1], kappa))
    h6 = h / 6.0
    new_q = q + h6 * (w + 2.0 * (v + u) + z)
    new_w = w + h6 * (a + 2.0 * (b + g) + j)
    return new_q[0], new_q[1], new_w[0], new_w[1]


def _locate_strike(k: _Consts, p1, p2, w1, w2, kappa, h, s0, s1, iterations: int = 8):
    """Fraction theta in [0, 1] of a sub-step at which phi1 + phi2 = 0 (Newton from the secant guess)."""
    theta = np.clip(s0 / (s0 - s1), 0.0, 1.0)
    for _ in range(iterations):
        q1, q2, v1, v2 = _rk4(k, p1, p2, w1, w2, kappa, theta * h)
        f = q1 + q2
        slope = h * (v1 + v2)
        safe = np.where(slope < -1e-12, slope, -1e-12)
        step = f / safe
        theta = np.clip(theta - step, 0.0, 1.0)
        if np.all(np.abs(f) < 1e-11):  # the step just taken brings |f| to ~1e-16 (rate ~5e-4 per step)
            break
    return theta


def _impact_at_root(params: WalkerParams, k: _Consts, walker_idx: np.ndarray, p1, p2, w1, w2, origin, leg,
                    kappa, iota, h, s0, s1):
    """Locate the strike inside a sub-step of size h starting at (p1..w2) (arrays of the candidates) and apply it.

    ``walker_idx`` are the candidates' indices among all walkers (for an impulse sampler); ``kappa``
    and ``iota`` are already restricted to the candidates (or scalars / a sampler). Returns (valid,
    theta, post-impact state, strike x, pre-impact rates (v1, v2), iota used); entries where
    ``valid`` is False (no regular strike: phi1 >= 0 at the root) must be ignored.
    """
    theta = _locate_strike(k, p1, p2, w1, w2, kappa, h, s0, s1)
    q1, q2, v1, v2 = _rk4(k, p1, p2, w1, w2, kappa, theta * h)
    valid = (q1 < 0.0) & (v1 + v2 < 0.0)
    pre = WalkerState(q1, q2, v1, v2, origin, leg)
    used = np.asarray(iota(walker_idx, pre), float) if callable(iota) else iota
    used = np.broadcast_to(used, walker_idx.shape)
    post = heel_strike(params, pre, used)
    strike_x = post.contact_origin - k.R * post.stance_angle
    return valid, theta, post, strike_x, (v1, v2), used


def fallen_mask(params: WalkerParams, state: WalkerState, time_since_strike: np.ndarray | None = None,
                max_strike_interval: float = MAX_STRIKE_INTERVAL) -> np.ndarray:
    """Walkers that have fallen: non-finite state, a leg past horizontal, hip below ground, or no strike for long."""
    k = _consts(params)
    p1, p2 = state.stance_angle, state.swing_angle
    finite = np.isfinite(p1) & np.isfinite(p2) & np.isfinite(state.stance_rate) & np.isfinite(state.swing_rate)
    with np.errstate(invalid="ignore"):
        bad = ~finite | (np.abs(p1) > 0.5 * np.pi) | (np.abs(p2) > 0.5 * np.pi) | (k.R + k.a * np.cos(p1) < 0.0)
        if time_since_strike is not None:
            bad |= np.asarray(time_since_strike) > max_strike_interval
    return bad


def substeps_for(dt: float) -> int:
    """Default number of RK4 sub-steps for a frame of dt seconds (sub-step <= 1/120 s)."""
    return max(1, int(np.ceil(dt / DEFAULT_MAX_SUBSTEP - 1e-9)))


def advance(
    params: WalkerParams,
    state: WalkerState,
    stiffness: np.ndarray | float,
    toe_off_impulse: np.ndarray | float | ImpulseSampler,
    dt: float,
    substeps: int | None = None,
    time_since_strike: np.ndarray | None = None,
    max_strike_interval: float = MAX_STRIKE_INTERVAL,
) -> tuple[WalkerState, StepEvents]:
    """Advance N walkers by one frame of ``dt`` seconds with RK4 sub-steps and heel strikes.

    ``stiffness`` kappa (N m/rad per kg) and ``toe_off_impulse`` iota (m/s) are scalars or (N,)
    and held constant over the frame; iota is used if the walker strikes in this frame. iota may
    also be an :data:`ImpulseSampler`, called once per frame with the striking walkers' pre-impact states.
    ``substeps`` defaults to :func:`substeps_for` (4 per 1/30 s). ``time_since_strike`` (s, (N,))
    carries the no-strike fall criterion between calls; it is returned updated in the events.
    Fallen walkers keep their input state (frozen, never NaN) and are flagged in the events.
    """
    n = len(state)
    k = _consts(params)
    substeps = substeps_for(dt) if substeps is None else int(substeps)
    if substeps < 1:
        raise ValueError("substeps must be >= 1")
    h = dt / substeps
    kappa = np.asarray(stiffness, float)
    if kappa.ndim:
        kappa = np.broadcast_to(kappa, (n,))
    iota = toe_off_impulse if callable(toe_off_impulse) else np.asarray(toe_off_impulse, float)
    if not callable(iota) and iota.ndim:
        iota = np.broadcast_to(iota, (n,))
    tss = np.zeros(n) if time_since_strike is None else np.asarray(time_since_strike, float)

    p1, p2 = state.stance_angle.astype(float), state.swing_angle.astype(float)
    w1, w2 = state.stance_rate.astype(float), state.swing_rate.astype(float)
    origin, leg = state.contact_origin.astype(float), state.stance_leg.astype(np.int8)
    struck = np.zeros(n, bool)
    fraction = np.zeros(n)
    strike_x = np.full(n, np.nan)
    used_iota = np.full(n, np.nan)
    pre_rates = np.full((n, 2), np.nan)
    # integrate all walkers ignoring impacts, remembering where each first crosses phi1 + phi2 = 0 downwards
    found: list[tuple[int, np.ndarray, tuple[np.ndarray, ...]]] = []
    seen = np.zeros(n, bool)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        for i in range(substeps):
            s0 = p1 + p2
            n1, n2, nw1, nw2 = _rk4(k, p1, p2, w1, w2, kappa, h)
            s1 = n1 + n2
            cand = (s0 > 0.0) & (s1 <= 0.0) & ((p1 < 0.0) | (n1 < 0.0)) & ~seen
            if cand.any():
                idx = np.flatnonzero(cand)
                seen[idx] = True
                found.append((i, idx, (p1[idx], p2[idx], w1[idx], w2[idx], s0[idx], s1[idx])))
            p1, p2, w1, w2 = n1, n2, nw1, nw2
        if found:
            # one batch for all strikes of the frame: locate, impact, integrate the rest of the frame
            sub = np.concatenate([np.full(f[1].size, f[0]) for f in found])
            idx = np.concatenate([f[1] for f in found])
            sp1, sp2, sw1, sw2, ss0, ss1 = (np.concatenate([f[2][j] for f in found]) for j in range(6))
            kap = kappa[idx] if np.ndim(kappa) else kappa
            iot = iota if callable(iota) else (iota[idx] if np.ndim(iota) else iota)
            valid, theta, post, sx, (r1, r2), ui = _impact_at_root(
                params, k, idx, sp1, sp2, sw1, sw2, origin[idx], leg[idx], kap, iot, h, ss0, ss1)
            sel = np.flatnonzero(valid)
            idx, sub, theta = idx[sel], sub[sel], theta[sel]
            kap = kap[sel] if np.ndim(kap) else kap
            a1, a2, b1, b2 = _rk4(k, post.stance_angle[sel], post.swing_angle[sel], post.stance_rate[sel],
                                  post.swing_rate[sel], kap, (1.0 - theta) * h)
            remaining = substeps - 1 - sub
            for r in range(int(remaining.max(initial=0))):
                m = remaining > r
                km = kap[m] if np.ndim(kap) else kap
                a1[m], a2[m], b1[m], b2[m] = _rk4(k, a1[m], a2[m], b1[m], b2[m], km, h)
            p1[idx], p2[idx], w1[idx], w2[idx] = a1, a2, b1, b2
            origin[idx], leg[idx] = post.contact_origin[sel], post.stance_leg[sel]
            struck[idx] = True
            fraction[idx] = (sub + theta) / substeps
            strike_x[idx] = sx[sel]
            used_iota[idx] = ui[sel]
            pre_rates[idx, 0], pre_rates[idx, 1] = r1[sel], r2[sel]
    new_tss = np.where(struck, (1.0 - fraction) * dt, tss + dt)
    out = WalkerState(p1, p2, w1, w2, origin, leg)
    fallen = fallen_mask(params, out, new_tss, max_strike_interval)
    if fallen.any():
        out = WalkerState(*(np.where(fallen, getattr(state, f), getattr(out, f)).astype(getattr(out, f).dtype)
                            for f in ("stance_angle", "swing_angle", "stance_rate", "swing_rate",
                                      "contact_origin", "stance_leg")))
        struck &= ~fallen
        fraction[fallen] = 0.0
        strike_x[fallen] = np.nan
        used_iota[fallen] = np.nan
        pre_rates[fallen] = np.nan
    fraction = np.minimum(fraction, np.nextafter(1.0, 0.0))
    return out, StepEvents(struck, fraction, strike_x, fallen, new_tss, used_iota, pre_rates)


def simulate_to_strike(
    params: WalkerParams,
    state: WalkerState,
    stiffness: np.ndarray | float,
    toe_off_impulse: np.ndarray | float | ImpulseSampler,
    step: float = 1.0 / 480.0,
    max_time: float = MAX_STRIKE_INTERVAL,
) -> tuple[WalkerState, np.ndarray, np.ndarray]:
    """Integrate N walkers until their next heel strike: (post-impact states, strike times (s), pre-impact rates (N, 2)).

    Used by the cyclic-gait solver (eq. 3). Walkers that do not strike within ``max_time``
    get time NaN and their last state. ``step`` is the RK4 step (s).
    """
    n = len(state)
    k = _consts(params)
    kappa = np.broadcast_to(np.asarray(stiffness, float), (n,))
    iota = toe_off_impulse if callable(toe_off_impulse) else np.broadcast_to(np.asarray(toe_off_impulse, float), (n,))
    p1, p2 = state.stance_angle.astype(float), state.swing_angle.astype(float)
    w1, w2 = state.stance_rate.astype(float), state.swing_rate.astype(float)
    origin, leg = state.contact_origin.astype(float).copy(), state.stance_leg.astype(np.int8).copy()
    out = [p1.copy(), p2.copy(), w1.copy(), w2.copy()]
    times = np.full(n, np.nan)
    pre_rates = np.full((n, 2), np.nan)
    active = np.ones(n, bool)
    t = 0.0
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        while active.any() and t < max_time:
            s0 = p1 + p2
            n1, n2, nw1, nw2 = _rk4(k, p1, p2, w1, w2, kappa, step)
            s1 = n1 + n2
            cand = active & (s0 > 0.0) & (s1 <= 0.0)
            if cand.any():
                idx = np.flatnonzero(cand)
                kap = kappa[idx]
                iot = iota if callable(iota) else iota[idx]
                valid, theta, post_state, _, (v1, v2), _ = _impact_at_root(
                    params, k, idx, p1[idx], p2[idx], w1[idx], w2[idx], origin[idx], leg[idx], kap, iot, step,
                    s0[idx], s1[idx])
                post = (post_state.stance_angle, post_state.swing_angle, post_state.stance_rate, post_state.swing_rate)
                idx, sel = idx[valid], valid
                for arr, val in zip(out, post):
                    arr[idx] = val[sel]
                origin[idx], leg[idx] = post_state.contact_origin[sel], post_state.stance_leg[sel]
                times[idx] = t + theta[sel] * step
                pre_rates[idx, 0], pre_rates[idx, 1] = v1[sel], v2[sel]
                active[idx] = False
            p1, p2, w1, w2 = n1, n2, nw1, nw2
            t += step
            lost = active & ~np.isfinite(p1 + p2 + w1 + w2)
            active &= ~lost
    still = np.isnan(times)
    for arr, val in zip(out, (p1, p2, w1, w2)):
        arr[still] = val[still]
    return WalkerState(out[0], out[1], out[2], out[3], origin, leg), times, pre_rates
