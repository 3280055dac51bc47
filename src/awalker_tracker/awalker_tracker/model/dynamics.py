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

Compiled: the per-walker work (RK4 sub-steps, strike location, impact map, accelerations) runs in
serial numba kernels (``_integrate``, ``_impact_rates``, ``_accelerations``) that loop over the
walkers; the Python functions below prepare arrays and call them. Kernels are cached on disk
(``cache=True``): the first import in a fresh checkout compiles them (a few seconds).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import numba
import numpy as np

from awalker_tracker.blocks import over_blocks

from .walker import WalkerParams, WalkerState

#: Walkers are flagged fallen when no heel strike happened for this long (s).
MAX_STRIKE_INTERVAL = 2.0
#: Walkers whose stance leg leans further than this from vertical (rad) are flagged fallen: a 1.4 m step
#: for a 0.9 m leg (the gait table's longest step, 1.2 m, strikes at 0.73 rad). A leg past horizontal, the
#: test before, let a whole cloud tip over in the last frames of a sequence, too late to be re-seeded.
MAX_STANCE_LEAN = 0.9
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


# ---- compiled per-walker kernels (numba, serial) ------------------------------------------
# Constants of the equations of motion, as the float tuple the kernels take (see _Consts).
KernelConsts = tuple[float, ...]


