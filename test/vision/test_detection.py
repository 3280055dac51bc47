"""Person detection: foreground blob -> ground position and height, one and two cameras."""
from __future__ import annotations

import numpy as np
import pytest

from awalker_tracker.model.kinematics import pose_body
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.detection import detect_person, ground_point, person_blob
from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor
from awalker_tracker.vision.flow import FlowConfig
from vision_scene import BODY, PARAMS, background_image, front_camera, noisy, render_frames, side_camera, walking_poses

CONFIG = FeatureConfig(background_frames=3, downsample=2, flow=FlowConfig(cell_size=8))


def features_of(camera, poses, seed):
    rng = np.random.default_rng(10 + seed)
    background = background_image(camera, seed=seed)
    frames, _ = render_frames(camera, poses, background, seed=seed)
    extractor = FeatureExtractor(CONFIG)
    for _ in range(CONFIG.background_frames):
        extractor.process(noisy(background, rng))
    return [extractor.process(f) for f in frames], background


@pytest.fixture(scope="module")
def scene():
    poses = walking_poses(3, x0=0.4)
    cameras = [side_camera(), front_camera()]
    features = [features_of(c, poses, k)[0] for k, c in enumerate(cameras)]
    markers = pose_body(BODY, PARAMS, poses[-1].walker, poses[-1].kin).markers[0]
    return cameras, [f[-1] for f in features], markers


def test_ground_point_inverts_the_projection():
    camera = side_camera()
    point = np.array([0.7, 0.4, 0.0])
    uv, _ = camera.project(point[None])
    assert np.allclose(ground_point(camera, tuple(uv[0])), point[:2], atol=1e-6)
    assert ground_point(camera, (160.0, -500.0)) is None        # a ray above the horizon


def test_blob_covers_the_person(scene):
    cameras, features, markers = scene
    blob = person_blob(features[0], "side")
    uv, _ = cameras[0].project(markers)
    u0, v0, u1, v1 = blob.box
    inside = (uv[:, 0] > u0 - 3) & (uv[:, 0] < u1 + 3) & (uv[:, 1] > v0 - 3) & (uv[:, 1] < v1 + 3)
    assert inside.all()
    assert blob.feet_uv[1] > uv[:, 1].max() - 6 and blob.head_uv[1] < uv[2, 1]   # below the feet, above the head


def test_one_and_two_camera_positions_and_height(scene):
    cameras, features, markers = scene
    truth = 0.5 * (markers[7, :2] + markers[8, :2])              # between the ankles
    mono = detect_person(features[:1], cameras[:1])
    assert np.linalg.norm(mono.position - truth) < 0.2           # feet rows: depth to about a map pixel
    both = detect_person(features, cameras)
    assert np.linalg.norm(both.position - truth) < 0.1           # two vertical planes meet under the person
    assert both.height == pytest.approx(BODY.height, abs=0.05)
    assert {b.camera for b in both.blobs} == {"side", "front"}


def test_one_feet_row_resolves_depth_to_d_squared_over_h(scene):
    """A feet-row position is as fine as one map row: over the ground a row lower moves it by about
    (D^2 + h^2) / h x (row height / focal length) (D: ground distance, h: camera height). A camera 2.5
    times as far and at half the height resolves depth ~13 times worse. Triangulated: 0."""
    cameras, features, markers = scene
    side = cameras[0]
    mono = detect_person(features[:1], cameras[:1])
    distance = float(np.linalg.norm(mono.position - side.position[:2]))
    height = float(side.position[2])
    row = CONFIG.downsample / 300.0                             # focal length 300 px
    expected = (distance**2 + height**2) / height * row
    assert mono.row_depth_m == pytest.approx(expected, rel=0.15)
    assert 0.03 < mono.row_depth_m < 0.15                       # ~0.09 m from 4 m at 1.1 m high
    assert detect_person(features, cameras).row_depth_m == 0.0  # two planes: no feet row
    far = Camera.look_at("far", 320, 240, 300.0, np.array([0.3, -10.0, 0.5]), np.array([0.3, 0.0, 0.9]))
    seen_far = detect_person([features_of(far, walking_poses(3, x0=0.4), 2)[0][-1]], [far])
    d_far = float(np.linalg.norm(seen_far.position - far.position[:2]))
    assert seen_far.row_depth_m == pytest.approx((d_far**2 + 0.25) / 0.5 * row, rel=0.15)
    assert seen_far.row_depth_m > 10 * mono.row_depth_m


