"""3D body geometry: tapered elliptical cylinders, named markers, the body description YAML.

The body (paper Sec. 5.1, Fig. 5) is eight rigid parts, each a tapered elliptical cylinder
(``PartShape``): torso, head, upper legs, lower legs and feet. Sizes come from a
``BodyDescription`` (metres), set per subject. Poses are computed in ``kinematics.py``;
this module only holds shapes and the batched pose containers.

Segment frames (``BodySegments.rotation``): column 2 is the cylinder axis from its start to
its end; columns 0 and 1 are the directions of the ellipse semi-axes ``radii[0]`` and
``radii[1]``. Torso/head: start at the pelvis/neck, axis up, column 0 forward. Legs: start
at the hip/knee, axis down the leg, column 0 forward. Feet: start at the heel, axis towards
the toe, column 0 up out of the foot (``radii[0]`` is the foot's half height).

Body description YAML (all lengths in metres; missing keys take the defaults of
``BodyDescription.default()``, unknown keys are an error)::

    body:
      upper_leg_length: 0.41        # hip joint centre -> knee joint centre
      lower_leg_length: 0.41        # knee -> ankle joint centre
      ankle_height: 0.066           # ankle joint centre above the flat sole line
      foot_length: 0.26             # heel -> toe along the sole
      heel_offset: 0.06             # heel behind the ankle, along the foot
      sole_radius: 0.6              # radius of the rocker sole (the rolling stance-foot contact)
      hip_width: 0.18               # distance between the hip joint centres
      torso_length: 0.56            # pelvis (hip midpoint) -> neck base (thorax marker)
      head_length: 0.28             # neck base -> top of the head
      torso_radii_bottom: [0.11, 0.16]   # [front-back, left-right] semi-axes at the pelvis
      torso_radii_top: [0.10, 0.18]      # ... at the neck base
      head_radii_bottom: [0.07, 0.065]
      head_radii_top: [0.095, 0.08]
      upper_leg_radii_top: [0.08, 0.075]
      upper_leg_radii_bottom: [0.055, 0.05]
      lower_leg_radii_top: [0.05, 0.048]
      lower_leg_radii_bottom: [0.04, 0.035]
      foot_radii_heel: [0.035, 0.04]     # [half height, half width] at the heel
      foot_radii_toe: [0.025, 0.048]     # ... at the toe

The walker's leg length L (hip to the bottom of the rounded foot) is the standing hip height:
``upper_leg_length + lower_leg_length + ankle_height + sole_sag`` where ``sole_sag`` is how far
the rocker sole bulges below the flat sole line (1.4 cm by default), 0.90 m by default.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from awalker_tracker.errors import InputError, parse_yaml, read_text_file
from awalker_tracker.model.walker import WalkerParams

MARKER_NAMES: tuple[str, ...] = (
    "pelvis", "thorax", "head",
    "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
    "left_heel", "right_heel", "left_toe", "right_toe",
)
#: The skeleton drawn over the markers (overlays, the pose publisher's lines): pairs of ``MARKER_NAMES``.
SKELETON_EDGES: tuple[tuple[str, str], ...] = (
    ("pelvis", "thorax"), ("thorax", "head"), ("pelvis", "left_hip"), ("pelvis", "right_hip"),
    ("left_hip", "left_knee"), ("left_knee", "left_ankle"), ("left_ankle", "left_heel"),
    ("left_heel", "left_toe"), ("left_ankle", "left_toe"),
    ("right_hip", "right_knee"), ("right_knee", "right_ankle"), ("right_ankle", "right_heel"),
    ("right_heel", "right_toe"), ("right_ankle", "right_toe"),
)
PART_NAMES: tuple[str, ...] = (
    "torso", "head", "left_upper_leg", "right_upper_leg",
    "left_lower_leg", "right_lower_leg", "left_foot", "right_foot",
)
PART_CLASSES: tuple[str, ...] = ("head", "torso", "legs", "feet")
PART_CLASS_OF: dict[str, str] = {
    "torso": "torso", "head": "head",
    "left_upper_leg": "legs", "right_upper_leg": "legs", "left_lower_leg": "legs", "right_lower_leg": "legs",
    "left_foot": "feet", "right_foot": "feet",
}
# Joint angles reported with a pose (rad). hip_flexion is the thigh's global sagittal angle from
# the vertical (foot ahead positive: the walker's leg angle plus the thigh's lead over the hip-ankle
# chord, kinematics *Knees*); ankle_flexion is the foot's from the shank; torso_yaw is the heading.
JOINT_NAMES: tuple[str, ...] = (
    "torso_pitch", "torso_roll", "torso_yaw",
    "left_hip_flexion", "left_hip_abduction", "left_hip_rotation", "left_knee",
    "left_ankle_flexion", "left_ankle_inversion",
    "right_hip_flexion", "right_hip_abduction", "right_hip_rotation", "right_knee",
    "right_ankle_flexion", "right_ankle_inversion",
)


@dataclass(frozen=True, eq=False)
class PartShape:
    """A tapered elliptical cylinder: ``length`` (m) along its axis, semi-axes (m) at both ends."""

    name: str
    part_class: str
    length: float
    radii_start: np.ndarray  # (2,) semi-axes along segment columns 0 and 1 at the start
    radii_end: np.ndarray    # (2,) ... at the end

    @property
    def max_radius(self) -> float:
        return float(max(self.radii_start.max(), self.radii_end.max()))


#: A walking person's standing hip height (the walker's leg length L) as a fraction of the height the images see
#: them walk at (``BodyDescription.from_seen_height``). The default body's is 0.517; on the development set's tuning
#: subjects, hands off, two cameras (seeds 0-1, 22 runs) the true leg length was a median 0.542 of the seen height
#: (0.527-0.575), where the default scaled to the seen height had legs 1.4-9.4 cm short (median 3.7; anthropometric
#: tables put the hip at 0.52-0.53 of a standing person's stature; the blob of a walking person is a little lower).
SEEN_HEIGHT_LEG_FRACTION = 0.54
#: Cameras from which the seen height is a measurement (the person triangulated): with fewer, one camera makes it from
#: the depth it estimates, and ``from_seen_height`` keeps the default's proportions for the leg fit that follows.
SEEN_HEIGHT_MIN_CAMERAS = 2


def seen_height_measured(cameras: int) -> bool:
    """Whether ``cameras`` cameras measure the height a person is seen walking at (``SEEN_HEIGHT_MIN_CAMERAS``):
    then a body scaled to it takes a walking person's leg fraction and its legs are not fitted."""
    return cameras >= SEEN_HEIGHT_MIN_CAMERAS

