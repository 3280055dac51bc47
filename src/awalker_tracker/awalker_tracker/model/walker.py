"""Anthropomorphic Walker: parameters, batched state, and planar geometry (paper Sec. 4.1, Fig. 2).

Conventions (shared by dynamics, kinematics and the tracker):
- The walker moves in its sagittal plane: x forward along the walking direction, y up, metres.
- ``stance_angle`` (phi1) and ``swing_angle`` (phi2) are global leg angles from the vertical;
  a leg's foot is ahead of its hip when its angle is positive. During a step phi1 goes from
  positive (just after heel strike) to negative, and the hip moves forward (+x).
- Each foot is a circle of radius R that rolls: the stance foot touches the ground at
  ``contact_origin - R * phi1``; ``contact_origin`` is where it touches when phi1 = 0.
- Masses are fractions of total body mass, so forces and impulses are per unit mass:
  stiffness kappa in N m / rad per kg, toe-off impulse iota in m/s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np


@dataclass(frozen=True)
class WalkerParams:
    """Physical parameters of the walker, SI units, masses as fractions of total mass.

    Defaults are Kuo's anthropomorphic walker scaled to ``leg_length``; g = 9.81 m/s^2
    (the paper uses 9.8: pass ``gravity=9.8`` to match it exactly).
    """

    leg_length: float = 0.9            # L (m): hip to bottom of the foot arc
    foot_radius_ratio: float = 0.3     # R / L
    leg_com_ratio: float = 0.645       # C / L, leg centre of mass measured from the foot
    leg_mass: float = 0.16             # m_l, fraction of total mass
    torso_mass: float = 0.68           # m_t, fraction of total mass
    leg_gyration_ratio: float = 0.326  # radius of gyration of a leg about its CoM / L
    torso_inertia_ratio: float = 0.0   # I_t / L^2 (Kuo: point mass at the hip)
    gravity: float = 9.81              # g (m/s^2)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"WalkerParams.{f.name} must be finite and >= 0, got {value!r}")
        if not (self.leg_length > 0 and self.gravity > 0 and math.isfinite(self.leg_length * self.gravity)):
            raise ValueError("WalkerParams.leg_length and gravity must be finite and > 0")
        if not 0 < self.foot_radius_ratio < 1:
            raise ValueError("WalkerParams.foot_radius_ratio must lie in (0, 1)")

    @property
    def foot_radius(self) -> float:
        """R (m)."""
        return self.foot_radius_ratio * self.leg_length

    @property
    def leg_com(self) -> float:
        """C (m), distance of a leg's centre of mass from the bottom of its foot arc."""
        return self.leg_com_ratio * self.leg_length

    @property
    def leg_inertia(self) -> float:
        """I_l (m^2 per unit total mass): leg inertia about its own centre of mass."""
        return self.leg_mass * (self.leg_gyration_ratio * self.leg_length) ** 2

    @property
    def torso_inertia(self) -> float:
        """I_t (m^2 per unit total mass)."""
        return self.torso_inertia_ratio * self.leg_length**2

    # Kuo's dimensionless units: length L, time sqrt(L/g), mass M (= 1 here, masses are fractions).
    @property
    def time_unit(self) -> float:
        """sqrt(L/g) (s)."""
        return float(np.sqrt(self.leg_length / self.gravity))

    @property
    def speed_unit(self) -> float:
        """sqrt(g L) (m/s)."""
        return float(np.sqrt(self.gravity * self.leg_length))

    def stiffness_to_dimensionless(self, stiffness: np.ndarray | float) -> np.ndarray | float:
        """kappa (N m/rad per kg) -> kappa / (M g L)."""
        return stiffness / (self.gravity * self.leg_length)

    def stiffness_from_dimensionless(self, stiffness: np.ndarray | float) -> np.ndarray | float:
        """kappa / (M g L) -> kappa (N m/rad per kg)."""
        return stiffness * (self.gravity * self.leg_length)

    def impulse_to_dimensionless(self, impulse: np.ndarray | float) -> np.ndarray | float:
        """iota (m/s, per unit mass) -> iota / (M sqrt(g L))."""
        return impulse / self.speed_unit

    def impulse_from_dimensionless(self, impulse: np.ndarray | float) -> np.ndarray | float:
        """iota / (M sqrt(g L)) -> iota (m/s, per unit mass)."""
        return impulse * self.speed_unit

    def step_length(self, double_support_angle: np.ndarray | float) -> np.ndarray | float:
        """Step length (m) for legs at +-a with both feet down: s = 2 (R a + (L - R) sin a)."""
        a = double_support_angle
        return 2.0 * (self.foot_radius * a + (self.leg_length - self.foot_radius) * np.sin(a))


