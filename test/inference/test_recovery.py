"""Recovery (inference/recovery.py): row replacement, re-seeding fallen walkers, the lost-track monitor."""
from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest

from awalker_tracker.inference.filter_model import StartDescription, TrackerConfig, TrackerModel, marker_likelihood
from awalker_tracker.inference.recovery import (
    HELD, NOT_RESEEDED, RESEEDED_FALLEN, LostTrackMonitor, RecoveryConfig, put_rows)
from awalker_tracker.model.body import MARKER_NAMES, BodyDescription
from awalker_tracker.model.walker import LEFT

from awalker_tracker.model.kinematics import pose_body
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.detection import person_blob

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vision"))
from test_detection import features_of  # noqa: E402
from vision_scene import BODY, PARAMS, side_camera, walking_poses  # noqa: E402
from side_view import seen  # noqa: E402,F401  (fixture)

PELVIS = MARKER_NAMES.index("pelvis")


@dataclass(frozen=True)
class _Inner:
    a: np.ndarray


@dataclass(frozen=True)
class _Outer:
    inner: _Inner
    b: np.ndarray


def test_put_rows_replaces_rows_of_nested_arrays_and_leaves_the_target_alone():
    target = _Outer(_Inner(np.zeros((4, 2))), np.arange(4))
    source = _Outer(_Inner(np.ones((2, 2))), np.array([10, 20]))
    out = put_rows(target, np.array([3, 1]), source)
    assert out.inner.a[:, 0].tolist() == [0, 1, 0, 1] and out.b.tolist() == [0, 20, 2, 10]
    assert target.inner.a.sum() == 0 and target.b.tolist() == [0, 1, 2, 3]


def _model(reseed: bool) -> TrackerModel:
    body = BodyDescription.default()
    config = TrackerConfig(dt=1 / 30, recovery=RecoveryConfig(reseed_fallen=reseed, reacquire=False))
    start = StartDescription(0, (0.5, -0.3), 0.3, 1.3, 0.7, LEFT)
    return TrackerModel(body, start, marker_likelihood(0.03), config)


@pytest.mark.parametrize("reseed", [True, False])
def test_fallen_walkers_are_caught_by_their_other_leg_where_they_fell(reseed: bool):
    model = _model(reseed)
    rng = np.random.default_rng(3)
    states = model.initial(8, rng)
    down = np.arange(8) < 3
    # a stance leg past horizontal: the walker has fallen forwards
    walker = replace(states.walker, stance_angle=np.where(down, -1.8, states.walker.stance_angle))
    states = replace(states, walker=walker)
    contact, heading = states.kin.contact_point.copy(), states.kin.heading.copy()
    stance_leg = states.walker.stance_leg.copy()
    new, events = model.transition(states, rng)
    assert np.asarray(events.fallen)[down].all() and not np.asarray(events.fallen)[~down].any()
    if not reseed:
        assert new.fallen[down].all() and (new.reseeded == NOT_RESEEDED).all()
        return
    assert not new.fallen.any()
    assert (new.reseeded[down] == RESEEDED_FALLEN).all() and (new.reseeded[~down] == NOT_RESEEDED).all()
    assert model.reseeded_fallen == 3
    # the fall's displacement is not walking speed: the re-seeded walkers walk on at the speed they had, drawn
    # within InitialSpread(speed_fraction=0.05) of it (another stream of random numbers drew 1.77 -> 2.01 m/s,
    # failing rtol 0.05); counting the fall's displacement as walking gave 2.1-2.7 times the speed
    assert np.allclose(new.speed[down], states.speed[down], rtol=0.25)
    pelvis = new.pose.markers[down, PELVIS]
    leg = model.params.leg_length
    assert (pelvis[:, 2] > 0.85 * leg).all()                    # upright again, hips at walking height
    # caught where it fell: the pelvis keeps its place over the ground (no jump recorded), far ahead of the foot
    # it fell over (stood over that foot instead, it jumped back 0.8-1.0 leg lengths)
    assert np.abs(new.jump[down, :2]).max() < 1e-6
    forward = np.column_stack([np.cos(heading[down]), np.sin(heading[down])])
    assert (np.sum((pelvis[:, :2] - contact[down]) * forward, axis=1) > 0.7 * leg).all()
    # on the leg that swung: it stands in front of the pelvis, the leg it fell over trails
    assert (new.walker.stance_leg[down] == 1 - stance_leg[down]).all()
    assert (np.sum((new.kin.contact_point[down] - pelvis[:, :2]) * forward, axis=1) > 0.1 * leg).all()
    assert np.allclose(new.kin.heading[down], heading[down], atol=0.05)
    # the others keep walking as the dynamics move them
    assert np.isfinite(new.pose.markers).all() and np.allclose(new.kin.heading[~down], heading[~down], atol=0.2)


def test_monitor_orders_reacquisition_after_the_lost_time_then_waits_the_cooldown(seen):
    camera, features, markers = seen
    config = RecoveryConfig(lost_after_s=0.09, cooldown_s=0.5)
    monitor = LostTrackMonitor([camera], config, dt=1 / 30)
    away = markers[PELVIS] + np.array([1.5, 0.0, 0.0])          # the particles walk 1.5 m beside the person
    orders = {f: monitor.update(f, [features], away) for f in range(30)}
    fired = [f for f, o in orders.items() if o is not None]
    assert fired == [2, 17]                                      # 3 frames off, then 15 frames of cooldown
    assert monitor.reacquisitions == 2
    truth = 0.5 * (markers[MARKER_NAMES.index("left_ankle"), :2] + markers[MARKER_NAMES.index("right_ankle"), :2])
    assert np.linalg.norm(orders[2].position - truth) < 0.25
    assert orders[2].heading is None and orders[17].heading is None      # a person standing still: no heading
    assert monitor.update(17, [features], away) is orders[17] and monitor.reacquisitions == 2   # re-asked: same answer


def test_a_body_gone_out_of_the_image_is_not_moved_onto_a_person_in_view(seen):
    """Particles whose pelvis has left the image are a person walking out of view (the track ends,
    inference.visibility): nobody else in view is re-acquired in their place."""
    camera, features, markers = seen
    monitor = LostTrackMonitor([camera], RecoveryConfig(lost_after_s=0.09, cooldown_s=0.5), dt=1 / 30)
    gone = markers[PELVIS] + np.array([2.5, 0.0, 0.0])
    assert not camera.in_image(gone)
    assert all(monitor.update(f, [features], gone) is None for f in range(30))
    assert monitor.reacquisitions == 0


