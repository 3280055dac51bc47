"""A dressed person drawn from a motion-capture skeleton: test images the tracker's body model did not make.

The tracker's likelihood expects its own body (``vision/render.py``: tapered elliptical cylinders,
one colour per part class, no arms). This renderer draws something else, as a camera would see a
real person: the whole CMU skeleton including swinging arms and a head with hair, every limb a
capsule (a sphere swept along the bone, per-person radii; the shoe's sole ``FOOT_LINE_HEIGHT`` under the
heel-toe line, on the floor while the foot lies flat, and what would lie under the floor hidden by it),
skin on the neck, face and hands; Lambert shading under a light from above, a soft contact shadow on the
floor under the feet and the body, and a slight lens blur (sensor noise is added by ``synth``).
Optionally the person carries something the tracker's body has even less of (``Outfit.carry``): a
backpack on the back, or a shoulder bag hanging by the right hip from a strap over the left shoulder,
brown leather either way (a fixed colour, so that a sequence with a bag draws the same random numbers
as one without).

Clothes (``Outfit``): ``Outfit.random`` dresses everyone alike (a shirt with horizontal stripes over the
torso and upper arms, jeans of one colour on both legs and the hips, dark shoes, bare forearms; widths
the template +- 10 %). ``Outfit.draw`` draws the range of people in users' videos: trousers, shorts
(skin below a hem over the knee) or a skirt (a flaring frustum from the hips, bare legs or dark tights
below), tops plain, striped, checked or printed with long or short sleeves, light to dark colours of any
hue (sometimes as grey or beige as a floor or wall), skin light to dark, slim to heavy builds. Patterns
other than the legacy ones are attached to the body (to the torso's frame, or to the limb's).

Ray casting per pixel (within each shape's projected box): the ray's closest approach to the
bone gives the hit where it passes within the capsule's radius; the skirt's frustum is intersected
exactly (``intersect_frustum``); the nearest hit wins. Units: m, world frame z up.
"""
from __future__ import annotations

import colorsys
from dataclasses import dataclass

import cv2
import numpy as np

from awalker_tools.walk_variants import FOOT_LINE_HEIGHT
from awalker_tracker.model.acclaim import EXTRA_POINTS
from awalker_tracker.model.body import MARKER_NAMES
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.render import pixel_rays

POINT_NAMES: tuple[str, ...] = MARKER_NAMES + tuple(EXTRA_POINTS)
_P = {n: i for i, n in enumerate(POINT_NAMES)}
LIGHT = np.array([0.3, -0.4, 0.85]) / np.linalg.norm([0.3, -0.4, 0.85])
UP = np.array([0.0, 0.0, 1.0])
#: What the person may carry (``Outfit.carry``).
CARRIED = ("none", "backpack", "shoulder-bag")
BAG_COLOUR = (110.0, 72.0, 42.0)
#: Lower garments (``Outfit.lower``) and the weights ``Outfit.draw`` gives them.
LOWER_GARMENTS = {"trousers": 0.5, "shorts": 0.25, "skirt": 0.25}
#: Top patterns (``Outfit.top_pattern``) and their weights in ``Outfit.draw``; "level-stripes" (``Outfit.random``'s
#: shirt) are horizontal stripes by world height, the others are attached to the body.
TOP_PATTERNS = {"plain": 0.35, "stripes": 0.2, "checks": 0.15, "print": 0.15, "dots": 0.15}
LEGACY_TOP_PATTERN = "level-stripes"
#: Lower garment patterns (``Outfit.lower_pattern``): "twill" is the jeans' fine weave, "check" a faint check.
LOWER_PATTERNS = {"plain": 0.5, "twill": 0.3, "check": 0.2}
SLEEVES = ("short", "long")
#: Garment colour classes ``Outfit.draw`` picks from: HSV value ranges (max channel, 0-255); "neutral" is a
#: grey or beige like the floor (150, 140, 120) or the walls (grey 150-210), "denim" the jeans' blue.
VALUE_RANGE = {"light": (170.0, 240.0), "mid": (80.0, 170.0), "dark": (20.0, 80.0)}
TOP_TONES = {"light": 0.35, "mid": 0.25, "dark": 0.3, "neutral": 0.1}
LOWER_TONES = {"denim": 0.2, "light": 0.2, "mid": 0.2, "dark": 0.3, "neutral": 0.1}
#: Skin tones from light to dark and hair from black to blond (RGB); ``Outfit.draw`` interpolates along them.
SKIN_TONES = np.array([[236.0, 200.0, 178.0], [214.0, 170.0, 140.0], [176.0, 128.0, 96.0], [130.0, 88.0, 62.0],
                       [84.0, 56.0, 42.0], [58.0, 40.0, 32.0]])