def _kernel_consts(k: _Consts) -> KernelConsts:
    """(R, a, c, b, A, B, m_l b, M22, G1, G2, m_l, m_t, I_l, I_t) for the kernels."""
    return (k.R, k.a, k.c, k.b, k.A, k.B, k.mlb, k.M22, k.G1, k.G2, k.m_l, k.m_t, k.I_l, k.I_t)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _acc(kc, s1, c1, s2, c2, gap, w1, w2, kappa):
    """q'' (rad/s^2) of eq. (17) for one walker, from sin/cos of phi1, phi2 and gap = phi2 - phi1."""
    R, a, _, _, A, B, mlb, M22, G1, G2 = kc[:10]
    sd = s1 * c2 - c1 * s2                 # sin(phi1 - phi2)
    cd = c1 * c2 + s1 * s2                 # cos(phi1 - phi2)
    m11 = A + B * c1
    m12 = -mlb * (R * c2 + a * cd)
    spring = kappa * gap
    w1sq = w1 * w1
    r1 = (0.5 * B * w1sq + G1) * s1 - mlb * (w2 * w2) * (R * s2 - a * sd) + spring
    r2 = -mlb * a * sd * w1sq - G2 * s2 - spring
    inv_det = 1.0 / (m11 * M22 - m12 * m12)
    return (M22 * r1 - m12 * r2) * inv_det, (m11 * r2 - m12 * r1) * inv_det


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _rotate(s, c, delta):
    """(sin, cos) of angle + delta from (sin, cos) of angle, with Taylor series for delta.

    RK4 stage angles differ from the sub-step's start by |delta| = |h phi'| (< 0.1 rad when walking
    at h = 1/120 s); the series to delta^10 is exact to < 1e-15 there (< 3e-8 even at |delta| = 1)
    and saves two of every three sin/cos evaluations of a sub-step.
    """
    d2 = delta * delta   # (1 / k) constants are folded at compile time: multiplications, no divisions
    sin_d = delta * (1.0 - d2 * (1 / 6) * (1.0 - d2 * (1 / 20) * (1.0 - d2 * (1 / 42) * (
        1.0 - d2 * (1 / 72) * (1.0 - d2 * (1 / 110))))))
    cos_d = 1.0 - d2 * 0.5 * (1.0 - d2 * (1 / 12) * (1.0 - d2 * (1 / 30) * (1.0 - d2 * (1 / 56) * (
        1.0 - d2 * (1 / 90)))))
    return s * cos_d + c * sin_d, c * cos_d - s * sin_d


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _rk4(kc, p1, p2, w1, w2, kappa, h):
    """One classical RK4 step of size h for one walker: (phi1, phi2, phi1', phi2') after it.

    Stage angles are q + delta; their sines/cosines come from the step start's by :func:`_rotate`.
    """
    s1, c1, s2, c2 = np.sin(p1), np.cos(p1), np.sin(p2), np.cos(p2)
    gap = p2 - p1
    hh = 0.5 * h
    a1, a2 = _acc(kc, s1, c1, s2, c2, gap, w1, w2, kappa)
    # stage 2: q + h/2 q'
    d1, d2 = hh * w1, hh * w2
    t1, u1 = _rotate(s1, c1, d1)
    t2, u2 = _rotate(s2, c2, d2)
    v1, v2 = w1 + hh * a1, w2 + hh * a2
    b1, b2 = _acc(kc, t1, u1, t2, u2, gap + (d2 - d1), v1, v2, kappa)
    # stage 3: q + h/2 (q' + h/2 a)
    e1, e2 = hh * v1, hh * v2
    t1, u1 = _rotate(s1, c1, e1)
    t2, u2 = _rotate(s2, c2, e2)
    x1, x2 = w1 + hh * b1, w2 + hh * b2
    g1, g2 = _acc(kc, t1, u1, t2, u2, gap + (e2 - e1), x1, x2, kappa)
    # stage 4: q + h (q' + h/2 b)
    f1, f2 = h * x1, h * x2
    t1, u1 = _rotate(s1, c1, f1)
    t2, u2 = _rotate(s2, c2, f2)
    z1, z2 = w1 + h * g1, w2 + h * g2
    j1, j2 = _acc(kc, t1, u1, t2, u2, gap + (f2 - f1), z1, z2, kappa)
    h6 = h / 6.0
    return (p1 + h6 * (w1 + 2.0 * (v1 + x1) + z1), p2 + h6 * (w2 + 2.0 * (v2 + x2) + z2),
            w1 + h6 * (a1 + 2.0 * (b1 + g1) + j1), w2 + h6 * (a2 + 2.0 * (b2 + g2) + j2))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _locate_strike(kc, p1, p2, w1, w2, kappa, h, s0, s1):
    """Fraction theta in [0, 1] of a sub-step at which phi1 + phi2 = 0 (Newton from the secant guess)."""
    theta = min(max(s0 / (s0 - s1), 0.0), 1.0)
    for _ in range(8):
        q1, q2, v1, v2 = _rk4(kc, p1, p2, w1, w2, kappa, theta * h)
        f = q1 + q2
        slope = min(h * (v1 + v2), -1e-12)
        theta = min(max(theta - f / slope, 0.0), 1.0)
        if abs(f) < 1e-11:  # the step just taken brings |f| to ~1e-16 (rate ~5e-4 per step)
            break
    return theta


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _integrate(kc, p1, p2, w1, w2, kappa, first_step, steps, h, detect):
    """Integrate each walker i by one RK4 step of ``first_step[i]`` (if > 0) and ``steps[i]`` steps of h.

    With ``detect`` a walker stops at its first regular heel strike (a downward zero crossing of
    phi1 + phi2 with phi1 < 0 and phi1' + phi2' < 0 at the root, located by Newton inside the
    step): its returned state is the pre-impact state there, ``strike_step`` the index of the step
    and ``theta`` the fraction of it (strike_step = -1 where none). Walkers whose state stops
    being finite stop there. Returns (phi1, phi2, phi1', phi2', strike_step, theta).
    """
    n = p1.shape[0]
    q1, q2, r1, r2 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    strike_step = np.full(n, -1, np.int64)
    theta = np.zeros(n)
    for i in range(n):
        a1, a2, b1, b2, kap = p1[i], p2[i], w1[i], w2[i], kappa[i]
        if first_step[i] > 0.0:
            a1, a2, b1, b2 = _rk4(kc, a1, a2, b1, b2, kap, first_step[i])
        for s in range(steps[i]):
            n1, n2, m1, m2 = _rk4(kc, a1, a2, b1, b2, kap, h)
            if detect:
                s0, s1 = a1 + a2, n1 + n2
                if s0 > 0.0 and s1 <= 0.0:
                    th = _locate_strike(kc, a1, a2, b1, b2, kap, h, s0, s1)
                    c1, c2, d1, d2 = _rk4(kc, a1, a2, b1, b2, kap, th * h)
                    if c1 < 0.0 and d1 + d2 < 0.0:
                        a1, a2, b1, b2 = c1, c2, d1, d2
                        strike_step[i], theta[i] = s, th
                        break
            a1, a2, b1, b2 = n1, n2, m1, m2
            if not (np.isfinite(a1) and np.isfinite(a2) and np.isfinite(b1) and np.isfinite(b2)):
                break
        q1[i], q2[i], r1[i], r2[i] = a1, a2, b1, b2
    return q1, q2, r1, r2, strike_step, theta