def test_monitor_keeps_a_track_on_the_person(seen):
    camera, features, markers = seen
    monitor = LostTrackMonitor([camera], RecoveryConfig(lost_after_s=0.0), dt=1 / 30)
    assert all(monitor.update(f, [features], markers[PELVIS]) is None for f in range(10))


def test_monitor_does_not_trust_a_person_cut_by_the_image_border():
    # the camera looks 2.1 m to the side: the person straddles the left image border
    camera = Camera.look_at("edge", 320, 240, 300.0, np.array([2.5, -4.0, 1.1]), np.array([2.5, 0.0, 0.9]))
    features, _ = features_of(camera, walking_poses(3, x0=0.4), 0)
    blob = person_blob(features[-1], "edge")
    assert blob is not None and blob.box[0] <= 2 < blob.box[2]     # seen, but cut by the border
    monitor = LostTrackMonitor([camera], RecoveryConfig(lost_after_s=0.0), dt=1 / 30)
    far = np.array([5.0, 0.0, 0.9])
    assert all(monitor.update(f, [features[-1]], far) is None for f in range(5))


def test_two_cameras_catch_a_depth_error_one_camera_catches_only_a_gross_one(seen):
    """The pelvis off along the side camera's line of sight still projects onto the person there. Cameras
    at two angles place the person on the ground: 0.6 m off is lost, 0.2 m kept. One camera places the
    person by the feet row, to ~0.2 m: only a median distance over track_window_s beyond
    lost_distance_one_camera_m (0.6 m) is lost, so 1.2 m off is lost after half a second, 0.4 m never,
    and only where the blob is as tall as the body."""
    from test_detection import features_of as features_in
    from vision_scene import front_camera

    side, side_features, markers = seen
    front = front_camera()
    front_features = features_in(front, walking_poses(3, x0=0.4), 1)[0][-1]
    pelvis = markers[PELVIS]
    config = RecoveryConfig(lost_after_s=0.0)
    for offset, lost in ((0.6, True), (0.2, False)):
        behind = pelvis + np.array([0.0, offset, 0.0])        # the side camera looks along +y
        both = LostTrackMonitor([side, front], config, dt=1 / 30)
        assert (both.update(0, [side_features, front_features], behind) is not None) == lost
    # the blob stands as tall as the body (1.73 m of 1.74), so its feet row counts; for a body 1.5 times
    # as tall it does not (legs hidden, the head lost: the feet row is not the feet), nor is 1.2 m lost then
    for offset, height, lost in ((1.2, BODY.height, True), (0.4, BODY.height, False), (-0.4, BODY.height, False),
                                 (1.2, 1.5 * BODY.height, False)):
        mono = LostTrackMonitor([side], config, dt=1 / 30, body_height_m=height)
        orders = [mono.update(f, [side_features], pelvis + np.array([0.0, offset, 0.0])) for f in range(20)]
        fired = [f for f, order in enumerate(orders) if order is not None]
        half_window = mono.track.span(config.track_window_s) // 2
        assert fired[:1] == ([half_window] if lost else []), (offset, height, fired)
        assert not lost or np.linalg.norm(orders[half_window].position - pelvis[:2]) < 0.3
    with pytest.raises(ValueError, match="feet_row_height_ratio"):
        RecoveryConfig(feet_row_height_ratio=(1.1, 0.85))


def _far_and_low_view(contact_shift: tuple[float, float] = (0.0, 0.0)):
    """A camera 10 m away at 0.5 m high (one map row of the feet row spans ~1.3 m of depth), the last frame's
    features of a stance phase at x = 0.4 m with its contact point moved by ``contact_shift`` (m), and that
    frame's pelvis."""
    far = Camera.look_at("far", 320, 240, 300.0, np.array([0.3, -10.0, 0.5]), np.array([0.3, 0.0, 0.9]))
    poses = walking_poses(3, x0=0.4)
    poses[-1].kin.contact_point = poses[-1].kin.contact_point + np.asarray(contact_shift)
    features = features_of(far, poses, 2)[0][-1]
    return far, features, pose_body(BODY, PARAMS, poses[-1].walker, poses[-1].kin).markers[0, PELVIS]


@pytest.fixture(scope="module")
def far_and_low():
    return _far_and_low_view()


def test_one_camera_far_and_low_holds_the_depth_only_to_its_feet_rows_resolution(far_and_low):
    """From 10 m at 0.5 m high one map row of the feet row spans ~1.3 m of depth (a hand start is right to
    ~0.1 m): a pelvis 1.2 m off along the view, lost from 4 m, is not lost there (the median gap must pass
    ``lost_rows_one_camera`` rows as well as 0.6 m), 4 m off still is; the depth band is a row wide, not
    ``depth_band_m``. With the rows set to 0 the fixed distances hold again."""
    far, features, pelvis = far_and_low
    for rows, offset, lost in ((2.0, 1.2, False), (2.0, 4.0, True), (0.0, 1.2, True)):
        config = RecoveryConfig(lost_after_s=0.0, lost_rows_one_camera=rows, depth_band_rows=rows / 2)
        monitor = LostTrackMonitor([far], config, dt=1 / 30, body_height_m=BODY.height)
        orders = [monitor.update(f, [features], pelvis + np.array([0.0, offset, 0.0])) for f in range(20)]
        assert any(order is not None for order in orders) == lost, (rows, offset)
        band = monitor.depth_band(19)
        assert band is not None and np.linalg.norm(band[0] - pelvis[:2]) < 1.0
        assert 1.0 < band[1] < 1.8 if rows else band[1] == config.depth_band_m   # one row's depth, or 0.15 m


