"""A dressed person drawn from a motion-capture skeleton: test images the tracker's body model did not make.

The tracker's likelihood expects its own body (``vision/render.py``: tapered elliptical cylinders,
one colour per part class, no arms). This renderer draws something else, as a camera would see a
real person: the whole CMU skeleton including swinging arms and a head with hair, every limb a
capsule (a sphere swept along the bone, per-person radii; the shoe's sole ``FOOT_LINE_HEIGHT`` under the
heel-toe line, on the floor while the foot lies flat, and what would lie under the floor hidden by it),
a shirt with horizontal stripes over the torso and upper arms, jeans of one colour on both legs and the hips, dark shoes, skin on the neck,
face, forearms and hands; Lambert shading under a light from above, a soft contact shadow on the
floor under the feet and the body, and a slight lens blur (sensor noise is added by ``synth``).
Optionally the person carries something the tracker's body has even less of (``Outfit.carry``): a
backpack on the back, or a shoulder bag hanging by the right hip from a strap over the left shoulder,
brown leather either way (a fixed colour, so that a sequence with a bag draws the same random numbers
as one without).

Ray casting per pixel (within each capsule's projected box): the ray's closest approach to the
bone gives the hit where it passes within the capsule's radius; the nearest hit wins. Units: m,
world frame z up.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from awalker_tools.mocap_motion import FOOT_LINE_HEIGHT
from awalker_tracker.model.body import MARKER_NAMES
from awalker_tracker.model.mocap import EXTRA_POINTS
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.render import pixel_rays

POINT_NAMES: tuple[str, ...] = MARKER_NAMES + tuple(EXTRA_POINTS)
_P = {n: i for i, n in enumerate(POINT_NAMES)}
LIGHT = np.array([0.3, -0.4, 0.85]) / np.linalg.norm([0.3, -0.4, 0.85])
UP = np.array([0.0, 0.0, 1.0])
#: What the person may carry (``Outfit.carry``).
CARRIED = ("none", "backpack", "shoulder-bag")
BAG_COLOUR = (110.0, 72.0, 42.0)


@dataclass(frozen=True)
class Outfit:
    """One person's look: RGB colours (0-255) and limb radii (m)."""

    shirt: tuple[tuple[float, float, float], tuple[float, float, float]]   # the two stripe colours
    stripe_m: float
    jeans: tuple[float, float, float]
    shoes: tuple[float, float, float]
    skin: tuple[float, float, float]
    hair: tuple[float, float, float]
    radii: dict[str, float]
    carry: str = "none"          # one of CARRIED

    def __post_init__(self) -> None:
        if self.carry not in CARRIED:
            raise ValueError(f"Outfit.carry must be one of {', '.join(CARRIED)}, got {self.carry!r}")

    @classmethod
    def random(cls, rng: np.random.Generator, carry: str = "none") -> "Outfit":
        """A person: clothes colours and body widths drawn around typical values (widths +- 10 %),
        carrying ``carry`` (one of ``CARRIED``; drawn without random numbers)."""
        base = {"torso": 0.11, "flank": 0.075, "hips": 0.1, "neck": 0.05, "head": 0.1, "upper_arm": 0.045,
                "forearm": 0.036, "hand": 0.04, "thigh": 0.075, "shin": 0.052, "foot": 0.038}
        radii = {k: v * float(rng.uniform(0.9, 1.1)) for k, v in base.items()}
        light = rng.uniform(170, 235, 3)
        dark = light * rng.uniform(0.35, 0.6)
        return cls(shirt=(tuple(light), tuple(dark)), stripe_m=float(rng.uniform(0.05, 0.09)),
                   jeans=tuple(np.array([55.0, 75.0, 125.0]) * rng.uniform(0.8, 1.2)),
                   shoes=tuple(rng.uniform(25, 60, 3)), skin=tuple(np.array([205.0, 160.0, 130.0]) * rng.uniform(0.75, 1.05)),
                   hair=tuple(rng.uniform(20, 70, 3)), radii=radii, carry=carry)