HAIR_TONES = np.array([[15.0, 13.0, 12.0], [50.0, 35.0, 25.0], [95.0, 65.0, 42.0], [150.0, 115.0, 75.0],
                       [205.0, 175.0, 125.0]])
#: Body-build factor range of ``Outfit.draw`` (slim to heavy): scales torso, flank, hips and thighs fully,
#: upper arms and shins by ``BUILD_SHARE_LIMBS`` of it.
BUILD_RANGE = (0.8, 1.35)
BUILD_SHARE_LIMBS = 0.4
HEAD_RADIUS_RANGE = (0.085, 0.11)
_BASE_RADII = {"torso": 0.11, "flank": 0.075, "hips": 0.1, "neck": 0.05, "head": 0.1, "upper_arm": 0.045,
               "forearm": 0.036, "hand": 0.04, "thigh": 0.075, "shin": 0.052, "foot": 0.038}
_BUILD_FULL = ("torso", "flank", "hips", "thigh")
_BUILD_PART = ("upper_arm", "shin")
#: With a skirt the thighs are drawn from this far down the bone (m; at most half of it): the skirt (as long as
#: the thighs less at most 0.1 m) is made wide enough to hold them from there down (``skirt``), and hides the rest.
SKIRT_THIGH_START_M = 0.2

Colour = tuple[float, float, float]


def _pick(rng: np.random.Generator, weights: dict[str, float]) -> str:
    """One key of ``weights`` drawn with probabilities proportional to its values (one random number)."""
    keys = list(weights)
    p = np.array([weights[k] for k in keys])
    return keys[int(rng.choice(len(keys), p=p / p.sum()))]


def _hsv(hue: float, saturation: float, value: float) -> Colour:
    """RGB (0-255) of hue (0-1), saturation (0-1) and value (0-255, the largest channel)."""
    r, g, b = colorsys.hsv_to_rgb(hue % 1.0, saturation, value / 255.0)
    return (255.0 * r, 255.0 * g, 255.0 * b)


def _garment_colour(rng: np.random.Generator, tone: str) -> Colour:
    """A garment colour of one class of ``VALUE_RANGE`` (any hue), "neutral" (floor or wall grey/beige) or
    "denim"; draws four random numbers whatever the class."""
    hue, sat, val, extra = rng.random(4)
    if tone == "neutral":
        return _hsv(0.07 + 0.07 * hue, 0.25 * sat, 120.0 + 90.0 * val)
    if tone == "denim":
        scale = 0.6 + 0.7 * val
        return (55.0 * scale, 75.0 * scale * (0.9 + 0.2 * extra), 125.0 * scale)
    lo, hi = VALUE_RANGE[tone]
    max_sat = {"light": 0.45, "mid": 0.8, "dark": 0.7}[tone]
    return _hsv(hue, max_sat * sat, lo + (hi - lo) * val)


def _along(tones: np.ndarray, s: float) -> Colour:
    """The colour at ``s`` (0-1) along a piecewise linear ramp of RGB ``tones`` (N, 3)."""
    x = s * (len(tones) - 1)
    k = min(int(x), len(tones) - 2)
    c = tones[k] + (x - k) * (tones[k + 1] - tones[k])
    return (float(c[0]), float(c[1]), float(c[2]))


def tone_of(colour: Colour) -> str:
    """"light" (largest channel >= 170), "dark" (<= 80) or "mid"."""
    value = max(colour)
    return "light" if value >= 170.0 else "dark" if value <= 80.0 else "mid"


def _floor_like(colour: Colour) -> bool:
    """Whether ``colour`` is a grey or beige of the floor's or walls' brightness (saturation <= 0.25, value 120-215)."""
    _, s, v = colorsys.rgb_to_hsv(*(c / 255.0 for c in colour))
    return bool(s <= 0.25 and 120.0 / 255.0 <= v <= 215.0 / 255.0)