def _integrate_blocks(kc, p1, p2, w1, w2, kappa, first_step, steps, h, detect):
    """``_integrate`` over blocks of walkers at once (``blocks.over_blocks``; per-walker arrays (N,)
    contiguous): the same result."""
    parts = over_blocks(p1.shape[0], lambda rows: _integrate(
        kc, p1[rows], p2[rows], w1[rows], w2[rows], kappa[rows], first_step[rows], steps[rows], h, detect))
    return parts[0] if len(parts) == 1 else tuple(np.concatenate(column) for column in zip(*parts))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _accelerations(kc, p1, p2, w1, w2, kappa):
    """Eq. (17)'s q'' (rad/s^2) of N walkers, (N, 2)."""
    out = np.empty((p1.shape[0], 2))
    for i in range(p1.shape[0]):
        out[i, 0], out[i, 1] = _acc(kc, np.sin(p1[i]), np.cos(p1[i]), np.sin(p2[i]), np.cos(p2[i]),
                                    p2[i] - p1[i], w1[i], w2[i], kappa[i])
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _impact_rates(kc, p1, p2, w1, w2, iota):
    """Post-impact (new stance, new swing) rates of N walkers from pre-impact angles/rates and toe-off iota.

    M(q+) q'+ = sum_b J+_b^T M_b V-_b + J+_hip^T iota e (module docstring), written out per body:
    pre-impact velocities V- of the old stance leg's CoM, the old swing leg's CoM and the torso
    (at the hip); after the impact the old swing leg is the new stance leg (angle P1 = phi2-) and
    the old stance leg the new swing leg (P2 = phi1-).
    """
    R, a, c, b, A, B, mlb, M22 = kc[:8]
    m_l, m_t, I_l, I_t = kc[10], kc[11], kc[12], kc[13]
    n = p1.shape[0]
    new_stance, new_swing = np.empty(n), np.empty(n)
    for i in range(n):
        sp1, cp1, sp2, cp2 = np.sin(p1[i]), np.cos(p1[i]), np.sin(p2[i]), np.cos(p2[i])
        # pre-impact body velocities (x', y') and angular rates
        hip_x, hip_y = -(R + a * cp1) * w1[i], -a * sp1 * w1[i]
        old_stance_x, old_stance_y, old_stance_w = -(R + c * cp1) * w1[i], -c * sp1 * w1[i], w1[i]
        old_swing_x, old_swing_y, old_swing_w = hip_x + b * cp2 * w2[i], hip_y + b * sp2 * w2[i], w2[i]
        # post-impact Jacobian columns (P1 = phi2-, P2 = phi1-): d/dP1' of each body, and d/dP2' of the new swing leg
        j_stance_x, j_stance_y = -(R + c * cp2), -c * sp2        # new stance leg CoM (rotates with P1)
        j_hip_x, j_hip_y = -(R + a * cp2), -a * sp2              # hip: torso and the new swing leg's hip end
        rhs1 = (m_l * (j_stance_x * old_swing_x + j_stance_y * old_swing_y) + I_l * old_swing_w
                + m_l * (j_hip_x * old_stance_x + j_hip_y * old_stance_y)
                + m_t * (j_hip_x * hip_x + j_hip_y * hip_y) + I_t * w1[i]
                + iota[i] * (j_hip_x * -sp1 + j_hip_y * cp1))   # toe-off along the old stance leg, at the hip
        rhs2 = m_l * b * (cp1 * old_stance_x + sp1 * old_stance_y) + I_l * old_stance_w
        # M(P1, P2) rates = rhs
        m11 = A + B * cp2
        m12 = -mlb * (R * cp1 + a * (cp2 * cp1 + sp2 * sp1))
        det = m11 * M22 - m12 * m12
        new_stance[i] = (M22 * rhs1 - m12 * rhs2) / det
        new_swing[i] = (m11 * rhs2 - m12 * rhs1) / det
    return new_stance, new_swing


