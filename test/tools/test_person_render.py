"""person_render: the range of people Outfit.draw dresses, Outfit.random unchanged, the skirt's frustum."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import MOCAP_07

from awalker_tools.person_render import (BUILD_RANGE, HEAD_RADIUS_RANGE, LOWER_GARMENTS, LOWER_PATTERNS, POINT_NAMES,
                                         TOP_PATTERNS, Outfit, PersonRenderer, _capsule_hits, frustum_normals,
                                         intersect_frustum, shapes)
from awalker_tools.walk_variants import level_floor
from awalker_tracker.model.acclaim import load_mocap
from awalker_tracker.vision.camera import Camera

P = {n: i for i, n in enumerate(POINT_NAMES)}
SHIRT, LOWER, SKIN, SHOES = (40.0, 40.0, 200.0), (200.0, 30.0, 30.0), (30.0, 200.0, 30.0), (200.0, 200.0, 30.0)
WIDTH, HEIGHT = 640, 480


@pytest.fixture(scope="module")
def standing() -> np.ndarray:
    """One frame of CMU 07_01 with the legs closest together (mid-swing: nearly standing), floor at z = 0,
    pelvis over the origin, walking along +x: points (len(POINT_NAMES), 3) m."""
    trial = load_mocap(MOCAP_07 / "07.asf", MOCAP_07 / "07_01.amc").resample(30.0)
    points = level_floor(np.concatenate([trial.markers, trial.extra], axis=1), 30.0)
    ahead = points[-1, P["pelvis"], :2] - points[0, P["pelvis"], :2]
    angle = -np.arctan2(ahead[1], ahead[0])
    c, s = np.cos(angle), np.sin(angle)
    spread = np.linalg.norm(points[:, P["left_ankle"], :2] - points[:, P["right_ankle"], :2], axis=1)
    frame = points[int(np.argmin(spread))]
    frame = frame - np.append(frame[P["pelvis"], :2], 0.0)
    return frame @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T


def arms_forward(points: np.ndarray) -> np.ndarray:
    """The points with both arms held straight forward (+x) at shoulder height, off the legs and the skirt."""
    out = points.copy()
    for side in ("left", "right"):
        shoulder = out[P[f"{side}_shoulder"]]
        for name, reach in (("elbow", 0.3), ("wrist", 0.55), ("hand", 0.63)):
            out[P[f"{side}_{name}"]] = shoulder + np.array([reach, 0.0, 0.0])
    return out


def side_camera(distance: float = 4.0) -> Camera:
    """A camera ``distance`` m to the person's right (-y), 1.2 m up, looking at the hips."""
    return Camera.look_at("side", WIDTH, HEIGHT, 0.82 * WIDTH, np.array([0.0, -distance, 1.2]),
                          np.array([0.0, 0.0, 0.8]), distortion=np.array([-0.04, 0.01, 0.0, 0.0, 0.0]))


def dressed(lower: str, **changes) -> Outfit:
    """A plain outfit in colours that tell garments apart (shirt blue, lower garment red, skin green)."""
    base = Outfit.draw(np.random.default_rng(5))
    fields = dict(lower=lower, shirt=(SHIRT, SHIRT), jeans=LOWER, skin=SKIN, shoes=SHOES, hair=(20.0, 20.0, 20.0),
                  top_pattern="plain", lower_pattern="plain", sleeves="short", tights=None, hem_m=0.0)
    return replace(base, **{**fields, **changes})


def pixel(image: np.ndarray, camera: Camera, point: np.ndarray) -> np.ndarray:
    (u, v), _ = camera.project(point)
    return image[int(round(v)), int(round(u))]


def is_colour(rgb: np.ndarray, albedo: tuple[float, float, float]) -> bool:
    """Whether a shaded pixel ``rgb`` is ``albedo`` times a shade (0.45-1): the same direction in RGB."""
    a = np.array(albedo) / np.linalg.norm(albedo)
    return bool(np.linalg.norm(rgb) > 20.0 and rgb @ a / np.linalg.norm(rgb) > 0.99)