_PAIR_FIELDS = (
    "torso_radii_bottom", "torso_radii_top", "head_radii_bottom", "head_radii_top",
    "upper_leg_radii_top", "upper_leg_radii_bottom", "lower_leg_radii_top", "lower_leg_radii_bottom",
    "foot_radii_heel", "foot_radii_toe",
)


@dataclass(frozen=True)
class BodyDescription:
    """Segment lengths and widths of one subject (m); see the module docstring for the YAML."""

    upper_leg_length: float = 0.41
    lower_leg_length: float = 0.41
    ankle_height: float = 0.066
    foot_length: float = 0.26
    heel_offset: float = 0.06
    sole_radius: float = 0.6
    hip_width: float = 0.18
    torso_length: float = 0.56
    head_length: float = 0.28
    torso_radii_bottom: tuple[float, float] = (0.11, 0.16)
    torso_radii_top: tuple[float, float] = (0.10, 0.18)
    head_radii_bottom: tuple[float, float] = (0.07, 0.065)
    head_radii_top: tuple[float, float] = (0.095, 0.08)
    upper_leg_radii_top: tuple[float, float] = (0.08, 0.075)
    upper_leg_radii_bottom: tuple[float, float] = (0.055, 0.05)
    lower_leg_radii_top: tuple[float, float] = (0.05, 0.048)
    lower_leg_radii_bottom: tuple[float, float] = (0.04, 0.035)
    foot_radii_heel: tuple[float, float] = (0.035, 0.04)
    foot_radii_toe: tuple[float, float] = (0.025, 0.048)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            values = value if f.name in _PAIR_FIELDS else (value,)
            if f.name in _PAIR_FIELDS and len(values) != 2:
                raise ValueError(f"BodyDescription.{f.name} must be two numbers, got {value!r}")
            if not all(np.isfinite(v) and v > 0 for v in values):
                raise ValueError(f"BodyDescription.{f.name} must be finite and > 0, got {value!r}")
        if self.heel_offset >= self.foot_length:
            raise ValueError("BodyDescription.heel_offset must be smaller than foot_length")
        if self.sole_radius <= self.foot_length / 2:
            raise ValueError("BodyDescription.sole_radius must exceed foot_length / 2")
        if self.foot_radii_heel[0] > self.ankle_height:
            raise ValueError("BodyDescription.foot_radii_heel[0] (foot half height) must not exceed ankle_height")

    @classmethod
    def default(cls) -> "BodyDescription":
        """A ~1.75 m adult with a 0.90 m leg."""
        return cls()

    # ---- derived sizes -------------------------------------------------------------------
    @property
    def sole_half_angle(self) -> float:
        """Half the angle (rad) the rocker sole spans: asin(foot_length / (2 sole_radius))."""
        return float(np.arcsin(self.foot_length / (2 * self.sole_radius)))

    @property
    def sole_sag(self) -> float:
        """How far the rocker sole's middle lies below the flat sole line (m)."""
        return float(self.sole_radius * (1 - np.cos(self.sole_half_angle)))

    @property
    def leg_length(self) -> float:
        """Standing hip height = the walker's leg length L (m)."""
        return self.upper_leg_length + self.lower_leg_length + self.ankle_height + self.sole_sag

    @property
    def height(self) -> float:
        """Standing height (m)."""
        return self.leg_length + self.torso_length + self.head_length

    def scaled_to_height(self, height: float) -> "BodyDescription":
        """This body's proportions at another standing height (m): every length and width scaled alike
        (a first guess from a person's height when nobody measured them)."""
        if not (np.isfinite(height) and 1.0 <= height <= 2.3):
            raise ValueError(f"BodyDescription.scaled_to_height: height must lie in 1.0-2.3 m, got {height!r}")
        k = height / self.height
        return type(self)(**{f.name: (tuple(v * k for v in getattr(self, f.name)) if f.name in _PAIR_FIELDS
                                      else getattr(self, f.name) * k) for f in fields(self)})

    def legs_scaled(self, factor: float, keep_height: bool = False) -> "BodyDescription":
        """This body with thigh and shank lengths times ``factor``; the rest unchanged, or with ``keep_height`` the
        torso and head lengths scaled alike so that the standing height stays."""
        legs = replace(self, upper_leg_length=self.upper_leg_length * factor,
                       lower_leg_length=self.lower_leg_length * factor)
        if not keep_height:
            return legs
        scale = (self.height - legs.leg_length) / (self.torso_length + self.head_length)
        if scale <= 0.5:
            raise ValueError(f"BodyDescription.legs_scaled: legs x{factor} leave {self.height - legs.leg_length:.3f} m "
                             f"of a {self.height:.3f} m body for torso and head")
        return replace(legs, torso_length=self.torso_length * scale, head_length=self.head_length * scale)

    @classmethod
    def from_seen_height(cls, height: float, cameras: int) -> "BodyDescription":
        """A body for a person whom nobody measured, seen ``height`` (m) tall walking by ``cameras`` cameras: the
        default's shape scaled to that height, and with ``SEEN_HEIGHT_MIN_CAMERAS`` or more its thigh and shank then
        scaled so that the leg length is ``SEEN_HEIGHT_LEG_FRACTION`` of the height, the torso and head giving what
        the legs gain. One camera keeps the default's proportions: `awalker track` fits its legs next, adding to
        the height (with the fraction as well, the tuning subjects' one-camera runs came out worse, docs/tracking.md,
        *Body from the seen height*)."""
        scaled = cls.default().scaled_to_height(height)
        if not seen_height_measured(cameras):
            return scaled
        thigh_and_shank = scaled.upper_leg_length + scaled.lower_leg_length
        ankle_to_sole = scaled.leg_length - thigh_and_shank        # ankle height and sole sag
        factor = (SEEN_HEIGHT_LEG_FRACTION * scaled.height - ankle_to_sole) / thigh_and_shank
        return scaled.legs_scaled(factor, keep_height=True)

    def walker_params(self, **overrides: float) -> WalkerParams:
        """Walker parameters with L = this body's leg length (other fields from ``overrides``)."""
        return WalkerParams(leg_length=self.leg_length, **overrides)

    @property
    def parts(self) -> tuple[PartShape, ...]:
        """The eight part shapes, in ``PART_NAMES`` order."""
        a = np.asarray
        shapes = {
            "torso": (self.torso_length, self.torso_radii_bottom, self.torso_radii_top),
            "head": (self.head_length, self.head_radii_bottom, self.head_radii_top),
            "upper_leg": (self.upper_leg_length, self.upper_leg_radii_top, self.upper_leg_radii_bottom),
            "lower_leg": (self.lower_leg_length, self.lower_leg_radii_top, self.lower_leg_radii_bottom),
            "foot": (self.foot_length, self.foot_radii_heel, self.foot_radii_toe),
        }
        out = []
        for name in PART_NAMES:
            key = name.removeprefix("left_").removeprefix("right_")
            length, r0, r1 = shapes[key]
            out.append(PartShape(name, PART_CLASS_OF[name], float(length), a(r0, float), a(r1, float)))
        return tuple(out)

    # ---- YAML ----------------------------------------------------------------------------
    def to_yaml_text(self) -> str:
        data = {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}
        return yaml.safe_dump({"body": data}, sort_keys=False)

    @classmethod
    def from_yaml_text(cls, text: str, where: str = "body description") -> "BodyDescription":
        """Parse the body YAML; ``where`` names the file or topic in errors."""
        data = parse_yaml(text, where)
        if not isinstance(data, dict) or not isinstance(data.get("body"), dict):
            raise InputError(f"{where}: expected a top-level 'body:' mapping of segment sizes in metres")
        entries: dict[str, Any] = data["body"]
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(entries) - known)
        if unknown:
            raise InputError(f"{where}: unknown body field(s) {', '.join(unknown)}; expected some of {sorted(known)}")
        values: dict[str, Any] = {}
        for key, value in entries.items():
            if key in _PAIR_FIELDS:
                if not (isinstance(value, list) and len(value) == 2 and all(_is_number(v) for v in value)):
                    raise InputError(f"{where}: body.{key} must be a list of two numbers (m), got {value!r}")
                values[key] = (float(value[0]), float(value[1]))
            else:
                if not _is_number(value):
                    raise InputError(f"{where}: body.{key} must be a number (m), got {value!r}")
                values[key] = float(value)
        try:
            body = replace(cls(), **values)
        except ValueError as exc:
            raise InputError(f"{where}: {exc}") from None
        for name, value, (low, high) in (("ankle_height", body.ankle_height, BODY_ANKLE_RANGE),
                                         ("leg length (upper + lower leg + ankle height + sole)", body.leg_length,
                                          BODY_LEG_RANGE),
                                         ("height", body.height, BODY_HEIGHT_RANGE)):
            if not low <= value <= high:
                raise InputError(f"{where}: body {name} {value:.3g} m: expected a person's, {low:g}-{high:g} m")
        return body

    @classmethod
    def from_yaml(cls, path: str | Path) -> "BodyDescription":
        path = Path(path)
        return cls.from_yaml_text(read_text_file(path, "body description"), str(path))


