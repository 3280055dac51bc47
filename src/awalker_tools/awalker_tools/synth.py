"""Synthetic test sequences: a walking person in a textured room, seen by 1-4 calibrated cameras.

The person's motion comes from the generative model itself (the walker dynamics steered along the cyclic gaits plus the
conditional kinematics, with optional scripted speed change and turn) or from a CMU motion
capture walk (``--from-mocap``), so the tracker can also be tested on motion it did not
produce. Frames are ray-cast (``vision/render.py``, drawn by ``model_render``): a room with a tiled, noisy floor and
cluttered walls, the textured body, an optional box occluder hiding the lower body for a
stretch (paper Experiments 1-3), a slow lighting change and per-pixel sensor noise. The
first ``background_frames`` frames hold the empty room (for background models).

Outputs in ``out_dir``: ``<name>.bag`` (bagio format, ground truth included),
``calibration.yaml``, ``body.yaml``, ``start.yaml`` (the paper's coarse hand
initialisation: first frame with the person, pelvis ground position, heading, speed, step
length, stance leg), ``ground_truth.csv`` (``frame,stamp_ns,marker,x,y,z``; frame counts
from 0 at the first bag frame), ``ground_truth_body.yaml`` (the drawn person's own sizes: ``body.yaml``
before ``tape_measure``; for a diagnosis, not for tracking) and ``overlay_<cam>.png`` (the ground truth drawn over the
middle frame with the person, to look at).
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import JOINT_NAMES, MARKER_NAMES, BodyDescription, BodySegments
from awalker_tracker.vision.camera import Camera, save_calibration
from awalker_tracker.vision.render import pixel_rays, render

from awalker_tools import bagio
from awalker_tools.model_render import render_rgb
from awalker_tools.overlay import save_overlay_png
from awalker_tools.person_render import CARRIED, Outfit, PersonRenderer

_M = {n: i for i, n in enumerate(MARKER_NAMES)}
ROOM_HALF_SIZE = 8.0   # m: the room spans [-8, 8] x [-8, 8]
ROOM_HEIGHT = 4.0      # m
TEXEL = 0.01           # m per texture pixel
FIRST_STAMP_NS = 1_700_000_000_000_000_000
#: The largest image side synth draws (pixels); 100000 x 100000 would need 30 GB a frame.
MAX_IMAGE_SIDE = 4096
#: A walk synth can make (m/s, m): the packaged gait table's 2-7 km/h and 0.3-1.2 m steps.
SPEED_RANGE = (0.55, 1.95)
STEP_RANGE = (0.3, 1.2)
OCCLUDED_SHARE = 0.5   # --occluder's default: the share of the pelvis's path behind the box (``make_occluder``)


@dataclass(frozen=True)
class SynthConfig:
    """What to synthesise. Speeds m/s, lengths m, angles deg, noise in grey levels (0-255)."""

    out_dir: Path
    name: str = "synth"
    cameras: int = 1
    rate: float = 30.0
    frames: int = 90                 # frames with the person
    background_frames: int = 8       # empty-room frames before the person appears
    seed: int = 0
    speed: float = 1.3
    step_length: float = 0.7
    speed_change: bool = False       # slow down to 65 % of the speed over the middle third
    turn_deg: float = 0.0            # turn left (+) or right (-) by this much over the middle third
    occluder: float = 0.0            # > 0: a box hides the lower body over this share of the walk (make_occluder)
    mocap: tuple[Path, Path] | None = None
    width: int = 640
    height: int = 480
    noise_sigma: float = 3.0
    lighting_change: float = 0.25    # the light dims by this fraction and recovers
    storage: str = "mcap"
    compressed: bool = True
    image_format: str = "jpeg"
    person: str = "model"            # "model": the tracker's own body; "dressed": person_render.py (mocap only)
    variant: str = "straight"        # mocap walks: straight, slow, fast, veer-left, veer-right, u-turn
    user_start: bool = False         # start.yaml as a user would write it (position +-5 cm, heading +-5 deg, ...)
    tape_measure: bool = False       # body.yaml lengths with tape-measure errors (a few per cent)
    descriptions: bool = True        # False: a user's own video, no start/body description (file or topic)
    second_person: bool = False      # dressed mocap walks: another person walks the other way, further back
    carry: str = "none"              # dressed person: carries nothing, a backpack or a shoulder bag (CARRIED)

    def __post_init__(self) -> None:
        if not 1 <= self.cameras <= 4:
            raise InputError(f"synth: --cameras must be 1..4, got {self.cameras}")
        if self.rate not in (30.0, 60.0):
            raise InputError(f"synth: --rate must be 30 or 60 Hz, got {self.rate:g}")
        if self.frames < 2 or self.background_frames < 0:
            raise InputError(f"synth: need --frames >= 2 (got {self.frames}) and background frames >= 0")
        if not (np.isfinite(self.occluder) and 0.0 <= self.occluder <= 2.0):
            raise InputError(f"synth: --occluder SHARE must lie in 0-2 (of the walk's path), got {self.occluder:g}")
        if abs(self.turn_deg) > 90:
            raise InputError(f"synth: --turn must be within [-90, 90] degrees, got {self.turn_deg:g}")
        if self.mocap is not None and (self.speed_change or self.turn_deg):
            raise InputError("synth: --speed-change and --turn shape the walker's motion; a --from-mocap walk "
                             "takes --variant (slow, fast, veer-left, veer-right, u-turn) instead")
        if self.person not in ("model", "dressed"):
            raise InputError(f"synth: --person must be 'model' or 'dressed', got {self.person!r}")
        if self.variant not in VARIANTS:
            raise InputError(f"synth: --variant must be one of {', '.join(VARIANTS)}, got {self.variant!r}")
        if self.carry not in CARRIED:
            raise InputError(f"synth: --carry must be one of {', '.join(CARRIED)}, got {self.carry!r}")
        if self.carry != "none" and self.person != "dressed":
            raise InputError("synth: --carry needs --person dressed (and --from-mocap)")
        if self.second_person and self.person != "dressed":
            raise InputError("synth: --second-person needs --person dressed (and --from-mocap)")
        if self.mocap is None and (self.person == "dressed" or self.variant != "straight" or self.tape_measure):
            raise InputError("synth: --person dressed, --variant and --tape-measure need a motion capture walk "
                             "(--from-mocap ASF AMC)")
        needed = VARIANTS[self.variant][2] * self.rate
        if self.frames < needed:
            raise InputError(f"synth: --variant {self.variant} needs --frames >= {int(np.ceil(needed))} at "
                             f"{self.rate:g} Hz (the turn and a second after it), got {self.frames}")
        if self.width < 64 or self.height < 48:
            raise InputError(f"synth: image size {self.width}x{self.height} is too small")
        if self.width > MAX_IMAGE_SIDE or self.height > MAX_IMAGE_SIDE:
            raise InputError(f"synth: --size {self.width} {self.height}: at most {MAX_IMAGE_SIDE} pixels a side")
        if not (np.isfinite(self.noise_sigma) and 0 <= self.noise_sigma <= 100):
            raise InputError(f"synth: --noise must lie in 0-100 grey levels, got {self.noise_sigma:g}")
        if not (np.isfinite(self.speed) and SPEED_RANGE[0] <= self.speed <= SPEED_RANGE[1]):
            raise InputError(f"synth: --speed must lie in {SPEED_RANGE[0]:g}-{SPEED_RANGE[1]:g} m/s (a walk), "
                             f"got {self.speed:g}")
        if not (np.isfinite(self.step_length) and STEP_RANGE[0] <= self.step_length <= STEP_RANGE[1]):
            raise InputError(f"synth: --step-length must lie in {STEP_RANGE[0]:g}-{STEP_RANGE[1]:g} m (the gait "
                             f"table's), got {self.step_length:g}")


# Mocap walk variants: (time-warp factor, (turn angle deg, turn start s, turn duration s) or None, shortest walk s)
VARIANTS: dict[str, tuple[float, tuple[float, float, float] | None, float]] = {
    "straight": (1.0, None, 0.0),
    "slow": (0.8, None, 0.0),
    "fast": (1.2, None, 0.0),
    "veer-left": (1.0, (35.0, 0.5, 2.5), 3.5),
    "veer-right": (1.0, (-35.0, 0.5, 2.5), 3.5),
    "u-turn": (1.0, (180.0, 1.0, 2.0), 4.2),
    "stop": (1.0, None, 4.5),
}
# The second person (--second-person) walks the same mocap walk straight the other way, this far behind
# the first person's start line as the cameras see it (m), in other clothes; the truth stays the first's.
SECOND_PERSON_BEHIND_M = 1.2
# Variants where the person stands still: (from s, for s)
PAUSES: dict[str, tuple[float, float]] = {"stop": (1.5, 1.5)}


@dataclass
class Motion:
    """Ground-truth motion for the frames with the person: markers (F, 13, 3), part poses, the
    body, joint angles (F, J) or None, the start description, and for mocap walks the whole
    skeleton's points (F, len(person_render.POINT_NAMES), 3)."""

    markers: np.ndarray
    segments: BodySegments
    body: BodyDescription
    joint_angles: np.ndarray | None
    start: dict = field(default_factory=dict)
    points: np.ndarray | None = None