def test_one_camera_far_and_low_counts_a_feet_row_that_moves_by_one_map_row(far_and_low):
    """From 10 m at 0.5 m high a map row spans ~1.3 m of depth, so a person walking along the view moves the
    feet row in steps of ~1.3 m, more than ``reach_m``: within ``reach_rows`` rows of its depth such a step
    still counts (the band and the lost test keep the depth), where a fixed 0.5 m dropped every feet row
    after it for ``reach_reset_s``."""
    far, there, pelvis_there = far_and_low
    _, nearer, pelvis_nearer = _far_and_low_view((0.0, -1.0))       # 1 m nearer the camera
    frames, pelvis = (there, nearer), (pelvis_there, pelvis_nearer)
    for rows, counts in ((RecoveryConfig.reach_rows, True), (0.0, False)):
        # (reach_agree_s off: the rows' reach alone; with it the step would count once it stayed where the pelvis is)
        monitor = LostTrackMonitor([far], RecoveryConfig(reach_rows=rows, reach_agree_s=0.0), dt=1 / 30,
                                   body_height_m=BODY.height)
        for f in range(20):
            monitor.update(f, [frames[f >= 10]], pelvis[f >= 10])
        before, after = monitor.feet_row_position(9), monitor.feet_row_position(10)
        assert before is not None
        if counts:
            assert after is not None and 0.8 < np.linalg.norm(after - before) < 1.8     # one row's step
            assert all(monitor.feet_row_position(f) is not None for f in range(10, 20))
            assert monitor.depth_band(19) is not None
        else:
            assert all(monitor.feet_row_position(f) is None for f in range(10, 20))
            assert monitor.depth_band(19) is None


@pytest.mark.parametrize("agree_s, cameras", [(0.0, 1), (0.3, 1), (0.3, 2)])
def test_one_camera_far_and_low_counts_a_feet_row_that_stepped_and_stayed_where_the_particles_are(far_and_low,
                                                                                                 agree_s: float,
                                                                                                 cameras: int):
    """A feet row that steps 3 m nearer (beyond ``reach_rows`` rows) and stays there counts, with
    ``reach_agree_s``, once it has stayed that long and lies where the particles are (a far, low camera's feet row
    that stepped a row or two after the counted ones went off); not where the particles are not (legs hidden behind
    something put the row away from a body on the person), nor, without ``reach_agree_s``, before
    ``reach_reset_s``. ``reach_agree_s`` is one camera's: in a rig of two whose second camera does not see the
    person (its frames fall back on the first camera's feet row) the row is left out as without the option."""
    far, there, pelvis_there = far_and_low
    _, nearer, pelvis_nearer = _far_and_low_view((0.0, -3.0))
    away = Camera.look_at("away", 320, 240, 300.0, np.array([0.3, 10.0, 0.5]), np.array([0.3, 20.0, 0.9]))
    empty = features_of(away, walking_poses(3, x0=0.4), 2)[0][-1]
    rig = [far, away][:cameras]
    span = round(agree_s * 30)
    for particles_follow in (True, False):
        monitor = LostTrackMonitor(rig, RecoveryConfig(reach_agree_s=agree_s), dt=1 / 30,
                                   body_height_m=BODY.height)
        for f in range(30):
            monitor.update(f, [nearer if f >= 10 else there, empty][:cameras],
                           pelvis_nearer if f >= 10 and particles_follow else pelvis_there)
        assert all(monitor.feet_row_position(f) is not None for f in range(10))
        counted = [f for f in range(10, 30) if monitor.feet_row_position(f) is not None]
        if agree_s and particles_follow and cameras == 1:
            assert counted and counted[0] == 10 + span - 1
            row = monitor.feet_row_position(counted[0])     # the new feet row (a row spans ~1.3 m there)
            assert np.linalg.norm(row - pelvis_nearer[:2]) < np.linalg.norm(row - pelvis_there[:2]) - 0.5
        else:
            assert counted == []
    with pytest.raises(ValueError, match="must be >= 0"):
        RecoveryConfig(reach_agree_s=-0.1)


def test_a_second_larger_person_does_not_count_as_losing_the_first():
    """Two people in view: the one followed stands at x = 0.4 m; another, nearer the camera (larger),
    at x = -0.5 m. The track on the first is not lost; a track on neither is."""
    from awalker_tracker.vision.detection import person_blobs
    from awalker_tracker.vision.features import FeatureExtractor
    from awalker_tools.model_render import render_rgb
    from awalker_tracker.vision.render import render
    from test_detection import CONFIG
    from vision_scene import background_image, noisy

    camera = side_camera()
    followed = walking_poses(3, x0=0.4)[-1]
    other = walking_poses(3, x0=-0.5)[-1]
    other.kin.contact_point = other.kin.contact_point + np.array([0.0, -0.8])   # 0.8 m nearer the camera
    background = background_image(camera, seed=0)
    image = render_rgb(BODY, followed.segments(), camera, background, result=render(BODY, followed.segments(), camera))
    image = render_rgb(BODY, other.segments(), camera, image, result=render(BODY, other.segments(), camera))
    rng = np.random.default_rng(3)
    extractor = FeatureExtractor(CONFIG)
    for _ in range(CONFIG.background_frames):
        extractor.process(noisy(background, rng))
    extractor.process(noisy(image, rng))                 # learns the foreground
    features = extractor.process(noisy(image, rng))
    blobs = person_blobs(features, camera.name)
    assert len(blobs) == 2 and blobs[0].area_px > blobs[1].area_px         # the other person is the larger
    pelvis = pose_body(BODY, PARAMS, followed.walker, followed.kin).markers[0, PELVIS]
    monitor = LostTrackMonitor([camera], RecoveryConfig(lost_after_s=0.0), dt=1 / 30)
    assert all(monitor.update(f, [features], pelvis) is None for f in range(5))
    lost = LostTrackMonitor([camera], RecoveryConfig(lost_after_s=0.0), dt=1 / 30)
    assert lost.update(0, [features], pelvis + np.array([1.5, 0.0, 0.0])) is not None


@pytest.fixture(scope="module")
def walk_stop_walk():
    """The side camera's features of a person walking at 1.3 m/s for 20 frames, standing for 25, walking on for 20."""
    camera = side_camera()
    x = np.concatenate([0.4 + 1.3 / 30 * np.arange(20), np.full(25, 0.4 + 1.3 / 30 * 19),
                        0.4 + 1.3 / 30 * np.arange(20, 40)]) - 0.6
    poses = [walking_poses(1, x0=float(x0))[0] for x0 in x]
    features, _ = features_of(camera, poses, 0)
    pelvis = np.array([pose_body(BODY, PARAMS, p.walker, p.kin).markers[0, PELVIS] for p in poses])
    return camera, features, pelvis


