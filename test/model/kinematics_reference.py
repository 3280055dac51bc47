"""Test oracle: a vectorised numpy implementation of the conditional kinematics' pose computation,
which ``awalker_tracker.model.kinematics`` runs in compiled kernels; used only to check the kernels
against it. Same maths, same rng stream; not used by the package.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from awalker_tracker.model.body import JOINT_NAMES, MARKER_NAMES, BodyDescription, BodyPoseBatch, BodySegments
from awalker_tracker.model.kinematics import (
    CHORD_LEAN,
    DOF_NAMES,
    PELVIS_CEILING_RANGE,
    KinematicConfig,
    KinematicState,
    _initial_dofs,
    _initial_leg_scale,
    _initial_posture,
    _posture_within_limit,
    _clearance,
    _initial_state,
    _plane_origin,
    leg_angles,
    truncated_normal,
)
from awalker_tracker.model.walker import LEFT, WalkerParams, WalkerState, hip_position

_D = len(DOF_NAMES)
_SIDE = np.array([1.0, -1.0])  # +1 left, -1 right: mirrors abduction, rotation, inversion


# ---- rotations (vectorised) ---------------------------------------------------------------
def _rot_z(angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about z."""
    c, s = np.cos(angle), np.sin(angle)
    r = np.zeros(np.shape(angle) + (3, 3))
    r[..., 0, 0] = c
    r[..., 0, 1] = -s
    r[..., 1, 0] = s
    r[..., 1, 1] = c
    r[..., 2, 2] = 1.0
    return r


def _turn(rotation: np.ndarray, axis: int, angle: np.ndarray) -> np.ndarray:
    """rotation @ R_axis(angle) for stacks (..., 3, 3) and angles (...): only two columns change,
    so this is much cheaper than a batched 3x3 matmul."""
    return _turn_cs(rotation, axis, np.cos(angle)[..., None], np.sin(angle)[..., None])