@dataclass(frozen=True)
class Outfit:
    """One person's look: RGB colours (0-255), limb radii (m) and the garments.

    ``shirt`` holds the top's two colours (the first is a plain top's), ``stripe_m`` the top pattern's
    period (m); ``jeans`` is the lower garment's colour whatever it is. ``hem_m``: how far the hem of
    shorts or a skirt lies above the knee (m, negative below), along the thigh; ``skirt_flare_m``: how much
    wider the skirt's hem is than the legs it covers (m); ``tights``: their colour under a skirt (None: bare
    legs); ``build``: the body-build factor the widths were drawn with (1: the template);
    ``pattern_seed``: seeds the top's print and dots."""

    shirt: tuple[Colour, Colour]
    stripe_m: float
    jeans: Colour
    shoes: Colour
    skin: Colour
    hair: Colour
    radii: dict[str, float]
    carry: str = "none"          # one of CARRIED
    lower: str = "trousers"      # one of LOWER_GARMENTS
    hem_m: float = 0.0
    skirt_flare_m: float = 0.05
    tights: Colour | None = None
    top_pattern: str = LEGACY_TOP_PATTERN   # LEGACY_TOP_PATTERN or one of TOP_PATTERNS
    lower_pattern: str = "twill"            # one of LOWER_PATTERNS
    sleeves: str = "short"                  # one of SLEEVES: "short" leaves the forearms bare
    build: float = 1.0
    pattern_seed: int = 0

    def __post_init__(self) -> None:
        choices = {"carry": CARRIED, "lower": tuple(LOWER_GARMENTS), "lower_pattern": tuple(LOWER_PATTERNS),
                   "top_pattern": (LEGACY_TOP_PATTERN, *TOP_PATTERNS), "sleeves": SLEEVES}
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"Outfit.{name} must be one of {', '.join(allowed)}, got {getattr(self, name)!r}")

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

    @classmethod
    def draw(cls, rng: np.random.Generator, carry: str = "none") -> "Outfit":
        """A person of the range users' videos show, from ``rng`` only (the same numbers whatever is drawn),
        carrying ``carry`` (one of ``CARRIED``).

        Lower garment: trousers 0.5, shorts 0.25 (hem 5-15 cm above the knee), skirt 0.25 (hem 10 cm above to
        10 cm below the knee, flaring 3-8 cm past the legs; bare legs 0.6, dark tights 0.4). Garment colours:
        any hue in a light (value 170-240), mid (80-170) or dark (20-80) class, or a floor/wall-like grey or
        beige (``TOP_TONES``, ``LOWER_TONES``; the lower garment also denim); a patterned top's second colour is
        of another class. Top pattern ``TOP_PATTERNS`` with a period of 3-9 cm, sleeves long or short (0.5
        each), lower pattern ``LOWER_PATTERNS``. Shoes light (0.35) or dark; skin anywhere from light to dark
        (``SKIN_TONES``), hair black to blond (darker more often). Build factor 0.8-1.35 (``BUILD_RANGE``)
        scaling the torso's and legs' widths, then each radius +- 8 %; head radius 0.085-0.11 m."""
        lower = _pick(rng, LOWER_GARMENTS)
        hem_u, flare_u, tights_u = rng.random(3)
        hem_m = {"trousers": 0.0, "shorts": 0.05 + 0.1 * hem_u, "skirt": -0.1 + 0.2 * hem_u}[lower]
        tights = _garment_colour(rng, "dark")
        top_tone = _pick(rng, TOP_TONES)
        second_tones = {"light": ("dark", "mid"), "dark": ("light", "mid")}.get(top_tone, ("light", "dark"))
        second_tone = second_tones[int(rng.integers(2))]
        shirt = (_garment_colour(rng, top_tone), _garment_colour(rng, second_tone))
        top_pattern = _pick(rng, TOP_PATTERNS)
        period = float(rng.uniform(0.03, 0.09))
        pattern_seed = int(rng.integers(0, 2**31 - 1))
        sleeves = SLEEVES[int(rng.integers(2))]
        jeans = _garment_colour(rng, _pick(rng, LOWER_TONES))
        lower_pattern = _pick(rng, LOWER_PATTERNS)
        shoes = _garment_colour(rng, "light" if rng.random() < 0.35 else "dark")
        skin = tuple(float(c) for c in np.array(_along(SKIN_TONES, float(rng.random()))) * rng.uniform(0.95, 1.05, 3))
        hair = _along(HAIR_TONES, float(rng.random()) ** 1.6)
        build = float(rng.uniform(*BUILD_RANGE))
        jitter = rng.uniform(0.92, 1.08, len(_BASE_RADII))
        scale = {**{n: build for n in _BUILD_FULL}, **{n: 1.0 + BUILD_SHARE_LIMBS * (build - 1.0) for n in _BUILD_PART}}
        radii = {name: float(base * scale.get(name, 1.0) * j) for (name, base), j in zip(_BASE_RADII.items(), jitter)}
        radii["head"] = float(rng.uniform(*HEAD_RADIUS_RANGE))
        return cls(shirt=shirt, stripe_m=period, jeans=jeans, shoes=shoes, skin=skin, hair=hair, radii=radii,
                   carry=carry, lower=lower, hem_m=float(hem_m), skirt_flare_m=float(0.03 + 0.05 * flare_u),
                   tights=tights if lower == "skirt" and tights_u < 0.4 else None, top_pattern=top_pattern, lower_pattern=lower_pattern,
                   sleeves=sleeves, build=build, pattern_seed=pattern_seed)

    def describe(self) -> dict:
        """JSON-serialisable summary: garments, their colours' tone (light/mid/dark, and whether floor-like
        grey/beige), patterns, sleeves, build factor and head radius (m), skin and hair value (0-255)."""
        r3 = lambda x: round(float(x), 3)  # noqa: E731
        out: dict = {
            "lower": self.lower,
            "top": {"pattern": self.top_pattern, "sleeves": self.sleeves, "tone": tone_of(self.shirt[0]),
                    "floor_like": _floor_like(self.shirt[0]), "rgb": [round(float(c)) for c in self.shirt[0]]},
            "lower_garment": {"pattern": self.lower_pattern, "tone": tone_of(self.jeans),
                              "floor_like": _floor_like(self.jeans), "rgb": [round(float(c)) for c in self.jeans]},
            "shoes": tone_of(self.shoes),
            "skin_value": round(float(max(self.skin))),
            "hair_value": round(float(max(self.hair))),
            "build": r3(self.build),
            "head_radius_m": r3(self.radii["head"]),
            "carry": self.carry,
        }
        if self.top_pattern != "plain":
            out["top"]["second_tone"] = tone_of(self.shirt[1])
        if self.lower != "trousers":
            out["hem_above_knee_m"] = r3(self.hem_m)
        if self.lower == "skirt":
            out["legs"] = "bare" if self.tights is None else "tights"
        return out