@pytest.mark.parametrize("hold", [True, False])
def test_monitor_says_when_the_person_stands_still_and_when_they_walk_on(walk_stop_walk, hold: bool):
    camera, features, pelvis = walk_stop_walk
    monitor = LostTrackMonitor([camera], RecoveryConfig(hold_still=hold), dt=1 / 30)
    still = []
    for f, (feats, p) in enumerate(zip(features, pelvis)):
        assert monitor.update(f, [feats], p) is None           # the track is on the person throughout
        still.append(monitor.still(f))
    if not hold:
        assert not any(still)
        return
    frames = np.flatnonzero(still)
    assert frames.size and np.all(np.diff(frames) == 1)       # one stop
    assert 20 <= frames[0] <= 20 + 10                          # noticed within a third of a second of stopping
    assert 45 <= frames[-1] + 1 <= 45 + 5                     # and the walk on within a sixth


@pytest.mark.parametrize("drift", [0.0, 0.03])
def test_the_walkers_are_held_while_the_person_stands_still(walk_stop_walk, drift: float):
    """Held walkers keep their pose about the pelvis and turn there; with ``held_drift`` they also shift over the
    ground, smoothly and no faster than a person standing still, and without it they stay where they stand."""
    from awalker_tracker.inference.filter_model import ImageObservation, image_likelihood

    camera, features, pelvis = walk_stop_walk
    body = BodyDescription.default()
    recovery = RecoveryConfig(reacquire=False)
    config = TrackerConfig(dt=1 / 30, recovery=recovery, held_drift=(0.95, drift))
    start = StartDescription(0, (float(pelvis[0, 0]), float(pelvis[0, 1])), 0.0, 1.3, 0.7, LEFT)
    model = TrackerModel(body, start, image_likelihood(body, [camera]), config, cameras=[camera])
    rng = np.random.default_rng(0)
    states = model.initial(16, rng)
    weights = np.zeros(16)
    held, turned, shifted, accelerations = [], [], [], []
    for f, feats in enumerate(features):
        parent = states
        moved, _ = model.transition(parent, rng)
        states = model.rejuvenate(f, weights, parent, moved, ImageObservation(features=(feats,)), rng)
        if model.monitor.still(f):
            # held where they stand: the body only turns about its pelvis and shifts with it (the same pose otherwise)
            step = states.pose.markers[:, PELVIS, :2] - parent.pose.markers[:, PELVIS, :2]
            assert np.all(np.linalg.norm(step, axis=1) <= recovery.still_m_s * config.dt + 1e-12)
            np.testing.assert_allclose(step, states.held_velocity * config.dt, atol=1e-9)
            if held:
                accelerations.append(np.linalg.norm(states.held_velocity - parent.held_velocity, axis=1))
            around = np.linalg.norm(states.pose.markers[..., :2] - states.pose.markers[:, PELVIS, None, :2], axis=2)
            before = np.linalg.norm(parent.pose.markers[..., :2] - parent.pose.markers[:, PELVIS, None, :2], axis=2)
            np.testing.assert_allclose(around, before, atol=1e-9)
            np.testing.assert_allclose(states.pose.markers[..., 2], parent.pose.markers[..., 2], atol=1e-9)
            assert (states.speed == 0).all() and (states.reseeded == HELD).all()
            assert not model.outputs(states, _).heel_strike.any()
            assert model.monitor.placed_position(f) is None       # one camera places no one: held_follow has no aim
            held.append(f)
            turned.append(np.angle(np.exp(1j * (states.kin.heading - parent.kin.heading))))
            shifted.append(step)
        else:
            assert states is moved
            assert not states.held_velocity.any()              # walking: no shuffle carried into the next stop
    assert 15 <= len(held) <= 30
    # free to turn round on the spot: over the stop the walkers' headings spread by tens of degrees
    spread = np.degrees(np.std(np.sum(turned, axis=0)))
    assert 20 < spread < 180, spread
    distance = np.linalg.norm(np.sum(shifted, axis=0), axis=1)
    if drift == 0:
        assert np.all(distance < 1e-9)
        return
    # over the ~0.8 s stop the walkers shuffle centimetres apart, each along a smooth path: the velocity changes
    # by about sigma a frame (not a random walk of positions, whose MAP path would jitter)
    assert 0.01 < np.median(distance) < recovery.still_m_s * len(held) * config.dt, distance
    assert np.median(np.concatenate(accelerations)) < 2 * drift * np.sqrt(2)


def _tracked(walk_stop_walk, config: TrackerConfig, n: int) -> list[tuple[bool, object, np.ndarray]]:
    """Each frame of ``walk_stop_walk`` tracked by ``n`` particles under ``config`` (seed 0, flat weights, the person
    started where they are at 1.3 m/s on the left leg): whether the person stood still, the particles after the
    frame's recovery, and the markers the outputs show."""
    from awalker_tracker.inference.filter_model import ImageObservation, image_likelihood

    camera, features, pelvis = walk_stop_walk
    body = BodyDescription.default()
    start = StartDescription(0, (float(pelvis[0, 0]), float(pelvis[0, 1])), 0.0, 1.3, 0.7, LEFT)
    model = TrackerModel(body, start, image_likelihood(body, [camera]), config, cameras=[camera])
    rng = np.random.default_rng(0)
    states = model.initial(n, rng)
    frames = []
    for f, feats in enumerate(features):
        moved, events = model.transition(states, rng)
        states = model.rejuvenate(f, np.zeros(n), states, moved, ImageObservation(features=(feats,)), rng)
        frames.append((model.monitor.still(f), states, model.outputs(states, events).markers))
    return frames