def test_no_person_no_detection():
    camera = side_camera()
    features, _ = features_of(camera, [], 0)
    assert features == []
    empty = FeatureExtractor(CONFIG)
    background = background_image(camera, seed=0)
    rng = np.random.default_rng(0)
    frames = [empty.process(noisy(background, rng)) for _ in range(CONFIG.background_frames + 2)]
    assert person_blob(frames[-1]) is None and detect_person([frames[-1]], [camera]) is None


@pytest.fixture(scope="module")
def two_people():
    """Two people seen by the side and the front camera: A at x = 0.4 m; B at x = -0.5 m and 0.8 m nearer the
    side camera (so B is the side camera's largest blob, A the front camera's). Features of each camera and
    the two pelvis positions."""
    from awalker_tools.model_render import render_rgb
    from awalker_tracker.vision.render import render

    a = walking_poses(3, x0=0.4)[-1]
    b = walking_poses(3, x0=-0.5)[-1]
    b.kin.contact_point = b.kin.contact_point + np.array([0.0, -0.8])
    pelvis = [pose_body(BODY, PARAMS, p.walker, p.kin).markers[0, 0] for p in (a, b)]
    cameras, features = [side_camera(), front_camera()], []
    for k, camera in enumerate(cameras):
        rng = np.random.default_rng(20 + k)
        background = background_image(camera, seed=k)
        image = background
        for person in (b, a) if k == 0 else (a, b):          # the farther first
            image = render_rgb(BODY, person.segments(), camera, image, result=render(BODY, person.segments(), camera))
        extractor = FeatureExtractor(CONFIG)
        for _ in range(CONFIG.background_frames):
            extractor.process(noisy(background, rng))
        extractor.process(noisy(image, rng))
        features.append(extractor.process(noisy(image, rng)))
    return cameras, features, pelvis


def test_two_people_are_not_mixed_across_cameras(two_people):
    from awalker_tracker.vision.detection import blob_near, person_blobs

    cameras, features, (a, b) = two_people
    largest = [person_blob(f, c.name) for f, c in zip(features, cameras)]
    side_gap = [np.linalg.norm(ground_point(cameras[0], largest[0].feet_uv) - p[:2]) for p in (a, b)]
    assert side_gap[1] < side_gap[0]                      # each camera's largest blob is another person
    assert blob_near(person_blobs(features[1], "front"), cameras[1], a) == largest[1]
    # nothing known: the largest blob of any camera (B, in the side camera) and the front camera's blob there
    found = detect_person(features, cameras)
    assert found is not None and found.triangulated
    assert np.linalg.norm(found.position - b[:2]) < 0.25
    # following A: each camera's blob nearest to A
    found = detect_person(features, cameras, near=a)
    assert found is not None and np.linalg.norm(found.position - a[:2]) < 0.25
    # a point near nobody (behind the front camera, far right of the side camera's image): no blob is near
    # it, so the detection is made as without it
    far = np.array([6.0, 0.0, 0.9])
    assert all(blob_near(person_blobs(f, c.name), c, far) is None for f, c in zip(features, cameras))
    assert np.allclose(detect_person(features, cameras, near=far).position, detect_person(features, cameras).position)


def test_the_column_is_the_upper_bodys_and_a_ghost_at_the_feet_does_not_move_it(scene):
    """What is left of a ghost (a planted foot learned into the background) or a shadow joins the blob
    at its feet: the column (upper half's mean) stays over the person, the whole blob's mean would not."""
    from dataclasses import replace

    from awalker_tracker.vision.detection import person_blobs

    cameras, features, markers = scene
    side = features[0]
    clean = person_blob(side, "side")
    llr = side.llr.copy()
    d = side.downsample
    u0, v1, middle = int(clean.box[0] / d), int(clean.box[3] / d), int(clean.feet_uv[0] / d)
    llr[:, v1 - 3 : v1 + 1, max(u0 - 35, 0) : middle] = 10.0  # a foot-high ghost reaching 35 map px behind
    ghosted = person_blobs(replace(side, llr=llr), "side")[0]
    assert ghosted.box[0] < clean.box[0] - 40                 # one blob, wider
    assert ghosted.feet_uv[0] == pytest.approx(clean.feet_uv[0], abs=1.0)
    rows, cols = np.nonzero(np.max(llr, axis=0) > 2.0)
    assert d * cols.mean() < clean.feet_uv[0] - 8             # the whole blob's mean column would move
    pelvis_u = cameras[0].project(markers[:1])[0][0, 0]
    assert ghosted.feet_uv[0] == pytest.approx(pelvis_u, abs=6.0)


def _map_box(blob, d):
    """A blob's box in map pixels: first row, row after the last, first column, column after the last."""
    u0, v0, u1, v1 = blob.box
    row0, row1, col0, col1 = ((c + 0.5) / d for c in (v0, v1, u0, u1))
    return int(round(row0)), int(round(row1)), int(round(col0)), int(round(col1))