# ---- scene --------------------------------------------------------------------------------
def make_cameras(count: int, width: int, height: int, path_centre: np.ndarray) -> list[Camera]:
    """Up to four cameras around the walkway (side, two diagonals, opposite side), slight
    barrel distortion, aimed at the middle of the path."""
    focal = 0.82 * width  # ~63 degrees horizontal field of view
    target = np.array([path_centre[0], path_centre[1], 0.9])
    placements = [(0.0, -4.8, 1.4), (3.6, -3.6, 2.0), (-3.6, 3.6, 2.0), (0.5, 4.8, 1.5)]
    cams = []
    for k in range(count):
        position = target * np.array([1, 1, 0]) + np.array(placements[k])
        cams.append(Camera.look_at(f"cam{k}", width, height, focal, position, target,
                                   distortion=np.array([-0.04, 0.01, 0.0, 0.0, 0.0])))
    return cams


def _value_noise(rng: np.random.Generator, shape: tuple[int, int], cell: int) -> np.ndarray:
    """Smooth noise in [0, 1] of the given shape with features of ~``cell`` pixels."""
    coarse = rng.random((shape[0] // cell + 2, shape[1] // cell + 2)).astype(np.float32)
    return cv2.resize(coarse, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC).clip(0, 1)


def make_textures(rng: np.random.Generator, half_size: float = ROOM_HALF_SIZE) -> dict[str, np.ndarray]:
    """Floor and wall textures (float32 RGB 0-255) at ``TEXEL`` m per pixel for a room spanning
    [-half_size, half_size] m both ways: floor tiles with stains, walls covered with random shelves,
    posters and boxes (clutter)."""
    size = int(2 * half_size / TEXEL)
    floor = np.empty((size, size, 3), np.float32)
    floor[:] = (150, 140, 120)
    tiles = (np.add.outer(np.arange(size) // 50, np.arange(size) // 50) % 2).astype(np.float32)  # 0.5 m tiles
    floor *= (0.9 + 0.1 * tiles)[..., None]
    floor *= (0.8 + 0.4 * _value_noise(rng, (size, size), 40))[..., None]
    for _ in range(25):  # rugs and stains
        x0, y0 = rng.integers(0, size - 200, 2)
        w, h = rng.integers(40, 200, 2)
        colour = rng.uniform(60, 220, 3)
        cv2.rectangle(floor, (int(x0), int(y0)), (int(x0 + w), int(y0 + h)), colour.tolist(), -1)
    grout = (np.arange(size) % 50 < 1)
    floor[grout] *= 0.6
    floor[:, grout] *= 0.6
    walls = []
    wall_h = int(ROOM_HEIGHT / TEXEL)
    for _ in range(4):
        wall = np.empty((wall_h, size, 3), np.float32)
        wall[:] = rng.uniform(150, 210, 3)
        wall *= (0.85 + 0.3 * _value_noise(rng, (wall_h, size), 60))[..., None]
        for _ in range(60):
            x0 = int(rng.integers(0, size - 50))
            y0 = int(rng.integers(0, wall_h - 40))
            w, h = int(rng.integers(20, 180)), int(rng.integers(20, 150))
            colour = rng.uniform(20, 240, 3).tolist()
            cv2.rectangle(wall, (x0, y0), (x0 + w, y0 + h), colour, -1)
            if rng.random() < 0.5:
                cv2.rectangle(wall, (x0, y0), (x0 + w, y0 + h), (30, 30, 30), 2)
        walls.append(wall)
    return {"floor": floor, "walls": walls}


def _world_rays(camera: Camera) -> np.ndarray:
    """World ray directions (H, W, 3) with unit camera-frame depth."""
    xy = pixel_rays(camera)
    local = np.concatenate([xy, np.ones(xy.shape[:2] + (1,))], axis=-1)
    return local @ camera.rotation.T


def _sample(texture: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    # Coordinates of pixels that do not see this surface can be inf/NaN: clamp them (remap's
    # border handling is very slow for huge coordinates).
    u = np.clip(np.nan_to_num(u, nan=0.0, posinf=0.0, neginf=0.0), 0, texture.shape[1] - 1)
    v = np.clip(np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0), 0, texture.shape[0] - 1)
    return cv2.remap(texture, u.astype(np.float32), v.astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


def render_room(camera: Camera, textures: dict[str, np.ndarray], half_size: float = ROOM_HALF_SIZE) -> np.ndarray:
    """The empty room (spanning [-half_size, half_size] m both ways, ``textures`` made for it) seen by
    ``camera``: float32 RGB (H, W, 3), 0-255."""
    d = _world_rays(camera)
    c = camera.position
    out = np.zeros(d.shape, np.float32)
    out[:] = (235, 235, 230)  # ceiling
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(d[..., 2] < 0, -c[2] / d[..., 2], np.inf)
        t_walls = []
        for axis in (0, 1):
            for sign in (-1.0, 1.0):
                t_walls.append(np.where(d[..., axis] * sign > 0, (sign * half_size - c[axis]) / d[..., axis], np.inf))
    t_wall = np.min(t_walls, axis=0)
    wall_index = np.argmin(t_walls, axis=0)
    floor_hit = t_floor <= t_wall
    p = c + np.where(floor_hit, t_floor, 0.0)[..., None] * d
    u = (p[..., 0] + half_size) / TEXEL
    v = (p[..., 1] + half_size) / TEXEL
    floor_rgb = _sample(textures["floor"], u, v)
    out[floor_hit] = floor_rgb[floor_hit]
    q = c + np.where(np.isfinite(t_wall), t_wall, 0)[..., None] * d
    for k in range(4):
        sel = ~floor_hit & (wall_index == k) & (q[..., 2] <= ROOM_HEIGHT)
        along = q[..., 1] if k < 2 else q[..., 0]
        wu = (along + half_size) / TEXEL
        wv = (ROOM_HEIGHT - q[..., 2]) / TEXEL
        rgb = _sample(textures["walls"][k], wu, wv)
        out[sel] = rgb[sel]
    return out


@dataclass(frozen=True)
class Occluder:
    """An axis-aligned box (world m) standing on the floor: min corner, max corner."""

    lower: np.ndarray
    upper: np.ndarray

    def depth(self, camera: Camera) -> np.ndarray:
        """Camera-frame depth (H, W) of the box surface per pixel (inf where not seen); slab method."""
        d = _world_rays(camera)
        c = camera.position
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (self.lower - c) / d
            t2 = (self.upper - c) / d
        t_near = np.nanmax(np.minimum(t1, t2), axis=-1)
        t_far = np.nanmin(np.maximum(t1, t2), axis=-1)
        hit = (t_near <= t_far) & (t_far > 0)
        return np.where(hit, np.maximum(t_near, 0.0), np.inf)


def make_occluder(motion: Motion, camera: Camera, hidden_share: float) -> Occluder:
    """A 0.65 m high box 1 m in front of the middle of the walk (towards ``camera``), as wide as
    ``hidden_share`` of the pelvis's path seen from the camera: some of the legs are behind it over about that
    share of the sequence, both feet on about a fifth of a 40-frame walk's frames (a third of a 90-frame
    one), and they are seen before and after it, as in the paper's occlusion experiment (Experiment 2)."""
    pelvis = motion.markers[:, _M["pelvis"]]
    mid = pelvis[len(pelvis) // 2]
    towards = camera.position[:2] - mid[:2]
    reach = float(np.linalg.norm(towards))
    towards /= reach
    centre = mid[:2] + 1.0 * towards
    side = np.array([-towards[1], towards[0]])
    path = abs(float((pelvis[-1, :2] - pelvis[0, :2]) @ side))       # m across the view, at the walk's depth
    half_width = 0.5 * hidden_share * path * (reach - 1.0) / reach     # the same share, at the box's depth
    corners = np.array([centre + half_width * side + 0.15 * towards, centre - half_width * side - 0.15 * towards])
    lower = np.append(corners.min(axis=0), 0.0)
    upper = np.append(corners.max(axis=0), 0.65)
    return Occluder(lower, upper)


# ---- motion -------------------------------------------------------------------------------
def _turn_schedule(config: SynthConfig, heading0: float) -> np.ndarray:
    """Heading (rad) per frame: constant, then a smooth turn of ``turn_deg`` over the middle third."""
    f = np.arange(config.frames) / max(config.frames - 1, 1)
    ramp = np.clip((f - 1 / 3) * 3, 0, 1)
    smooth = 0.5 - 0.5 * np.cos(np.pi * ramp)
    return heading0 + np.radians(config.turn_deg) * smooth


# The walking direction is measured over one stride (about a second): the pelvis sways from side to side
# within a stride, so over shorter windows its direction is off by several degrees.
STRIDE_S = 1.0


def walking_direction(pelvis: np.ndarray, rate: float) -> float:
    """Walking direction (rad, from world +x about +z) over the first stride of a pelvis track (F, >= 2)."""
    ahead = pelvis[min(len(pelvis) - 1, int(round(STRIDE_S * rate))), :2] - pelvis[0, :2]
    return float(np.arctan2(ahead[1], ahead[0]))


# Feet whose lowest marker lies within this of the other's both stand on the ground (a double support).
ON_GROUND_M = 0.02


def stance_foot(markers: np.ndarray, heading: float) -> int:
    """The foot (0 left, 1 right) a start description names for markers (13, 3) of one frame: the foot on
    the ground, and at a double support (both within ``ON_GROUND_M`` of the floor) the trailing one along
    ``heading`` (rad), on which the walker still stands until its toe-off (README, start description)."""
    lowest = np.array([min(markers[_M[f"{side}_heel"], 2], markers[_M[f"{side}_toe"], 2]) for side in ("left", "right")])
    if abs(lowest[0] - lowest[1]) > ON_GROUND_M:
        return int(np.argmin(lowest))
    direction = np.array([np.cos(heading), np.sin(heading)])
    ahead = [float(markers[_M[f"{side}_heel"], :2] @ direction) for side in ("left", "right")]
    return int(np.argmin(ahead))


def _start_from_markers(markers: np.ndarray, rate: float, first_frame: int, speed: float,
                        step_length: float) -> dict:
    pelvis = markers[:, _M["pelvis"]]
    heading = walking_direction(pelvis, rate)
    stance = "left" if stance_foot(markers[0], heading) == 0 else "right"
    return {"start": {
        "frame": int(first_frame),
        "position": [round(float(pelvis[0, 0]), 4), round(float(pelvis[0, 1]), 4)],
        "heading": round(heading, 4),
        "speed": round(float(speed), 4),
        "step_length": round(float(step_length), 4),
        "stance_leg": stance,
    }}


def user_start(start: dict, rng: np.random.Generator) -> dict:
    """The start description as a person would write it after a look at the first frames: position
    within 5 cm, heading within 5 degrees, speed within 10 %, no step length."""
    s = dict(start["start"])
    radius, angle = 0.05 * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
    s["position"] = [round(float(s["position"][0] + radius * np.cos(angle)), 3),
                     round(float(s["position"][1] + radius * np.sin(angle)), 3)]
    s["heading"] = round(float(s["heading"] + np.radians(rng.uniform(-5, 5))), 3)
    s["speed"] = round(float(s["speed"] * rng.uniform(0.9, 1.1)), 2)
    s.pop("step_length", None)
    return {"start": s}


def tape_measured(body: BodyDescription, rng: np.random.Generator) -> BodyDescription:
    """Segment lengths as a tape measure gives them: each off by up to about 5 % (1 sigma 3 %)."""
    from dataclasses import replace

    names = ("upper_leg_length", "lower_leg_length", "hip_width", "torso_length", "foot_length")
    return replace(body, **{n: round(getattr(body, n) * float(np.clip(1 + 0.03 * rng.standard_normal(), 0.94, 1.06)), 3)
                            for n in names})


def walk_variants(config: SynthConfig, start_xy: np.ndarray, heading: float) -> Motion:
    """Motion from a CMU walk (with arms, ``Motion.points``): floor levelled, resampled, played faster or
    slower and turned as ``config.variant`` asks, repeated as long as ``config.frames`` needs, then turned
    and moved so that it starts at ``start_xy`` walking along ``heading``; body sizes measured from the
    markers."""
    from awalker_tracker.model.acclaim import body_from_markers, load_mocap, segments_from_markers

    from awalker_tools import walk_variants as variants

    asf, amc = config.mocap  # type: ignore[misc]
    trial = load_mocap(asf, amc).resample(config.rate)
    rate = config.rate
    points = variants.level_floor(np.concatenate([trial.markers, trial.extra], axis=1), rate)
    warp, turn, _ = VARIANTS[config.variant]
    if warp != 1.0:
        points = variants.time_warp(points, warp)
    points = variants.loop_to_duration(points, rate, (config.frames - 1) / rate)
    if config.variant in PAUSES:
        points = variants.pause(points, rate, *PAUSES[config.variant])
    # face the start heading: the walking direction over the first stride
    pelvis = points[:, _M["pelvis"], :2]
    angle = heading - walking_direction(pelvis, rate)
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    points = (points - np.append(pelvis[0], 0.0)) @ rotation.T + np.append(start_xy, 0.0)
    if turn is not None:
        points = variants.bend(points, rate, np.radians(turn[0]), turn[1], turn[2])
    points = points[: config.frames]
    markers = np.ascontiguousarray(points[:, : len(MARKER_NAMES)])
    body = body_from_markers(markers)
    first_second = min(len(markers) - 1, int(rate))
    speed = float(np.linalg.norm(markers[first_second, 0, :2] - markers[0, 0, :2]) / (first_second / rate))
    # Step length: distance between the feet along the path at their widest over the first 1.5 s, plus
    # ankles -> feet contact points, roughly
    early = markers[: int(1.5 * rate) + 1]
    direction = np.array([np.cos(heading), np.sin(heading)])
    spread = np.abs((early[:, _M["left_ankle"], :2] - early[:, _M["right_ankle"], :2]) @ direction)
    step = float(np.percentile(spread, 95)) + 0.1
    start = _start_from_markers(markers, rate, config.background_frames, speed, step)
    return Motion(markers, segments_from_markers(body, markers), body, None, start, points)


def _speed_schedule(config: SynthConfig) -> np.ndarray:
    """Target walking speed (m/s) per frame: constant, or with ``speed_change`` a smooth slow-down
    to 70 % over the middle third."""
    f = np.arange(config.frames) / max(config.frames - 1, 1)
    ramp = np.clip((f - 1 / 3) * 3, 0, 1) if config.speed_change else np.zeros_like(f)
    return config.speed * (1.0 - 0.3 * (0.5 - 0.5 * np.cos(np.pi * ramp)))


def walker_motion(config: SynthConfig, start_xy: np.ndarray, heading: float, rng: np.random.Generator) -> Motion:
    """Motion from the model: the walker dynamics driven along the cyclic gaits of the target
    speed (gait table stiffness and toe-off impulse, plus a little stiffness noise), and the
    conditional kinematics prior (eq. 6) for everything else; the heading is scripted.

    The walker is steered along the gait table rather than sampled from the control prior, so
    that it follows the requested speed profile (and the tracker is not tested on its own prior).
    The hips rest as Table 1 has them (unabducted: the feet tread the hip joints' distance apart), not
    at the tracker's narrower step width (``KinematicConfig.step_width``).
    """
    from awalker_tracker.model import dynamics, cyclic_gaits
    from awalker_tracker.model.kinematics import KinematicConfig, initial_kinematics, pose_body, sample_kinematics
    from awalker_tracker.model.walker import LEFT

    body = BodyDescription.default()
    params = body.walker_params()
    dt = 1.0 / config.rate
    table = cyclic_gaits.GaitTable.load().scaled_to(params)
    speeds = _speed_schedule(config)
    steps = config.step_length * (speeds / config.speed) ** 0.42  # preferred step length ~ speed^0.42
    walker = cyclic_gaits.gait_initial_state(params, config.speed, config.step_length, contact_origin=0.0,
                                      stance_leg=LEFT, table=table)
    kin_config = KinematicConfig(dt=dt, step_width=None)
    headings = _turn_schedule(config, heading)
    kin = initial_kinematics(kin_config, walker, start_xy, heading, 1, rng, body=body, params=params)
    since_strike = None
    markers, origins, rotations, joints = [], [], [], []
    for f in range(config.frames):
        if f > 0:
            _, _, stiffness, impulse = table.lookup(speeds[f], steps[f])
            stiffness = np.atleast_1d(stiffness + 0.02 * rng.standard_normal())
            new_walker, events = dynamics.advance(params, walker, stiffness, np.atleast_1d(impulse), dt,
                                                  time_since_strike=since_strike)
            since_strike = events.time_since_strike
            if np.any(events.fallen):
                raise InputError(f"synth: the walker fell at frame {f} (seed {config.seed}); try another --seed, "
                                 f"a milder --speed/--step-length or fewer --frames")
            kin = sample_kinematics(kin_config, body, params, walker, new_walker, events, kin, rng,
                                    heading=headings[f])
            walker = new_walker
        pose = pose_body(body, params, walker, kin)
        markers.append(pose.markers[0])
        origins.append(pose.segments.origin[0])
        rotations.append(pose.segments.rotation[0])
        joints.append(pose.joint_angles[0])
    markers_arr = np.array(markers)
    start = _start_from_markers(markers_arr, config.rate, config.background_frames, config.speed, config.step_length)
    start["start"]["heading"] = round(float(heading), 4)
    return Motion(markers_arr, BodySegments(np.array(origins), np.array(rotations)), body, np.array(joints), start)


# ---- writing ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Lighting:
    """The light and sensor of a recording: ``exposure`` (overall gain), a colour ``tint`` (per-channel
    gains), a slow ``change`` (the light dims by this fraction and recovers over the sequence, with a slight
    colour drift of +-4 %) and per-pixel sensor noise of ``noise_sigma`` grey levels (0-255)."""

    exposure: float = 1.0
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    change: float = 0.25
    noise_sigma: float = 3.0

    def channel_gains(self, total: int) -> np.ndarray:
        """(total, 3) RGB gains of each frame."""
        phase = np.arange(total) / max(total - 1, 1)
        gain = 1.0 - self.change * 0.5 * (1 - np.cos(2 * np.pi * phase))
        drift = np.stack([1 + 0.04 * np.sin(2 * np.pi * phase), np.ones(total), 1 - 0.04 * np.sin(2 * np.pi * phase)], 1)
        return self.exposure * np.asarray(self.tint, float)[None, :] * gain[:, None] * drift


@dataclass
class Scene:
    """What the cameras see besides the person: the empty room per camera (float32 RGB 0-255), box
    occluders' depth per camera (inf where none), a second person (``Motion``), the painters of both people
    (``PersonRenderer`` per camera; None: the tracker's own body model draws the person) and a lens blur."""

    cameras: list[Camera]
    rooms: list[np.ndarray]
    occluders: dict[str, np.ndarray] = field(default_factory=dict)
    painters: dict[str, PersonRenderer] | None = None
    other: Motion | None = None
    other_painters: dict[str, PersonRenderer] | None = None
    blur_px: float = 0.0          # lens blur (Gaussian sigma, pixels) of every frame, the empty ones too


def _frame_images(scene: Scene, motion: Motion, person: int, gains: np.ndarray, noise_sigma: float,
                  rng: np.random.Generator) -> dict[str, np.ndarray]:
    """uint8 RGB image per camera of one frame (``person`` < 0: the empty room)."""
    images = {}
    for cam, room in zip(scene.cameras, scene.rooms):
        base = room
        if person >= 0 and scene.painters:
            behind = room
            if scene.other is not None:       # the second person first, then the first in front where nearer
                behind, other_depth = scene.other_painters[cam.name].render(scene.other.points[person], room)
            base, depth = scene.painters[cam.name].render(motion.points[person], behind)
            if scene.other is not None:
                nearer = other_depth < depth
                base[nearer] = behind[nearer]
            if cam.name in scene.occluders:
                hidden = scene.occluders[cam.name] < depth
                base[hidden] = room[hidden]
        elif person >= 0:
            segments = BodySegments(motion.segments.origin[person][None], motion.segments.rotation[person][None])
            result = render(motion.body, segments, cam)
            if cam.name in scene.occluders:
                hidden = scene.occluders[cam.name] < result.depth
                result.labels[hidden] = -1
                result.depth[hidden] = np.inf
            base = render_rgb(motion.body, segments, cam, np.clip(room, 0, 255).astype(np.uint8),
                              result=result).astype(np.float32)
        if scene.blur_px > 0:
            base = cv2.GaussianBlur(base, (0, 0), scene.blur_px)
        noisy = base * gains.astype(np.float32) + np.float32(noise_sigma) * rng.standard_normal(base.shape, np.float32)
        images[cam.name] = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
    return images


def _csv_rows(frame: int, stamp: int, markers: np.ndarray) -> list[str]:
    return [f"{frame},{stamp},{name},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}" for name, p in zip(MARKER_NAMES, markers)]


def write_sequence(out: Path, name: str, motion: Motion, scene: Scene, lighting: Lighting, rate: float,
                   background_frames: int, rng: np.random.Generator, start_text: str | None = None,
                   body_text: str | None = None, storage: str = "mcap", compressed: bool = True,
                   image_format: str = "jpeg", progress: bool = True) -> dict[str, Path]:
    """Render and write ``out/<name>.bag``: ``background_frames`` frames of the empty scene, then one frame per
    row of ``motion`` at ``rate`` Hz, lit by ``lighting`` (noise drawn from ``rng``), with the ground truth, the
    start and body descriptions as latched topics when given, and occlusion masks; ``out/ground_truth.csv``
    (and ``second_person.csv``), ``overlay_<cam>.png`` (the truth over the middle frame). Returns the paths."""
    bag_path = out / f"{name}.bag"
    person_frames = len(motion.markers)
    total = background_frames + person_frames
    stamps = FIRST_STAMP_NS + np.round(np.arange(total) * 1e9 / rate).astype(np.int64)
    gains = lighting.channel_gains(total)
    csv_lines = ["frame,stamp_ns,marker,x,y,z"]
    other_lines = list(csv_lines)
    overlays: dict[str, Path] = {}
    with bagio.SequenceWriter(bag_path, scene.cameras, storage=storage, compressed=compressed,
                              image_format=image_format) as writer:
        if start_text is not None:
            writer.write_text(bagio.START_DESCRIPTION_TOPIC, int(stamps[0]), start_text)
        if body_text is not None:
            writer.write_text(bagio.BODY_DESCRIPTION_TOPIC, int(stamps[0]), body_text)
        for frame in range(total):
            person = frame - background_frames
            images = _frame_images(scene, motion, person, gains[frame], lighting.noise_sigma, rng)
            writer.write_frame(int(stamps[frame]), images)
            if person == person_frames // 2:  # a look at the ground truth over the frames
                for cam in scene.cameras:
                    segments = BodySegments(motion.segments.origin[person][None], motion.segments.rotation[person][None])
                    overlays[cam.name] = save_overlay_png(out / f"overlay_{cam.name}.png", images[cam.name],
                                                          motion.markers[person], cam, segments, motion.body)
            for cam_name, depth in scene.occluders.items():
                writer.write_occlusion_mask(int(stamps[frame]), cam_name, np.isfinite(depth))
            if person >= 0:
                markers = motion.markers[person]
                if motion.joint_angles is not None:
                    writer.write_ground_truth(int(stamps[frame]), markers, list(JOINT_NAMES), motion.joint_angles[person])
                else:
                    writer.write_ground_truth(int(stamps[frame]), markers)
                csv_lines += _csv_rows(frame, int(stamps[frame]), markers)
                if scene.other is not None:
                    other_lines += _csv_rows(frame, int(stamps[frame]), scene.other.markers[person])
            if progress and (frame % 20 == 0 or frame == total - 1):
                print(f"synth: frame {frame + 1}/{total}", file=sys.stderr, flush=True)
    (out / "ground_truth.csv").write_text("\n".join(csv_lines) + "\n")
    paths = {"bag": bag_path, "ground_truth": out / "ground_truth.csv"}
    if scene.other is not None:
        (out / "second_person.csv").write_text("\n".join(other_lines) + "\n")
        paths["second person's truth"] = out / "second_person.csv"
    return {**paths, **{f"overlay {cam}": path for cam, path in overlays.items()}}


def synthesise(config: SynthConfig, progress: bool = True) -> dict[str, Path]:
    """Make the sequence; returns the paths written (bag, calibration, body, start, ground_truth)."""
    out = Path(config.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    bag_path = out / f"{config.name}.bag"
    if bag_path.exists():
        raise InputError(f"{bag_path}: exists already; choose another --out or remove it")
    rng = np.random.default_rng(config.seed)
    start_xy = np.array([-2.0, 0.0])
    heading = 0.0
    if config.mocap is not None:
        motion = walk_variants(config, start_xy, heading)
    else:
        motion = walker_motion(config, start_xy, heading, rng)
    path_centre = 0.5 * (motion.markers[0, 0, :2] + motion.markers[-1, 0, :2])
    if VARIANTS[config.variant][1] is not None:      # a turning walk: the middle of the ground it covers
        pelvis = motion.markers[:, 0, :2]
        path_centre = 0.5 * (pelvis.min(axis=0) + pelvis.max(axis=0))
    cameras = make_cameras(config.cameras, config.width, config.height, path_centre)
    other = None
    if config.second_person:
        from dataclasses import replace

        far_end = np.array([motion.markers[-1, 0, 0], start_xy[1] + SECOND_PERSON_BEHIND_M])
        other = walk_variants(replace(config, variant="straight"), far_end, heading + np.pi)
    textures = make_textures(rng)
    scene = Scene(cameras, [render_room(cam, textures) for cam in cameras], other=other)
    if config.occluder:
        box = make_occluder(motion, cameras[0], config.occluder)
        for cam, room in zip(cameras, scene.rooms):
            depth = box.depth(cam)
            seen = np.isfinite(depth)
            wood = np.array([120, 80, 45], np.float32) * (0.85 + 0.3 * _value_noise(rng, depth.shape, 12))[..., None]
            room[seen] = wood[seen]
            scene.occluders[cam.name] = depth

    given_body = tape_measured(motion.body, rng) if config.tape_measure else motion.body
    given_start = user_start(motion.start, rng) if config.user_start else motion.start
    if config.person == "dressed":
        outfit = Outfit.random(rng, carry=config.carry)
        scene.painters = {cam.name: PersonRenderer(cam, outfit) for cam in cameras}
    if other is not None:
        other_outfit = Outfit.random(rng)
        scene.other_painters = {cam.name: PersonRenderer(cam, other_outfit) for cam in cameras}
    save_calibration(cameras, out / "calibration.yaml")
    start_text = yaml.safe_dump(given_start, sort_keys=False)
    if config.descriptions:
        (out / "body.yaml").write_text(given_body.to_yaml_text())
        (out / "start.yaml").write_text(start_text)
    written = write_sequence(out, config.name, motion, scene,
                             Lighting(change=config.lighting_change, noise_sigma=config.noise_sigma), config.rate,
                             config.background_frames, rng,
                             start_text=start_text if config.descriptions else None,
                             body_text=given_body.to_yaml_text() if config.descriptions else None,
                             storage=config.storage, compressed=config.compressed,
                             image_format=config.image_format, progress=progress)
    (out / "ground_truth_body.yaml").write_text(motion.body.to_yaml_text())
    descriptions = {"body": out / "body.yaml", "start": out / "start.yaml"} if config.descriptions else {}
    overlays = {k: v for k, v in written.items() if k.startswith("overlay")}
    second = {k: v for k, v in written.items() if k == "second person's truth"}
    return {"bag": bag_path, "calibration": out / "calibration.yaml", **descriptions, **second,
            "ground_truth": out / "ground_truth.csv", "ground_truth_body": out / "ground_truth_body.yaml", **overlays}
