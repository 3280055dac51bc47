"""Conditional 3D kinematics (paper Sec. 4.3): the 3D body driven by the planar walker, for N particles.

Each particle's ``KinematicState`` holds 13 DOFs (``DOF_NAMES``: torso heading, pitch and roll, hip
abduction and rotation, knees, ankle flexion and inversion); the sagittal hip angles follow the
walker's leg angles and the body is placed by the stance foot's rolling contact on the ground.
``initial_kinematics`` draws the start, ``sample_kinematics``/``sample_posed_kinematics`` advance one
frame by eq. (6) with Table 1's parameters (``TABLE1``, ``KinematicConfig``, ``TurnPrior``) and
``pose_body`` poses the body. Units: angles rad, lengths m, time s; Table 1's k in 1/s^2 and sigma in
deg/s^2 (``KinematicConfig.sigma_unit``); world frame z up, ground at z = 0.

What is built and why (the knees, the rolling foot, swing-foot clearance, turning, step width, posture,
pelvis ceiling, leg length, the numba kernels): docs/design.md, "Conditional kinematics".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import NamedTuple

import numba
import numpy as np
from scipy.special import ndtr, ndtri

from awalker_tracker.blocks import over_blocks
from awalker_tracker.model.body import (
    JOINT_NAMES,
    MARKER_NAMES,
    PART_NAMES,
    BodyDescription,
    BodyPoseBatch,
    BodySegments,
)
from awalker_tracker.model.walker import LEFT, WalkerParams, WalkerState, hip_position, stance_contact_x

DOF_NAMES: tuple[str, ...] = (
    "torso_pitch", "torso_roll", "heading",
    "left_hip_abduction", "right_hip_abduction", "left_hip_rotation", "right_hip_rotation",
    "left_knee", "right_knee",
    "left_ankle_flexion", "right_ankle_flexion", "left_ankle_inversion", "right_ankle_inversion",
)
_D = len(DOF_NAMES)
_LEFT_ABDUCTION = DOF_NAMES.index("left_hip_abduction")    # the right one follows it
_LEFT_KNEE = DOF_NAMES.index("left_knee")


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
    "swing_knee": JointPrior(0.9, 15.0, 0.0, 300.0, 0.0, np.pi),  # rest = gain x psi_hip (docs/design.md, *Knees*)
    "ankle_side": JointPrior(0.9, 50.0, 0.0, 50.0, -_EIGHTH, _EIGHTH),
    "ankle_front": JointPrior(0.9, 50.0, 0.0, 50.0, -_EIGHTH, _EIGHTH),
}
# Table 1 row for each DOF in DOF_NAMES (knees: chosen per particle by stance/swing role).
_DOF_ROWS = ("torso_side", "torso_front", "torso_up", "hip_front", "hip_front", "hip_up", "hip_up",
             "stance_knee", "stance_knee", "ankle_side", "ankle_side", "ankle_front", "ankle_front")


@dataclass(frozen=True)
class TurnPrior:
    """Turning, per step (our addition to Table 1; docs/design.md, *Turning*): the heading turns at a
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


# fractions of the walker's hip height a particle's pelvis ceiling may take (docs/design.md, *Pelvis ceiling*)
PELVIS_CEILING_RANGE = (0.85, 1.0)