def test_draw_covers_the_range_of_people_and_is_reproducible():
    outfits = [Outfit.draw(np.random.default_rng(seed)) for seed in range(200)]
    summaries = [o.describe() for o in outfits]
    json.dumps(summaries)
    assert {o.lower for o in outfits} == set(LOWER_GARMENTS)
    assert {o.top_pattern for o in outfits} == set(TOP_PATTERNS)
    assert {o.lower_pattern for o in outfits} == set(LOWER_PATTERNS)
    assert {o.sleeves for o in outfits} == {"short", "long"}
    assert {s["top"]["tone"] for s in summaries} == {"light", "mid", "dark"}
    assert {s["lower_garment"]["tone"] for s in summaries} == {"light", "mid", "dark"}
    assert {s["shoes"] for s in summaries} == {"light", "dark"}
    assert any(s["top"]["floor_like"] for s in summaries) and any(s["lower_garment"]["floor_like"] for s in summaries)
    assert {s["legs"] for s in summaries if s["lower"] == "skirt"} == {"bare", "tights"}
    assert all(o.tights is None for o in outfits if o.lower != "skirt")
    # the lower garment is not always blue: some red- or green-dominant, and some nearly grey
    assert any(o.jeans[0] > o.jeans[2] + 30 for o in outfits) and any(o.jeans[1] > o.jeans[2] + 30 for o in outfits)
    trousers = sum(o.lower == "trousers" for o in outfits)
    assert 80 <= trousers <= 120
    hems = {kind: [o.hem_m for o in outfits if o.lower == kind] for kind in ("shorts", "skirt")}
    assert 0.05 <= min(hems["shorts"]) and max(hems["shorts"]) <= 0.15
    assert -0.1 <= min(hems["skirt"]) < -0.05 and 0.05 < max(hems["skirt"]) <= 0.1
    builds = np.array([o.build for o in outfits])
    assert BUILD_RANGE[0] <= builds.min() < 0.85 and 1.3 < builds.max() <= BUILD_RANGE[1]
    for o in outfits:     # the torso's and thighs' widths follow the build, within +- 8 %
        assert 0.92 <= o.radii["torso"] / (0.11 * o.build) <= 1.08 and 0.92 <= o.radii["thigh"] / (0.075 * o.build) <= 1.08
        assert HEAD_RADIUS_RANGE[0] <= o.radii["head"] <= HEAD_RADIUS_RANGE[1]
    skin = [max(o.skin) for o in outfits]
    hair = [max(o.hair) for o in outfits]
    assert min(skin) < 90 and max(skin) > 220 and min(hair) < 30 and max(hair) > 150
    assert Outfit.draw(np.random.default_rng(17)) == Outfit.draw(np.random.default_rng(17))
    assert Outfit.draw(np.random.default_rng(17)) != Outfit.draw(np.random.default_rng(18))
    assert Outfit.draw(np.random.default_rng(17), carry="backpack").carry == "backpack"
    with pytest.raises(ValueError, match="Outfit.lower"):
        replace(outfits[0], lower="kilt")


def test_random_draws_what_it_drew_before():
    """Values Outfit.random gave before Outfit.draw existed (old sequences stay reproducible)."""
    o = Outfit.random(np.random.default_rng(0))
    assert o.shirt[0] == pytest.approx((170.17800251105962, 225.731277978192, 172.18306239485517), abs=1e-9)
    assert o.shirt[1] == pytest.approx((90.60512747756171, 120.18246139396207, 91.67264915304756), abs=1e-9)
    assert o.stripe_m == pytest.approx(0.05702622482410236, abs=1e-12)
    assert o.jeans == pytest.approx((62.989936291697504, 85.8953676704966, 143.15894611749434), abs=1e-9)
    assert o.skin == pytest.approx((155.49165977544598, 121.35934421498222, 98.60446717467305), abs=1e-9)
    assert o.radii["torso"] == pytest.approx(0.11301315712107202, abs=1e-12)
    assert o.radii["foot"] == pytest.approx(0.04040048701132364, abs=1e-12)
    assert (o.lower, o.top_pattern, o.lower_pattern, o.sleeves, o.build) == ("trousers", "level-stripes", "twill", "short", 1.0)
    o = Outfit.random(np.random.default_rng(7), carry="backpack")
    assert o.hair == pytest.approx((28.010601692892227, 50.626980213651535, 22.197100398069168), abs=1e-9)
    assert o.radii["hips"] == pytest.approx(0.10551371380490389, abs=1e-12) and o.carry == "backpack"
    rng = np.random.default_rng(3)
    Outfit.random(rng)
    assert rng.random() == pytest.approx(0.8917110704451572, abs=1e-15)      # a fixed count of numbers drawn