#: Sizes a body description may give (m): the walker's leg length, the ankle height and the standing height
#: of people, children to the tallest adults; outside them a file's value is a slip (10 m legs tracked at 6 m error).
BODY_LEG_RANGE = (0.4, 1.4)
BODY_ANKLE_RANGE = (0.02, 0.2)
BODY_HEIGHT_RANGE = (0.8, 2.6)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and bool(np.isfinite(value))


@dataclass
class BodySegments:
    """World poses of the parts of N bodies: origin (N, P, 3) m, rotation (N, P, 3, 3)."""

    origin: np.ndarray
    rotation: np.ndarray

    def __len__(self) -> int:
        return int(self.origin.shape[0])

    def take(self, indices: np.ndarray | int) -> "BodySegments":
        idx = np.atleast_1d(indices)
        return BodySegments(self.origin[idx], self.rotation[idx])

    def end_points(self, parts: tuple[PartShape, ...]) -> np.ndarray:
        """Centre of each part's end cap (N, P, 3)."""
        lengths = np.array([p.length for p in parts])
        return self.origin + self.rotation[..., :, 2] * lengths[:, None]


@dataclass
class BodyPoseBatch:
    """Posed bodies: markers (N, 13, 3) world m (``MARKER_NAMES``), joint_angles (N, J) rad
    (``JOINT_NAMES``), segments."""

    markers: np.ndarray
    joint_angles: np.ndarray
    segments: BodySegments

    def __len__(self) -> int:
        return int(self.markers.shape[0])
