"""Conditional 3D kinematics (paper Sec. 4.3): a 3D body driven by the planar walker.

State of N particles (``KinematicState``): torso orientation (heading = torso yaw, pitch,
roll), hip abduction and rotation, knees, ankle flexion and inversion (13 DOFs, ``DOF_NAMES``);
the two sagittal hip angles ("Hip X") are the walker's leg angles, so with them the body has
3 torso-orientation DOFs and 12 joint angles as in the paper. The torso position is not free:
it follows from the stance-foot ground contact.

Each DOF psi follows eq. (6):
    psi_t = psi_{t-1} + alpha (psi_{t-1} - psi_{t-2}) + dt^2 (k (psi_bar - psi_{t-1}) + eta),
    eta ~ N(0, sigma^2) truncated so that psi_t stays within its joint limits,
with Table 1's parameters (``TABLE1``; the joint column reconstructed as in MODEL.md Sec. 5).
alpha is given for dt = 1/30 s; at another dt we use alpha^(30 dt) (square root at 1/60 s,
as the paper does). k is in 1/s^2. The swing knee's rest angle is 5 x psi_hip with
psi_hip = phi1 - phi2, the sagittal angle of the swing leg behind the stance leg (bent knee
early in the stride, straight towards its end).

Units of sigma (the paper does not state them): **deg/s^2**. Decided by sampling the prior
on the walker's 1.3 m/s cyclic gait (``benchmarks/bench_render.py``, 2000 particles, 60
frames at 30 Hz). Read as deg/s^2: median per-frame change 0.04 deg (torso, hips), 0.08 deg
(ankles), 0.33 deg (heading); the heading wanders 10 deg (std) in 2 s; the swing knee peaks
at ~90 deg through its rest-angle spring (people: ~65 deg): plausible. Read as rad/s^2: 2-3 deg per frame
for torso, hips and ankles (95th percentile ~7-10 deg), 19 deg per frame for the heading
(560 deg std after 2 s: the body spins), the swing knee slams into its 180 deg limit.
``KinematicConfig.sigma_unit`` holds the conversion factor to rad (pi/180).

Stance-foot contact: the foot's sole is a rocker, a circular arc of radius
``body.sole_radius`` through the heel and toe ends of the sole line (bulging ``sole_sag`` below
it). The contact is the arc's lowest point (angle ``contact_roll`` beta on the arc, clipped
at the heel/toe ends where the foot then pivots about the end). As the foot pitches with the
walker's stance leg (its pitch follows phi1 plus knee and ankle), the contact rolls from
heel to toe, and the ground contact point moves by the rolled arc length sole_radius *
d(beta): rolling without slip, and the foot never goes below the ground. The whole body is
placed by putting this contact point at ``contact_point`` on the ground (z = 0); heading
changes turn the body about it. At heel strike the contact passes to the other foot at
the ground position under that foot's lowest point (its height is snapped to the ground: the
paper's small "jump").

Swing-foot clearance (our addition, MODEL.md: prefer testable physics): the knee-less walker's
trailing leg sweeps through the floor just after toe-off; where the sampled swing knee would
put the swing foot's sole lower than ``swing_clearance`` (2 cm, about the minimum toe
clearance of human gait) above the ground while the swing leg trails the stance leg, or
below the ground later in the swing, the knee is bent just enough to clear it (a
pose-dependent lower joint limit, applied as a position projection that adds no knee velocity).

Known consequence of Table 1's swing knee (k = 15, alpha = 0.9): it lags the stride and is
still bent ~40 deg at heel strike, so the foot lands short of the knee-less walker's foot and
the body walks at ~0.85 x the walker's speed (1.10 vs 1.30 m/s on the sample bag; measure
speed from the pelvis, not from the walker).

Turning (our addition to Table 1; ``TurnPrior``): Table 1's torso "up" row alone (alpha 0.75,
k 0, sigma 300 deg/s^2) makes the heading a quickly damped random walk: about 10 degrees of drift in
2 s, so a person who turns 180 degrees in 2 s (90 deg/s) or veers 35 degrees is lost. People steer
step by step, at foot placement; so each particle also carries a turn rate omega that is redrawn at
every heel strike (omega' = 0.9 omega + e; e ~ N(0, (4 deg/s)^2), or with probability 0.15 a turn,
N(0, (45 deg/s)^2); at most 150 deg/s) and kept through the step. The heading integrates omega,
and eq. (6) with Table 1's row runs on the heading's deviation from that integral (its velocity term
would otherwise amplify the turn). Straight walks stay straight for most particles (85 % of steps
change omega by a few deg/s), while some particles of every step try a turn for the likelihood
to confirm. Measured on a 180-degree turn in 1.7 s (walker render, 320x240, 2000 particles): heading
error at most 16 degrees (Table 1 alone: lost, 160 degrees); straight walks unchanged (33-53 mm mean
absolute against 46-64 over seeds 0-2).

``plane_origin`` maps the walker's sagittal x to the world: the walker's stance contact
x (``walker.stance_contact_x``) lands on ``contact_point``, x grows along the heading.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np
from scipy.special import ndtr, ndtri

from awalker_tracker.model.body import (
    JOINT_NAMES,
    MARKER_NAMES,
    BodyDescription,
    BodyPoseBatch,
    BodySegments,
)
from awalker_tracker.model.walker import LEFT, WalkerParams, WalkerState, stance_contact_x

DOF_NAMES: tuple[str, ...] = (
    "torso_pitch", "torso_roll", "heading",
    "left_hip_abduction", "right_hip_abduction", "left_hip_rotation", "right_hip_rotation",
    "left_knee", "right_knee",
    "left_ankle_flexion", "right_ankle_flexion", "left_ankle_inversion", "right_ankle_inversion",
)
_D = len(DOF_NAMES)
_SIDE = np.array([1.0, -1.0])  # +1 left, -1 right: mirrors abduction, rotation, inversion


@dataclass(frozen=True)
class JointPrior:
    """One row of Table 1: eq. (6) parameters. alpha at dt = 1/30 s; k in 1/s^2; rest (rad);
    sigma in the config's sigma unit (deg/s^2); limits (rad)."""

    alpha: float
    stiffness: float
    rest: float
    sigma: float
    lower: float = -np.inf
    upper: float = np.inf