def _first_solid_entry(origin, direction, top, axis, length, r_top, r_bottom, far, step=2e-4):
    """Brute force: (t, h) where the ray first enters the solid frustum (None if never), by sampling and bisection."""
    def inside(t):
        q = origin + np.multiply.outer(t, direction) - top
        h = q @ axis
        radial = np.linalg.norm(q - np.multiply.outer(h, axis), axis=-1)
        return (h >= 0) & (h <= length) & (radial <= r_top + (r_bottom - r_top) * h / length)

    t = np.arange(0.0, far, step)
    found = np.flatnonzero(inside(t))
    if not len(found):
        return None
    lo, hi = t[found[0] - 1], t[found[0]]
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if inside(np.array([mid]))[0] else (mid, hi)
    return hi, float((origin + hi * direction - top) @ axis)


def test_ray_frustum_intersection_matches_brute_force_sampling():
    rng = np.random.default_rng(1)
    side = cap = missed = bottom = 0
    for _ in range(6):
        top = rng.uniform(-0.3, 0.3, 3) + np.array([0.0, 0.0, 0.9])
        axis = np.array([0.0, 0.0, -1.0]) + rng.uniform(-0.4, 0.4, 3)
        axis /= np.linalg.norm(axis)
        length, r_top, r_bottom = rng.uniform(0.3, 0.6), rng.uniform(0.1, 0.2), rng.uniform(0.05, 0.4)
        for _ in range(40):
            origin = top + rng.normal(size=3) * 3.0
            aim = top + axis * rng.uniform(-0.2, length + 0.2) + rng.uniform(-0.25, 0.25, 3)
            d = (aim - origin) / np.linalg.norm(aim - origin)
            t = intersect_frustum(origin, d[None], top, axis, length, r_top, r_bottom)[0]
            entry = _first_solid_entry(origin, d, top, axis, length, r_top, r_bottom,
                                       far=float(np.linalg.norm(origin - top)) + 1.0)
            if entry is None:
                assert t == np.inf
                missed += 1
                continue
            t_entry, h_entry = entry
            if h_entry > length - 1e-6:        # in through the open bottom: a wall or the cap from inside, further on
                assert t > t_entry
                bottom += 1
                continue
            assert t == pytest.approx(t_entry, abs=1e-6)
            hit = origin + t * d
            n = frustum_normals(hit[None], top, axis, length, r_top, r_bottom)[0]
            if h_entry < 1e-6:
                cap += 1
                assert n == pytest.approx(-axis)
            else:                              # the normal is the gradient of the cone's implicit function
                side += 1
                f = lambda p: np.linalg.norm((p - top) - ((p - top) @ axis) * axis) - (  # noqa: E731
                    r_top + (r_bottom - r_top) * ((p - top) @ axis) / length)
                grad = np.array([f(hit + e * 1e-6) - f(hit - e * 1e-6) for e in np.eye(3)]) / 2e-6
                assert n @ grad / np.linalg.norm(grad) > 1 - 1e-6
    assert side > 50 and cap > 5 and missed > 10 and bottom > 5
    # straight up the axis from below: through the open bottom to the cap's inside
    below = top + axis * (length + 1.0)
    assert intersect_frustum(below, -axis[None], top, axis, length, r_top, r_bottom)[0] == pytest.approx(length + 1.0)