def test_a_row_lost_across_the_waist_does_not_cut_the_person_in_two(scene):
    """A belt or a waist whose colours are near the background's leaves a map row of the body below the
    threshold: the pieces above and below are still one blob, with the box, column and area of the whole,
    and a piece beside the person one row lower is not joined."""
    from dataclasses import replace

    from awalker_tracker.vision.detection import person_blobs

    _, features, _ = scene
    side = features[0]
    clean = person_blob(side, "side")
    d = side.downsample
    v0, v1, u0, u1 = _map_box(clean, d)
    waist = (v0 + v1) // 2
    llr = side.llr.copy()
    llr[:, waist, :] = -5.0                                   # a row across the body: background
    cut = person_blobs(replace(side, llr=llr), "side")
    assert cut[0].box == clean.box and cut[0].feet_uv == pytest.approx(clean.feet_uv, abs=d)
    assert cut[0].area_px == clean.area_px                    # the lost row filled back (``_fill_row_gaps``)
    beside = side.llr.copy()
    beside[:, v0 - 10 : v0 - 1, u1 + 3 : u1 + 25] = 10.0       # a block to the right ending a row above the head
    beside[:, v0 - 1, :] = -5.0
    blobs = person_blobs(replace(side, llr=beside), "side")
    assert any(b.box[:2] == clean.box[:2] and b.box[3] == clean.box[3] for b in blobs)   # the person alone


def _drawn(like, rectangles):
    """``like``'s features with only the given map rectangles (row0, row1, col0, col1; ends excluded) foreground."""
    from dataclasses import replace

    llr = np.full_like(like.llr, -5.0)
    for r0, r1, c0, c1 in rectangles:
        llr[0, r0:r1, c0:c1] = 10.0
    return replace(like, llr=llr)


def test_a_skirt_of_the_floors_colour_does_not_cut_the_legs_off(scene):
    """A skirt near the floor's colour leaves the legs a few rows under the trunk, or as fragments whose top
    rows reach up beside the hem: they join the trunk, whose feet row alone would put the person metres
    away. Legs farther below than 30 % of the trunk's height, a flat contact shadow and a speck stay apart
    (``vision.detection.STACK_*``)."""
    from awalker_tracker.vision.detection import STACK_LOWER_AREA, person_blobs

    _, features, _ = scene
    side = features[0]
    d = side.downsample
    min_pixels = 0.0015 * side.image_width * side.image_height / d**2
    trunk = (10, 40, 20, 33)                                   # 30 rows x 13 columns
    assert 30 * 13 >= min_pixels                               # the trunk alone is a person blob
    legs = (45, 75, 22, 31)                                    # 5 empty rows under the trunk (< 30 % of 30)
    joined = person_blobs(_drawn(side, [trunk, legs]), "side")
    assert len(joined) == 1 and _map_box(joined[0], d) == (10, 75, 20, 33)
    assert joined[0].feet_uv[1] == pytest.approx(d * 74 + 0.5 * (d - 1))          # the legs' lowest row

    far_below = (52, 82, 22, 31)                               # 12 empty rows: something else
    parted = person_blobs(_drawn(side, [trunk, far_below]), "side")
    assert sorted(_map_box(b, d) for b in parted) == [(10, 40, 20, 33), (52, 82, 22, 31)]

    # the trunk's left edge (an arm, a hem) hangs down to row 43; the legs' top (row 37) is beside it
    hem = [(10, 37, 20, 33), (37, 43, 20, 24)]
    fragment = (37, 70, 27, 33)
    reaching = person_blobs(_drawn(side, hem + [fragment]), "side")
    assert len(reaching) == 1 and _map_box(reaching[0], d) == (10, 70, 20, 33)

    shadow = (42, 45, 14, 40)                                  # 3 rows x 26 columns, 2 rows under the trunk
    assert 3 * 26 >= STACK_LOWER_AREA * min_pixels
    kept = person_blobs(_drawn(side, [trunk, shadow]), "side")
    assert _map_box(kept[0], d) == (10, 40, 20, 33)

    speck = (43, 45, 25, 27)                                   # 2 x 2, under a quarter of a person blob
    assert 4 < STACK_LOWER_AREA * min_pixels
    assert _map_box(person_blobs(_drawn(side, [trunk, speck]), "side")[0], d) == (10, 40, 20, 33)