_EIGHTH = np.pi / 8
TABLE1: dict[str, JointPrior] = {
    "torso_side": JointPrior(0.9, 5.0, 0.0, 25.0),
    "torso_front": JointPrior(0.9, 5.0, 0.0, 25.0),
    "torso_up": JointPrior(0.75, 0.0, 0.0, 300.0),
    "hip_front": JointPrior(0.5, 5.0, 0.0, 50.0, -_EIGHTH, _EIGHTH),
    "hip_up": JointPrior(0.5, 5.0, 0.0, 50.0, -_EIGHTH, _EIGHTH),
    "stance_knee": JointPrior(0.75, 20.0, 0.0, 50.0, 0.0, np.pi),
    "swing_knee": JointPrior(0.9, 15.0, 0.0, 300.0, 0.0, np.pi),  # rest = 5 psi_hip (see module doc)
    "ankle_side": JointPrior(0.9, 50.0, 0.0, 50.0, -_EIGHTH, _EIGHTH),
    "ankle_front": JointPrior(0.9, 50.0, 0.0, 50.0, -_EIGHTH, _EIGHTH),
}
# Table 1 row for each DOF in DOF_NAMES (knees: chosen per particle by stance/swing role).
_DOF_ROWS = ("torso_side", "torso_front", "torso_up", "hip_front", "hip_front", "hip_up", "hip_up",
             "stance_knee", "stance_knee", "ankle_side", "ankle_side", "ankle_front", "ankle_front")