def mass_matrix(params: WalkerParams, stance_angle: np.ndarray, swing_angle: np.ndarray) -> np.ndarray:
    """Generalised mass matrix M(q) = T^T M T (m^2 per unit mass), shape (N, 2, 2)."""
    k = _consts(params)
    p1, p2 = np.asarray(stance_angle, float), np.asarray(swing_angle, float)
    m11 = k.A + k.B * np.cos(p1)
    m12 = -k.mlb * (k.R * np.cos(p2) + k.a * np.cos(p1 - p2))
    m22 = np.full_like(m11, k.M22)
    return np.stack([np.stack([m11, m12], -1), np.stack([m12, m22], -1)], -2)


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


def _per_walker(value: np.ndarray | float, n: int) -> np.ndarray:
    """A scalar or (n,) value as a contiguous float (n,) array for the kernels."""
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, float), (n,)))


def accelerations(params: WalkerParams, state: WalkerState, stiffness: np.ndarray | float) -> np.ndarray:
    """Angular accelerations (phi1'', phi2'') in rad/s^2 of eq. (17), shape (N, 2).

    ``stiffness`` kappa: hip spring stiffness, N m/rad per kg, scalar or (N,).
    """
    n = len(state)
    return _accelerations(_kernel_consts(_consts(params)), *(_per_walker(v, n) for v in (
        state.stance_angle, state.swing_angle, state.stance_rate, state.swing_rate, stiffness)))


def heel_strike(params: WalkerParams, state: WalkerState, toe_off_impulse: np.ndarray | float) -> WalkerState:
    """Impact map at heel strike: toe-off, inelastic collision, leg swap (paper eq. 2, App. B).

    ``state`` is the pre-impact state (phi1 + phi2 = 0, phi1 < 0 for a regular strike);
    ``toe_off_impulse`` iota in m/s (impulse per unit mass), scalar or (N,). Returns the
    post-impact state: angles and rates swapped to the new stance/swing legs, ``stance_leg``
    flipped and ``contact_origin`` moved to where the new stance foot rolls from, so that the
    new contact point is the old swing foot's lowest point.
    """
    n = len(state)
    p1, p2 = state.stance_angle, state.swing_angle
    w1n, w2n = _impact_rates(_kernel_consts(_consts(params)), *(_per_walker(v, n) for v in (
        p1, p2, state.stance_rate, state.swing_rate, toe_off_impulse)))
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
    n = len(pre_state)
    kc = _kernel_consts(_consts(params))
    angles_rates = [_per_walker(v, n) for v in (pre_state.stance_angle, pre_state.swing_angle,
                                                 pre_state.stance_rate, pre_state.swing_rate)]
    zero, _ = _impact_rates(kc, *angles_rates, np.zeros(n))
    one, _ = _impact_rates(kc, *angles_rates, np.ones(n))
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

    def take(self, indices: np.ndarray) -> "StepEvents":
        """The events of the walkers ``indices``."""
        return StepEvents(*(getattr(self, f.name)[indices] for f in fields(self)))


#: iota given as a function of (walker indices, pre-impact states of those walkers) -> iota (m/s)
ImpulseSampler = Callable[[np.ndarray, WalkerState], np.ndarray]


def integrate(params: WalkerParams, state: WalkerState, stiffness: np.ndarray | float, step: float,
              steps: int) -> WalkerState:
    """``steps`` RK4 steps of ``step`` seconds for N walkers, ignoring heel strikes (kappa scalar or (N,))."""
    n = len(state)
    q1, q2, r1, r2, _, _ = _integrate_blocks(
        _kernel_consts(_consts(params)), *(_per_walker(v, n) for v in (
            state.stance_angle, state.swing_angle, state.stance_rate, state.swing_rate, stiffness)),
        np.zeros(n), np.full(n, int(steps), np.int64), float(step), False)
    return WalkerState(q1, q2, r1, r2, state.contact_origin.copy(), state.stance_leg.copy())


def _strike(params: WalkerParams, indices: np.ndarray, pre: WalkerState,
            toe_off_impulse: np.ndarray | ImpulseSampler) -> tuple[WalkerState, np.ndarray]:
    """Apply heel strikes to the walkers ``indices`` in their pre-impact states: (post states, iota used)."""
    iota = toe_off_impulse(indices, pre) if callable(toe_off_impulse) else toe_off_impulse[indices]
    iota = _per_walker(iota, indices.size)
    return heel_strike(params, pre, iota), iota