@dataclass(frozen=True, eq=False)
class Shape:
    """One piece of the person: a capsule (``end_radius`` None: a sphere of ``radius`` m swept from ``start`` to
    ``end``) or a frustum (a cone's side from the circle of ``radius`` around ``start`` to the circle of
    ``end_radius`` around ``end``, perpendicular to its axis, closed at ``start`` and open at ``end``); drawn in
    ``material``, whose pattern is attached to ``frame``: origin (3,) and axes as rows (3, 3), m."""

    start: np.ndarray
    end: np.ndarray
    radius: float
    material: str
    frame: tuple[np.ndarray, np.ndarray]
    end_radius: float | None = None


def _torso_axes(p: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit (forward, left, up) of the torso: ``up`` from the pelvis to the neck, ``left`` from the right hip
    to the left, ``forward`` = left x up."""
    up = p["neck"] - p["pelvis"]
    up /= np.linalg.norm(up)
    left = p["left_hip"] - p["right_hip"]
    left -= (left @ up) * up
    left /= np.linalg.norm(left)
    forward = np.cross(left, up)
    return forward, left, up


def _limb_frame(start: np.ndarray, end: np.ndarray, forward: np.ndarray, left: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frame of a limb from ``start`` to ``end``: origin ``start``, third axis along the bone, first axis the
    torso's ``forward`` made perpendicular to it (``left`` if the bone runs along ``forward``)."""
    z = end - start
    length = float(np.linalg.norm(z))
    z = z / length if length > 1e-9 else UP.copy()
    x = forward - (forward @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = left - (left @ z) * z
    x /= np.linalg.norm(x)
    return start, np.stack([x, np.cross(z, x), z])


def shapes(points: np.ndarray, outfit: Outfit) -> list[Shape]:
    """Every shape of the person for one frame's points (len(POINT_NAMES), 3): limbs, garments and what is carried."""
    p = {n: points[i] for n, i in _P.items()}
    r = outfit.radii
    forward, left, up = _torso_axes(p)
    torso_frame = (p["pelvis"], np.stack([forward, left, up]))
    on_torso = lambda a, b, radius, material: Shape(a, b, radius, material, torso_frame)  # noqa: E731
    limb = lambda a, b, radius, material: Shape(a, b, radius, material, _limb_frame(a, b, forward, left))  # noqa: E731
    lift = lambda v, dz: v + np.array([0.0, 0.0, dz])  # noqa: E731
    sole = r["foot"] - FOOT_LINE_HEIGHT      # the shoe's sole FOOT_LINE_HEIGHT under the heel-toe line
    neck_up = p["neck"] + 0.07 * UP
    head_centre = p["neck"] + 0.6 * (p["head_top"] - p["neck"]) + 0.04 * UP
    out = [
        on_torso(p["pelvis"] + 0.05 * UP, p["neck"] - 0.05 * UP, r["torso"], "shirt"),
        on_torso(p["left_hip"] + 0.08 * UP, p["left_shoulder"] - 0.04 * UP, r["flank"], "shirt"),
        on_torso(p["right_hip"] + 0.08 * UP, p["right_shoulder"] - 0.04 * UP, r["flank"], "shirt"),
        on_torso(p["left_hip"], p["right_hip"], r["hips"], "lower"),
        limb(p["neck"], neck_up, r["neck"], "skin"),
        limb(head_centre, head_centre, r["head"], "head"),
    ]
    forearm = "shirt" if outfit.sleeves == "long" else "skin"
    bare = "skin" if outfit.tights is None else "tights"
    for side in ("left", "right"):
        hip, knee, ankle = p[f"{side}_hip"], p[f"{side}_knee"], p[f"{side}_ankle"]
        out += [
            limb(p[f"{side}_shoulder"], p[f"{side}_elbow"], r["upper_arm"], "shirt"),
            limb(p[f"{side}_elbow"], p[f"{side}_wrist"], r["forearm"], forearm),
            limb(p[f"{side}_wrist"], p[f"{side}_hand"], r["hand"], "skin"),
        ]
        thigh = knee - hip
        thigh_length = float(np.linalg.norm(thigh))
        if outfit.lower == "trousers":
            out += [limb(hip, knee, r["thigh"], "lower"), limb(knee, ankle, r["shin"], "lower")]
        elif outfit.lower == "shorts":
            hem = knee - thigh * (float(np.clip(outfit.hem_m, 0.0, thigh_length)) / thigh_length)
            out += [limb(hip, hem, r["thigh"], "lower"), limb(hem, knee, r["thigh"], "skin"),
                    limb(knee, ankle, r["shin"], "skin")]
        else:       # under the skirt: the thigh's top is always hidden
            top = hip + thigh * min(SKIRT_THIGH_START_M / thigh_length, 0.5)
            out += [limb(top, knee, r["thigh"], bare), limb(knee, ankle, r["shin"], bare)]
        out.append(limb(lift(p[f"{side}_heel"], sole), lift(p[f"{side}_toe"], sole), r["foot"], "shoes"))
    if outfit.lower == "skirt":
        out.append(skirt(p, outfit, torso_frame))
    return out + [limb(a, b, radius, material) for a, b, radius, material in carried(p, outfit)]


def capsules(points: np.ndarray, outfit: Outfit) -> list[tuple[np.ndarray, np.ndarray, float, str]]:
    """(start, end, radius, material) of every capsule of ``shapes`` (all but a skirt) for one frame's points."""
    return [(s.start, s.end, s.radius, s.material) for s in shapes(points, outfit) if s.end_radius is None]


def skirt(p: dict[str, np.ndarray], outfit: Outfit, frame: tuple[np.ndarray, np.ndarray]) -> Shape:
    """The skirt's frustum for points ``p`` (name -> (3,)): its top circle centred between the hip joints, of
    half the joints' distance plus half the hips' radius (the hips' capsule bulges out at the sides, as hips
    under a skirt do); its axis towards the middle of the knees; as long as the thighs less ``outfit.hem_m``;
    its hem as wide as it must be to hold the drawn legs' capsules (from ``SKIRT_THIGH_START_M`` down the
    thighs, sampled along hip-knee-ankle) over the skirt's lower 90 %, plus ``outfit.skirt_flare_m``."""
    r = outfit.radii
    top = 0.5 * (p["left_hip"] + p["right_hip"])
    axis = 0.5 * (p["left_knee"] + p["right_knee"]) - top
    axis /= np.linalg.norm(axis)
    thighs = 0.5 * sum(float(np.linalg.norm(p[f"{s}_knee"] - p[f"{s}_hip"])) for s in ("left", "right"))
    length = max(thighs - outfit.hem_m, 0.1)
    r_top = 0.5 * float(np.linalg.norm(p["left_hip"] - p["right_hip"])) + 0.5 * r["hips"]
    f = np.linspace(0.0, 1.0, 16)[:, None]
    leg_radius = np.concatenate([np.full(16, r["thigh"]), np.full(16, r["shin"])])
    needed = r_top
    for side in ("left", "right"):
        hip, knee, ankle = p[f"{side}_hip"], p[f"{side}_knee"], p[f"{side}_ankle"]
        thigh_top = hip + (knee - hip) * min(SKIRT_THIGH_START_M / float(np.linalg.norm(knee - hip)), 0.5)
        q = np.concatenate([thigh_top + f * (knee - thigh_top), knee + f * (ankle - knee)]) - top
        h = q @ axis
        radial = np.linalg.norm(q - h[:, None] * axis, axis=1)
        inside = (h >= 0.1 * length) & (h <= length)
        if inside.any():
            needed = max(needed, float(np.max(r_top + (radial + leg_radius - r_top)[inside] * length / h[inside])))
    return Shape(top, top + length * axis, r_top, "lower", frame, end_radius=needed + outfit.skirt_flare_m)


def carried(p: dict[str, np.ndarray], outfit: Outfit) -> list[tuple[np.ndarray, np.ndarray, float, str]]:
    """Capsules of what the person carries (``outfit.carry``), placed in the torso's frame: ``up`` from the
    pelvis to the neck, ``left`` from the right hip to the left, ``forward`` = left x up."""
    if outfit.carry == "none":
        return []
    forward, left, up = _torso_axes(p)
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


def intersect_frustum(origin: np.ndarray, directions: np.ndarray, top: np.ndarray, axis: np.ndarray, length: float,
                      r_top: float, r_bottom: float) -> np.ndarray:
    """Distance (N,) along unit ``directions`` (N, 3) from ``origin`` (3,) to the first hit on a frustum (inf
    where missed): the side of a cone from the circle of radius ``r_top`` around ``top`` to the circle of
    ``r_bottom`` at ``length`` along unit ``axis``, and the disc closing it at ``top`` (open at the bottom).
    Units m. The side solves |w + t d|^2 - h(t)^2 = (r_top + k h(t))^2 with h(t) = (w + t d).axis, w = origin
    - top, k = (r_bottom - r_top) / length, for h in [0, length]."""
    k = (r_bottom - r_top) / length
    w = origin - top
    wa = float(w @ axis)
    da = directions @ axis
    g = r_top + k * wa
    a = 1.0 - (1.0 + k * k) * da * da
    b = 2.0 * (directions @ w - da * (wa + k * g))
    c = float(w @ w) - wa * wa - g * g
    disc = b * b - 4.0 * a * c
    root = np.sqrt(np.maximum(disc, 0.0))
    q = -0.5 * (b + np.where(b >= 0.0, root, -root))          # the roots are q / a and c / q (stable)
    best = np.full(len(directions), np.inf)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for t in (q / a, c / q):
            h = wa + t * da
            side = (disc >= 0.0) & np.isfinite(t) & (t > 1e-9) & (h >= 0.0) & (h <= length)
            best = np.where(side & (t < best), t, best)
        t_cap = -wa / da
        on_plane = w + np.where(np.isfinite(t_cap), t_cap, 0.0)[:, None] * directions
        cap = np.isfinite(t_cap) & (t_cap > 1e-9) & (np.einsum("ij,ij->i", on_plane, on_plane) <= r_top * r_top)
    return np.where(cap & (t_cap < best), t_cap, best)


def frustum_normals(hits: np.ndarray, top: np.ndarray, axis: np.ndarray, length: float, r_top: float,
                    r_bottom: float) -> np.ndarray:
    """Outward unit normals (K, 3) at points ``hits`` (K, 3) on the frustum of ``intersect_frustum``: the
    cap's (-axis) at the top, else the cone's, tilted against the axis as the frustum widens."""
    q = hits - top
    h = q @ axis
    radial = q - h[:, None] * axis
    radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)
    n = radial - ((r_bottom - r_top) / length) * axis
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.where((h < 1e-7)[:, None], -axis, n)


_HASH_PRIMES = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F), np.uint64(0x165667B19E3779F9))