@dataclass(frozen=True)
class TurnPrior:
    """Turning, per step (our addition to Table 1; see the module docstring): the heading turns at a
    rate omega (rad/s) that is redrawn at each heel strike, omega' = persistence * omega + e, with e
    from N(0, small_sigma^2) or, with probability ``turn_probability``, N(0, large_sigma^2) (a turn
    decided at this step), |omega'| <= max_rate. Table 1's torso "up" row adds its within-step noise."""

    persistence: float = 0.9                     # rho: share of the turn rate kept into the next step
    small_sigma: float = np.radians(4.0)         # rad/s: step-to-step steering of a straight walk
    large_sigma: float = np.radians(45.0)        # rad/s: a deliberate turn
    turn_probability: float = 0.15
    max_rate: float = np.radians(150.0)          # rad/s

    def __post_init__(self) -> None:
        if not (0.0 <= self.persistence <= 1.0 and 0.0 <= self.turn_probability <= 1.0):
            raise ValueError("TurnPrior: persistence and turn_probability must lie in [0, 1]")
        if min(self.small_sigma, self.large_sigma, self.max_rate) < 0:
            raise ValueError("TurnPrior: sigmas and max_rate must be >= 0")

    def sample(self, rate: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The next step's turn rates (rad/s) given this step's (N,)."""
        sigma = np.where(rng.random(rate.shape) < self.turn_probability, self.large_sigma, self.small_sigma)
        return np.clip(self.persistence * rate + sigma * rng.standard_normal(rate.shape), -self.max_rate,
                       self.max_rate)


@dataclass(frozen=True)
class KinematicConfig:
    """Conditional kinematics settings. ``dt`` (s): 1/30 or 1/60 as in the paper."""

    dt: float = 1.0 / 30.0
    table: dict[str, JointPrior] = field(default_factory=lambda: dict(TABLE1))
    sigma_unit: float = np.pi / 180.0       # Table 1 sigma is in deg/s^2 (see module docstring)
    swing_knee_rest_gain: float = 5.0       # psi_bar_swing_knee = gain * psi_hip
    swing_clearance: float = 0.02           # m: the swing foot's sole stays this far above the ground
    turning: TurnPrior = TurnPrior()

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"KinematicConfig.dt must be > 0 s, got {self.dt!r}")

    def alpha(self, row: str) -> float:
        """alpha for this dt: Table 1 value (for 1/30 s) ^ (30 dt)."""
        return float(self.table[row].alpha ** (30.0 * self.dt))

    def arrays(self) -> dict[str, np.ndarray]:
        """Per-DOF (13,) arrays of alpha, k, rest, sigma (rad/s^2), lower, upper (stance knee rows)."""
        rows = [self.table[r] for r in _DOF_ROWS]
        return {
            "alpha": np.array([self.alpha(r) for r in _DOF_ROWS]),
            "stiffness": np.array([r.stiffness for r in rows]),
            "rest": np.array([r.rest for r in rows]),
            "sigma": np.array([r.sigma for r in rows]) * self.sigma_unit,
            "lower": np.array([r.lower for r in rows]),
            "upper": np.array([r.upper for r in rows]),
        }


@dataclass
class KinematicState:
    """Kinematic state of N particles (arrays with leading N); angles rad, positions m.

    Pairs are [left, right]. ``previous`` holds all 13 DOFs of the previous frame (eq. 6 needs
    psi_{t-2}) in ``DOF_NAMES`` order. ``contact_*`` describe the stance foot's rolling contact.
    """

    heading: np.ndarray         # (N,) torso yaw = walking direction, from world +x about +z
    torso_lean: np.ndarray      # (N, 2) [pitch (forward lean +), roll (lean to the right +)]
    hip_abduction: np.ndarray   # (N, 2) leg away from the midline +
    hip_rotation: np.ndarray    # (N, 2) internal rotation +
    knee: np.ndarray            # (N, 2) flexion + (0 = straight)
    ankle: np.ndarray           # (N, 2, 2) [..., 0] dorsiflexion (toes up) +, [..., 1] inversion +
    previous: np.ndarray        # (N, 13) DOFs one frame earlier
    contact_point: np.ndarray   # (N, 2) world xy of the stance foot's ground contact
    contact_roll: np.ndarray    # (N,) beta: angle of the contact on the rocker sole (+ toward the toe)
    contact_leg: np.ndarray     # (N,) int8 LEFT/RIGHT: the foot holding the contact
    plane_origin: np.ndarray    # (N, 2) world xy of the walker's sagittal x = 0
    turn_rate: np.ndarray       # (N,) omega: the heading's turn rate during this step (rad/s, left +)

    def __len__(self) -> int:
        return int(self.heading.shape[0])

    def dofs(self) -> np.ndarray:
        """Current DOFs packed in ``DOF_NAMES`` order, (N, 13)."""
        return np.column_stack([
            self.torso_lean[:, 0], self.torso_lean[:, 1], self.heading,
            self.hip_abduction, self.hip_rotation, self.knee, self.ankle[:, :, 0], self.ankle[:, :, 1],
        ])

    @staticmethod
    def unpack(dofs: np.ndarray) -> dict[str, np.ndarray]:
        """Named DOF arrays from a packed (N, 13) array (inverse of ``dofs``)."""
        return {
            "torso_lean": dofs[:, 0:2].copy(), "heading": dofs[:, 2].copy(),
            "hip_abduction": dofs[:, 3:5].copy(), "hip_rotation": dofs[:, 5:7].copy(),
            "knee": dofs[:, 7:9].copy(), "ankle": np.stack([dofs[:, 9:11], dofs[:, 11:13]], axis=2),
        }

    def copy(self) -> "KinematicState":
        return KinematicState(*(getattr(self, f.name).copy() for f in fields(self)))

    def take(self, indices: np.ndarray) -> "KinematicState":
        return KinematicState(*(getattr(self, f.name)[indices] for f in fields(self)))


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


def leg_angles(walker: WalkerState) -> np.ndarray:
    """Global sagittal leg angles [left, right] (N, 2) from the walker's stance/swing angles."""
    left_is_stance = walker.stance_leg == LEFT
    left = np.where(left_is_stance, walker.stance_angle, walker.swing_angle)
    right = np.where(left_is_stance, walker.swing_angle, walker.stance_angle)
    return np.stack([left, right], axis=1)


def _local_pose(body: BodyDescription, legs: np.ndarray, dofs: np.ndarray) -> _LocalPose:
    """Forward kinematics relative to the pelvis. legs (N, 2) sagittal leg angles, dofs (N, 13)."""
    d = KinematicState.unpack(dofs)
    heading = _rot_z(d["heading"])                                            # (N,3,3)
    torso = _turn(_turn(heading, 1, d["torso_lean"][:, 0]), 0, d["torso_lean"][:, 1])
    hips = (0.5 * body.hip_width) * _SIDE[None, :, None] * torso[:, None, :, 1]
    # Leg angle phi about the lateral axis (foot ahead for phi > 0), then abduction, rotation.
    thigh = np.repeat(heading[:, None], 2, axis=1)
    thigh = _turn(_turn(_turn(thigh, 1, -legs), 0, _SIDE * d["hip_abduction"]), 2, -_SIDE * d["hip_rotation"])
    knees = hips - body.upper_leg_length * thigh[..., :, 2]
    shank, ankles, foot = _lower_legs(body, thigh, knees, dofs)
    return _LocalPose(torso, hips, thigh, knees, shank, ankles, foot)


def _lower_legs(body: BodyDescription, thigh: np.ndarray, knees: np.ndarray,
                dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shank frames, ankle positions and foot frames (N, 2, ...) below the given thighs and knees."""
    shank = _turn(thigh, 1, dofs[:, 7:9])                         # knee flexion
    ankles = knees - body.lower_leg_length * shank[..., :, 2]
    foot = _turn(_turn(shank, 1, -dofs[:, 9:11]), 0, -_SIDE * dofs[:, 11:13])   # ankle flexion, inversion
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


def truncated_normal(rng: np.random.Generator, mean: np.ndarray, sigma: np.ndarray,
                     lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Samples of N(mean, sigma^2) truncated to [lower, upper] (inverse CDF, broadcast shapes).

    Sampled in the tail that keeps precision (mirror when the interval lies above the mean);
    bounds far in a tail fall back to the nearest bound.
    """
    mean, sigma, lower, upper = np.broadcast_arrays(*(np.asarray(v, float) for v in (mean, sigma, lower, upper)))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (lower - mean) / sigma
        b = (upper - mean) / sigma
    flip = a > 0  # interval entirely above the mean: sample -x from [-b, -a]
    lo = np.where(flip, -b, a)
    hi = np.where(flip, -a, b)
    # ndtr is exactly 0 below -37.7 and exactly 1 above 8.3: evaluate it only for bounds nearer
    # than that (most joints are far from their limits), same numbers for a fraction of the cost
    near = ~((lo <= -38.0) & (hi >= 9.0))
    cdf_lo, cdf_hi = np.zeros(mean.shape), np.ones(mean.shape)
    cdf_lo[near], cdf_hi[near] = ndtr(lo[near]), ndtr(hi[near])
    u = rng.random(mean.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = ndtri(cdf_lo + u * (cdf_hi - cdf_lo))
    z = np.where(flip, -z, z)
    out = mean + sigma * z
    out = np.where(np.isfinite(out), out, np.where(flip, lower, upper))
    return np.clip(out, lower, upper)


def _eq6(config: KinematicConfig, walker: WalkerState, current: np.ndarray, previous: np.ndarray,
         rng: np.random.Generator, turn_rates: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """One step of eq. (6) for all DOFs (N, 13) with truncated noise; knees by stance/swing role.

    The heading runs eq. (6) on its deviation from the turn (``turn_rates``: omega of this frame and
    of the previous one, rad/s): h_t = h_{t-1} + omega_t dt + alpha (h_{t-1} - h_{t-2} - omega_{t-1} dt)
    + dt^2 eta, so the turn is not amplified by eq. (6)'s velocity term."""
    n = current.shape[0]
    p = {k: np.broadcast_to(v, (n, _D)).copy() for k, v in config.arrays().items()}
    swing = config.table["swing_knee"]
    knee_cols = np.array([7, 8])
    is_swing = np.stack([walker.stance_leg != LEFT, walker.stance_leg == LEFT], axis=1)  # (N, 2) [left, right]
    psi_hip = walker.stance_angle - walker.swing_angle
    swing_values = {
        "alpha": config.alpha("swing_knee"), "stiffness": swing.stiffness,
        "rest": config.swing_knee_rest_gain * psi_hip[:, None], "sigma": swing.sigma * config.sigma_unit,
        "lower": swing.lower, "upper": swing.upper,
    }
    for key, value in swing_values.items():
        p[key][:, knee_cols] = np.where(is_swing, value, p[key][:, knee_cols])
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


def _plane_origin(params: WalkerParams, walker: WalkerState, contact_point: np.ndarray,
                  heading: np.ndarray) -> np.ndarray:
    along = np.stack([np.cos(heading), np.sin(heading)], axis=1)
    return contact_point - stance_contact_x(params, walker)[:, None] * along


def _swing_foot_lowest_z(body: BodyDescription, thigh_z: np.ndarray, knee_z: np.ndarray,
                         knee: np.ndarray, ankle_turns: tuple[np.ndarray, ...], shift_z: np.ndarray) -> np.ndarray:
    """World height (M,) of the lowest point of the swing foot's sole for a given swing knee angle.

    thigh_z (M, 1, 3): the z row of the swing thigh's frame; knee_z (M,): the knee's height
    (pelvis-relative); knee (M,) rad; ankle_turns: cos and sin (M, 1) of the foot's two turns
    (flexion about y, inversion about x). Only the frames' z rows are turned (the height needs no more).
    """
    shank_z = _turn(thigh_z, 1, knee)
    ankle_z = knee_z - body.lower_leg_length * shank_z[:, 0, 2]
    c_flex, s_flex, c_inv, s_inv = ankle_turns
    foot_z = _turn_cs(_turn_cs(shank_z, 1, c_flex, s_flex), 0, c_inv, s_inv)[:, 0]
    along, up = _sole_offsets(body, _lowest_roll_from(body, foot_z[:, 0], foot_z[:, 2]))
    return ankle_z + foot_z[:, 0] * along + foot_z[:, 2] * up + shift_z


def _keep_swing_foot_above_ground(body: BodyDescription, local: _LocalPose, dofs: np.ndarray,
                                  stance_leg: np.ndarray, shift_z: np.ndarray, iterations: int = 14) -> None:
    """Ground clearance: where the swing foot would go below z = 0, bend the swing knee (in place
    in ``dofs``) just enough, found by bisection. The knee-less walker's trailing leg sweeps
    through the floor after toe-off; this pose-dependent lower knee limit keeps the body
    physical (no penetration), like the joint limits of eq. (6)."""
    swing = (1 - stance_leg).astype(np.intp)
    rows = np.arange(dofs.shape[0])
    knee_col = DOF_NAMES.index("left_knee") + swing
    ankle_dofs = np.stack([dofs[rows, DOF_NAMES.index("left_ankle_flexion") + swing],
                           dofs[rows, DOF_NAMES.index("left_ankle_inversion") + swing]], axis=1)
    knee = dofs[rows, knee_col]
    thigh_z = _pick(local.thigh, swing)[:, 2:3, :]
    knee_z = _pick(local.hips, swing)[:, 2] - body.upper_leg_length * thigh_z[:, 0, 2]
    flex, inversion = -ankle_dofs[:, 0], -_SIDE[swing] * ankle_dofs[:, 1]
    turns = tuple(f(a)[:, None] for a in (flex, inversion) for f in (np.cos, np.sin))
    low = np.flatnonzero(_swing_foot_lowest_z(body, thigh_z, knee_z, knee, turns, shift_z) < 0.0)
    if low.size == 0:
        return
    # the bisection works on the low rows only, with everything but the knee angle fixed
    thigh_z, knee_z, shift_low = thigh_z[low], knee_z[low], shift_z[low]
    turns = tuple(t[low] for t in turns)
    below, above = knee[low], np.full(low.size, np.pi)
    for _ in range(iterations):
        middle = 0.5 * (below + above)
        clear = _swing_foot_lowest_z(body, thigh_z, knee_z, middle, turns, shift_low) >= 0.0
        above = np.where(clear, middle, above)
        below = np.where(clear, below, middle)
    dofs[low, knee_col[low]] = above


def moved_on_ground(kin: KinematicState, centre_xy: np.ndarray, new_centre_xy: np.ndarray,
                    turn: np.ndarray) -> KinematicState:
    """The bodies of ``kin`` moved rigidly on the ground: turned by ``turn`` (N,) rad about the vertical
    through ``centre_xy`` (N, 2) and carried to ``new_centre_xy`` (N, 2) (m). Joint angles, the rolling
    contact and the turn rate are kept; the heading (and its previous value) turns with the body."""
    c, s = np.cos(turn), np.sin(turn)

    def carried(point: np.ndarray) -> np.ndarray:
        d = point - centre_xy
        return new_centre_xy + np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1)

    moved = kin.copy()
    moved.heading = kin.heading + turn
    moved.previous[:, DOF_NAMES.index("heading")] += turn
    moved.contact_point = carried(kin.contact_point)
    moved.plane_origin = carried(kin.plane_origin)
    return moved


def initial_kinematics(
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
) -> KinematicState:
    """N kinematic states near a rest pose: pelvis above ``start_position_xy`` ((2,) or (N, 2), m),
    torso yaw ``heading`` (rad); Gaussian spreads (m, rad, rad; joints truncated to their limits; turn rate rad/s).

    ``walker`` has N or 1 entries (broadcast). Zero joint velocities. The swing knee starts at
    min(its rest angle 5 psi_hip, 0.6 rad) so the swing foot clears the ground.
    """
    body = body or BodyDescription.default()
    params = params or body.walker_params()
    if len(walker) == 1 and n > 1:
        walker = walker.take(np.zeros(n, dtype=np.intp))
    if len(walker) != n:
        raise ValueError(f"initial_kinematics: walker has {len(walker)} entries, expected 1 or {n}")
    p = config.arrays()
    dofs = np.zeros((n, _D))
    dofs[:, 2] = np.asarray(heading, float) + heading_spread * rng.standard_normal(n)
    swing_knee = np.clip(config.swing_knee_rest_gain * (walker.stance_angle - walker.swing_angle), 0.05, 0.6)
    stance_knee = np.full(n, 0.05)
    left_stance = walker.stance_leg == LEFT
    dofs[:, 7] = np.where(left_stance, stance_knee, swing_knee)
    dofs[:, 8] = np.where(left_stance, swing_knee, stance_knee)
    if joint_spread > 0:
        cols = np.array([0, 1, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12])
        lower = np.broadcast_to(p["lower"][cols], (n, cols.size))
        upper = np.broadcast_to(p["upper"][cols], (n, cols.size))
        dofs[:, cols] = truncated_normal(rng, dofs[:, cols], joint_spread, lower, upper)
    legs = leg_angles(walker)
    local = _local_pose(body, legs, dofs)
    leg = walker.stance_leg.astype(np.int8)
    beta = _lowest_roll(body, _pick(local.foot, leg))
    pelvis_xy = np.broadcast_to(np.asarray(start_position_xy, float).reshape(-1, 2), (n, 2)) \
        + position_spread * rng.standard_normal((n, 2))
    point = _sole_point(body, _pick(local.ankles, leg), _pick(local.foot, leg), beta)
    contact_point = pelvis_xy + point[:, :2]
    named = KinematicState.unpack(dofs)
    return KinematicState(
        heading=named["heading"], torso_lean=named["torso_lean"], hip_abduction=named["hip_abduction"],
        hip_rotation=named["hip_rotation"], knee=named["knee"], ankle=named["ankle"], previous=dofs.copy(),
        contact_point=contact_point, contact_roll=beta, contact_leg=leg.copy(),
        plane_origin=_plane_origin(params, walker, contact_point, named["heading"]),
        turn_rate=turn_rate_spread * rng.standard_normal(n) if turn_rate_spread > 0 else np.zeros(n),
    )


def sample_kinematics(
    config: KinematicConfig,
    body: BodyDescription,
    params: WalkerParams,
    walker_prev: WalkerState | None,
    walker: WalkerState,
    events: object | None,
    kin: KinematicState,
    rng: np.random.Generator,
    heading: np.ndarray | float | None = None,
) -> KinematicState:
    """Sample k_t ~ p(k_t | d_t, k_{t-1}) for N particles (eq. 6 plus the contact constraint).

    ``walker`` is the walker state after this frame's dynamics step; a change of
    ``walker.stance_leg`` against ``kin.contact_leg`` is a heel strike (``walker_prev`` and
    ``events`` are accepted for interface symmetry and not needed). ``heading`` (rad), if
    given, replaces the sampled torso heading (a scripted turn, e.g. for synthesis); the body
    still turns about the stance-foot contact.
    """
    del walker_prev, events
    return _sample_kinematics(config, body, params, walker, kin, rng, heading)[0]


def sample_posed_kinematics(
    config: KinematicConfig,
    body: BodyDescription,
    params: WalkerParams,
    walker: WalkerState,
    kin: KinematicState,
    rng: np.random.Generator,
) -> tuple[KinematicState, BodyPoseBatch]:
    """``sample_kinematics`` and then ``pose_body`` of the sampled states, in one pass: the
    pelvis-relative pose computed for the contact is reused for the posed body (same result)."""
    new_kin, legs, dofs, local, shift = _sample_kinematics(config, body, params, walker, kin, rng, None)
    return new_kin, _posed_body(body, legs, dofs, local, shift)


def _sample_kinematics(
    config: KinematicConfig,
    body: BodyDescription,
    params: WalkerParams,
    walker: WalkerState,
    kin: KinematicState,
    rng: np.random.Generator,
    heading: np.ndarray | float | None,
) -> tuple[KinematicState, np.ndarray, np.ndarray, _LocalPose, np.ndarray]:
    """The sampled states plus their leg angles (N, 2), DOFs (N, 13), pelvis-relative pose and
    the contact translation (N, 3) (pelvis world position), for ``_posed_body``."""
    current = kin.dofs()
    struck = walker.stance_leg.astype(np.int8) != kin.contact_leg
    turn_rate = kin.turn_rate
    if np.any(struck):      # a new step: a new turn rate
        turn_rate = np.where(struck, config.turning.sample(kin.turn_rate, rng), kin.turn_rate)
    new = _eq6(config, walker, current, kin.previous, rng, (turn_rate, kin.turn_rate))
    if heading is not None:
        new[:, DOF_NAMES.index("heading")] = heading
    legs = leg_angles(walker)
    local = _local_pose(body, legs, new)
    old_leg = kin.contact_leg
    old_foot = _pick(local.foot, old_leg)
    beta = _lowest_roll(body, old_foot)
    # Roll without slip: the ground contact advances by the arc length rolled on the sole.
    contact = kin.contact_point + (body.sole_radius * (beta - kin.contact_roll))[:, None] * _horizontal_direction(old_foot)
    new_leg = walker.stance_leg.astype(np.int8)
    switched = new_leg != old_leg
    if np.any(switched):
        shift = _contact_translation(body, local, old_leg, beta, contact)
        new_beta = _lowest_roll(body, _pick(local.foot, new_leg))
        new_point = _sole_point(body, _pick(local.ankles, new_leg), _pick(local.foot, new_leg), new_beta)
        contact = np.where(switched[:, None], new_point[:, :2] + shift[:, :2], contact)
        beta = np.where(switched, new_beta, beta)
    shift = _contact_translation(body, local, new_leg, beta, contact)
    before = new.copy()
    # Clearance while the swing leg trails the stance leg (early swing); later the foot must be
    # free to come down for heel strike, and is only kept out of the ground.
    margin = np.where(walker.stance_angle > walker.swing_angle, config.swing_clearance, 0.0)
    _keep_swing_foot_above_ground(body, local, new, new_leg, shift[:, 2] - margin)
    # The clearance moves the knee without giving it velocity (a position projection): shift
    # psi_{t-1} along, so that eq. (6) next frame sees the sampled velocity.
    current = current + (new - before)
    # The clearance bent some swing knees: pose those lower legs again (their contact foot and
    # so ``shift`` are unchanged).
    changed = np.flatnonzero(np.any(new != before, axis=1))
    if changed.size:
        local.shank[changed], local.ankles[changed], local.foot[changed] = _lower_legs(
            body, local.thigh[changed], local.knees[changed], new[changed])
    named = KinematicState.unpack(new)
    state = KinematicState(
        heading=named["heading"], torso_lean=named["torso_lean"], hip_abduction=named["hip_abduction"],
        hip_rotation=named["hip_rotation"], knee=named["knee"], ankle=named["ankle"], previous=current,
        contact_point=contact, contact_roll=beta, contact_leg=new_leg,
        plane_origin=_plane_origin(params, walker, contact, named["heading"]), turn_rate=turn_rate,
    )
    return state, legs, new, local, shift


def pose_body(body: BodyDescription, params: WalkerParams, walker: WalkerState, kin: KinematicState) -> BodyPoseBatch:
    """World markers, joint angles and part poses of N bodies (vectorised).

    The pelvis-relative pose comes from the walker's leg angles and the kinematic DOFs; the
    body is then translated so that the contact foot's sole point at ``contact_roll`` sits on
    the ground at ``contact_point``.
    """
    del params  # the sagittal leg angles come from the walker; the geometry from ``body``
    legs = leg_angles(walker)
    dofs = kin.dofs()
    local = _local_pose(body, legs, dofs)
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
    for side in (0, 1):                         # hip flexion (walker leg angle), abduction, rotation, knee, ankle x2
        joints[:, 3 + 6 * side] = legs[:, side]
        joints[:, 4 + 6 * side: 9 + 6 * side] = dofs[:, 3 + side:13:2]
    return BodyPoseBatch(markers=markers, joint_angles=joints, segments=BodySegments(origin, rotation))


def sole_point_world(body: BodyDescription, walker: WalkerState, kin: KinematicState,
                     leg: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """World position (N, 3) of the material point at angle ``beta`` on the rocker sole of foot
    ``leg`` (LEFT/RIGHT per particle) for the bodies posed by ``pose_body`` (used to check slip)."""
    local = _local_pose(body, leg_angles(walker), kin.dofs())
    shift = _contact_translation(body, local, kin.contact_leg, kin.contact_roll, kin.contact_point)
    leg = np.broadcast_to(np.asarray(leg, np.int8), (len(kin),))
    return _sole_point(body, _pick(local.ankles, leg), _pick(local.foot, leg), np.asarray(beta, float)) + shift