def capsules(points: np.ndarray, outfit: Outfit) -> list[tuple[np.ndarray, np.ndarray, float, str]]:
    """(start, end, radius, material) of every limb for one frame's points (len(POINT_NAMES), 3)."""
    p = {n: points[i] for n, i in _P.items()}
    r = outfit.radii
    lift = lambda v, dz: v + np.array([0.0, 0.0, dz])  # noqa: E731
    sole = r["foot"] - FOOT_LINE_HEIGHT      # the shoe's sole FOOT_LINE_HEIGHT under the heel-toe line
    neck_up = p["neck"] + 0.07 * UP
    head_centre = p["neck"] + 0.6 * (p["head_top"] - p["neck"]) + 0.04 * UP
    out = [
        (p["pelvis"] + 0.05 * UP, p["neck"] - 0.05 * UP, r["torso"], "shirt"),
        (p["left_hip"] + 0.08 * UP, p["left_shoulder"] - 0.04 * UP, r["flank"], "shirt"),
        (p["right_hip"] + 0.08 * UP, p["right_shoulder"] - 0.04 * UP, r["flank"], "shirt"),
        (p["left_hip"], p["right_hip"], r["hips"], "jeans"),
        (p["neck"], neck_up, r["neck"], "skin"),
        (head_centre, head_centre, r["head"], "head"),
    ]
    for side in ("left", "right"):
        out += [
            (p[f"{side}_shoulder"], p[f"{side}_elbow"], r["upper_arm"], "shirt"),
            (p[f"{side}_elbow"], p[f"{side}_wrist"], r["forearm"], "skin"),
            (p[f"{side}_wrist"], p[f"{side}_hand"], r["hand"], "skin"),
            (p[f"{side}_hip"], p[f"{side}_knee"], r["thigh"], "jeans"),
            (p[f"{side}_knee"], p[f"{side}_ankle"], r["shin"], "jeans"),
            (lift(p[f"{side}_heel"], sole), lift(p[f"{side}_toe"], sole), r["foot"], "shoes"),
        ]
    return out + carried(p, outfit)


def carried(p: dict[str, np.ndarray], outfit: Outfit) -> list[tuple[np.ndarray, np.ndarray, float, str]]:
    """Capsules of what the person carries (``outfit.carry``), placed in the torso's frame: ``up`` from the
    pelvis to the neck, ``left`` from the right hip to the left, ``forward`` = left x up."""
    if outfit.carry == "none":
        return []
    up = p["neck"] - p["pelvis"]
    up /= np.linalg.norm(up)
    left = p["left_hip"] - p["right_hip"]
    left -= (left @ up) * up
    left /= np.linalg.norm(left)
    forward = np.cross(left, up)
    r = outfit.radii
    if outfit.carry == "backpack":
        # two upright capsules side by side on the back: about 0.34 m wide, 0.45 m high, 0.17 m deep
        centre = 0.5 * (p["pelvis"] + p["neck"]) + 0.05 * up - (r["torso"] + 0.09) * forward
        return [(centre + s * 0.085 * left - 0.14 * up, centre + s * 0.085 * left + 0.14 * up, 0.085, "bag")
                for s in (-1.0, 1.0)]
    # shoulder bag: a 0.42 m long, 0.18 m high bag lying along the walk outside the right hip, its strap
    # from the left shoulder across the chest and back
    centre = p["right_hip"] - (r["hips"] + 0.1) * left - 0.02 * up
    strap_end = centre + 0.08 * up
    return [(centre - 0.12 * forward, centre + 0.12 * forward, 0.09, "bag"),
            (p["left_shoulder"] + 0.02 * forward, strap_end, 0.015, "bag"),
            (p["left_shoulder"] - 0.02 * forward, strap_end, 0.015, "bag")]


def _colour(material: str, hit: np.ndarray, centre: np.ndarray, outfit: Outfit) -> np.ndarray:
    """(K, 3) albedo of ``material`` at the hit points (K, 3); ``centre``: the capsule's start."""
    k = len(hit)
    if material == "shirt":
        stripe = (np.floor(hit[:, 2] / outfit.stripe_m) % 2)[:, None]
        return np.where(stripe > 0, np.array(outfit.shirt[0]), np.array(outfit.shirt[1]))
    if material == "jeans":
        weave = 0.9 + 0.1 * np.sin(hit[:, 0] * 900.0) * np.sin(hit[:, 1] * 830.0) + 0.08 * np.sin(hit[:, 2] * 60.0)
        return np.array(outfit.jeans)[None] * weave[:, None]
    if material == "head":
        hair = (hit[:, 2] - centre[2]) > -0.01
        return np.where(hair[:, None], np.array(outfit.hair), np.array(outfit.skin))
    colour = {"skin": outfit.skin, "shoes": outfit.shoes, "bag": BAG_COLOUR}[material]
    return np.broadcast_to(np.array(colour, float), (k, 3))