LEFT = 0
RIGHT = 1
LEG_NAMES = {LEFT: "left", RIGHT: "right"}   # as start descriptions and logs name them


@dataclass
class WalkerState:
    """State of N walkers as arrays of shape (N,); angles in rad, rates in rad/s, positions in m."""

    stance_angle: np.ndarray    # phi1
    swing_angle: np.ndarray     # phi2
    stance_rate: np.ndarray     # dphi1/dt
    swing_rate: np.ndarray      # dphi2/dt
    contact_origin: np.ndarray  # x of the stance foot's rolling origin (m)
    stance_leg: np.ndarray      # LEFT (0) or RIGHT (1), int8

    def __len__(self) -> int:
        return int(self.stance_angle.shape[0])

    @classmethod
    def from_arrays(
        cls,
        stance_angle: np.ndarray,
        swing_angle: np.ndarray,
        stance_rate: np.ndarray,
        swing_rate: np.ndarray,
        contact_origin: np.ndarray | float = 0.0,
        stance_leg: np.ndarray | int = LEFT,
    ) -> "WalkerState":
        """Build a state, broadcasting scalars to the common length N."""
        arrays = np.broadcast_arrays(
            np.atleast_1d(np.asarray(stance_angle, float)),
            np.atleast_1d(np.asarray(swing_angle, float)),
            np.atleast_1d(np.asarray(stance_rate, float)),
            np.atleast_1d(np.asarray(swing_rate, float)),
            np.atleast_1d(np.asarray(contact_origin, float)),
            np.atleast_1d(np.asarray(stance_leg, np.int8)),
        )
        return cls(*(np.array(a) for a in arrays))

    def copy(self) -> "WalkerState":
        return WalkerState(*(getattr(self, f.name).copy() for f in fields(self)))

    def take(self, indices: np.ndarray) -> "WalkerState":
        """The walkers at ``indices`` (e.g. after resampling), as a new state."""
        return WalkerState(*(getattr(self, f.name)[indices] for f in fields(self)))

    def angles(self) -> np.ndarray:
        """q = (phi1, phi2), shape (N, 2)."""
        return np.stack([self.stance_angle, self.swing_angle], axis=1)

    def rates(self) -> np.ndarray:
        """dq/dt, shape (N, 2)."""
        return np.stack([self.stance_rate, self.swing_rate], axis=1)


def stance_contact_x(params: WalkerParams, state: WalkerState) -> np.ndarray:
    """x of the stance foot's ground contact point (m): origin - R phi1."""
    return state.contact_origin - params.foot_radius * state.stance_angle


def hip_position(params: WalkerParams, state: WalkerState) -> tuple[np.ndarray, np.ndarray]:
    """Hip (x, y) in the sagittal plane (m), each of shape (N,)."""
    r, l = params.foot_radius, params.leg_length
    phi1 = state.stance_angle
    x = state.contact_origin - r * phi1 - (l - r) * np.sin(phi1)
    y = r + (l - r) * np.cos(phi1)
    return x, y


def foot_centres(
    params: WalkerParams, state: WalkerState
) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Centres (x, y) of the stance and swing foot circles (m)."""
    r, l = params.foot_radius, params.leg_length
    hx, hy = hip_position(params, state)
    stance = (state.contact_origin - r * state.stance_angle, np.full_like(hx, r))
    swing = (hx + (l - r) * np.sin(state.swing_angle), hy - (l - r) * np.cos(state.swing_angle))
    return stance, swing


def hip_velocity(params: WalkerParams, state: WalkerState) -> tuple[np.ndarray, np.ndarray]:
    """Hip velocity (dx/dt, dy/dt) in the sagittal plane (m/s)."""
    r, l = params.foot_radius, params.leg_length
    phi1, rate = state.stance_angle, state.stance_rate
    return (-r - (l - r) * np.cos(phi1)) * rate, -(l - r) * np.sin(phi1) * rate