def test_held_bodies_are_shown_standing_and_tracked_as_before(walk_stop_walk):
    """``TrackerConfig.held_settle_s``: while the person stands still the bodies the outputs show come dt /
    held_settle_s a frame nearer standing, their feet side by side once there and their pelvis over the ground where
    the walkers' is; once the person walks on they return to the walkers' own poses at the same rate. The particles
    (what the likelihood scores) are those of the tracker without it, bit for bit."""
    ankles = [MARKER_NAMES.index("left_ankle"), MARKER_NAMES.index("right_ankle")]
    runs = {settle: _tracked(walk_stop_walk, TrackerConfig(dt=1 / 30, recovery=RecoveryConfig(reacquire=False),
                                                          held_settle_s=settle), 16)
            for settle in (0.0, 0.3)}
    still = np.array([f[0] for f in runs[0.3]])
    held = np.flatnonzero(still)
    # standing reached within the stop, and the walk after it long enough to be shown as the walkers' own again
    assert held.size > 0.3 * 30 and held[-1] + 1 + 0.3 * 30 < len(still) and np.all(np.diff(held) == 1)
    step = (1 / 30) / 0.3
    standing = 0.0
    for f, ((_, own, own_shown), (_, particles, shown)) in enumerate(zip(runs[0.0], runs[0.3])):
        standing = float(np.clip(standing + (step if still[f] else -step), 0.0, 1.0))
        np.testing.assert_allclose(particles.standing, standing)
        np.testing.assert_array_equal(particles.pose.markers, own.pose.markers)
        np.testing.assert_array_equal(particles.walker.stance_angle, own.walker.stance_angle)
        np.testing.assert_array_equal(own_shown, own.pose.markers)
        np.testing.assert_allclose(shown[:, PELVIS, :2], own.pose.markers[:, PELVIS, :2], atol=1e-9)
        if standing == 0.0:
            np.testing.assert_allclose(shown, own.pose.markers, atol=1e-9)
        if standing == 1.0:
            along = np.stack([np.cos(own.kin.heading), np.sin(own.kin.heading)], axis=1)
            apart = np.abs(np.sum((shown[:, ankles[0], :2] - shown[:, ankles[1], :2]) * along, axis=1))
            assert np.all(apart < 0.03)
            own_apart = np.abs(np.sum((own.pose.markers[:, ankles[0], :2] - own.pose.markers[:, ankles[1], :2])
                                      * along, axis=1))
            assert np.median(own_apart) > 0.1                  # the walkers held mid-stride


@pytest.mark.parametrize("follow_s", [0.0, 0.3])
def test_held_walkers_follow_where_two_cameras_place_the_person(seen, follow_s: float):
    """A person standing where cameras at two angles place them, the walkers held 0.25 m off (they walked on past
    the stop): with ``held_follow_s`` every held walker takes the same ground step towards that place, no longer
    than ``held_follow_m_s`` a frame's time, until the weighted mean pelvis stands within ``held_follow_within_m``
    of it; without, they stay where the hold began."""
    from test_detection import features_of as features_in
    from vision_scene import front_camera

    from awalker_tracker.inference.filter_model import ImageObservation, image_likelihood

    side, side_features, markers = seen
    front = front_camera()
    front_features = features_in(front, walking_poses(3, x0=0.4), 1)[0][-1]
    observation = ImageObservation(features=(side_features, front_features))
    person = markers[PELVIS, :2]
    config = TrackerConfig(dt=1 / 30, recovery=RecoveryConfig(reacquire=False), held_turn=(0.95, 0.0),
                           held_follow_s=follow_s)
    off = person + np.array([0.25, 0.0])            # ahead along the walk: 0.25 m past where the person stopped
    start = StartDescription(0, (float(off[0]), float(off[1])), 0.0, 1.0, 0.6, LEFT)
    model = TrackerModel(BODY, start, image_likelihood(BODY, [side, front]), config, cameras=[side, front])
    for f in range(10):                             # the person has stood there for a third of a second
        model.monitor.update(f, list(observation.features), markers[PELVIS])
    rng = np.random.default_rng(0)
    states = model.initial(16, rng)
    weights = np.full(16, 1 / 16)
    for f in range(10, 55):
        parent = states
        moved, _ = model.transition(parent, rng)
        states = model.rejuvenate(f, np.log(weights), parent, moved, observation, rng)
        assert model.monitor.still(f) and model.monitor.placed_position(f) is not None     # held; triangulated
        step = states.pose.markers[:, PELVIS, :2] - parent.pose.markers[:, PELVIS, :2]
        np.testing.assert_allclose(step, np.broadcast_to(step[0], step.shape), atol=1e-9)   # one step for all
        assert np.linalg.norm(step[0]) <= config.held_follow_m_s * config.dt + 1e-12
    gap = np.linalg.norm(weights @ states.pose.markers[:, PELVIS, :2] - person)
    if follow_s == 0:
        assert gap > 0.15, gap
    else:        # within held_follow_within_m of it: the place is good to ~0.1 m, a hand start to 0.05
        assert config.held_follow_within_m - 0.01 < gap < config.held_follow_within_m + 0.03, gap


@pytest.mark.parametrize("held", [{"held_turn": (1.5, 0.3)}, {"held_turn": (0.9, -0.1)},
                                  {"held_drift": (-0.1, 0.03)}, {"held_drift": (0.95, float("nan"))},
                                  {"held_follow_s": -0.1}, {"held_follow_m_s": float("nan")},
                                  {"held_follow_within_m": -0.2}, {"held_settle_s": -0.3},
                                  {"held_settle_s": float("nan")}, {"held_settle_s": float("inf")},
                                  {"walk_on_mirror_fraction": 1.5}, {"walk_on_mirror_fraction": float("nan")},
                                  {"walk_on_min_hold_s": -0.5}, {"walk_on_after_walked_s": float("inf")}])
def test_held_walkers_refuse_a_persistence_outside_0_1_or_a_negative_or_nan_noise(held: dict):
    with pytest.raises(ValueError, match=next(iter(held))):
        TrackerConfig(**held)


@pytest.mark.parametrize("min_hold_s", [0.5, 5.0])
def test_walkers_walk_on_with_either_foot_after_a_hold(walk_stop_walk, min_hold_s: float):
    """``TrackerConfig.walk_on_mirror_fraction``: at the first frame after a hold of ``walk_on_min_hold_s`` or longer,
    that share of the walkers walk on with their legs named the other way round (each body its own mirror image about
    its pelvis: the other foot steps), as a new stride, not a renaming; up to then the run is the run without it, bit
    for bit, and after a shorter hold nothing changes."""
    n = 64
    runs = {fraction: _tracked(walk_stop_walk, TrackerConfig(
                dt=1 / 30, recovery=RecoveryConfig(reacquire=False), walk_on_mirror_fraction=fraction,
                walk_on_min_hold_s=min_hold_s, walk_on_after_walked_s=0.5), n)
            for fraction in (0.0, 0.5)}
    still = np.array([frame[0] for frame in runs[0.5]])
    held = np.flatnonzero(still)
    walk_on = held[-1] + 1
    assert held.size > 0.5 * 30 and np.all(np.diff(held) == 1) and held[0] >= 0.5 * 30 and walk_on < len(still)
    for f in range(walk_on):
        np.testing.assert_array_equal(runs[0.5][f][1].pose.markers, runs[0.0][f][1].pose.markers)
    own, mixed = runs[0.0][walk_on][1], runs[0.5][walk_on][1]
    other = mixed.walker.stance_leg != own.walker.stance_leg
    if min_hold_s * 30 > held.size:
        assert not other.any()
        np.testing.assert_array_equal(mixed.pose.markers, own.pose.markers)
        return
    assert 0.25 < other.mean() < 0.75, other.mean()
    np.testing.assert_array_equal(mixed.pose.markers[~other], own.pose.markers[~other])
    np.testing.assert_allclose(mixed.pose.markers[:, PELVIS], own.pose.markers[:, PELVIS], atol=1e-9)
    # mirrored about the sagittal plane: each joint stands as high as its other side's did, and the feet swap sides
    left, right = (np.array([MARKER_NAMES.index(f"{side}_{j}") for j in ("hip", "knee", "ankle", "heel", "toe")])
                   for side in ("left", "right"))
    np.testing.assert_allclose(mixed.pose.markers[other][:, left, 2], own.pose.markers[other][:, right, 2], atol=1e-9)
    np.testing.assert_allclose(mixed.pose.markers[other][:, right, 2], own.pose.markers[other][:, left, 2], atol=1e-9)
    assert np.array_equal(mixed.continues, np.arange(n)) and not mixed.flipped.any()     # no renaming of the past