def _hash(cells: np.ndarray, seed: int, salt: int = 0) -> np.ndarray:
    """A pseudo-random number in [0, 1) per integer lattice cell (K, 3), fixed by ``seed`` and ``salt``."""
    c = cells.astype(np.int64).astype(np.uint64)
    h = (c[:, 0] * _HASH_PRIMES[0]) ^ (c[:, 1] * _HASH_PRIMES[1]) ^ (c[:, 2] * _HASH_PRIMES[2])
    h ^= np.uint64((seed * 1_000_003 + salt * 7_919) % 2**63)
    for multiplier in (np.uint64(0xFF51AFD7ED558CCD), np.uint64(0xC4CEB9FE1A85EC53)):
        h ^= h >> np.uint64(33)
        h *= multiplier
    h ^= h >> np.uint64(33)
    return (h >> np.uint64(11)).astype(np.float64) / float(2**53)


def _value_noise(x: np.ndarray, seed: int) -> np.ndarray:
    """Smooth noise in [0, 1] at points ``x`` (K, 3) in lattice units (features about one unit across)."""
    cell = np.floor(x)
    f = x - cell
    w = f * f * (3.0 - 2.0 * f)
    out = np.zeros(len(x))
    for corner in np.ndindex(2, 2, 2):
        offset = np.array(corner)
        weight = np.prod(np.where(offset > 0, w, 1.0 - w), axis=1)
        out += weight * _hash(cell + offset, seed)
    return out