@dataclass(frozen=True)
class KinematicConfig:
    """Conditional kinematics settings. ``dt`` (s): 1/30 or 1/60 as in the paper."""

    dt: float = 1.0 / 30.0
    table: dict[str, JointPrior] = field(default_factory=lambda: dict(TABLE1))
    sigma_unit: float = np.pi / 180.0       # Table 1 sigma is in deg/s^2 (docs/design.md, *Units of sigma*)
    swing_knee_rest_gain: float = 2.5       # psi_bar_swing_knee = gain * psi_hip (the paper: 5; docs/design.md, *Knees*)
    stance_knee_rest: float = 0.4           # rad, psi_bar of the stance knee (Table 1: 0; docs/design.md, *Knees*)
    swing_clearance: float = 0.02           # m: the swing foot's sole stays this far above the ground
    turning: TurnPrior = TurnPrior()
    # m: how far apart (centre to centre) the feet tread with the hips at rest (docs/design.md, *Step width*);
    # None: Table 1's rest, hips unabducted, so that the feet tread the hip joints' distance apart
    step_width: float | None = 0.10
    # per frame: each particle's leg scale wanders by this (log, standard deviation) within leg_scale_range
    leg_scale_drift: float = 0.0
    leg_scale_range: tuple[float, float] = (0.85, 1.10)
    # per frame (rad, standard deviation): each particle's posture (torso_rest) wanders by this within
    # +- POSTURE_LIMIT of Table 1's rest (docs/design.md, *Posture*)
    posture_drift: float = 0.0
    # the particles' pelvis ceilings (docs/design.md, *Pelvis ceiling*) are drawn around this fraction of the
    # walker's hip height and wander by pelvis_ceiling_drift per frame (standard deviation) within
    # PELVIS_CEILING_RANGE; 1 = the walker's hip height itself
    pelvis_ceiling: float = 1.0
    pelvis_ceiling_drift: float = 0.0
    # the knee rule (docs/design.md, *Knees*): False, a bent knee shortens the hip-ankle chord along its angle; True,
    # it lowers the hip straight down over the ankle, which keeps the straight leg's reach (the tracker's with two
    # cameras or more and with the pelvis ceilings: ``TrackerConfig.hip_over_ankle_min_cameras``)
    hip_over_ankle: bool = False

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"KinematicConfig.dt must be > 0 s, got {self.dt!r}")
        if not (np.isfinite(self.stance_knee_rest) and 0.0 <= self.stance_knee_rest < np.pi / 2):
            raise ValueError(f"KinematicConfig.stance_knee_rest must lie in [0, pi/2) rad, got {self.stance_knee_rest!r}")
        if self.step_width is not None and not (np.isfinite(self.step_width) and 0.0 <= self.step_width <= 0.5):
            raise ValueError(f"KinematicConfig.step_width must lie in 0-0.5 m (or be None), got {self.step_width!r}")
        low, high = PELVIS_CEILING_RANGE
        if not (np.isfinite(self.pelvis_ceiling) and low <= self.pelvis_ceiling <= high):
            raise ValueError(f"KinematicConfig.pelvis_ceiling must lie in {low}-{high} (of the walker's hip height), "
                             f"got {self.pelvis_ceiling!r}")
        if not (np.isfinite(self.pelvis_ceiling_drift) and 0.0 <= self.pelvis_ceiling_drift <= 0.02):
            raise ValueError(f"KinematicConfig.pelvis_ceiling_drift must lie in 0-0.02 per frame, got "
                             f"{self.pelvis_ceiling_drift!r}")

    def hip_abduction_rest(self, body: BodyDescription) -> float:
        """psi_bar of both hips' abduction (rad, away from the midline +): Table 1's, or with ``step_width``
        the adduction that brings each ankle (the hip-ankle chord at the stance knee's rest below its hip
        joint) to step_width / 2 from the midline, within Table 1's limits."""
        row = self.table["hip_front"]
        if self.step_width is None:
            return float(row.rest)
        inward = 0.5 * (body.hip_width - self.step_width)
        thigh, shank = body.upper_leg_length, body.lower_leg_length
        chord = np.sqrt(thigh**2 + shank**2 + 2 * thigh * shank * np.cos(self.stance_knee_rest))
        return float(np.clip(-np.arcsin(np.clip(inward / chord, -1.0, 1.0)), row.lower, row.upper))

    def noise_scale(self, row: str) -> float:
        """Factor on Table 1's sigma of ``row`` at this dt (1 at 1/30 s): eta is the discretised noise of a
        damped velocity (per frame v_t = alpha v_{t-1} + dt eta), scaled so that the velocity's stationary
        variance, dt^2 sigma^2 / (1 - alpha^2), is Table 1's at any dt: (1/30 s / dt) sqrt((1 - alpha_dt^2) /
        (1 - alpha_30^2)), which tends to sqrt(1/30 s / dt) (white noise in acceleration) as alpha -> 1.
        Exactly 1 when dt is 1/30 s to within a millionth (a frame interval from stamps in whole ns)."""
        alpha_30, ratio = self.table[row].alpha, (1.0 / 30.0) / self.dt
        if abs(ratio - 1.0) < 1e-6:
            return 1.0
        if alpha_30 >= 1.0 - 1e-9:
            return float(np.sqrt(ratio))
        return float(ratio * np.sqrt((1.0 - self.alpha(row) ** 2) / (1.0 - alpha_30 ** 2)))

    def alpha(self, row: str) -> float:
        """alpha for this dt: Table 1 value (for 1/30 s) ^ (30 dt)."""
        return float(self.table[row].alpha ** (30.0 * self.dt))

    def arrays(self, body: BodyDescription) -> dict[str, np.ndarray]:
        """Per-DOF (13,) arrays of alpha, k, rest, sigma (rad/s^2), lower, upper (stance knee rows) for
        ``body`` (the hips' rest abduction depends on its sizes: ``hip_abduction_rest``)."""
        rows = [self.table[r] for r in _DOF_ROWS]
        rest = np.array([r.rest for r in rows])
        rest[[_LEFT_ABDUCTION, _LEFT_ABDUCTION + 1]] = self.hip_abduction_rest(body)
        rest[[_LEFT_KNEE, _LEFT_KNEE + 1]] = self.stance_knee_rest
        return {
            "alpha": np.array([self.alpha(r) for r in _DOF_ROWS]),
            "stiffness": np.array([r.stiffness for r in rows]),
            "rest": rest,
            "sigma": np.array([r.sigma * self.noise_scale(name) for name, r in zip(_DOF_ROWS, rows)]) * self.sigma_unit,
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
    leg_scale: np.ndarray       # (N,) thigh and shank lengths x this (the body's: 1; docs/design.md, *Leg length per particle*)
    torso_rest: np.ndarray      # (N,) rad: eq. 6's psi_bar of the torso pitch, this particle's posture (*Posture*)
    pelvis_ceiling: np.ndarray  # (N,) the pelvis at most this fraction of the walker's hip height (*Pelvis ceiling*)

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


def leg_angles(walker: WalkerState) -> np.ndarray:
    """Global sagittal leg angles [left, right] (N, 2) from the walker's stance/swing angles."""
    left_is_stance = walker.stance_leg == LEFT
    left = np.where(left_is_stance, walker.stance_angle, walker.swing_angle)
    right = np.where(left_is_stance, walker.swing_angle, walker.stance_angle)
    return np.stack([left, right], axis=1)


def truncated_normal(rng: np.random.Generator, mean: np.ndarray, sigma: np.ndarray,
                     lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Samples of N(mean, sigma^2) truncated to [lower, upper] (broadcast shapes; see
    ``_standard_truncated_normal``).

    Sampled in the tail that keeps precision (mirror when the interval lies above the mean);
    bounds far in a tail fall back to the nearest bound.
    """
    mean, sigma, lower, upper = np.broadcast_arrays(*(np.asarray(v, float) for v in (mean, sigma, lower, upper)))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (lower - mean) / sigma
        b = (upper - mean) / sigma
    flip = a > 0  # interval entirely above the mean: sample -x from [-b, -a]
    z = _standard_truncated_normal(rng, np.where(flip, -b, a), np.where(flip, -a, b))
    z = np.where(flip, -z, z)
    out = mean + sigma * z
    out = np.where(np.isfinite(out), out, np.where(flip, lower, upper))
    return np.clip(out, lower, upper)


def _standard_truncated_normal(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Samples of N(0, 1) truncated to [lo, hi] (same shapes); lo should be <= 0 (the precise tail).
    Not finite where the interval lies too far in the tail (the caller falls back to a bound).

    Most joints are far from their limits (lo <= -38, hi >= 9: a standard normal falls outside with
    probability < 1e-18): they get ``rng.standard_normal`` draws. The others are drawn by the inverse
    CDF from ``rng.random``, in the same order, after those."""
    z = rng.standard_normal(lo.shape)
    near = np.flatnonzero(~((lo <= -38.0) & (hi >= 9.0)))
    if near.size:
        cdf_lo, cdf_hi = ndtr(lo.flat[near]), ndtr(hi.flat[near])
        with np.errstate(divide="ignore", invalid="ignore"):
            z.flat[near] = ndtri(cdf_lo + rng.random(near.size) * (cdf_hi - cdf_lo))
    return z


# Columns of the eq. (6) parameter table (``_eq6_table``), and its swing-knee row.
_ALPHA, _STIFFNESS, _REST, _SIGMA, _LOWER, _UPPER = range(6)
_SWING_KNEE_ROW = _D
_HEADING = DOF_NAMES.index("heading")
_TORSO_PITCH = DOF_NAMES.index("torso_pitch")
# rad: how far a particle's posture (torso_rest) may lie from Table 1's rest of the torso pitch
POSTURE_LIMIT = 0.35


def _eq6_table(config: KinematicConfig, body: BodyDescription) -> np.ndarray:
    """Eq. (6) parameters (14, 6) for ``body``: a row per DOF (knees: the stance knee) and a last row for
    the swing knee, columns alpha (for dt), k (1/s^2), rest (rad; swing knee: the gain on psi_hip),
    sigma (rad/s^2), lower, upper (rad)."""
    p = config.arrays(body)
    table = np.empty((_D + 1, 6))
    for column, key in enumerate(("alpha", "stiffness", "rest", "sigma", "lower", "upper")):
        table[:_D, column] = p[key]
    swing = config.table["swing_knee"]
    table[_SWING_KNEE_ROW] = (config.alpha("swing_knee"), swing.stiffness, config.swing_knee_rest_gain,
                              swing.sigma * config.noise_scale("swing_knee") * config.sigma_unit, swing.lower, swing.upper)
    return table


def _eq6(config: KinematicConfig, body: BodyDescription, walker: WalkerState, current: np.ndarray,
         previous: np.ndarray, torso_rest: np.ndarray, rng: np.random.Generator,
         turn_rates: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """One step of eq. (6) for all DOFs (N, 13) of ``body`` with truncated noise; knees by stance/swing role,
    the torso pitch towards each particle's own rest ``torso_rest`` (N,) rad.

    The heading runs eq. (6) on its deviation from the turn (``turn_rates``: omega of this frame and
    of the previous one, rad/s): h_t = h_{t-1} + omega_t dt + alpha (h_{t-1} - h_{t-2} - omega_{t-1} dt)
    + dt^2 eta, so the turn is not amplified by eq. (6)'s velocity term. The means and the truncation
    bounds are compiled (``_eq6_mean_kernel``, ``_eq6_draw_kernel``); the noise is drawn in between."""
    n = current.shape[0]
    table, dt2 = _eq6_table(config, body), config.dt**2
    stance_leg = np.ascontiguousarray(walker.stance_leg, np.int8)
    psi_hip = np.ascontiguousarray(walker.stance_angle - walker.swing_angle, float)
    rate, previous_rate = (np.ascontiguousarray(np.broadcast_to(r, (n,)), float) for r in turn_rates)
    mean, lo, hi = np.empty((n, _D)), np.empty((n, _D)), np.empty((n, _D))
    current, previous, torso_rest = (np.ascontiguousarray(a, float) for a in (current, previous, torso_rest))
    over_blocks(n, lambda rows: _eq6_mean_kernel(
        table, config.dt, dt2, current[rows], previous[rows], torso_rest[rows], stance_leg[rows], psi_hip[rows],
        rate[rows], previous_rate[rows], mean[rows], lo[rows], hi[rows]))
    z = _standard_truncated_normal(rng, lo, hi)
    new = np.empty((n, _D))
    over_blocks(n, lambda rows: _eq6_draw_kernel(table, dt2, stance_leg[rows], psi_hip[rows], mean[rows], z[rows],
                                                 new[rows]))
    return new


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


#: DOF pairs [left, right] of ``DOF_NAMES`` that a mirror swaps, and the torso roll it negates (``mirrored_legs``)
_MIRROR_ORDER = np.array([DOF_NAMES.index(n.replace("left_", "#").replace("right_", "left_").replace("#", "right_"))
                          for n in DOF_NAMES])
_ROLL = DOF_NAMES.index("torso_roll")


def mirrored_legs(walker: WalkerState, kin: KinematicState, pelvis_xy: np.ndarray, body: BodyDescription,
                  params: WalkerParams, config: KinematicConfig | None = None) -> tuple[WalkerState, KinematicState]:
    """The bodies of ``walker``/``kin`` with left and right named the other way round: the walker stands on the
    other leg's name, the legs' DOFs swap sides and the torso's roll changes sign, so that each body is its own
    mirror image about its sagittal plane, with its pelvis kept at ``pelvis_xy`` (N, 2) (m). Seen from one side
    the near and the far leg look alike: the two namings are the ambiguity the tracker's posterior keeps
    (``TrackerConfig.label_flip_rate_hz``). Joint angles, rates, the heading and the turn rate are kept."""
    mirrored_walker = walker.copy()
    mirrored_walker.stance_leg = (1 - walker.stance_leg).astype(np.int8)
    dofs, previous = kin.dofs()[:, _MIRROR_ORDER], kin.previous[:, _MIRROR_ORDER]
    dofs[:, _ROLL] *= -1.0
    previous[:, _ROLL] *= -1.0
    named = KinematicState.unpack(dofs)
    mirrored = replace(kin.copy(), torso_lean=named["torso_lean"], hip_abduction=named["hip_abduction"],
                       hip_rotation=named["hip_rotation"], knee=named["knee"], ankle=named["ankle"], previous=previous,
                       contact_leg=(1 - kin.contact_leg).astype(np.int8))
    moved = pose_body(body, params, mirrored_walker, mirrored, config).markers[:, MARKER_NAMES.index("pelvis"), :2]
    shift = np.asarray(pelvis_xy, float) - moved
    mirrored.contact_point = mirrored.contact_point + shift
    mirrored.plane_origin = mirrored.plane_origin + shift
    return mirrored_walker, mirrored


def standing_body(walker: WalkerState, kin: KinematicState, pelvis_xy: np.ndarray, fraction: np.ndarray,
                  body: BodyDescription, params: WalkerParams, config: KinematicConfig | None = None
                  ) -> tuple[WalkerState, KinematicState]:
    """Copies of ``walker``/``kin`` whose bodies are ``fraction`` (N,) (0-1) of the way from their own pose towards
    standing with both legs vertical, both knees straight and both feet flat (ankle flexion and inversion 0), the
    pelvis kept at ``pelvis_xy`` (N, 2) m: the walker's leg angles phi1, phi2 shrink towards 0, its contact origin
    moves so that its hip stays put, and the contact foot stands on its sole's lowest point, slid on the ground
    under the pelvis. For posing only (a person who stops brings the trailing foot alongside, where a walker held
    mid-stride stands on one leg): the copies' rates and eq. (6)'s previous joint angles are the originals'."""
    keep = 1.0 - np.clip(np.asarray(fraction, float), 0.0, 1.0)
    settled = walker.copy()
    hip_x = hip_position(params, walker)[0]
    settled.stance_angle = keep * walker.stance_angle
    settled.swing_angle = keep * walker.swing_angle
    settled.contact_origin = walker.contact_origin + hip_x - hip_position(params, settled)[0]   # the hip kept
    moved = kin.copy()
    moved.knee = keep[:, None] * kin.knee
    moved.ankle = keep[:, None, None] * kin.ankle
    geometry, legs, dofs = _geometry(body, config), leg_angles(settled), moved.dofs()
    sole = np.empty((len(moved), 3))
    beta = np.array(moved.contact_roll, float)
    _sole_points_kernel(geometry, legs, dofs, np.ascontiguousarray(moved.leg_scale, float),
                        np.ascontiguousarray(moved.contact_leg, np.int8), beta, True, sole)
    moved.contact_roll = beta
    moved.contact_point = np.asarray(pelvis_xy, float) + sole[:, :2]
    moved.plane_origin = _plane_origin(params, settled, moved.contact_point, moved.heading)
    return settled, moved


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
    leg_scale_spread: float = 0.0,
    posture_spread: float = 0.0,
    pelvis_ceiling_spread: float = 0.0,
) -> KinematicState:
    """N kinematic states near a rest pose: pelvis above ``start_position_xy`` ((2,) or (N, 2), m),
    torso yaw ``heading`` (rad); Gaussian spreads (m, rad, rad; joints truncated to their limits; turn rate rad/s).

    ``walker`` has N or 1 entries (broadcast). Zero joint velocities. The swing knee starts at
    min(its rest angle gain x psi_hip, 0.6 rad), bent further where the swing foot would otherwise go
    below the ground (a foot trailing in double support stays on it); the stance knee at its rest. Each
    particle's posture (the torso pitch's rest) is Table 1's rest plus N(0, ``posture_spread``^2) rad
    within +- ``POSTURE_LIMIT``, and its torso starts at it. Each particle's pelvis ceiling is
    ``config.pelvis_ceiling`` plus N(0, ``pelvis_ceiling_spread``^2) within ``PELVIS_CEILING_RANGE``.
    """
    body = body or BodyDescription.default()
    params = params or body.walker_params()
    torso_rest = _initial_posture(config, n, rng, posture_spread)
    walker, dofs = _initial_dofs(config, body, walker, heading, n, rng, heading_spread, joint_spread, torso_rest)
    leg = np.ascontiguousarray(walker.stance_leg, np.int8)
    beta = np.empty(n)
    point = np.empty((n, 3))
    scale = _initial_leg_scale(config, n, rng, leg_scale_spread)
    ceiling = _pelvis_ceiling_within_range(config.pelvis_ceiling + pelvis_ceiling_spread * rng.standard_normal(n)
                                           if pelvis_ceiling_spread > 0 else np.full(n, config.pelvis_ceiling))
    legs = leg_angles(walker)
    geometry = _geometry(body, config)
    _initial_clearance_kernel(geometry, legs, dofs, scale, leg,
                              np.ascontiguousarray(ceiling * hip_position(params, walker)[1], float))
    _sole_points_kernel(geometry, legs, dofs, scale, leg, beta, True, point)
    return _initial_state(params, walker, dofs, beta, point, start_position_xy, rng, position_spread,
                          turn_rate_spread, scale, torso_rest, ceiling)


def _clearance(config: KinematicConfig, walker: WalkerState) -> np.ndarray:
    """(N,) m the swing foot's wanted clearance: ``swing_clearance`` while the swing leg trails the stance
    leg (early swing); later the foot must be free to come down for heel strike, and is only kept out
    of the ground."""
    return np.where(walker.stance_angle > walker.swing_angle, config.swing_clearance, 0.0)


def _initial_leg_scale(config: KinematicConfig, n: int, rng: np.random.Generator, spread: float) -> np.ndarray:
    """(N,) leg scales: log-normal around 1 with ``spread``, within ``config.leg_scale_range``; ones without."""
    if spread <= 0:
        return np.ones(n)
    low, high = config.leg_scale_range
    return np.clip(np.exp(spread * rng.standard_normal(n)), low, high)


def _pelvis_ceiling_within_range(ceiling: np.ndarray) -> np.ndarray:
    """(N,) pelvis ceilings clipped to ``PELVIS_CEILING_RANGE``."""
    return np.clip(ceiling, *PELVIS_CEILING_RANGE)


def _initial_posture(config: KinematicConfig, n: int, rng: np.random.Generator, spread: float) -> np.ndarray:
    """(N,) rad rest pitches of the torso: Table 1's, plus N(0, spread^2) within +- POSTURE_LIMIT of it."""
    rest = config.table[_DOF_ROWS[_TORSO_PITCH]].rest
    if spread <= 0:
        return np.full(n, rest)
    return _posture_within_limit(config, rest + spread * rng.standard_normal(n))


def _posture_within_limit(config: KinematicConfig, torso_rest: np.ndarray) -> np.ndarray:
    """Postures (N,) rad clipped to +- POSTURE_LIMIT of Table 1's rest of the torso pitch."""
    upright = config.table[_DOF_ROWS[_TORSO_PITCH]].rest
    return np.clip(torso_rest, upright - POSTURE_LIMIT, upright + POSTURE_LIMIT)


def _initial_dofs(config: KinematicConfig, body: BodyDescription, walker: WalkerState, heading: float | np.ndarray,
                  n: int, rng: np.random.Generator, heading_spread: float, joint_spread: float,
                  torso_rest: np.ndarray) -> tuple[WalkerState, np.ndarray]:
    """``initial_kinematics``' walker broadcast to n entries and its sampled DOFs (n, 13) for ``body``
    (the hips at their rest abduction, the torso pitch at ``torso_rest`` (N,))."""
    if len(walker) == 1 and n > 1:
        walker = walker.take(np.zeros(n, dtype=np.intp))
    if len(walker) != n:
        raise ValueError(f"initial_kinematics: walker has {len(walker)} entries, expected 1 or {n}")
    p = config.arrays(body)
    dofs = np.zeros((n, _D))
    dofs[:, 0] = torso_rest
    dofs[:, 2] = np.asarray(heading, float) + heading_spread * rng.standard_normal(n)
    dofs[:, [_LEFT_ABDUCTION, _LEFT_ABDUCTION + 1]] = p["rest"][_LEFT_ABDUCTION]
    swing_knee = np.clip(config.swing_knee_rest_gain * (walker.stance_angle - walker.swing_angle), 0.05, 0.6)
    stance_knee = np.full(n, p["rest"][_LEFT_KNEE])
    left_stance = walker.stance_leg == LEFT
    dofs[:, 7] = np.where(left_stance, stance_knee, swing_knee)
    dofs[:, 8] = np.where(left_stance, swing_knee, stance_knee)
    if joint_spread > 0:
        cols = np.array([0, 1, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12])
        lower = np.broadcast_to(p["lower"][cols], (n, cols.size))
        upper = np.broadcast_to(p["upper"][cols], (n, cols.size))
        dofs[:, cols] = truncated_normal(rng, dofs[:, cols], joint_spread, lower, upper)
    return walker, dofs


def _initial_state(params: WalkerParams, walker: WalkerState, dofs: np.ndarray, beta: np.ndarray, point: np.ndarray,
                   start_position_xy: np.ndarray, rng: np.random.Generator, position_spread: float,
                   turn_rate_spread: float, leg_scale: np.ndarray, torso_rest: np.ndarray,
                   pelvis_ceiling: np.ndarray) -> KinematicState:
    """``initial_kinematics``' states from the DOFs, the stance foot's contact roll ``beta`` (N,) and its sole
    point relative to the pelvis ``point`` (N, 3) m, the leg scales, postures and pelvis ceilings (N,): the
    pelvis above the (spread) start position."""
    n = dofs.shape[0]
    pelvis_xy = np.broadcast_to(np.asarray(start_position_xy, float).reshape(-1, 2), (n, 2)) \
        + position_spread * rng.standard_normal((n, 2))
    contact_point = pelvis_xy + point[:, :2]
    named = KinematicState.unpack(dofs)
    return KinematicState(
        heading=named["heading"], torso_lean=named["torso_lean"], hip_abduction=named["hip_abduction"],
        hip_rotation=named["hip_rotation"], knee=named["knee"], ankle=named["ankle"], previous=dofs.copy(),
        contact_point=contact_point, contact_roll=beta, contact_leg=walker.stance_leg.astype(np.int8),
        plane_origin=_plane_origin(params, walker, contact_point, named["heading"]),
        turn_rate=turn_rate_spread * rng.standard_normal(n) if turn_rate_spread > 0 else np.zeros(n),
        leg_scale=leg_scale, torso_rest=np.asarray(torso_rest, float).copy(),
        pelvis_ceiling=np.asarray(pelvis_ceiling, float).copy(),
    )


def _plane_origin(params: WalkerParams, walker: WalkerState, contact_point: np.ndarray,
                  heading: np.ndarray) -> np.ndarray:
    """World xy (N, 2) of the walker's sagittal x = 0: its stance contact x lands on ``contact_point``."""
    along = np.stack([np.cos(heading), np.sin(heading)], axis=1)
    return contact_point - stance_contact_x(params, walker)[:, None] * along


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
    return _sample_kinematics(config, body, params, walker, kin, rng, None)


def _sample_kinematics(
    config: KinematicConfig,
    body: BodyDescription,
    params: WalkerParams,
    walker: WalkerState,
    kin: KinematicState,
    rng: np.random.Generator,
    heading: np.ndarray | float | None,
) -> tuple[KinematicState, BodyPoseBatch]:
    """The sampled states and their posed bodies. The random numbers are drawn first with ``rng``,
    vectorised (``TurnPrior.sample``, then eq. 6's noise in ``_eq6``); the per-particle geometry
    then runs in ``_sample_kernel``."""
    n = len(kin)
    current = kin.dofs()
    stance_leg = np.ascontiguousarray(walker.stance_leg, np.int8)
    contact_leg = np.ascontiguousarray(kin.contact_leg, np.int8)
    struck = stance_leg != contact_leg
    turn_rate = kin.turn_rate
    if np.any(struck):      # a new step: a new turn rate
        turn_rate = np.where(struck, config.turning.sample(kin.turn_rate, rng), kin.turn_rate)
    new = _eq6(config, body, walker, current, kin.previous, kin.torso_rest, rng, (turn_rate, kin.turn_rate))
    scale = np.ascontiguousarray(kin.leg_scale, float)
    if config.leg_scale_drift > 0:
        scale = np.clip(scale * np.exp(config.leg_scale_drift * rng.standard_normal(n)), *config.leg_scale_range)
    torso_rest = kin.torso_rest
    if config.posture_drift > 0:
        torso_rest = _posture_within_limit(config, torso_rest + config.posture_drift * rng.standard_normal(n))
    ceiling = kin.pelvis_ceiling
    if config.pelvis_ceiling_drift > 0:
        ceiling = _pelvis_ceiling_within_range(ceiling + config.pelvis_ceiling_drift * rng.standard_normal(n))
    if heading is not None:
        new[:, DOF_NAMES.index("heading")] = heading
    legs = leg_angles(walker)
    margin = _clearance(config, walker)
    previous = current             # becomes psi_{t-1} of the next frame (moved with the clearance)
    contact = np.empty((n, 2))
    beta = np.empty(n)
    plane_origin = np.empty((n, 2))
    pose = _empty_pose(n)
    geometry = _geometry(body, config)
    contact_point, contact_roll = (np.ascontiguousarray(kin.contact_point, float),
                                   np.ascontiguousarray(kin.contact_roll, float))
    stance_x = np.ascontiguousarray(stance_contact_x(params, walker), float)
    hip_height = np.ascontiguousarray(ceiling * hip_position(params, walker)[1], float)   # heel rise's bound (m)
    over_blocks(n, lambda rows: _sample_kernel(
        geometry, legs[rows], new[rows], scale[rows], previous[rows], contact_point[rows], contact_roll[rows],
        contact_leg[rows],
        stance_leg[rows], margin[rows], stance_x[rows], hip_height[rows], contact[rows], beta[rows], plane_origin[rows],
        pose.markers[rows], pose.joint_angles[rows], pose.segments.origin[rows], pose.segments.rotation[rows]))
    named = KinematicState.unpack(new)
    state = KinematicState(
        heading=named["heading"], torso_lean=named["torso_lean"], hip_abduction=named["hip_abduction"],
        hip_rotation=named["hip_rotation"], knee=named["knee"], ankle=named["ankle"], previous=previous,
        contact_point=contact, contact_roll=beta, contact_leg=stance_leg.copy(),
        plane_origin=plane_origin, turn_rate=turn_rate, leg_scale=scale, torso_rest=torso_rest.copy(),
        pelvis_ceiling=np.array(ceiling, float),
    )
    return state, pose


def pose_body(body: BodyDescription, params: WalkerParams, walker: WalkerState, kin: KinematicState,
              config: KinematicConfig | None = None) -> BodyPoseBatch:
    """World markers, joint angles and part poses of N bodies.

    The pelvis-relative pose comes from the walker's leg angles and the kinematic DOFs; the
    body is then translated so that the contact foot's sole point at ``contact_roll`` sits on
    the ground at ``contact_point``. ``config``: the kinematics the states were sampled with, for its knee
    rule (``KinematicConfig.hip_over_ankle``; None: the default's).
    """
    del params  # the sagittal leg angles come from the walker; the geometry from ``body``
    pose = _empty_pose(len(kin))
    geometry, legs, dofs = _geometry(body, config), leg_angles(walker), kin.dofs()
    contact_leg, contact_roll, contact_point = (np.ascontiguousarray(kin.contact_leg, np.int8),
                                                np.ascontiguousarray(kin.contact_roll, float),
                                                np.ascontiguousarray(kin.contact_point, float))
    scale = np.ascontiguousarray(kin.leg_scale, float)
    over_blocks(len(kin), lambda rows: _pose_kernel(
        geometry, legs[rows], dofs[rows], scale[rows], contact_leg[rows], contact_roll[rows], contact_point[rows],
        pose.markers[rows], pose.joint_angles[rows], pose.segments.origin[rows], pose.segments.rotation[rows]))
    return pose


def sole_point_world(body: BodyDescription, walker: WalkerState, kin: KinematicState,
                     leg: np.ndarray, beta: np.ndarray, config: KinematicConfig | None = None) -> np.ndarray:
    """World position (N, 3) of the material point at angle ``beta`` on the rocker sole of foot
    ``leg`` (LEFT/RIGHT per particle) for the bodies posed by ``pose_body`` (used to check slip; ``config`` as
    there)."""
    n = len(kin)
    geometry, legs, dofs = _geometry(body, config), leg_angles(walker), kin.dofs()
    contact = np.empty((n, 3))      # pelvis-relative contact point: the body's translation is minus it
    scale = np.ascontiguousarray(kin.leg_scale, float)
    _sole_points_kernel(geometry, legs, dofs, scale, np.ascontiguousarray(kin.contact_leg, np.int8),
                        np.array(kin.contact_roll, float), False, contact)
    point = np.empty((n, 3))
    _sole_points_kernel(geometry, legs, dofs, scale,
                        np.ascontiguousarray(np.broadcast_to(np.asarray(leg, np.int8), (n,))),
                        np.array(np.broadcast_to(np.asarray(beta, float), (n,))), False, point)
    shift = np.column_stack([kin.contact_point - contact[:, :2], -contact[:, 2]])
    return point + shift


def _empty_pose(n: int) -> BodyPoseBatch:
    """Output arrays for N posed bodies (filled by the kernels)."""
    return BodyPoseBatch(markers=np.empty((n, len(MARKER_NAMES), 3)), joint_angles=np.empty((n, len(JOINT_NAMES))),
                         segments=BodySegments(np.empty((n, len(PART_NAMES), 3)), np.empty((n, len(PART_NAMES), 3, 3))))


# ---- compiled per-particle geometry ---------------------------------------------------------
# Serial numba kernels: one pass per particle, its pose in two small scratch arrays that are
# reused for every particle (no prange: on the tracker's 2 cores its threads cost more than they
# saved; large batches are instead cut into one block of particles per core, ``blocks.over_blocks``).
# Arrays are indexed, never sliced, inside the loops: a view costs a reference count.
# The small per-particle helpers are inlined into the kernels (``inline="always"``): the pose
# kernel runs ~1.6x faster than with calls (measured at 5000 particles), for a longer first
# compilation (cached afterwards). So are the knee solvers and the body writer that take the
# per-particle arrays (``_knee_at_ground`` .. ``_write_posed_body``): the sample kernel in the filter,
# 15000 particles, one thread, 9.5 -> 8.0 ms a call (median of 56), first compilation 14 -> 17 s.
# ``_leg_turns`` and ``_foot_height`` stay calls: inlined as well, 7.6 ms but 23 s to compile.
# ``frames`` (7, 3, 3): rotation matrices whose columns are a frame's axes in world orientation
# (torso and legs: forward, left, up; feet: along the foot heel->toe, left, up); ``points``
# (6, 3): joint positions relative to the pelvis (m). Legs are [left, right] = side 0, 1; the side
# sign +1 (left) / -1 (right) mirrors abduction, rotation and inversion.
# ``turns`` (16,): what posing computed of the particle's angles that later steps need again, so that each
# cosine and sine is taken once (sines and cosines are ~90 % of the kernels' time): the heading's cosine and
# sine, then per leg its thigh lead (``_thigh_lead``, rad) and the cosines and sines of its abduction, rotation
# and inversion turns (signed by side, as ``_leg_turns`` uses them). ``_leg_pose`` writes a leg's entries.
_TORSO, _THIGH, _SHANK, _FOOT = 0, 1, 3, 5     # frames: torso, then left/right thigh, shank, foot
_HIP, _KNEE, _ANKLE = 0, 2, 4                   # points: left/right hip, knee, ankle
_C_HEAD, _S_HEAD = 0, 1                         # turns: the heading's cosine and sine
_LEAD, _C_ABD, _S_ABD, _C_ROT, _S_ROT, _C_INV, _S_INV = range(7)   # turns[_leg_slot(side) + these]


class _Geometry(NamedTuple):
    """The body sizes the kernels use (m; sole_half_angle rad), from a ``BodyDescription``."""

    upper_leg_length: float
    lower_leg_length: float
    ankle_height: float
    foot_length: float
    heel_offset: float
    sole_radius: float
    sole_sag: float
    sole_half_angle: float
    hip_width: float
    torso_length: float
    head_length: float
    foot_axis_height: float     # the foot cylinder's axis above the sole line at the heel
    hip_over_ankle: bool        # a bent knee lowers the hip over the ankle (``KinematicConfig.hip_over_ankle``)


def _geometry(body: BodyDescription, config: KinematicConfig | None = None) -> _Geometry:
    """The kernels' body sizes, and the knee rule of ``config`` (None: the chord keeps its angle)."""
    return _Geometry(
        float(body.upper_leg_length), float(body.lower_leg_length), float(body.ankle_height),
        float(body.foot_length), float(body.heel_offset), float(body.sole_radius), body.sole_sag,
        body.sole_half_angle, float(body.hip_width), float(body.torso_length), float(body.head_length),
        float(body.foot_radii_heel[0]), bool(config is not None and config.hip_over_ankle))


@numba.njit(cache=True, nogil=True)
def _scratch() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-particle scratch: frames (7, 3, 3), points (6, 3) and turns (16,) (see above)."""
    return np.empty((7, 3, 3)), np.empty((6, 3)), np.empty(16)


@numba.njit(cache=True, nogil=True, inline="always")
def _leg_slot(side: int) -> int:
    """Index in ``turns`` of leg ``side``'s entries."""
    return 2 + 7 * side


@numba.njit(cache=True, nogil=True, inline="always")
def _turn(frames: np.ndarray, f: int, axis: int, c: float, s: float) -> None:
    """frames[f] <- frames[f] @ R_axis(angle) in place, given the angle's cosine c and sine s:
    only the two columns other than ``axis`` change."""
    i, j = (axis + 1) % 3, (axis + 2) % 3
    for row in range(3):
        a, b = frames[f, row, i], frames[f, row, j]
        frames[f, row, i] = c * a + s * b
        frames[f, row, j] = c * b - s * a


@numba.njit(cache=True, nogil=True, inline="always")
def _set_heading(frames: np.ndarray, f: int, c: float, s: float) -> None:
    """frames[f] <- rotation about z by the heading (cosine c, sine s)."""
    frames[f, 0, 0], frames[f, 0, 1], frames[f, 0, 2] = c, -s, 0.0
    frames[f, 1, 0], frames[f, 1, 1], frames[f, 1, 2] = s, c, 0.0
    frames[f, 2, 0], frames[f, 2, 1], frames[f, 2, 2] = 0.0, 0.0, 1.0


@numba.njit(cache=True, nogil=True, inline="always")
def _copy_frame(frames: np.ndarray, source: int, target: int) -> None:
    for row in range(3):
        for col in range(3):
            frames[target, row, col] = frames[source, row, col]


# rad: how far each leg's hip-ankle chord leans back from the walker's leg (docs/design.md, *Knees*)
CHORD_LEAN = 0.08


@numba.njit(cache=True, nogil=True, inline="always")
def _chord_angle(g: _Geometry, leg: float, c_knee: float, s_knee: float) -> float:
    """The hip-ankle chord's sagittal angle theta (rad, foot ahead > 0) under ``g.hip_over_ankle``, for the walker's
    leg angle ``leg`` at knee flexion ``knee`` (rad): the bent knee lowers the hip straight down over the ankle, so
    that the ankle stays as far ahead of the hip as the straight leg's (which lies ``CHORD_LEAN`` behind the
    walker's leg): sin theta = L0 sin(leg - CHORD_LEAN) / L(knee), L0 = l_thigh + l_shank and L(knee) =
    sqrt(l_thigh^2 + l_shank^2 + 2 l_thigh l_shank cos knee) the chord's length (a leg scale multiplies both
    lengths and leaves it unchanged; |sin theta| is capped at 1, a knee bent past where that reaches). Without
    the rule the chord's angle is leg - CHORD_LEAN at any knee (``_thigh_lead`` uses that directly). The knee
    comes as its cosine ``c_knee`` and sine ``s_knee``."""
    thigh, shank = g.upper_leg_length, g.lower_leg_length
    chord = math.hypot(thigh + shank * c_knee, shank * s_knee)   # (> 0 at pi: sin pi > 0 in floats)
    return math.asin(min(max((thigh + shank) * math.sin(leg - CHORD_LEAN) / chord, -1.0), 1.0))


@numba.njit(cache=True, nogil=True, inline="always")
def _thigh_lead(g: _Geometry, leg: float, c_knee: float, s_knee: float) -> float:
    """How far (rad) the thigh leans ahead of the walker's leg angle ``leg`` at knee flexion ``knee`` (rad): ahead
    of the hip-ankle chord (``_chord_angle``) by delta = atan2(l_shank sin knee, l_thigh + l_shank cos knee); the
    shank then trails the walker's leg by knee - lead, and the foot, counted from the walker's leg, does not tip
    with the knee. (A leg scale multiplies both lengths and leaves it unchanged.) The knee comes as its cosine
    ``c_knee`` and sine ``s_knee``."""
    delta = math.atan2(g.lower_leg_length * s_knee, g.upper_leg_length + g.lower_leg_length * c_knee)
    if not g.hip_over_ankle:
        return delta - CHORD_LEAN
    return _chord_angle(g, leg, c_knee, s_knee) + delta - leg


@numba.njit(cache=True, nogil=True, inline="always")
def _local_pose(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, i: int, frames: np.ndarray,
                points: np.ndarray, turns: np.ndarray) -> None:
    """Forward kinematics of body i relative to the pelvis (world orientation) into ``frames``, ``points`` and
    ``turns``: legs (N, 2) the sagittal leg angles (rad), dofs (N, 13) in ``DOF_NAMES`` order, scale (N,)
    the factor on thigh and shank lengths."""
    c_head, s_head = math.cos(dofs[i, 2]), math.sin(dofs[i, 2])
    turns[_C_HEAD], turns[_S_HEAD] = c_head, s_head
    _set_heading(frames, _TORSO, c_head, s_head)
    _turn(frames, _TORSO, 1, math.cos(dofs[i, 0]), math.sin(dofs[i, 0]))    # pitch: lean forward
    _turn(frames, _TORSO, 0, math.cos(dofs[i, 1]), math.sin(dofs[i, 1]))    # roll: lean to the right
    for side in range(2):
        _leg_pose(g, legs, dofs, scale, i, side, frames, points, turns)


@numba.njit(cache=True, nogil=True, inline="always")
def _leg_pose(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, i: int, side: int,
              frames: np.ndarray, points: np.ndarray, turns: np.ndarray) -> None:
    """Hip, thigh frame, knee and what lies below of leg ``side`` of body i (the torso frame and the heading's
    ``turns`` are set): the thigh ``_thigh_lead`` ahead of the walker's leg angle phi (foot ahead for phi > 0),
    so that the hip-ankle chord lies ``CHORD_LEAN`` behind phi (over the ankle: at ``_chord_angle``), then
    abduction and rotation. Writes the leg's ``turns``."""
    sign, thigh, slot = 1.0 - 2.0 * side, _THIGH + side, _leg_slot(side)
    for k in range(3):
        points[_HIP + side, k] = (0.5 * g.hip_width) * sign * frames[_TORSO, k, 1]
    knee = dofs[i, 7 + side]
    c_knee, s_knee = math.cos(knee), math.sin(knee)
    lead = _thigh_lead(g, legs[i, side], c_knee, s_knee)
    abduction, rotation = sign * dofs[i, 3 + side], -sign * dofs[i, 5 + side]
    c_abd, s_abd, c_rot, s_rot = math.cos(abduction), math.sin(abduction), math.cos(rotation), math.sin(rotation)
    turns[slot + _LEAD] = lead
    turns[slot + _C_ABD], turns[slot + _S_ABD], turns[slot + _C_ROT], turns[slot + _S_ROT] = c_abd, s_abd, c_rot, s_rot
    pitch = legs[i, side] + lead
    _set_heading(frames, thigh, turns[_C_HEAD], turns[_S_HEAD])
    _turn(frames, thigh, 1, math.cos(pitch), -math.sin(pitch))
    _turn(frames, thigh, 0, c_abd, s_abd)
    _turn(frames, thigh, 2, c_rot, s_rot)
    for k in range(3):
        points[_KNEE + side, k] = points[_HIP + side, k] - (scale[i] * g.upper_leg_length) * frames[thigh, k, 2]
    _lower_leg(g, dofs, scale, i, side, frames, points, turns, c_knee, s_knee)


@numba.njit(cache=True, nogil=True, inline="always")
def _lower_leg(g: _Geometry, dofs: np.ndarray, scale: np.ndarray, i: int, side: int,
               frames: np.ndarray, points: np.ndarray, turns: np.ndarray, c_knee: float, s_knee: float) -> None:
    """Shank frame, ankle position and foot frame of leg ``side`` of body i below its thigh and knee
    (knee flexion, then ankle flexion and inversion from ``dofs`` (N, 13); the shank ``scale[i]`` x its length).
    The foot hangs from the walker's leg: its flexion counts from the leg's direction, the shank's own plus
    knee - lead (``_ankle_from_shank``), so that a bent knee does not tip the foot. ``turns``: the leg's lead is
    set (``_leg_pose``); writes its inversion's. The knee comes also as its cosine and sine."""
    sign, shank, foot, slot = 1.0 - 2.0 * side, _SHANK + side, _FOOT + side, _leg_slot(side)
    _copy_frame(frames, _THIGH + side, shank)
    _turn(frames, shank, 1, c_knee, s_knee)                                                      # knee flexion
    for k in range(3):
        points[_ANKLE + side, k] = points[_KNEE + side, k] - (scale[i] * g.lower_leg_length) * frames[shank, k, 2]
    _copy_frame(frames, shank, foot)
    flexion = _ankle_from_shank(dofs[i, 9 + side], dofs[i, 7 + side], turns[slot + _LEAD])
    _turn(frames, foot, 1, math.cos(flexion), -math.sin(flexion))                                # ankle flexion
    inversion = -sign * dofs[i, 11 + side]
    c_inv, s_inv = math.cos(inversion), math.sin(inversion)
    turns[slot + _C_INV], turns[slot + _S_INV] = c_inv, s_inv
    _turn(frames, foot, 0, c_inv, s_inv)                                                         # inversion


@numba.njit(cache=True, nogil=True, inline="always")
def _ankle_from_shank(ankle: float, knee: float, lead: float) -> float:
    """The foot's flexion (rad) from its shank for the ankle DOF ``ankle`` (counted from the walker's leg) at knee
    flexion ``knee`` with the thigh ``lead`` (``_thigh_lead``) ahead of the walker's leg: ankle + knee - lead."""
    return ankle + knee - lead


@numba.njit(cache=True, nogil=True, inline="always")
def _lowest_roll(g: _Geometry, along_z: float, up_z: float) -> float:
    """beta (rad) of the rocker sole's lowest point for a foot whose along and up axes have these
    world z components, clipped to the sole's ends (the foot then pivots about the heel/toe)."""
    beta = math.atan2(-along_z, up_z)
    return min(max(beta, -g.sole_half_angle), g.sole_half_angle)


@numba.njit(cache=True, nogil=True, inline="always")
def _foot_lowest_roll(g: _Geometry, frames: np.ndarray, side: int) -> float:
    """``_lowest_roll`` of foot ``side`` in ``frames``."""
    return _lowest_roll(g, frames[_FOOT + side, 2, 0], frames[_FOOT + side, 2, 2])


@numba.njit(cache=True, nogil=True, inline="always")
def _sole_offsets(g: _Geometry, beta: float) -> tuple[float, float]:
    """Foot-frame coordinates (along the foot, up; m) of the rocker sole's point at angle beta
    (the circle's centre lies above the sole's middle; the lateral coordinate is 0)."""
    rho = g.sole_radius
    along = (g.foot_length / 2 - g.heel_offset) + rho * math.sin(beta)
    up = (-g.ankle_height - g.sole_sag + rho) - rho * math.cos(beta)
    return along, up


@numba.njit(cache=True, nogil=True, inline="always")
def _sole_point(g: _Geometry, frames: np.ndarray, points: np.ndarray, side: int,
                beta: float) -> tuple[float, float, float]:
    """Pelvis-relative point (m) at angle beta (rad) on the rocker sole of foot ``side``."""
    along, up = _sole_offsets(g, beta)
    foot, ankle = _FOOT + side, _ANKLE + side
    return (points[ankle, 0] + frames[foot, 0, 0] * along + frames[foot, 0, 2] * up,
            points[ankle, 1] + frames[foot, 1, 0] * along + frames[foot, 1, 2] * up,
            points[ankle, 2] + frames[foot, 2, 0] * along + frames[foot, 2, 2] * up)


class _LegTurns(NamedTuple):
    """What ``_foot_height`` needs of one leg that does not change with its knee angle."""

    lengths: tuple[float, float]      # m: thigh, shank (scaled)
    leg_turn: tuple[float, float]     # cosine, sine of the walker's leg angle less CHORD_LEAN (the straight chord's)
    hip_turns: tuple[float, float, float, float]   # c_abd, s_abd, c_rot, s_rot: the thigh's turns about x, z
    hip_z: float                      # m: the hip's height relative to the pelvis
    ankle_turn: tuple[float, float]   # cosine, sine of the ankle DOF plus CHORD_LEAN (from the walker's leg)
    inversion_turn: tuple[float, float]   # cosine, sine of the foot's inversion turn


@numba.njit(cache=True, nogil=True)
def _leg_turns(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, i: int, side: int,
               points: np.ndarray, turns: np.ndarray) -> _LegTurns:
    """``_LegTurns`` of body i's leg ``side`` (the leg posed: its hip in ``points``, its abduction, rotation and
    inversion turns in ``turns``)."""
    slot = _leg_slot(side)
    leg, ankle = legs[i, side] - CHORD_LEAN, dofs[i, 9 + side] + CHORD_LEAN
    return _LegTurns((scale[i] * g.upper_leg_length, scale[i] * g.lower_leg_length), (math.cos(leg), math.sin(leg)),
                     (turns[slot + _C_ABD], turns[slot + _S_ABD], turns[slot + _C_ROT], turns[slot + _S_ROT]),
                     points[_HIP + side, 2], (math.cos(ankle), math.sin(ankle)),
                     (turns[slot + _C_INV], turns[slot + _S_INV]))


@numba.njit(cache=True, nogil=True)
def _foot_height(g: _Geometry, turns: _LegTurns, knee: float, shift_z: float) -> float:
    """World height (m) of the lowest point of a foot's sole with its knee at ``knee`` (rad), the pelvis
    at height ``shift_z`` (m); ``turns`` (``_leg_turns``) holds what of its leg does not change with the
    knee. The thigh leads the chord (``_chord_angle``, which turns with the knee over the ankle) by the knee's
    delta (``_thigh_lead``), so it is turned anew for each knee angle; only the frames' z rows are turned (the
    height needs no more). The bisection calls this ~14 times per leg, so the angles that do not change with
    the knee come in as cosines and sines, and delta's and the chord's by the law of cosines: per call one
    cosine, one sine and one square root, two over the ankle (no arctangent)."""
    lengths, leg_turn, ankle_turn, hip_z = turns.lengths, turns.leg_turn, turns.ankle_turn, turns.hip_z
    c_abd, s_abd, c_rot, s_rot = turns.hip_turns
    c_inv, s_inv = turns.inversion_turn
    c_knee, s_knee = math.cos(knee), math.sin(knee)
    # delta = atan2(l2 sin knee, l1 + l2 cos knee): its cosine and sine over the chord's length
    across, ahead = g.upper_leg_length + g.lower_leg_length * c_knee, g.lower_leg_length * s_knee
    chord = math.sqrt(across * across + ahead * ahead)
    c_delta, s_delta = across / chord, ahead / chord
    # the chord's angle theta (``_chord_angle``): leg - CHORD_LEAN, or over the ankle sin theta = L0 sin(leg -
    # CHORD_LEAN) / L(knee)
    c_chord, s_chord = leg_turn
    if g.hip_over_ankle:
        s_chord = min(max((g.upper_leg_length + g.lower_leg_length) * leg_turn[1] / chord, -1.0), 1.0)
        c_chord = math.sqrt(1.0 - s_chord * s_chord)
    # thigh pitch = theta + delta
    c_pitch = c_chord * c_delta - s_chord * s_delta
    s_pitch = s_chord * c_delta + c_chord * s_delta
    x, y, z = s_pitch, 0.0, c_pitch                                 # thigh: the heading leaves z alone
    y, z = c_abd * y + s_abd * z, c_abd * z - s_abd * y             # abduction about x
    x, y = c_rot * x + s_rot * y, c_rot * y - s_rot * x             # rotation about z
    knee_z = hip_z - lengths[0] * z
    x, z = c_knee * x - s_knee * z, c_knee * z + s_knee * x         # shank: knee flexion about y
    ankle_z = knee_z - lengths[1] * z
    # the foot's flexion from the shank, -_ankle_from_shank = -((ankle + CHORD_LEAN) + (theta0 - theta) +
    # (knee - delta)), theta0 = leg - CHORD_LEAN the straight leg's chord (theta0 - theta = 0 along it)
    c_bend = c_knee * c_delta + s_knee * s_delta                    # knee - delta
    s_bend = s_knee * c_delta - c_knee * s_delta
    if g.hip_over_ankle:
        c_turn = leg_turn[0] * c_chord + leg_turn[1] * s_chord      # theta0 - theta
        s_turn = leg_turn[1] * c_chord - leg_turn[0] * s_chord
        c_bend, s_bend = c_bend * c_turn - s_bend * s_turn, s_bend * c_turn + c_bend * s_turn   # + theta0 - theta
    c_flex = ankle_turn[0] * c_bend - ankle_turn[1] * s_bend        # ankle + CHORD_LEAN + theta0 - theta + knee - delta
    s_flex = -(ankle_turn[1] * c_bend + ankle_turn[0] * s_bend)     # its negative's sine
    x, z = c_flex * x - s_flex * z, c_flex * z + s_flex * x         # foot: ankle flexion about y
    y, z = c_inv * y + s_inv * z, c_inv * z - s_inv * y             # inversion about x
    # The sole is an arc of radius rho in the foot's sagittal plane through the sole line's heel and
    # toe ends; x, z are the world heights of the foot's along and up axes. Its lowest point lies
    # rho |(x, z)| below the arc's centre, unless that is beyond an end: then the end is lowest
    # (the toe if the foot points down, x < 0). Same as ``_lowest_roll`` without the trigonometry.
    rho = g.sole_radius
    if abs(x) * (rho - g.sole_sag) > z * (0.5 * g.foot_length):
        along = g.foot_length - g.heel_offset if x < 0.0 else -g.heel_offset
        return ankle_z + x * along - z * g.ankle_height + shift_z
    centre_z = x * (0.5 * g.foot_length - g.heel_offset) + z * (rho - g.ankle_height - g.sole_sag)
    return ankle_z + centre_z - rho * math.sqrt(x * x + z * z) + shift_z


@numba.njit(cache=True, nogil=True, inline="always")
def _knee_at_ground(g: _Geometry, turns: _LegTurns, shift_z: float, low: float, high: float) -> float:
    """The knee angle (rad) in [low, high] at which the lowest point of a foot (``turns``: its leg)
    reaches height 0 (``shift_z``: the pelvis height, m), found by bisection (14 halvings): bending the
    knee shortens the hip-ankle chord and lifts the foot, so the height grows with the knee. Returns the
    end of the bracket on the foot's clear side (height >= 0)."""
    below, above = low, high
    for _ in range(14):
        middle = 0.5 * (below + above)
        if _foot_height(g, turns, middle, shift_z) >= 0.0:
            above = middle
        else:
            below = middle
    return above


@numba.njit(cache=True, nogil=True, inline="always")
def _clear_knee(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, i: int, swing: int,
                points: np.ndarray, turns: np.ndarray, shift_z: float) -> float:
    """Ground clearance: where body i's foot ``swing`` would go below z = 0 (``shift_z``: the pelvis
    height minus the wanted clearance, m), the knee angle (rad) that bends it just enough
    (``_knee_at_ground`` in [knee, pi]); else the sampled knee angle. The knee-less walker's trailing
    leg sweeps through the floor after toe-off; this pose-dependent lower knee limit keeps the body
    physical (no penetration), like the joint limits of eq. (6). (``_stance_knee`` uses it too.)"""
    knee = dofs[i, 7 + swing]
    leg_turns = _leg_turns(g, legs, dofs, scale, i, swing, points, turns)
    if _foot_height(g, leg_turns, knee, shift_z) >= 0.0:
        return knee
    return _knee_at_ground(g, leg_turns, shift_z, knee, math.pi)


@numba.njit(cache=True, nogil=True, inline="always")
def _landing_knee(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, i: int, leg: int,
                  points: np.ndarray, turns: np.ndarray, shift_z: float) -> float:
    """Heel strike: the walker's feet meet the ground together, but a landing knee still bent holds the
    kinematic foot above it (the chord is shorter than the walker's leg). Where body i's landing foot
    ``leg`` is above the ground (``shift_z``: the pelvis height held by the old contact, m), the knee
    straightened just enough for it to touch (``_knee_at_ground`` in [0, knee]; fully straight if even
    that does not reach); else the sampled knee angle. Without it the body dropped by the gap at the
    contact's snap to the ground (up to 6 cm)."""
    knee = dofs[i, 7 + leg]
    if knee <= 0.0:
        return knee
    leg_turns = _leg_turns(g, legs, dofs, scale, i, leg, points, turns)
    if _foot_height(g, leg_turns, knee, shift_z) <= 0.0:
        return knee
    if _foot_height(g, leg_turns, 0.0, shift_z) >= 0.0:
        return 0.0
    return _knee_at_ground(g, leg_turns, shift_z, 0.0, knee)


@numba.njit(cache=True, nogil=True, inline="always")
def _project_knee(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, previous: np.ndarray, i: int,
                  side: int, knee: float, frames: np.ndarray, points: np.ndarray, turns: np.ndarray) -> None:
    """Set body i's knee ``side`` to ``knee`` (rad) as a position projection: psi_{t-1} in ``previous`` moves
    along, so that eq. (6) next frame sees the sampled knee velocity; the leg is posed again."""
    if knee != dofs[i, 7 + side]:
        previous[i, 7 + side] += knee - dofs[i, 7 + side]
        dofs[i, 7 + side] = knee
        _leg_pose(g, legs, dofs, scale, i, side, frames, points, turns)


@numba.njit(cache=True, nogil=True, inline="always")
def _stance_knee(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, previous: np.ndarray, i: int,
                 leg: int, frames: np.ndarray, points: np.ndarray, turns: np.ndarray, hip_height: float) -> None:
    """Heel rise: the stance foot hangs from the walker's leg, so late in a long stance it stands on its
    toe and would carry the pelvis above the walker's hip (where the landing foot then cannot reach the
    ground). Where body i's pelvis at ``hip_height`` (m, the walker's)
    would put its stance foot ``leg`` below the ground, the stance knee is bent just enough
    (``_clear_knee``: people flex it ~35 degrees at toe-off), as a position projection (``previous``
    moves along), and the leg posed again."""
    _project_knee(g, legs, dofs, scale, previous, i, leg,
                  _clear_knee(g, legs, dofs, scale, i, leg, points, turns, hip_height), frames, points, turns)


@numba.njit(cache=True, nogil=True, inline="always")
def _write_posed_body(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, i: int, shift: tuple[float, float, float],
                      frames: np.ndarray, points: np.ndarray, turns: np.ndarray, markers: np.ndarray, joints: np.ndarray,
                      origin: np.ndarray, rotation: np.ndarray) -> None:
    """Posed body i from its pelvis-relative pose and the pelvis world position ``shift`` (m):
    markers (N, 13, 3) m in MARKER_NAMES order, joints (N, 15) rad in JOINT_NAMES order, segment
    origins (N, 8, 3) m and rotations (N, 8, 3, 3) in PART_NAMES order (frames as in ``BodySegments``)."""
    heel_along, sole_up = -g.heel_offset, -g.ankle_height
    toe_along = g.foot_length - g.heel_offset
    axis_up = -g.ankle_height + g.foot_axis_height
    for k in range(3):
        up = frames[_TORSO, k, 2]
        markers[i, 0, k] = shift[k]                                             # pelvis
        markers[i, 1, k] = shift[k] + g.torso_length * up                       # thorax
        markers[i, 2, k] = markers[i, 1, k] + 0.5 * g.head_length * up          # head
        origin[i, 0, k], origin[i, 1, k] = markers[i, 0, k], markers[i, 1, k]   # torso, head
        for side in range(2):
            along, foot_up = frames[_FOOT + side, k, 0], frames[_FOOT + side, k, 2]
            ankle = points[_ANKLE + side, k] + shift[k]
            markers[i, 3 + side, k] = points[_HIP + side, k] + shift[k]
            markers[i, 5 + side, k] = points[_KNEE + side, k] + shift[k]
            markers[i, 7 + side, k] = ankle
            markers[i, 9 + side, k] = ankle + (heel_along * along + sole_up * foot_up)   # heel
            markers[i, 11 + side, k] = ankle + (toe_along * along + sole_up * foot_up)   # toe
            origin[i, 2 + side, k] = markers[i, 3 + side, k]                   # upper leg at the hip
            origin[i, 4 + side, k] = markers[i, 5 + side, k]                   # lower leg at the knee
            origin[i, 6 + side, k] = ankle + (heel_along * along + axis_up * foot_up)   # foot
        for col in range(3):
            rotation[i, 0, k, col] = frames[_TORSO, k, col]
            rotation[i, 1, k, col] = frames[_TORSO, k, col]
        for side in range(2):
            # legs: (forward, -left, down); feet: (up, -left, along the foot)
            thigh, shank, foot = _THIGH + side, _SHANK + side, _FOOT + side
            rotation[i, 2 + side, k, 0] = frames[thigh, k, 0]
            rotation[i, 2 + side, k, 1] = -frames[thigh, k, 1]
            rotation[i, 2 + side, k, 2] = -frames[thigh, k, 2]
            rotation[i, 4 + side, k, 0] = frames[shank, k, 0]
            rotation[i, 4 + side, k, 1] = -frames[shank, k, 1]
            rotation[i, 4 + side, k, 2] = -frames[shank, k, 2]
            rotation[i, 6 + side, k, 0] = frames[foot, k, 2]
            rotation[i, 6 + side, k, 1] = -frames[foot, k, 1]
            rotation[i, 6 + side, k, 2] = frames[foot, k, 0]
    joints[i, 0], joints[i, 1], joints[i, 2] = dofs[i, 0], dofs[i, 1], dofs[i, 2]   # torso pitch, roll, yaw
    for side in range(2):
        lead = turns[_leg_slot(side) + _LEAD]
        joints[i, 3 + 6 * side] = legs[i, side] + lead       # hip flexion: the thigh's angle
        for j in range(5):                                                # abduction, rotation, knee, ankle x2
            joints[i, 4 + 6 * side + j] = dofs[i, 3 + side + 2 * j]
        joints[i, 7 + 6 * side] = _ankle_from_shank(dofs[i, 9 + side], dofs[i, 7 + side], lead)   # from the shank


@numba.njit(cache=True, nogil=True)
def _sample_kernel(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, previous: np.ndarray,
                   contact_point: np.ndarray, contact_roll: np.ndarray, contact_leg: np.ndarray,
                   stance_leg: np.ndarray, clearance: np.ndarray, stance_x: np.ndarray, hip_height: np.ndarray,
                   new_contact: np.ndarray, new_roll: np.ndarray, plane_origin: np.ndarray, markers: np.ndarray,
                   joints: np.ndarray, origin: np.ndarray, rotation: np.ndarray) -> None:
    """The deterministic part of sampling k_t for N particles, after eq. (6) drew the DOFs:

    legs (N, 2) rad; dofs (N, 13) the sampled DOFs, in place: swing knees bent for ground clearance;
    scale (N,) the leg scales; previous (N, 13) psi_{t-1}, in place: moved along with those knees;
    contact_point (N, 2) m, contact_roll (N,) rad, contact_leg (N,) of the previous frame; stance_leg (N,) the walker's;
    clearance (N,) m the wanted swing-foot clearance; stance_x (N,) m the walker's stance contact x;
    hip_height (N,) m the walker's hip height over the ground, which the stance knee keeps the body's
    pelvis from exceeding (``_stance_knee``).
    Writes the new contact (N, 2), its roll (N,), the plane origin (N, 2) and the posed bodies."""
    frames, points, turns = _scratch()
    for i in range(dofs.shape[0]):
        _local_pose(g, legs, dofs, scale, i, frames, points, turns)
        old, leg = contact_leg[i], stance_leg[i]
        if leg == old:
            _stance_knee(g, legs, dofs, scale, previous, i, leg, frames, points, turns, hip_height[i])
        # Roll without slip: the ground contact advances by the arc length rolled on the sole,
        # along the old contact foot's heel->toe direction on the ground.
        beta = _foot_lowest_roll(g, frames, old)
        dx, dy = frames[_FOOT + old, 0, 0], frames[_FOOT + old, 1, 0]
        norm = max(math.sqrt(dx * dx + dy * dy), 1e-9)
        rolled = g.sole_radius * (beta - contact_roll[i])
        cx, cy = contact_point[i, 0] + rolled * (dx / norm), contact_point[i, 1] + rolled * (dy / norm)
        if leg != old:
            # heel strike: the landing knee straightened until the foot reaches the ground (the body
            # held by the old contact), then the contact passes to the new stance foot's lowest point,
            # put where the body has that point; its height snaps to the ground
            px, py, pz = _sole_point(g, frames, points, old, beta)
            _project_knee(g, legs, dofs, scale, previous, i, leg,
                          _landing_knee(g, legs, dofs, scale, i, leg, points, turns, -pz), frames, points, turns)
            beta = _foot_lowest_roll(g, frames, leg)
            qx, qy, _ = _sole_point(g, frames, points, leg, beta)
            cx, cy = qx + (cx - px), qy + (cy - py)
        # the translation (pelvis world position) that puts the contact on the ground at (cx, cy)
        px, py, pz = _sole_point(g, frames, points, leg, beta)
        shift = (cx - px, cy - py, -pz)
        swing = 1 - leg
        # the stance foot (and so ``shift``) is unchanged by the swing knee
        _project_knee(g, legs, dofs, scale, previous, i, swing,
                      _clear_knee(g, legs, dofs, scale, i, swing, points, turns, shift[2] - clearance[i]), frames, points,
                      turns)
        new_contact[i, 0], new_contact[i, 1] = cx, cy
        new_roll[i] = beta
        plane_origin[i, 0] = cx - stance_x[i] * turns[_C_HEAD]
        plane_origin[i, 1] = cy - stance_x[i] * turns[_S_HEAD]
        _write_posed_body(g, legs, dofs, i, shift, frames, points, turns, markers, joints, origin, rotation)


@numba.njit(cache=True, nogil=True)
def _pose_kernel(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, contact_leg: np.ndarray,
                 contact_roll: np.ndarray, contact_point: np.ndarray, markers: np.ndarray, joints: np.ndarray,
                 origin: np.ndarray, rotation: np.ndarray) -> None:
    """``pose_body`` for N particles: legs (N, 2) rad, dofs (N, 13), leg scales (N,); the contact foot's sole point at
    contact_roll (N,) rad is put on the ground at contact_point (N, 2) m. Writes the posed bodies."""
    frames, points, turns = _scratch()
    for i in range(dofs.shape[0]):
        _local_pose(g, legs, dofs, scale, i, frames, points, turns)
        px, py, pz = _sole_point(g, frames, points, contact_leg[i], contact_roll[i])
        shift = (contact_point[i, 0] - px, contact_point[i, 1] - py, -pz)
        _write_posed_body(g, legs, dofs, i, shift, frames, points, turns, markers, joints, origin, rotation)


@numba.njit(cache=True, nogil=True)
def _sole_points_kernel(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray, leg: np.ndarray,
                        beta: np.ndarray,
                        lowest: bool, out: np.ndarray) -> None:
    """Pelvis-relative points (N, 3) m at angle beta (N,) rad on the rocker soles of feet ``leg`` (N,);
    with ``lowest``, beta is first set to each sole's lowest point (in place)."""
    frames, points, turns = _scratch()
    for i in range(dofs.shape[0]):
        _local_pose(g, legs, dofs, scale, i, frames, points, turns)
        if lowest:
            beta[i] = _foot_lowest_roll(g, frames, leg[i])
        out[i, 0], out[i, 1], out[i, 2] = _sole_point(g, frames, points, leg[i], beta[i])


@numba.njit(cache=True, nogil=True)
def _initial_clearance_kernel(g: _Geometry, legs: np.ndarray, dofs: np.ndarray, scale: np.ndarray,
                              stance_leg: np.ndarray, hip_height: np.ndarray) -> None:
    """Initial knees (in ``dofs`` (N, 13), in place): the stance knee bent where the pelvis would stand above
    the walker's ``hip_height`` (N,) m (``_stance_knee``), then the swing knee where the swing foot would go
    below the ground (no clearance: a foot trailing in double support stays on it), the body standing on
    its stance foot's lowest point."""
    frames, points, turns = _scratch()
    for i in range(dofs.shape[0]):
        _local_pose(g, legs, dofs, scale, i, frames, points, turns)
        leg = stance_leg[i]
        _stance_knee(g, legs, dofs, scale, dofs, i, leg, frames, points, turns, hip_height[i])
        _, _, pz = _sole_point(g, frames, points, leg, _foot_lowest_roll(g, frames, leg))
        dofs[i, 8 - leg] = _clear_knee(g, legs, dofs, scale, i, 1 - leg, points, turns, -pz)


@numba.njit(cache=True, nogil=True, inline="always")
def _eq6_row(table: np.ndarray, j: int, swing: int, psi_hip: float) -> tuple[float, float, float, float, float, float]:
    """Eq. (6) parameters (alpha, k, rest, sigma, lower, upper) of DOF j for a particle whose swing
    leg is ``swing``: its swing knee rests at gain x psi_hip (rad), the other DOFs at their rows."""
    if j == 7 + swing:
        row = table[_SWING_KNEE_ROW]
        return row[_ALPHA], row[_STIFFNESS], row[_REST] * psi_hip, row[_SIGMA], row[_LOWER], row[_UPPER]
    return (table[j, _ALPHA], table[j, _STIFFNESS], table[j, _REST], table[j, _SIGMA], table[j, _LOWER],
            table[j, _UPPER])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _eq6_mean_kernel(table: np.ndarray, dt: float, dt2: float, current: np.ndarray, previous: np.ndarray,
                     torso_rest: np.ndarray, stance_leg: np.ndarray, psi_hip: np.ndarray, rate: np.ndarray,
                     previous_rate: np.ndarray, mean: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Eq. (6) without its noise for N particles: mean (N, 13) = psi_{t-1} + alpha (psi_{t-1} - psi_{t-2})
    + dt^2 k (psi_bar - psi_{t-1}) (psi_bar of the torso pitch: the particle's ``torso_rest`` (N,); the
    heading relative to its turn at rate (N,) rad/s, previously
    previous_rate), and the bounds [lo, hi] (N, 13) of eta / sigma that keep psi_t = mean + dt^2 eta
    within the joint limits, mirrored (-hi, -lo) where they lie above 0 (``_standard_truncated_normal``)."""
    for i in range(current.shape[0]):
        swing = 1 - stance_leg[i]
        for j in range(current.shape[1]):
            alpha, stiffness, rest, sigma, lower, upper = _eq6_row(table, j, swing, psi_hip[i])
            if j == _TORSO_PITCH:
                rest = torso_rest[i]
            psi, psi_before = current[i, j], previous[i, j]
            if j == _HEADING:
                psi_before += previous_rate[i] * dt
            m = psi + alpha * (psi - psi_before) + dt2 * stiffness * (rest - psi)
            if j == _HEADING:
                m += rate[i] * dt
            mean[i, j] = m
            a, b = ((lower - m) / dt2) / sigma, ((upper - m) / dt2) / sigma
            lo[i, j], hi[i, j] = (-b, -a) if a > 0 else (a, b)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _eq6_draw_kernel(table: np.ndarray, dt2: float, stance_leg: np.ndarray, psi_hip: np.ndarray, mean: np.ndarray,
                     z: np.ndarray, out: np.ndarray) -> None:
    """psi_t (N, 13) = mean + dt^2 eta (eq. 6) from the standard truncated normal samples z (N, 13)
    drawn within ``_eq6_mean_kernel``'s bounds: eta = sigma z (mirrored back), falling back to the
    nearest bound where z is not finite; psi_t is clipped to the joint limits."""
    for i in range(mean.shape[0]):
        swing = 1 - stance_leg[i]
        for j in range(mean.shape[1]):
            _, _, _, sigma, lower, upper = _eq6_row(table, j, swing, psi_hip[i])
            m = mean[i, j]
            eta_lower, eta_upper = (lower - m) / dt2, (upper - m) / dt2
            flip = eta_lower / sigma > 0
            eta = sigma * (-z[i, j] if flip else z[i, j])
            if not math.isfinite(eta):
                eta = eta_lower if flip else eta_upper
            eta = min(max(eta, eta_lower), eta_upper)
            out[i, j] = min(max(m + dt2 * eta, lower), upper)