def test_skirt_hides_the_thighs_and_stops_at_its_hem(standing):
    points = arms_forward(standing)
    camera = side_camera()
    renderer = PersonRenderer(camera, dressed("skirt", hem_m=0.0), blur_sigma_px=0.0)
    image, depth = renderer.render(points, np.zeros((HEIGHT, WIDTH, 3), np.float32))
    for side in ("left", "right"):
        hip, knee, ankle = (points[P[f"{side}_{n}"]] for n in ("hip", "knee", "ankle"))
        assert is_colour(pixel(image, camera, 0.5 * (hip + knee)), LOWER)      # the thighs are under the skirt
        assert is_colour(pixel(image, camera, 0.5 * (knee + ankle)), SKIN)     # bare shins below the hem
    skirt = [s for s in shapes(points, renderer.outfit) if s.end_radius is not None]
    assert len(skirt) == 1
    centre = 0.5 * (skirt[0].start + skirt[0].end)
    (u, v), _ = camera.project(centre)
    _, pelvis_depth = camera.project(points[P["pelvis"]])
    assert depth[int(round(v)), int(round(u))] < pelvis_depth - 0.1
    # a skirt is not the legs' capsules: it reaches out past both thighs
    (_, v_knee), _ = camera.project(0.5 * (points[P["left_knee"]] + points[P["right_knee"]]) + np.array([0, 0, 0.05]))
    row = is_colour_row(image[int(round(v_knee))], LOWER)
    trouser_image, _ = PersonRenderer(camera, dressed("trousers"), blur_sigma_px=0.0).render(points, image * 0)
    assert row.sum() > is_colour_row(trouser_image[int(round(v_knee))], LOWER).sum() + 10
    # dark tights under the skirt instead of bare legs
    tights = (30.0, 25.0, 60.0)
    renderer = PersonRenderer(camera, dressed("skirt", hem_m=0.08, tights=tights), blur_sigma_px=0.0)
    image, _ = renderer.render(points, np.zeros((HEIGHT, WIDTH, 3), np.float32))
    assert is_colour(pixel(image, camera, 0.5 * (points[P["left_knee"]] + points[P["left_ankle"]])), tights)


def is_colour_row(row: np.ndarray, albedo: tuple[float, float, float]) -> np.ndarray:
    a = np.array(albedo) / np.linalg.norm(albedo)
    norm = np.linalg.norm(row, axis=1)
    return (norm > 20.0) & (row @ a > 0.99 * norm)


def test_skirt_takes_part_in_the_depth_test(standing):
    """Nearest hit wins between the skirt and the capsules: the skirt hides thighs (it is nearer where both are
    hit), and a hand hanging by the hip hides the skirt; the depth image is never farther than the skirt."""
    camera = side_camera(3.0)
    outfit = dressed("skirt", hem_m=-0.05)
    renderer = PersonRenderer(camera, outfit, blur_sigma_px=0.0)
    image, depth = renderer.render(standing, np.zeros((HEIGHT, WIDTH, 3), np.float32))
    skirt = next(s for s in shapes(standing, outfit) if s.end_radius is not None)
    length = float(np.linalg.norm(skirt.end - skirt.start))
    rays = renderer.rays.reshape(-1, 3)
    t_skirt = intersect_frustum(camera.position, rays, skirt.start, (skirt.end - skirt.start) / length, length,
                                skirt.radius, skirt.end_radius)
    skirt_depth = (t_skirt * renderer.depth_per_t.reshape(-1)).reshape(HEIGHT, WIDTH)
    seen = np.isfinite(skirt_depth)
    flat = image.reshape(-1, 3)
    red = is_colour_row(flat, LOWER).reshape(HEIGHT, WIDTH)
    assert np.all(depth[seen] <= skirt_depth[seen] + 1e-9)
    on_top = seen & (depth == skirt_depth)
    assert on_top.sum() > 2000 and red[on_top].all()
    in_front = seen & (depth < skirt_depth - 0.02)          # something nearer than the skirt, e.g. the near hand
    assert is_colour_row(flat, SKIN).reshape(HEIGHT, WIDTH)[in_front].sum() > 50
    knees = [standing[P["left_knee"]], standing[P["right_knee"]]]
    thighs = [s for s in shapes(standing, outfit) if any(np.array_equal(s.end, knee) for knee in knees)]
    assert len(thighs) == 2
    hidden = 0
    for thigh in thighs:
        t, hit, _ = _capsule_hits(camera.position, rays, thigh.start, thigh.end, thigh.radius)
        thigh_depth = np.where(hit, t, np.inf).reshape(HEIGHT, WIDTH) * renderer.depth_per_t
        both = np.isfinite(thigh_depth) & seen
        assert both.any() and np.all(skirt_depth[both] < thigh_depth[both])
        hidden += int(both.sum())
    assert hidden > 500