def _checks(local: np.ndarray, period: float) -> np.ndarray:
    """Gingham weight (K,) in {0, 0.5, 1}: bands across the frame's third axis plus bands around it."""
    across = np.floor(local[:, 2] / period) % 2
    around = (np.floor(local[:, 0] / period) + np.floor(local[:, 1] / period)) % 2
    return 0.5 * (across + around)


def _top_colour(hit: np.ndarray, local: np.ndarray, outfit: Outfit) -> np.ndarray:
    """(K, 3) albedo of the top at hit points (K, 3) world, ``local`` (K, 3) in the shape's pattern frame."""
    first, second = np.array(outfit.shirt[0]), np.array(outfit.shirt[1])
    period, pattern = outfit.stripe_m, outfit.top_pattern
    if pattern == LEGACY_TOP_PATTERN:
        stripe = (np.floor(hit[:, 2] / period) % 2)[:, None]
        return np.where(stripe > 0, first, second)
    if pattern == "plain":
        mix = np.zeros(len(hit))
    elif pattern == "stripes":
        mix = np.floor(local[:, 2] / period) % 2
    elif pattern == "checks":
        mix = _checks(local, period)
    elif pattern == "print":
        mix = np.clip((_value_noise(local / (1.5 * period), outfit.pattern_seed) - 0.4) / 0.2, 0.0, 1.0)
    else:       # dots: one per lattice cell of the period, placed at random inside it
        cell = np.floor(local / period)
        centre = cell + 0.25 + 0.5 * np.stack([_hash(cell, outfit.pattern_seed, salt) for salt in (1, 2, 3)], axis=1)
        mix = (np.linalg.norm(local / period - centre, axis=1) < 0.22).astype(float)
    return first + mix[:, None] * (second - first)