@pytest.mark.parametrize("target", ["seen_gait", "usual_gait"])
def test_eq5_aims_at_the_speed_the_images_move_not_the_walkers(walk_stop_walk, target: str):
    """stiffness_target "seen_gait": eq. (5)'s target speed is the speed of the images' ground track over
    ``seen_speed_window_s`` (1.3 m/s walking, ~0 standing), whatever the walkers do (started at 0.7 m/s, their
    speed would pull them towards their own gait); "usual_gait": the walkers' (posterior's) speed."""
    from awalker_tracker.inference.filter_model import ImageObservation, image_likelihood

    camera, features, pelvis = walk_stop_walk
    body = BodyDescription.default()
    config = TrackerConfig(dt=1 / 30, recovery=RecoveryConfig(reacquire=False), stiffness_target=target,
                           seen_speed_window_s=0.5)
    start = StartDescription(0, (float(pelvis[0, 0]), float(pelvis[0, 1])), 0.0, 0.7, 0.5, LEFT)
    model = TrackerModel(body, start, image_likelihood(body, [camera]), config, cameras=[camera])
    rng = np.random.default_rng(0)
    states = model.initial(16, rng)
    targets, walkers = [], []
    for f, feats in enumerate(features):
        parent = states
        moved, _ = model.transition(parent, rng)
        states = model.rejuvenate(f, np.zeros(16), parent, moved, ImageObservation(features=(feats,)), rng)
        targets.append(model.target_speed)
        walkers.append(float(np.mean(moved.speed)))
    if target == "usual_gait":
        np.testing.assert_allclose(targets, walkers)
        return
    assert abs(targets[19] - 1.3) < 0.15 and targets[40] < 0.15        # walking, then standing (frames 20-44)
    assert abs(walkers[19] - 1.3) > 0.3                                 # the walkers' own speed is elsewhere
    assert model.prior.stiffness_target == "usual_gait"
    # two cameras see the ground track too; no detections to see (recovery off): eq. (5)'s constant
    for cameras, recovery, used in (([camera, camera], RecoveryConfig(), "seen_gait"),
                                    ([camera], RecoveryConfig(reacquire=False, hold_still=False), "constant")):
        other = TrackerModel(body, start, image_likelihood(body, cameras), replace(config, recovery=recovery),
                             cameras=cameras)
        assert other.stiffness_target == used
        assert other.prior.stiffness_target == ("constant" if used == "constant" else "usual_gait")
        # the stride's stiffness tilt: with two cameras, not with one
        assert other.prior.stiffness_tilt_variance == (config.stiffness_tilt_variance if len(cameras) > 1 else 0.0)
    assert config.stiffness_tilt_variance > 0 and model.prior.stiffness_tilt_variance == 0.0
    with pytest.raises(ValueError, match="stiffness_tilt_variance must be >= 0"):
        TrackerConfig(stiffness_tilt_variance=-0.1)
    with pytest.raises(ValueError, match="stiffness_target must be one of .*'seen_gait'.*got 'seen'"):
        TrackerConfig(stiffness_target="seen")
    with pytest.raises(ValueError, match="seen_speed_window_s must be > 0 s"):
        TrackerConfig(seen_speed_window_s=0.0)


def test_one_camera_places_the_person_by_the_feet_row_only_where_the_blob_is_as_tall_as_the_body(seen):
    """``feet_row_position``: one camera, a blob as tall as the body: the person's ground position (within
    the feet row's ~0.2 m); a body 1.5 times as tall (the blob lost the legs or the head): none; two cameras
    triangulate instead: none."""
    from test_detection import features_of as features_in
    from vision_scene import front_camera

    camera, features, markers = seen
    pelvis = markers[PELVIS]
    mono = LostTrackMonitor([camera], RecoveryConfig(), dt=1 / 30, body_height_m=BODY.height)
    mono.update(0, [features], pelvis)
    assert np.linalg.norm(mono.feet_row_position(0) - pelvis[:2]) < 0.25
    assert mono.feet_row_position(1) is None                      # a frame not seen yet
    tall = LostTrackMonitor([camera], RecoveryConfig(), dt=1 / 30, body_height_m=1.5 * BODY.height)
    tall.update(0, [features], pelvis)
    assert tall.feet_row_position(0) is None
    front = front_camera()
    front_features = features_in(front, walking_poses(3, x0=0.4), 1)[0][-1]
    both = LostTrackMonitor([camera, front], RecoveryConfig(), dt=1 / 30, body_height_m=BODY.height)
    both.update(0, [features, front_features], pelvis)
    assert both.feet_row_position(0) is None


def _legs_hidden(camera, features, behind_m: float, ground_point_xy: np.ndarray, masked: bool = False):
    """``features`` with every map row below the one where the ground ``behind_m`` beyond ``ground_point_xy``
    (along the camera's view, +y) projects set to background (``masked``: under the camera's occlusion mask,
    ratio 0, as the features node gives them): the blob's lowest row is then that row, as when a box hides
    the legs and its top edge cuts the blob there."""
    uv, _ = camera.project(np.array([[ground_point_xy[0], ground_point_xy[1] + behind_m, 0.0]]))
    cut = int(np.ceil(uv[0, 1] / features.downsample))
    llr = features.llr.copy()
    llr[:, cut:, :] = 0.0 if masked else -20.0
    if not masked:
        return replace(features, llr=llr)
    occlusion = np.zeros(features.map_shape, bool)
    occlusion[cut:, :] = True
    return replace(features, llr=llr, occlusion=occlusion)