def test_legs_in_fragments_under_the_trunk_join_it(scene):
    """Trousers near the floor's colour leave the legs as strips a row apart, each too flat to join as a stacked
    piece: the chain joins the trunk (whose own lowest row, the waist, puts the person metres farther away).
    A chain reaching less than 30 % of the trunk's height lower (a contact shadow), one beyond a gap of 15 % of it
    and someone larger standing under it stay apart (``vision.detection.TRAIL_*``)."""
    from awalker_tracker.vision.detection import STACK_LOWER_ASPECT, TRAIL_MAX_GAP, TRAIL_MIN_DROP, person_blobs

    _, features, _ = scene
    side = features[0]
    d = side.downsample
    trunk = (10, 40, 20, 33)                                   # 30 rows x 13 columns
    strips = [(41 + 4 * k, 44 + 4 * k, 21 + 2 * (k % 2), 27 + 2 * (k % 2)) for k in range(6)]   # 3 x 6 each
    assert all(3 < STACK_LOWER_ASPECT * 6 for _ in strips)     # none upright: no stacked piece
    legs = person_blobs(_drawn(side, [trunk] + strips), "side")
    assert len(legs) == 1 and _map_box(legs[0], d) == (10, 64, 20, 33)
    assert legs[0].feet_uv[1] == pytest.approx(d * 63 + 0.5 * (d - 1))          # the lowest strip's row
    assert legs[0].area_px >= d * d * (30 * 13 + 6 * 18)      # (and the one-row notches filled)

    shadow = strips[:2]                                        # down to row 48: 8 rows, under 30 % of 30
    assert 48 - 40 < TRAIL_MIN_DROP * 30
    assert _map_box(person_blobs(_drawn(side, [trunk] + shadow), "side")[0], d) == (10, 40, 20, 33)

    apart = [(r0 + 5, r1 + 5, c0, c1) for r0, r1, c0, c1 in strips]   # the first 6 rows under the trunk
    assert 6 > TRAIL_MAX_GAP * 30
    assert _map_box(person_blobs(_drawn(side, [trunk] + apart), "side")[0], d) == (10, 40, 20, 33)

    larger = (54, 94, 12, 36)                                  # 40 x 24 two rows under the third strip: someone
    parted = person_blobs(_drawn(side, [trunk] + strips[:3] + [larger]), "side")   # nearer, 2.5 x the trunk
    assert sorted(_map_box(b, d) for b in parted) == [(10, 52, 20, 33), (54, 94, 12, 36)]


def test_ground_track_fit_drops_a_misplaced_detection():
    """A blob broken in two puts one frame's person metres away: the line fit drops it."""
    from awalker_tracker.vision.detection import GroundTrack

    track = GroundTrack(dt=1 / 30)
    rng = np.random.default_rng(0)
    for f in range(30):
        track.add(f, np.array([1.2 * f / 30, 0.5]) + rng.normal(0, 0.03, 2))
    track.add(30, np.array([1.2, 9.8]))                        # the feet row of a torso alone: 9 m deep
    velocity = track.velocity(30, 1.0)
    assert velocity == pytest.approx([1.2, 0.0], abs=0.1)
    assert track.fitted_position(30, 1.0, at=15) == pytest.approx([0.6, 0.5], abs=0.05)
    assert track.fitted_position(30, 1.0) == pytest.approx([1.2, 0.5], abs=0.05)    # at the window's end
    t = np.arange(31) / 30
    plain = np.polyfit(t, [0.5] * 30 + [9.8], 1)[0]
    assert plain > 1.0                                         # what a plain fit would say across the walk
    for f in range(31, 41):
        track.add(f, None)                                     # the person out of view
    assert track.velocity(40, 0.5) is None                     # too few detections in the window


def test_ground_track_counts_frames_seen_without_a_position():
    """Frames the person was seen in but not placed (their feet unseen) count towards a window's share of
    frames, not into its fit; a window needs half that share placed."""
    from awalker_tracker.vision.detection import GroundTrack

    def track(seen: bool, placed_every: int = 2) -> GroundTrack:
        t = GroundTrack(dt=1 / 30)
        for f in range(31):
            placed = f % placed_every == 0
            t.add(f, np.array([1.2 * f / 30, 0.5]) if placed else None, seen=seen and not placed)
        return t

    assert track(seen=False).velocity(30, 1.0) is None           # 16 of 31 frames placed: under 0.8 of them
    assert track(seen=True).velocity(30, 1.0) == pytest.approx([1.2, 0.0], abs=1e-6)
    assert track(seen=True, placed_every=3).velocity(30, 1.0) is None   # 11 placed: under half of 0.8 x 30
    assert track(seen=True).fitted_position(30, 1.0, at=15) == pytest.approx([0.6, 0.5], abs=1e-6)
    old = track(seen=True)
    old.add(400, None)                                           # frames older than keep_frames are dropped
    assert not old.seen_without_position