def _lower_colour(hit: np.ndarray, local: np.ndarray, outfit: Outfit) -> np.ndarray:
    """(K, 3) albedo of the lower garment (trousers, shorts or skirt) at hit points, as ``_top_colour``."""
    if outfit.lower_pattern == "twill":
        weave = 0.9 + 0.1 * np.sin(hit[:, 0] * 900.0) * np.sin(hit[:, 1] * 830.0) + 0.08 * np.sin(hit[:, 2] * 60.0)
    elif outfit.lower_pattern == "check":
        weave = 0.92 + 0.08 * _checks(local, 0.04)
    else:
        weave = np.ones(len(hit))
    return np.array(outfit.jeans)[None] * weave[:, None]


def _colour(material: str, hit: np.ndarray, shape: Shape, outfit: Outfit) -> np.ndarray:
    """(K, 3) albedo of ``material`` at the hit points (K, 3) on ``shape``."""
    k = len(hit)
    if material in ("shirt", "lower"):
        origin, axes = shape.frame
        local = (hit - origin) @ axes.T
        return (_top_colour if material == "shirt" else _lower_colour)(hit, local, outfit)
    if material == "head":
        hair = (hit[:, 2] - shape.start[2]) > -0.01
        return np.where(hair[:, None], np.array(outfit.hair), np.array(outfit.skin))
    colour = {"skin": outfit.skin, "shoes": outfit.shoes, "bag": BAG_COLOUR, "tights": outfit.tights}[material]
    return np.broadcast_to(np.array(colour, float), (k, 3))