def _turn_cs(rotation: np.ndarray, axis: int, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``_turn`` with the angle's cosine and sine given, shaped (..., 1)."""
    i, j = ((1, 2), (2, 0), (0, 1))[axis]
    col_i, col_j = rotation[..., :, i], rotation[..., :, j]
    out = np.empty_like(rotation)
    out[..., :, axis] = rotation[..., :, axis]
    # written in place into the strided output columns: ~2.5x faster than assigning temporaries
    np.multiply(c, col_i, out=out[..., :, i])
    out[..., :, i] += s * col_j
    np.multiply(c, col_j, out=out[..., :, j])
    out[..., :, j] -= s * col_i
    return out


def _apply(rotation: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """rotation (..., 3, 3) @ constant vector (3,) -> (..., 3), as a sum of scaled columns."""
    out = 0.0
    for k in range(3):
        if vector[k] != 0.0:
            out = out + vector[k] * rotation[..., :, k]
    return out if not np.isscalar(out) else np.zeros(rotation.shape[:-1])


# Segment frames from joint frames (columns forward, left, up): legs (fwd, -left, down),
# feet (up, -left, along the foot).
_LEG_SEGMENT_SIGNS = np.array([1.0, -1.0, -1.0])
_FOOT_SEGMENT_COLUMNS = np.array([2, 1, 0])
_FOOT_SEGMENT_SIGNS = np.array([1.0, -1.0, 1.0])


@dataclass
class _LocalPose:
    """Body posed with the pelvis at the origin (world orientation), arrays over N (and legs)."""

    torso: np.ndarray   # (N, 3, 3) columns forward, left, up
    hips: np.ndarray    # (N, 2, 3)
    thigh: np.ndarray   # (N, 2, 3, 3) columns forward, left, up of each thigh
    knees: np.ndarray   # (N, 2, 3)
    shank: np.ndarray   # (N, 2, 3, 3)
    ankles: np.ndarray  # (N, 2, 3)
    foot: np.ndarray    # (N, 2, 3, 3) columns along the foot (heel->toe), left, up

@dataclass(frozen=True)
class _RuledBody(BodyDescription):
    """A body with the kinematics' knee rule attached (``KinematicConfig.hip_over_ankle``), so that the
    reference's helpers, which take the body, see it."""

    hip_over_ankle: bool = False

    def __post_init__(self) -> None:
        """Made from a body that passed its checks (``_ruled``); the rule is no size to check."""


def _ruled(body: BodyDescription, config: KinematicConfig | None) -> BodyDescription:
    """``body`` carrying ``config``'s knee rule (None: the default's)."""
    values = {f.name: getattr(body, f.name) for f in fields(BodyDescription)}
    return _RuledBody(**values, hip_over_ankle=bool(config is not None and config.hip_over_ankle))


def _thigh_lead(body: BodyDescription, leg: np.ndarray, knee: np.ndarray) -> np.ndarray:
    """How far (rad) the thigh leans ahead of the walker's leg angle ``leg`` at knee flexion ``knee`` (rad): ahead
    of the hip-ankle chord, which leans ``CHORD_LEAN`` back from the walker's leg, or with the body's
    ``hip_over_ankle`` keeps the straight leg's reach (its angle theta: sin theta = L0 sin(leg - CHORD_LEAN) / L)."""
    thigh, shank = body.upper_leg_length, body.lower_leg_length
    delta = np.arctan2(shank * np.sin(knee), thigh + shank * np.cos(knee))
    if not getattr(body, "hip_over_ankle", False):
        return delta - CHORD_LEAN
    chord = np.hypot(thigh + shank * np.cos(knee), shank * np.sin(knee))
    theta = np.arcsin(np.clip((thigh + shank) * np.sin(leg - CHORD_LEAN) / chord, -1.0, 1.0))
    return theta + delta - leg


def _local_pose(body: BodyDescription, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray) -> _LocalPose:
    """Forward kinematics relative to the pelvis. legs (N, 2) sagittal leg angles (of the hip-ankle
    chords), dofs (N, 13), leg scales (N,) on thigh and shank lengths."""
    d = KinematicState.unpack(dofs)
    heading = _rot_z(d["heading"])                                            # (N,3,3)
    torso = _turn(_turn(heading, 1, d["torso_lean"][:, 0]), 0, d["torso_lean"][:, 1])
    hips = (0.5 * body.hip_width) * _SIDE[None, :, None] * torso[:, None, :, 1]
    # Chord angle phi about the lateral axis (foot ahead for phi > 0) plus the thigh's lead, then
    # abduction, rotation.
    thigh = np.repeat(heading[:, None], 2, axis=1)
    pitch = legs + _thigh_lead(body, legs, d["knee"])
    thigh = _turn(_turn(_turn(thigh, 1, -pitch), 0, _SIDE * d["hip_abduction"]), 2, -_SIDE * d["hip_rotation"])
    knees = hips - (body.upper_leg_length * scale)[:, None, None] * thigh[..., :, 2]
    shank, ankles, foot = _lower_legs(body, legs, thigh, knees, dofs, scale)
    return _LocalPose(torso, hips, thigh, knees, shank, ankles, foot)


def _lower_legs(body: BodyDescription, legs: np.ndarray, thigh: np.ndarray, knees: np.ndarray,
                dofs: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shank frames, ankle positions and foot frames (N, 2, ...) below the given thighs and knees."""
    knee = dofs[:, 7:9]
    shank = _turn(thigh, 1, knee)                                 # knee flexion
    ankles = knees - (body.lower_leg_length * scale)[:, None, None] * shank[..., :, 2]
    # ankle flexion (the DOF counts from the hip-ankle chord), inversion
    foot = _turn(_turn(shank, 1, -(dofs[:, 9:11] + knee - _thigh_lead(body, legs, knee))), 0,
                 -_SIDE * dofs[:, 11:13])
    return shank, ankles, foot


def _sole_point(body: BodyDescription, ankles: np.ndarray, foot: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Point at angle beta on the rocker sole (..., 3) for feet at ``ankles`` with frames ``foot``."""
    along, up = _sole_offsets(body, beta)
    return ankles + foot[..., :, 0] * along[..., None] + foot[..., :, 2] * up[..., None]


def _sole_offsets(body: BodyDescription, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Foot-frame coordinates (along the foot, up; m) of the rocker sole's point at angle beta
    (the circle's centre lies above the sole's middle; the lateral coordinate is 0)."""
    rho = body.sole_radius
    along = (body.foot_length / 2 - body.heel_offset) + rho * np.sin(beta)
    up = (-body.ankle_height - body.sole_sag + rho) - rho * np.cos(beta)
    return along, up


def _lowest_roll(body: BodyDescription, foot: np.ndarray) -> np.ndarray:
    """beta of the rocker sole's lowest point, clipped to the sole's ends (heel/toe pivots)."""
    return _lowest_roll_from(body, foot[..., 2, 0], foot[..., 2, 2])


def _lowest_roll_from(body: BodyDescription, along_z: np.ndarray, up_z: np.ndarray) -> np.ndarray:
    """``_lowest_roll`` from the world z components of the foot's along and up axes."""
    beta = np.arctan2(-along_z, up_z)
    limit = body.sole_half_angle
    return np.clip(beta, -limit, limit)


def _pick(values: np.ndarray, leg: np.ndarray) -> np.ndarray:
    """values (N, 2, ...) at the given leg index per particle -> (N, ...)."""
    n = values.shape[0]   # flat take: several times faster than fancy indexing
    return np.take(values.reshape((2 * n,) + values.shape[2:]), 2 * np.arange(n) + leg.astype(np.intp), axis=0)


def _horizontal_direction(foot: np.ndarray) -> np.ndarray:
    """Unit xy direction (N, 2) of a foot's heel->toe axis projected on the ground."""
    xy = foot[:, :2, 0]
    norm = np.linalg.norm(xy, axis=1, keepdims=True)
    return xy / np.maximum(norm, 1e-9)

def _eq6(config: KinematicConfig, body: BodyDescription, walker: WalkerState, current: np.ndarray,
         previous: np.ndarray, torso_rest: np.ndarray, rng: np.random.Generator,
         turn_rates: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """One step of eq. (6) for all DOFs (N, 13) with truncated noise; knees by stance/swing role, the torso
    pitch towards each particle's ``torso_rest`` (N,).

    The heading runs eq. (6) on its deviation from the turn (``turn_rates``: omega of this frame and
    of the previous one, rad/s): h_t = h_{t-1} + omega_t dt + alpha (h_{t-1} - h_{t-2} - omega_{t-1} dt)
    + dt^2 eta, so the turn is not amplified by eq. (6)'s velocity term."""
    n = current.shape[0]
    p = {k: np.broadcast_to(v, (n, _D)).copy() for k, v in config.arrays(body).items()}
    swing = config.table["swing_knee"]
    knee_cols = np.array([7, 8])
    is_swing = np.stack([walker.stance_leg != LEFT, walker.stance_leg == LEFT], axis=1)  # (N, 2) [left, right]
    psi_hip = walker.stance_angle - walker.swing_angle
    swing_values = {
        "alpha": config.alpha("swing_knee"), "stiffness": swing.stiffness,
        "rest": config.swing_knee_rest_gain * psi_hip[:, None], "sigma": swing.sigma * config.noise_scale("swing_knee") * config.sigma_unit,
        "lower": swing.lower, "upper": swing.upper,
    }
    for key, value in swing_values.items():
        p[key][:, knee_cols] = np.where(is_swing, value, p[key][:, knee_cols])
    p["rest"][:, DOF_NAMES.index("torso_pitch")] = torso_rest
    dt2 = config.dt**2
    rate, previous_rate = turn_rates
    heading = DOF_NAMES.index("heading")
    previous = previous.copy()
    previous[:, heading] += previous_rate * config.dt
    mean = current + p["alpha"] * (current - previous) + dt2 * p["stiffness"] * (p["rest"] - current)
    mean[:, heading] += rate * config.dt
    # psi_t = mean + dt^2 eta; truncate eta so that psi_t stays within the limits.
    eta = truncated_normal(rng, 0.0, p["sigma"], (p["lower"] - mean) / dt2, (p["upper"] - mean) / dt2)
    return np.clip(mean + dt2 * eta, p["lower"], p["upper"])


def _contact_translation(body: BodyDescription, local: _LocalPose, leg: np.ndarray, beta: np.ndarray,
                         ground_xy: np.ndarray) -> np.ndarray:
    """Translation (N, 3) that puts the pelvis-relative sole point (leg, beta) on the ground at ground_xy."""
    point = _sole_point(body, _pick(local.ankles, leg), _pick(local.foot, leg), beta)
    return np.column_stack([ground_xy - point[:, :2], -point[:, 2]])


def _foot_lowest_z(body: BodyDescription, swing: _Leg, knee: np.ndarray, shift_z: np.ndarray) -> np.ndarray:
    """World height (M,) of the lowest point of a foot's sole for a given knee angle knee (M,) rad;
    the thigh (which leads the chord by the knee's lead) is posed anew for it. Only the frames' z rows
    are turned (the height needs no more)."""
    thigh_z = np.zeros((knee.shape[0], 1, 3))
    thigh_z[:, 0, 2] = 1.0                                        # the heading leaves the z row alone
    thigh_z = _turn(_turn(_turn(thigh_z, 1, -(swing.leg + _thigh_lead(body, swing.leg, knee))), 0, swing.abduction), 2,
                    swing.rotation)
    knee_z = swing.hip_z - swing.thigh_length * thigh_z[:, 0, 2]
    shank_z = _turn(thigh_z, 1, knee)
    ankle_z = knee_z - swing.shank_length * shank_z[:, 0, 2]
    flexion = -(swing.ankle + knee - _thigh_lead(body, swing.leg, knee))
    foot_z = _turn(_turn(shank_z, 1, flexion), 0, swing.inversion)[:, 0]
    along, up = _sole_offsets(body, _lowest_roll_from(body, foot_z[:, 0], foot_z[:, 2]))
    return ankle_z + foot_z[:, 0] * along + foot_z[:, 2] * up + shift_z


@dataclass
class _Leg:
    """What a foot's height depends on besides the knee (M,): the chord angle, the thigh's
    abduction and rotation turns and the foot's ankle DOF and inversion turn (rad), the hip height and
    the thigh and shank lengths (m)."""

    leg: np.ndarray
    abduction: np.ndarray
    rotation: np.ndarray
    ankle: np.ndarray
    inversion: np.ndarray
    hip_z: np.ndarray
    thigh_length: np.ndarray
    shank_length: np.ndarray

    def take(self, rows: np.ndarray) -> "_Leg":
        return _Leg(*(getattr(self, f)[rows] for f in self.__dataclass_fields__))


def _leg(body: BodyDescription, local: _LocalPose, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray,
         side: np.ndarray) -> _Leg:
    """The ``_Leg`` of leg ``side`` (N,) of each body."""
    rows, sign = np.arange(dofs.shape[0]), _SIDE[side]
    return _Leg(legs[rows, side], sign * dofs[rows, DOF_NAMES.index("left_hip_abduction") + side],
                -sign * dofs[rows, DOF_NAMES.index("left_hip_rotation") + side],
                dofs[rows, DOF_NAMES.index("left_ankle_flexion") + side],
                -sign * dofs[rows, DOF_NAMES.index("left_ankle_inversion") + side],
                _pick(local.hips, side)[:, 2], body.upper_leg_length * scale, body.lower_leg_length * scale)


def _knee_at_ground(body: BodyDescription, leg: _Leg, shift_z: np.ndarray, below: np.ndarray, above: np.ndarray,
                    iterations: int) -> np.ndarray:
    """Knee angles (M,) in [below, above] where the foot's lowest point reaches height 0 with the pelvis at
    ``shift_z`` (bisection; the end of the bracket on the foot's clear side)."""
    for _ in range(iterations):
        middle = 0.5 * (below + above)
        clear = _foot_lowest_z(body, leg, middle, shift_z) >= 0.0
        above = np.where(clear, middle, above)
        below = np.where(clear, below, middle)
    return above


def _land_knees(body: BodyDescription, local: _LocalPose, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray,
                landing: np.ndarray, struck: np.ndarray, shift_z: np.ndarray, iterations: int = 14) -> None:
    """Heel strike (rows ``struck``): where the landing foot (leg ``landing``) is above the ground with
    the pelvis at ``shift_z`` (held by the old contact), straighten its knee (in place in ``dofs``) just
    enough for it to touch, by bisection in [0, knee]; fully straight if even that does not reach."""
    rows = np.arange(dofs.shape[0])
    knee_col = DOF_NAMES.index("left_knee") + landing
    leg, knee = _leg(body, local, legs, dofs, scale, landing.astype(np.intp)), dofs[rows, knee_col]
    high = struck & (knee > 0) & (_foot_lowest_z(body, leg, knee, shift_z) > 0.0)
    straight = high & (_foot_lowest_z(body, leg, np.zeros_like(knee), shift_z) >= 0.0)
    dofs[straight, knee_col[straight]] = 0.0
    bend = np.flatnonzero(high & ~straight)
    if bend.size == 0:
        return
    dofs[bend, knee_col[bend]] = _knee_at_ground(body, leg.take(bend), shift_z[bend], np.zeros(bend.size), knee[bend],
                                                 iterations)


def _keep_swing_foot_above_ground(body: BodyDescription, local: _LocalPose, legs: np.ndarray, dofs: np.ndarray,
                                  scale: np.ndarray,
                                  stance_leg: np.ndarray, shift_z: np.ndarray, iterations: int = 14) -> None:
    """Ground clearance: where the swing foot would go below z = 0, bend the swing knee (in place
    in ``dofs``) just enough, found by bisection. The knee-less walker's trailing leg sweeps
    through the floor after toe-off; this pose-dependent lower knee limit keeps the body
    physical (no penetration), like the joint limits of eq. (6)."""
    swing = (1 - stance_leg).astype(np.intp)
    rows = np.arange(dofs.shape[0])
    knee_col = DOF_NAMES.index("left_knee") + swing
    leg = _leg(body, local, legs, dofs, scale, swing)
    knee = dofs[rows, knee_col]
    low = np.flatnonzero(_foot_lowest_z(body, leg, knee, shift_z) < 0.0)
    if low.size == 0:
        return
    # the bisection works on the low rows only, with everything but the knee angle fixed
    dofs[low, knee_col[low]] = _knee_at_ground(body, leg.take(low), shift_z[low], knee[low], np.full(low.size, np.pi),
                                               iterations)




def sample_posed_kinematics_reference(
    config: KinematicConfig,
    body: BodyDescription,
    params: WalkerParams,
    walker: WalkerState,
    kin: KinematicState,
    rng: np.random.Generator,
    heading: np.ndarray | float | None = None,
) -> tuple[KinematicState, BodyPoseBatch]:
    """Reference of ``sample_posed_kinematics`` (and, with ``heading``, of ``sample_kinematics``):
    the sampled states and their posed bodies."""
    body = _ruled(body, config)
    current = kin.dofs()
    struck = walker.stance_leg.astype(np.int8) != kin.contact_leg
    turn_rate = kin.turn_rate
    if np.any(struck):      # a new step: a new turn rate
        turn_rate = np.where(struck, config.turning.sample(kin.turn_rate, rng), kin.turn_rate)
    new = _eq6(config, body, walker, current, kin.previous, kin.torso_rest, rng, (turn_rate, kin.turn_rate))
    scale = kin.leg_scale
    if config.leg_scale_drift > 0:
        scale = np.clip(scale * np.exp(config.leg_scale_drift * rng.standard_normal(len(kin))), *config.leg_scale_range)
    torso_rest = kin.torso_rest
    if config.posture_drift > 0:
        torso_rest = _posture_within_limit(config, torso_rest + config.posture_drift * rng.standard_normal(len(kin)))
    ceiling = kin.pelvis_ceiling
    if config.pelvis_ceiling_drift > 0:
        ceiling = np.clip(ceiling + config.pelvis_ceiling_drift * rng.standard_normal(len(kin)), *PELVIS_CEILING_RANGE)
    if heading is not None:
        new[:, DOF_NAMES.index("heading")] = heading
    legs = leg_angles(walker)
    local = _local_pose(body, legs, new, scale)
    old_leg = kin.contact_leg
    new_leg = walker.stance_leg.astype(np.int8)
    switched = new_leg != old_leg
    before = new.copy()
    # heel rise: the stance knee bent where the pelvis would stand above the particle's ceiling, that fraction of
    # the walker's hip height (not at a strike)
    hip = np.where(switched, np.inf, ceiling * hip_position(params, walker)[1])
    _keep_swing_foot_above_ground(body, local, legs, new, scale, 1 - new_leg, hip)
    _repose(body, local, legs, new, scale, np.flatnonzero(np.any(new != before, axis=1)))
    old_foot = _pick(local.foot, old_leg)
    beta = _lowest_roll(body, old_foot)
    # Roll without slip: the ground contact advances by the arc length rolled on the sole.
    contact = kin.contact_point + (body.sole_radius * (beta - kin.contact_roll))[:, None] * _horizontal_direction(old_foot)
    if np.any(switched):
        shift = _contact_translation(body, local, old_leg, beta, contact)
        # the landing knee straightened until the foot reaches the ground, then that leg posed again
        stanced = new.copy()
        _land_knees(body, local, legs, new, scale, new_leg, switched, shift[:, 2])
        _repose(body, local, legs, new, scale, np.flatnonzero(np.any(new != stanced, axis=1)))
        new_beta = _lowest_roll(body, _pick(local.foot, new_leg))
        new_point = _sole_point(body, _pick(local.ankles, new_leg), _pick(local.foot, new_leg), new_beta)
        contact = np.where(switched[:, None], new_point[:, :2] + shift[:, :2], contact)
        beta = np.where(switched, new_beta, beta)
    shift = _contact_translation(body, local, new_leg, beta, contact)
    landed = new.copy()
    # Clearance while the swing leg trails the stance leg (early swing); later the foot must be
    # free to come down for heel strike, and is only kept out of the ground.
    _keep_swing_foot_above_ground(body, local, legs, new, scale, new_leg, shift[:, 2] - _clearance(config, walker))
    # The landing and the clearance move knees without giving them velocity (position projections):
    # shift psi_{t-1} along, so that eq. (6) next frame sees the sampled velocity.
    current = current + (new - before)
    # The clearance bent some swing knees: pose those legs again (their contact foot and so ``shift``
    # are unchanged; the thigh leads the chord by the new knee's lead).
    _repose(body, local, legs, new, scale, np.flatnonzero(np.any(new != landed, axis=1)))
    named = KinematicState.unpack(new)
    state = KinematicState(
        heading=named["heading"], torso_lean=named["torso_lean"], hip_abduction=named["hip_abduction"],
        hip_rotation=named["hip_rotation"], knee=named["knee"], ankle=named["ankle"], previous=current,
        contact_point=contact, contact_roll=beta, contact_leg=new_leg,
        plane_origin=_plane_origin(params, walker, contact, named["heading"]), turn_rate=turn_rate,
        leg_scale=scale, torso_rest=torso_rest, pelvis_ceiling=ceiling,
    )
    return state, _posed_body(body, legs, new, local, shift)


def _repose(body: BodyDescription, local: _LocalPose, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray,
            rows: np.ndarray) -> None:
    """Pose the legs of bodies ``rows`` again (in place in ``local``) after their knees moved."""
    if rows.size:
        again = _local_pose(body, legs[rows], dofs[rows], scale[rows])
        for name in ("thigh", "knees", "shank", "ankles", "foot"):
            getattr(local, name)[rows] = getattr(again, name)


def pose_body_reference(body: BodyDescription, params: WalkerParams, walker: WalkerState, kin: KinematicState,
                        config: KinematicConfig | None = None) -> BodyPoseBatch:
    """World markers, joint angles and part poses of N bodies (vectorised).

    The pelvis-relative pose comes from the walker's leg angles and the kinematic DOFs; the
    body is then translated so that the contact foot's sole point at ``contact_roll`` sits on
    the ground at ``contact_point``.
    """
    body = _ruled(body, config)
    del params  # the sagittal leg angles come from the walker; the geometry from ``body``
    legs = leg_angles(walker)
    dofs = kin.dofs()
    local = _local_pose(body, legs, dofs, kin.leg_scale)
    shift = _contact_translation(body, local, kin.contact_leg, kin.contact_roll, kin.contact_point)
    return _posed_body(body, legs, dofs, local, shift)


def _posed_body(body: BodyDescription, legs: np.ndarray, dofs: np.ndarray, local: _LocalPose,
                shift: np.ndarray) -> BodyPoseBatch:
    """``pose_body`` from the pelvis-relative pose ``local`` and the pelvis world position ``shift`` (N, 3)."""
    n = dofs.shape[0]
    # written straight into the output arrays (MARKER_NAMES, PART_NAMES and JOINT_NAMES order)
    markers = np.empty((n, len(MARKER_NAMES), 3))
    torso_up = local.torso[:, :, 2]
    markers[:, 0] = shift                                                           # pelvis
    np.add(shift, body.torso_length * torso_up, out=markers[:, 1])                 # thorax
    np.add(markers[:, 1], 0.5 * body.head_length * torso_up, out=markers[:, 2])    # head
    np.add(local.hips, shift[:, None], out=markers[:, 3:5])
    np.add(local.knees, shift[:, None], out=markers[:, 5:7])
    ankles = markers[:, 7:9]
    np.add(local.ankles, shift[:, None], out=ankles)
    heel_local = (-body.heel_offset, 0.0, -body.ankle_height)
    toe_local = (body.foot_length - body.heel_offset, 0.0, -body.ankle_height)
    np.add(ankles, _apply(local.foot, heel_local), out=markers[:, 9:11])
    np.add(ankles, _apply(local.foot, toe_local), out=markers[:, 11:13])

    foot_axis_height = body.foot_radii_heel[0]  # the foot cylinder's bottom touches the heel end of the sole line
    origin = np.empty((n, 8, 3))
    origin[:, 0:2] = markers[:, 0:2]            # torso at the pelvis, head at the thorax
    origin[:, 2:6] = markers[:, 3:7]            # upper legs at the hips, lower legs at the knees
    np.add(ankles, _apply(local.foot, (heel_local[0], 0.0, heel_local[2] + foot_axis_height)), out=origin[:, 6:8])
    rotation = np.empty((n, 8, 3, 3))
    rotation[:, 0] = local.torso
    rotation[:, 1] = local.torso
    np.multiply(local.thigh, _LEG_SEGMENT_SIGNS, out=rotation[:, 2:4])
    np.multiply(local.shank, _LEG_SEGMENT_SIGNS, out=rotation[:, 4:6])
    for column, (source, sign) in enumerate(zip(_FOOT_SEGMENT_COLUMNS, _FOOT_SEGMENT_SIGNS)):
        np.multiply(local.foot[..., source], sign, out=rotation[:, 6:8, :, column])

    joints = np.empty((n, len(JOINT_NAMES)))
    joints[:, 0:3] = dofs[:, 0:3]               # torso pitch, roll, yaw (heading)
    lead = _thigh_lead(body, legs, dofs[:, 7:9])
    for side in (0, 1):                         # hip flexion (the thigh's angle), abduction, rotation, knee, ankle x2
        joints[:, 3 + 6 * side] = legs[:, side] + lead[:, side]
        joints[:, 4 + 6 * side: 9 + 6 * side] = dofs[:, 3 + side:13:2]
        joints[:, 7 + 6 * side] += dofs[:, 7 + side] - lead[:, side]      # ankle flexion from the shank
    return BodyPoseBatch(markers=markers, joint_angles=joints, segments=BodySegments(origin, rotation))


def sole_point_world_reference(body: BodyDescription, walker: WalkerState, kin: KinematicState,
                               leg: np.ndarray, beta: np.ndarray, config: KinematicConfig | None = None) -> np.ndarray:
    """World position (N, 3) of the material point at angle ``beta`` on the rocker sole of foot
    ``leg`` (LEFT/RIGHT per particle) for the bodies posed by ``pose_body`` (used to check slip)."""
    body = _ruled(body, config)
    local = _local_pose(body, leg_angles(walker), kin.dofs(), kin.leg_scale)
    shift = _contact_translation(body, local, kin.contact_leg, kin.contact_roll, kin.contact_point)
    leg = np.broadcast_to(np.asarray(leg, np.int8), (len(kin),))
    return _sole_point(body, _pick(local.ankles, leg), _pick(local.foot, leg), np.asarray(beta, float)) + shift


def initial_kinematics_reference(
    config: KinematicConfig,
    walker: WalkerState,
    start_position_xy: np.ndarray,
    heading: float | np.ndarray,
    n: int,
    rng: np.random.Generator,
    *,
    body: BodyDescription | None = None,
    params: WalkerParams | None = None,
    position_spread: float = 0.0,
    heading_spread: float = 0.0,
    joint_spread: float = 0.0,
    turn_rate_spread: float = 0.0,
    leg_scale_spread: float = 0.0,
    posture_spread: float = 0.0,
    pelvis_ceiling_spread: float = 0.0,
) -> KinematicState:
    """``kinematics.initial_kinematics`` with the sole geometry in numpy (same arguments)."""
    body = body or BodyDescription.default()
    params = params or body.walker_params()
    body = _ruled(body, config)
    # the sampling and the state assembly are the package's (not compiled); the sole geometry is the reference's
    torso_rest = _initial_posture(config, n, rng, posture_spread)
    walker, dofs = _initial_dofs(config, body, walker, heading, n, rng, heading_spread, joint_spread, torso_rest)
    scale = _initial_leg_scale(config, n, rng, leg_scale_spread)
    ceiling = np.clip(config.pelvis_ceiling + pelvis_ceiling_spread * rng.standard_normal(n)
                      if pelvis_ceiling_spread > 0 else np.full(n, config.pelvis_ceiling), *PELVIS_CEILING_RANGE)
    legs = leg_angles(walker)
    local = _local_pose(body, legs, dofs, scale)
    leg = walker.stance_leg.astype(np.int8)
    # the stance knees bent where the pelvis would stand above its ceiling; then the swing knees bent
    # where the swing foot would go below the ground, the body on its stance foot
    before = dofs.copy()
    _keep_swing_foot_above_ground(body, local, legs, dofs, scale, 1 - leg, ceiling * hip_position(params, walker)[1])
    _repose(body, local, legs, dofs, scale, np.flatnonzero(np.any(dofs != before, axis=1)))
    beta = _lowest_roll(body, _pick(local.foot, leg))
    stance = _sole_point(body, _pick(local.ankles, leg), _pick(local.foot, leg), beta)
    before = dofs.copy()
    _keep_swing_foot_above_ground(body, local, legs, dofs, scale, leg, -stance[:, 2])
    _repose(body, local, legs, dofs, scale, np.flatnonzero(np.any(dofs != before, axis=1)))
    point = _sole_point(body, _pick(local.ankles, leg), _pick(local.foot, leg), beta)
    return _initial_state(params, walker, dofs, beta, point, start_position_xy, rng, position_spread,
                          turn_rate_spread, scale, torso_rest, ceiling)