class PersonRenderer:
    """Draws the dressed person into one camera's image over a background (the empty room)."""

    def __init__(self, camera: Camera, outfit: Outfit, blur_sigma_px: float = 0.6) -> None:
        self.camera = camera
        self.outfit = outfit
        self.blur_sigma_px = blur_sigma_px
        xy = pixel_rays(camera)
        local = np.concatenate([xy, np.ones(xy.shape[:2] + (1,))], axis=-1)
        rays = local @ camera.rotation.T
        self.depth_per_t = 1.0 / np.linalg.norm(rays, axis=-1)       # camera depth per unit distance
        self.rays = rays * self.depth_per_t[..., None]                 # unit world directions (H, W, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_floor = np.where(self.rays[..., 2] < -1e-6, -camera.position[2] / self.rays[..., 2], np.inf)
        self.floor_xy = camera.position[:2] + np.where(np.isfinite(t_floor), t_floor, 0.0)[..., None] * self.rays[..., :2]
        self.sees_floor = np.isfinite(t_floor) & (t_floor < 30.0)

    def _box(self, start: np.ndarray, end: np.ndarray, radius: float) -> tuple[int, int, int, int] | None:
        """Pixel box (u0, v0, u1, v1) that holds the capsule's projection, or None if behind the camera."""
        corners = np.array([start, end])
        uv, depth = self.camera.project(corners)
        if np.any(depth <= 0.05) or not np.all(np.isfinite(uv)):
            return None
        pad = radius * self.camera.K[0, 0] / depth.min() + 3
        u0, v0 = np.floor(uv.min(axis=0) - pad).astype(int)
        u1, v1 = np.ceil(uv.max(axis=0) + pad).astype(int)
        h, w = self.camera.height, self.camera.width
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w), min(v1, h)
        return (u0, v0, u1, v1) if u0 < u1 and v0 < v1 else None

    def render(self, points: np.ndarray, background: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(RGB float32 (H, W, 3) 0-255, camera depth (H, W) m, inf where no person) of one frame."""
        shape = self.rays.shape[:2]
        distance = np.full(shape, np.inf)
        colour = np.zeros(shape + (3,))
        normal = np.zeros(shape + (3,))
        origin = self.camera.position
        for start, end, radius, material in capsules(points, self.outfit):
            box = self._box(start, end, radius)
            if box is None:
                continue
            u0, v0, u1, v1 = box
            d = self.rays[v0:v1, u0:u1].reshape(-1, 3)
            axis = end - start
            length = float(np.linalg.norm(axis))
            u = axis / length if length > 1e-9 else np.zeros(3)
            w0 = origin - start
            b, dw, uw = d @ u, d @ w0, float(u @ w0)
            denom = np.maximum(1.0 - b * b, 1e-9)
            s = np.clip((uw - b * dw) / denom, 0.0, length)
            closest = start + s[:, None] * u                       # on the bone
            t = np.einsum("ij,ij->i", closest - origin, d)
            gap = np.linalg.norm(origin + t[:, None] * d - closest, axis=1)
            t_hit = t - np.sqrt(np.maximum(radius * radius - gap * gap, 0.0))
            # a hit under the floor is hidden by it (a shoe rolling on its heel or toe presses into it)
            hit = (gap < radius) & (t > 0) & (origin[2] + t_hit * d[:, 2] >= 0.0)
            block = distance[v0:v1, u0:u1].reshape(-1)
            nearer = hit & (t_hit < block)
            if not nearer.any():
                continue
            idx = np.flatnonzero(nearer)
            points_hit = origin + t_hit[idx, None] * d[idx]
            n = points_hit - closest[idx]
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)
            block[idx] = t_hit[idx]
            distance[v0:v1, u0:u1] = block.reshape(v1 - v0, u1 - u0)
            cblock = colour[v0:v1, u0:u1].reshape(-1, 3)
            nblock = normal[v0:v1, u0:u1].reshape(-1, 3)
            cblock[idx] = _colour(material, points_hit, start, self.outfit)
            nblock[idx] = n
            colour[v0:v1, u0:u1] = cblock.reshape(v1 - v0, u1 - u0, 3)
            normal[v0:v1, u0:u1] = nblock.reshape(v1 - v0, u1 - u0, 3)
        person = np.isfinite(distance)
        image = background.astype(np.float32).copy()
        image *= self._shadow(points)[..., None]
        shade = 0.45 + 0.55 * np.clip(normal @ LIGHT, 0.0, 1.0)
        image[person] = (colour * shade[..., None])[person].astype(np.float32)
        if self.blur_sigma_px > 0:
            image = cv2.GaussianBlur(image, (0, 0), self.blur_sigma_px)
        return image, np.where(person, distance * self.depth_per_t, np.inf)

    def _shadow(self, points: np.ndarray) -> np.ndarray:
        """(H, W) floor darkening factor: soft dark spots under the feet and a wide faint one under the body."""
        factor = np.ones(self.rays.shape[:2])
        # a foot in the air casts a weaker, wider spot
        spots = [(points[_P[n], :2], 0.1 + 0.5 * max(points[_P[n], 2], 0.0), 0.5 * np.exp(-max(points[_P[n], 2], 0.0) / 0.1))
                 for n in ("left_heel", "left_toe", "right_heel", "right_toe")]
        spots.append((points[_P["pelvis"], :2], 0.35, 0.3))
        for centre, width, strength in spots:
            d2 = np.sum(np.square(self.floor_xy - centre), axis=-1)
            factor *= 1.0 - strength * np.exp(-d2 / (width * width))
        return np.where(self.sees_floor, factor, 1.0)