def _capsule_hits(origin: np.ndarray, d: np.ndarray, start: np.ndarray, end: np.ndarray,
                  radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For unit rays ``d`` (N, 3) from ``origin``: the distance to the capsule's surface (N,), whether it is hit
    above the floor (N,), and the bone's point closest to each ray (N, 3). Units m."""
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
    return t_hit, hit, closest


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
        """Pixel box (u0, v0, u1, v1) that holds the projection of everything within ``radius`` (m) of the
        segment ``start``-``end``, or None if behind the camera."""
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
        for piece in shapes(points, self.outfit):
            frustum = piece.end_radius is not None
            box = self._box(piece.start, piece.end, max(piece.radius, piece.end_radius or 0.0))
            if box is None:
                continue
            u0, v0, u1, v1 = box
            d = self.rays[v0:v1, u0:u1].reshape(-1, 3)
            if frustum:
                length = float(np.linalg.norm(piece.end - piece.start))
                axis = (piece.end - piece.start) / length
                t_hit = intersect_frustum(origin, d, piece.start, axis, length, piece.radius, piece.end_radius)
                hit = np.isfinite(t_hit)
                hit[hit] = origin[2] + t_hit[hit] * d[hit, 2] >= 0.0
            else:
                t_hit, hit, closest = _capsule_hits(origin, d, piece.start, piece.end, piece.radius)
            block = distance[v0:v1, u0:u1].reshape(-1)
            nearer = hit & (t_hit < block)
            if not nearer.any():
                continue
            idx = np.flatnonzero(nearer)
            points_hit = origin + t_hit[idx, None] * d[idx]
            if frustum:
                n = frustum_normals(points_hit, piece.start, axis, length, piece.radius, piece.end_radius)
                n *= np.where(np.einsum("ij,ij->i", n, d[idx]) > 0.0, -1.0, 1.0)[:, None]   # inside: faces the camera
            else:
                n = points_hit - closest[idx]
                n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)
            block[idx] = t_hit[idx]
            distance[v0:v1, u0:u1] = block.reshape(v1 - v0, u1 - u0)
            cblock = colour[v0:v1, u0:u1].reshape(-1, 3)
            nblock = normal[v0:v1, u0:u1].reshape(-1, 3)
            cblock[idx] = _colour(piece.material, points_hit, piece, self.outfit)
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
        """(H, W) floor darkening factor: soft dark spots under the feet and a wide faint one under the body
        (each a Gaussian over the floor, computed only within 4 of its widths: beyond, it darkens by < 1e-7)."""
        factor = np.ones(self.rays.shape[:2])
        # a foot in the air casts a weaker, wider spot
        spots = [(points[_P[n], :2], 0.1 + 0.5 * max(points[_P[n], 2], 0.0), 0.5 * np.exp(-max(points[_P[n], 2], 0.0) / 0.1))
                 for n in ("left_heel", "left_toe", "right_heel", "right_toe")]
        spots.append((points[_P["pelvis"], :2], 0.35, 0.3))
        for centre, width, strength in spots:
            v0, v1, u0, u1 = self._floor_box(centre, 4.0 * width)
            if v0 >= v1 or u0 >= u1:
                continue
            d2 = np.sum(np.square(self.floor_xy[v0:v1, u0:u1] - centre), axis=-1)
            factor[v0:v1, u0:u1] *= 1.0 - strength * np.exp(-d2 / (width * width))
        return np.where(self.sees_floor, factor, 1.0)

    def _floor_box(self, centre: np.ndarray, reach: float) -> tuple[int, int, int, int]:
        """Pixel rows and columns (v0, v1, u0, u1) that hold the floor within ``reach`` m of ``centre`` (the whole
        image if part of that square lies behind the camera)."""
        h, w = self.rays.shape[:2]
        corners = np.array([[centre[0] + dx, centre[1] + dy, 0.0] for dx in (-reach, reach) for dy in (-reach, reach)])
        uv, depth = self.camera.project(corners)
        if np.any(depth <= 0.05) or not np.all(np.isfinite(uv)):
            return 0, h, 0, w
        u0, v0 = np.floor(uv.min(axis=0)).astype(int) - 2
        u1, v1 = np.ceil(uv.max(axis=0)).astype(int) + 3
        return max(v0, 0), min(v1, h), max(u0, 0), min(u1, w)