@pytest.mark.parametrize("reach", [True, False])
def test_one_camera_does_not_count_a_feet_row_that_jumps_away(seen, reach: bool):
    """Legs hidden for frames 15-29 put the blob's lowest row 0.9 m behind the person, where the head's row
    still makes the blob 1.08 times as tall as the body (the camera stands 1.1 m high, near the
    head), so only the reach test keeps those rows out: with it, none counts and the track on the person
    is not lost; with the reach unlimited, they count and the monitor re-acquires the track 0.9 m off the
    person. The legs back in view, the feet row counts again; a monitor that has counted nothing within
    ``reach_reset_s`` counts the hidden-legs row (it cannot know better), unless what hides them lies under
    the camera's occlusion mask."""
    camera, features, markers = seen
    pelvis = markers[PELVIS]
    hidden = _legs_hidden(camera, features, 0.8, pelvis[:2])
    config = RecoveryConfig(lost_after_s=0.0) if reach else RecoveryConfig(lost_after_s=0.0, reach_m=1e3)
    monitor = LostTrackMonitor([camera], config, dt=1 / 30, body_height_m=BODY.height)
    orders = [monitor.update(f, [hidden if 15 <= f < 30 else features], pelvis) for f in range(40)]
    fired = [f for f, order in enumerate(orders) if order is not None]
    hidden_rows = [monitor.feet_row_position(f) for f in range(15, 30)]
    assert all(np.linalg.norm(monitor.feet_row_position(f) - pelvis[:2]) < 0.25 for f in (*range(15), *range(30, 40)))
    if reach:
        assert fired == [] and all(row is None for row in hidden_rows)
    else:
        assert all(row is not None and 0.7 < row[1] - pelvis[1] < 1.3 for row in hidden_rows)
        assert fired and 15 < fired[0] < 30 and orders[fired[0]].position[1] - pelvis[1] > 0.7
    fresh = LostTrackMonitor([camera], config, dt=1 / 30, body_height_m=BODY.height)
    fresh.update(0, [hidden], pelvis)
    assert fresh.feet_row_position(0) is not None
    # the same legs hidden by something under the camera's occlusion mask: that row does not count, ever
    behind_mask = _legs_hidden(camera, features, 0.8, pelvis[:2], masked=True)
    fresh = LostTrackMonitor([camera], config, dt=1 / 30, body_height_m=BODY.height)
    fresh.update(0, [behind_mask], pelvis)
    assert fresh.feet_row_position(0) is None
    # ratios of 0 alone are not a mask (a pixel unlike both appearance models reads 0 too): without the
    # camera's occlusion map the same row counts
    fresh = LostTrackMonitor([camera], config, dt=1 / 30, body_height_m=BODY.height)
    fresh.update(0, [replace(behind_mask, occlusion=None)], pelvis)
    assert fresh.feet_row_position(0) is not None
    with pytest.raises(ValueError, match="must be >= 0"):
        RecoveryConfig(reach_m=-0.1)


@pytest.mark.parametrize("band", [0.3, 0.0])
def test_walkers_straying_in_depth_beyond_the_band_lose_weight(seen, band: float):
    """One camera: walkers whose pelvis lies within ``depth_band_m`` of the feet-row position over the ground
    keep the image's log-likelihood; beyond it they lose 0.5 (excess / sigma)^2 nats, levelling off at
    ~-log(depth_band_outlier) (a feet row metres from every walker changes no weights). Not over the first
    ``depth_band_delay_s`` (0.5 s: 15 frames) of the track. Band 0 (off): no term."""
    from awalker_tracker.inference.filter_model import ImageObservation

    camera, features, markers = seen
    pelvis = markers[PELVIS]
    recovery = RecoveryConfig(depth_band_m=band, depth_band_sigma_m=0.1, depth_band_outlier=0.05)
    config = TrackerConfig(dt=1 / 30, recovery=recovery)
    start = StartDescription(0, (float(pelvis[0]), float(pelvis[1])), 0.0, 1.3, 0.7, LEFT)
    flat = lambda prev, states, obs: np.full(len(states), -7.0)    # noqa: E731  the images rate all alike
    model = TrackerModel(BODY, start, flat, config, cameras=[camera])    # the drawn body: its blob counts
    rng = np.random.default_rng(0)
    states = model.initial(5, rng)
    offsets = np.array([0.0, 0.2, 0.5, 0.8, -0.8])                 # along the camera's view (+y), m
    moved_markers = states.pose.markers.copy()
    moved_markers[:, :, :2] += pelvis[:2] - states.pose.markers[:, PELVIS, None, :2]
    moved_markers[:, :, 1] += offsets[:, None]
    states = replace(states, pose=replace(states.pose, markers=moved_markers))
    base = config.likelihood_scale * -7.0                          # the images' tempered log-likelihood
    first = model.rejuvenate(0, np.zeros(5), None, states, ImageObservation(features=(features,)), rng)
    assert model.monitor.feet_row_position(0) is not None          # the feet row counts, but the start holds
    np.testing.assert_allclose(model.log_likelihood(None, first, ImageObservation(features=(features,))), base)
    for frame in range(1, 14):
        model.monitor.update(frame, [features], pelvis)
    for frame in (14, 15):
        states = model.rejuvenate(frame, np.array([0.0, -50, -50, -50, -50]), None, states,
                                  ImageObservation(features=(features,)), rng)
        loglik = model.log_likelihood(None, states, ImageObservation(features=(features,)))
        if frame == 14:                                             # 0.47 s after the first frame
            np.testing.assert_allclose(loglik, base)
    gap = np.linalg.norm(moved_markers[:, PELVIS, :2] - model.monitor.feet_row_position(15), axis=1)
    squared = 0.5 * (np.maximum(gap - band, 0.0) / 0.1) ** 2
    levelled = np.log1p(0.05) - np.logaddexp(-squared, np.log(0.05))
    np.testing.assert_allclose(loglik, base - (levelled if band > 0 else 0.0))
    if band > 0:
        assert np.all(levelled <= squared + 1e-12) and base - loglik.min() < -np.log(0.05) + 0.06
        inside = gap <= band
        assert inside[0] and np.all(loglik[inside] == base)
        assert loglik[3] < loglik[2] < base and loglik[4] < base    # 0.5 and 0.8 m off: beyond the band
    with pytest.raises(ValueError, match="depth_band_sigma_m"):
        RecoveryConfig(depth_band_sigma_m=0.0)