def test_shorts_and_trousers(standing):
    points = arms_forward(standing)
    camera = side_camera()
    background = np.zeros((HEIGHT, WIDTH, 3), np.float32)
    image, _ = PersonRenderer(camera, dressed("shorts", hem_m=0.1), blur_sigma_px=0.0).render(points, background)
    near = min(("left", "right"), key=lambda s: camera.project(points[P[f"{s}_knee"]])[1])
    hip, knee, ankle = (points[P[f"{near}_{n}"]] for n in ("hip", "knee", "ankle"))
    up = (hip - knee) / np.linalg.norm(hip - knee)
    assert is_colour(pixel(image, camera, 0.5 * (knee + ankle)), SKIN)
    assert is_colour(pixel(image, camera, knee + 0.05 * up), SKIN)       # 5 cm over the knee, under the hem
    assert is_colour(pixel(image, camera, knee + 0.15 * up), LOWER)      # 5 cm over the hem
    image, _ = PersonRenderer(camera, dressed("trousers"), blur_sigma_px=0.0).render(points, background)
    for side in ("left", "right"):
        knee, ankle = points[P[f"{side}_knee"]], points[P[f"{side}_ankle"]]
        assert is_colour(pixel(image, camera, 0.5 * (knee + ankle)), LOWER)


def test_long_sleeves_cover_the_forearms(standing):
    points = arms_forward(standing)
    camera = side_camera()
    forearm = 0.5 * (points[P["right_elbow"]] + points[P["right_wrist"]])
    for sleeves, albedo in (("short", SKIN), ("long", SHIRT)):
        image, _ = PersonRenderer(camera, dressed("trousers", sleeves=sleeves), blur_sigma_px=0.0).render(
            points, np.zeros((HEIGHT, WIDTH, 3), np.float32))
        assert is_colour(pixel(image, camera, forearm), albedo)


@pytest.mark.parametrize("pattern", list(TOP_PATTERNS))
def test_top_patterns_are_attached_to_the_body(standing, pattern):
    """Moving the person and the camera together changes no torso pixel for a body-attached pattern (only the
    level stripes of Outfit.random stay at their world height); every pattern but plain shows both colours."""
    outfit = replace(dressed("trousers"), shirt=((220.0, 210.0, 60.0), (40.0, 60.0, 160.0)), top_pattern=pattern,
                     stripe_m=0.05)
    shift = np.array([0.4, -0.3, 0.037])

    def torso_pixels(outfit: Outfit, offset: np.ndarray) -> np.ndarray:
        camera = Camera.look_at("c", WIDTH, HEIGHT, 0.82 * WIDTH, np.array([0.5, -3.0, 1.3]) + offset,
                                np.array([0.0, 0.0, 1.1]) + offset)
        image, depth = PersonRenderer(camera, outfit, blur_sigma_px=0.0).render(
            standing + offset, np.zeros((HEIGHT, WIDTH, 3), np.float32))
        (_, v_hip), _ = camera.project(standing[P["pelvis"]] + offset + np.array([0.0, 0.0, 0.15]))
        return image[: int(v_hip)][np.isfinite(depth[: int(v_hip)])]

    still = torso_pixels(outfit, np.zeros(3))
    assert np.abs(torso_pixels(outfit, shift) - still).max() < 1e-3
    yellow = (still[:, 0] > still[:, 2] + 40).mean()
    blue = (still[:, 2] > still[:, 0] + 40).mean()
    if pattern == "plain":
        assert blue == 0.0
    else:
        assert yellow > 0.1 and blue > 0.03
    legacy = replace(outfit, top_pattern="level-stripes")
    assert np.abs(torso_pixels(legacy, shift) - torso_pixels(legacy, np.zeros(3))).max() > 50