def fallen_mask(params: WalkerParams, state: WalkerState, time_since_strike: np.ndarray | None = None,
                max_strike_interval: float = MAX_STRIKE_INTERVAL) -> np.ndarray:
    """Walkers that have fallen: non-finite state, the stance leg leaning more than ``MAX_STANCE_LEAN``, the
    swing leg past horizontal, hip below ground, or no strike for long."""
    k = _consts(params)
    p1, p2 = state.stance_angle, state.swing_angle
    finite = np.isfinite(p1) & np.isfinite(p2) & np.isfinite(state.stance_rate) & np.isfinite(state.swing_rate)
    with np.errstate(invalid="ignore"):
        bad = ~finite | (np.abs(p1) > MAX_STANCE_LEAN) | (np.abs(p2) > 0.5 * np.pi) | (k.R + k.a * np.cos(p1) < 0.0)
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

    Compiled: one kernel call integrates every walker to the frame's end or to its heel strike;
    the strikers get their impact (and iota) here, and a second call integrates them on.
    """
    n = len(state)
    kc = _kernel_consts(_consts(params))
    substeps = substeps_for(dt) if substeps is None else int(substeps)
    if substeps < 1:
        raise ValueError("substeps must be >= 1")
    h = dt / substeps
    kappa = _per_walker(stiffness, n)
    iota = toe_off_impulse if callable(toe_off_impulse) else _per_walker(toe_off_impulse, n)
    tss = np.zeros(n) if time_since_strike is None else np.asarray(time_since_strike, float)

    p1, p2, w1, w2, strike_step, theta = _integrate_blocks(
        kc, *(_per_walker(v, n) for v in (state.stance_angle, state.swing_angle, state.stance_rate,
                                          state.swing_rate)),
        kappa, np.zeros(n), np.full(n, substeps, np.int64), h, True)
    origin, leg = state.contact_origin.astype(float), state.stance_leg.astype(np.int8)
    struck = strike_step >= 0
    fraction = np.zeros(n)
    strike_x = np.full(n, np.nan)
    used_iota = np.full(n, np.nan)
    pre_rates = np.full((n, 2), np.nan)
    idx = np.flatnonzero(struck)
    if idx.size:
        pre = WalkerState(p1[idx], p2[idx], w1[idx], w2[idx], origin[idx], leg[idx])
        post, used = _strike(params, idx, pre, iota)
        sub, th = strike_step[idx], theta[idx]
        # the rest of the strike's sub-step from the post-impact state, then the frame's remaining sub-steps
        p1[idx], p2[idx], w1[idx], w2[idx], _, _ = _integrate_blocks(
            kc, post.stance_angle, post.swing_angle, post.stance_rate, post.swing_rate, kappa[idx],
            (1.0 - th) * h, substeps - 1 - sub, h, False)
        origin[idx], leg[idx] = post.contact_origin, post.stance_leg
        fraction[idx] = (sub + th) / substeps
        strike_x[idx] = post.contact_origin - params.foot_radius * post.stance_angle
        used_iota[idx] = used
        pre_rates[idx, 0], pre_rates[idx, 1] = pre.stance_rate, pre.swing_rate
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
    iota = toe_off_impulse if callable(toe_off_impulse) else _per_walker(toe_off_impulse, n)
    steps = max(1, int(np.ceil(max_time / step - 1e-9)))
    q1, q2, r1, r2, strike_step, theta = _integrate_blocks(
        _kernel_consts(_consts(params)), *(_per_walker(v, n) for v in (
            state.stance_angle, state.swing_angle, state.stance_rate, state.swing_rate, stiffness)),
        np.zeros(n), np.full(n, steps, np.int64), float(step), True)
    out = WalkerState(q1, q2, r1, r2, state.contact_origin.astype(float).copy(), state.stance_leg.astype(np.int8).copy())
    times = np.full(n, np.nan)
    pre_rates = np.full((n, 2), np.nan)
    idx = np.flatnonzero(strike_step >= 0)
    if idx.size:
        pre = out.take(idx)
        post, _ = _strike(params, idx, pre, iota)
        for name in ("stance_angle", "swing_angle", "stance_rate", "swing_rate", "contact_origin", "stance_leg"):
            getattr(out, name)[idx] = getattr(post, name)
        times[idx] = (strike_step[idx] + theta[idx]) * step
        pre_rates[idx, 0], pre_rates[idx, 1] = pre.stance_rate, pre.swing_rate
    return out, times, pre_rates