def _feet_rows_along(path: np.ndarray, recovery: RecoveryConfig = RecoveryConfig(),
                     row_depth_m: float = 0.0) -> LostTrackMonitor:
    """A one-camera monitor whose counted feet rows (the ground positions its detections gave, one a frame at 30 Hz,
    each map row spanning ``row_depth_m`` of depth) lie along ``path`` (F, 2) m."""
    monitor = LostTrackMonitor([], recovery, dt=1 / 30)
    for frame, position in enumerate(path):
        monitor._feet_rows.add(frame, position)
        monitor._row_depths[frame] = row_depth_m
    return monitor


def test_heading_band_points_where_the_feet_rows_move_straight():
    """One camera: the heading band points where the counted feet rows moved over ``heading_band_window_s`` (1 s),
    its free half width ``heading_band_rad`` widened by the angle to the window's last half and by the angle a map
    row's depth subtends over the distance moved; none where the track turns by more than
    ``heading_band_turning_rad`` over the window, moves slower than ``moving_m_s``, the person stands still, this
    frame's feet row does not count, or the band is off (``heading_band_rad`` 0, the default)."""
    on = RecoveryConfig(heading_band_rad=0.6)
    rng = np.random.default_rng(4)
    t = np.arange(40) / 30
    direction = 2.5                                            # rad: walking up and to the left
    straight = t[:, None] * np.array([np.cos(direction), np.sin(direction)]) + 0.02 * rng.standard_normal((40, 2))
    band = _feet_rows_along(straight, on).heading_band(39)
    assert band is not None and abs(band[0] - direction) < 0.05
    assert on.heading_band_rad <= band[1] < on.heading_band_rad + 0.1
    # map rows 1 m deep over a 1 m walk: the direction is uncertain by ~45 degrees more
    far = _feet_rows_along(straight, on, row_depth_m=1.0).heading_band(39)
    assert far is not None and far[0] == band[0] and 0.7 < far[1] - band[1] < 0.85
    turning = 0.5 * np.column_stack([np.cos(2.0 * t), np.sin(2.0 * t)])   # 1 m/s round a 0.5 m circle: 2 rad/s
    assert _feet_rows_along(turning, on).heading_band(39) is None
    assert _feet_rows_along(turning, replace(on, heading_band_turning_rad=1.0)).heading_band(39) is not None
    assert _feet_rows_along(0.2 * straight, on).heading_band(39) is None      # 0.2 m/s, under moving_m_s
    assert _feet_rows_along(straight).heading_band(39) is None                # off: the default
    unseen = _feet_rows_along(straight, on)
    unseen._feet_rows.add(40, None)                           # this frame's feet row does not count
    assert unseen.heading_band(40) is None and unseen.heading_band(39) is not None
    still = _feet_rows_along(straight, on)
    still._still[39] = True
    assert still.heading_band(39) is None
    with pytest.raises(ValueError, match="heading_band_sigma_rad"):
        RecoveryConfig(heading_band_sigma_rad=0.0)
    with pytest.raises(ValueError, match="heading_band_window_s must be > 0"):
        RecoveryConfig(heading_band_window_s=0.0)
    with pytest.raises(ValueError, match="must be >= 0"):
        RecoveryConfig(heading_band_rad=-0.1)


class _BandMonitor:
    """A lost-track monitor that orders nothing and gives a heading band (rad) at every frame."""

    def __init__(self, band: tuple[float, float] | None) -> None:
        from awalker_tracker.vision.detection import GroundTrack

        self.band, self.track = band, GroundTrack(1 / 30)

    def update(self, frame, features, pelvis):
        return None

    def depth_band(self, frame):
        return None

    def heading_band(self, frame):
        return self.band

    def still(self, frame):
        return False


@pytest.mark.parametrize("band", [(0.3, 0.35), None])
def test_walkers_heading_beyond_the_heading_band_lose_weight(seen, band):
    """Walkers heading within the band's half width of its direction keep the image's log-likelihood; beyond it
    they lose 0.5 (excess / heading_band_sigma_rad)^2 nats, levelling off at ~-log(depth_band_outlier), the
    angle taken round the circle (a walker facing the other way loses the most). No band: no term."""
    from awalker_tracker.inference.filter_model import ImageObservation

    camera, features, markers = seen
    config = TrackerConfig(dt=1 / 30, recovery=RecoveryConfig(heading_band_sigma_rad=0.2, depth_band_outlier=0.05))
    start = StartDescription(0, (float(markers[PELVIS, 0]), float(markers[PELVIS, 1])), 0.0, 1.3, 0.7, LEFT)
    flat = lambda prev, states, obs: np.full(len(states), -7.0)    # noqa: E731  the images rate all alike
    model = TrackerModel(BODY, start, flat, config, cameras=[camera])
    model.monitor = _BandMonitor(band)
    rng = np.random.default_rng(0)
    headings = np.array([0.3, 0.0, 0.6, 1.2, -0.6, 0.3 + np.pi, 0.3 - 2 * np.pi + 0.5])
    states = model.initial(headings.size, rng)
    states = replace(states, kin=replace(states.kin, heading=headings))
    obs = ImageObservation(features=(features,))
    states = model.rejuvenate(20, np.zeros(headings.size), states, states, obs, rng)
    loglik = model.log_likelihood(None, states, obs)
    base = config.likelihood_scale * -7.0
    if band is None:
        np.testing.assert_allclose(loglik, base)
        return
    excess = np.array([0.0, 0.0, 0.0, 0.55, 0.55, np.pi - 0.35, 0.15])
    squared = 0.5 * (excess / 0.2) ** 2
    np.testing.assert_allclose(loglik, base - (np.log1p(0.05) - np.logaddexp(-squared, np.log(0.05))), atol=1e-9)
    assert np.all(loglik[:3] == base) and loglik[5] < loglik[3] < loglik[6] < base
    assert base - loglik.min() < -np.log(0.05) + 0.06

