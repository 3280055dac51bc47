"""Automatic start (inference/autostart.py): the walking person found in rendered frames."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from awalker_tools.cli import main
from awalker_tracker.inference.autostart import AutoStartConfig, StartFinder
from awalker_tracker.model.kinematics import pose_body
from awalker_tracker.vision.features import FeatureExtractor

from conftest import MOCAP_07  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vision"))
from test_detection import CONFIG  # noqa: E402
from vision_scene import BODY, PARAMS, background_image, noisy, render_frames, side_camera, walking_poses  # noqa: E402

DT = 1 / 30
SPEED, HEADING = 1.2, 0.0   # the side camera looks along +y; the person walks along +x


def walking(frames: int, x0: float) -> list:
    """Poses moving along +x at SPEED: a repeated leg swing carried forward."""
    swing = walking_poses(6, x0=x0)
    poses = []
    for f in range(frames):
        pose = swing[f % 6]
        kin = pose.kin.copy()
        kin.contact_point = kin.contact_point + np.array([SPEED * f * DT, 0.0])
        poses.append(type(pose)(pose.walker, kin))
    return poses


def side_scene():
    """The side camera, its background image, a noise generator and a features extractor that has learned
    that background."""
    camera = side_camera()
    background = background_image(camera, seed=0)
    rng = np.random.default_rng(5)
    extractor = FeatureExtractor(CONFIG)
    for _ in range(CONFIG.background_frames):
        extractor.process(noisy(background, rng))
    return camera, background, rng, extractor


@pytest.fixture(scope="module")
def frames():
    """Features of 4 empty frames, then 30 of a person walking from x = -0.8 m."""
    camera, background, rng, extractor = side_scene()
    empty = [extractor.process(noisy(background, rng)) for _ in range(4)]
    poses = walking(30, x0=-0.8)
    images, _ = render_frames(camera, poses, background, seed=2)
    return camera, empty + [extractor.process(image) for image in images], poses


def test_the_walking_person_starts_the_tracker(frames):
    camera, features, poses = frames
    # the track is fitted over 0.9 s (the scene's walk lasts 1 s), from the first frame of the 0.7 s window
    finder = StartFinder([camera], DT, AutoStartConfig(fit_window_s=0.9))
    found = None
    for k, f in enumerate(features):
        found = finder.push(k, f and [f])
        if found is not None:
            break
        if "walking since" not in finder.status():
            walking_at = k + 1
            assert "not yet walking" in finder.status() or "no person seen" in finder.status()
    assert found is not None, finder.status()
    # walking found after the empty frames and about the 0.7 s of track it needs (21 frames, 80 % of them
    # seen), answered 0.2 s (6 frames) later; the start is the central frame of the 0.7 s window's
    # detections, so the track begins before the walk was found
    assert 4 + 15 <= walking_at <= 4 + 23
    assert k == walking_at + 6
    assert 4 + 4 <= found.frame <= walking_at - 6
    pose = poses[found.frame - 4]
    pelvis = pose_body(BODY, PARAMS, pose.walker, pose.kin).markers[0, 0, :2]
    # (one camera's depth from the feet row: the first detections of this scene are 0.1-0.3 m too far)
    # (0.22 m: this render of the knees-bent body ends its blob a map row above the feet, 0.2 m of depth)
    assert np.linalg.norm(np.array(found.position) - pelvis) < 0.25
    # one camera: the feet row jitters in depth by ~8 cm as the legs swing, so the heading is rough
    assert abs(np.angle(np.exp(1j * (found.heading - HEADING)))) < np.radians(20)
    assert found.speed == pytest.approx(SPEED, rel=0.2)
    assert found.stance_leg is None and found.step_length is None
    # the person's height from the blob's top row over the ground point, and a body scaled to it
    assert finder.estimated_height() == pytest.approx(BODY.height, rel=0.08)
    scaled = BODY.scaled_to_height(finder.estimated_height())
    assert scaled.height == pytest.approx(finder.estimated_height())
    assert scaled.leg_length / scaled.height == pytest.approx(BODY.leg_length / BODY.height)
    with pytest.raises(ValueError, match="1.0-2.3 m"):
        BODY.scaled_to_height(3.0)


def test_a_sequence_ending_before_the_fit_window_is_in_still_starts(frames):
    camera, features, poses = frames
    finder = StartFinder([camera], DT)       # fit over 1.3 s: longer than the walk
    assert all(finder.push(k, f and [f]) is None for k, f in enumerate(features))
    assert "walking since" in finder.status()
    found = finder.finish()
    assert found is not None and 4 + 4 <= found.frame <= len(features) - 10
    pose = poses[found.frame - 4]
    pelvis = pose_body(BODY, PARAMS, pose.walker, pose.kin).markers[0, 0, :2]
    # (0.22 m: this render of the knees-bent body ends its blob a map row above the feet, 0.2 m of depth)
    assert np.linalg.norm(np.array(found.position) - pelvis) < 0.25
    assert found.speed == pytest.approx(SPEED, rel=0.2)
    # a finder that never saw a walking person has nothing to finish with
    assert StartFinder([camera], DT).finish() is None


def test_a_person_standing_still_does_not_start_it(frames):
    camera, features, _ = frames
    finder = StartFinder([camera], DT)
    still = features[10]
    assert all(finder.push(k, [still]) is None for k in range(30))
    assert "not yet walking" in finder.status()


def test_a_person_who_stood_where_the_background_was_learned_is_found_walking_off_their_ghost():
    """No empty frames: the background is learned while the person stands at x = -0.8 m, so where they stood
    stays foreground once they walk off (a motionless "ghost" blob, beside them at first). The finder follows
    the ghost and the person apart, and starts on the one who walks, at their position, heading and speed (a
    finder following only the first one seen kept to the ghost and never started)."""
    camera = side_camera()
    background = background_image(camera, seed=0)
    rng = np.random.default_rng(5)
    poses = walking(40, x0=-0.8)
    standing, _ = render_frames(camera, poses[:1], background, seed=2)
    extractor = FeatureExtractor(CONFIG)
    for _ in range(CONFIG.background_frames):
        extractor.process(noisy(standing[0], rng))
    images, _ = render_frames(camera, poses, background, seed=2)
    features = [extractor.process(image) for image in images]
    found, finder = _start(camera, features, AutoStartConfig(fit_window_s=0.9))
    assert found is not None, finder.status()
    pose = poses[found.frame]
    pelvis = pose_body(BODY, PARAMS, pose.walker, pose.kin).markers[0, 0, :2]
    assert np.linalg.norm(np.array(found.position) - pelvis) < 0.25
    assert abs(np.angle(np.exp(1j * (found.heading - HEADING)))) < np.radians(20)
    assert found.speed == pytest.approx(SPEED, rel=0.2)


def test_a_camera_too_far_and_low_to_place_the_feet_does_not_start_it():
    """From 10 m at 0.5 m high one map row at the feet spans ~1.3 m of depth: the feet rows would put the
    person metres off, so the finder does not start and says why; allowed such rows, it starts."""
    from awalker_tracker.vision.camera import Camera

    far = Camera.look_at("far", 320, 240, 300.0, np.array([0.3, -10.0, 0.5]), np.array([0.3, 0.0, 0.9]))
    background = background_image(far, seed=0)
    rng = np.random.default_rng(5)
    extractor = FeatureExtractor(CONFIG)
    for _ in range(CONFIG.background_frames):
        extractor.process(noisy(background, rng))
    images, _ = render_frames(far, walking(40, x0=-0.8), background, seed=2)
    features = [extractor.process(image) for image in images]
    found, finder = _start(far, features, AutoStartConfig(fit_window_s=0.9))
    assert found is None and "too far or too low" in finder.status(), finder.status()
    allowed, finder = _start(far, features, AutoStartConfig(fit_window_s=0.9, max_row_depth_m=2.0))
    assert allowed is not None, finder.status()
    with pytest.raises(ValueError, match="invalid settings"):
        AutoStartConfig(max_row_depth_m=0.0)


def legs_hidden(features, hem: float = 0.6):
    """``features`` with the person's blob cut at ``hem`` of its height from the top: the legs (bare, or in
    shorts or a skirt of the floor's colour) gone into the background."""
    from dataclasses import replace

    from awalker_tracker.vision.detection import person_blob

    blob = person_blob(features)
    if blob is None:
        return features
    llr = features.llr.copy()
    u0, v0, u1, v1 = (value / features.downsample for value in blob.box)
    llr[:, int(v0 + hem * (v1 - v0)):, int(u0):int(np.ceil(u1)) + 1] = -5.0
    return replace(features, llr=llr)


def test_legs_lost_to_the_floor_in_every_other_frame_still_start_it(frames):
    """A blob cut at the hem puts the person's feet row metres farther and their top taller than they are. In
    every other frame of this walk the finder sees the person there but does not place them, and the start is
    as near the person as with the legs seen; without that (the ratio out of reach) only half of the window's
    frames place the person and it does not start."""
    camera, features, poses = frames
    cut = [legs_hidden(f) if k >= 8 and k % 2 else f for k, f in enumerate(features)]
    found, finder = _start(camera, cut, AutoStartConfig(fit_window_s=0.9))
    assert found is not None, finder.status()
    assert finder.frames_feet_hidden >= 5
    pose = poses[found.frame - 4]
    pelvis = pose_body(BODY, PARAMS, pose.walker, pose.kin).markers[0, 0, :2]
    assert np.linalg.norm(np.array(found.position) - pelvis) < 0.25
    assert found.speed == pytest.approx(SPEED, rel=0.2)
    unseen, finder = _start(camera, cut, AutoStartConfig(fit_window_s=0.9, feet_hidden_height_ratio=100.0))
    assert unseen is None and "not yet walking" in finder.status() and finder.frames_feet_hidden == 0
    with pytest.raises(ValueError, match="invalid settings"):
        AutoStartConfig(feet_hidden_height_ratio=1.0)


@pytest.fixture(scope="module")
def two_walking():
    """The side camera's features of two people walking along +x: A from x = -0.8 m as in ``frames``, B from
    x = 0.2 m and 0.8 m nearer the camera (its blob the larger)."""
    from awalker_tools.model_render import render_rgb
    from awalker_tracker.vision.render import render

    camera, background, rng, extractor = side_scene()
    a, b = walking(30, x0=-0.8), walking(30, x0=0.2)
    features = []
    for pa, pb in zip(a, b):
        pb.kin.contact_point = pb.kin.contact_point + np.array([0.0, -0.8])
        image = background
        for person in (pa, pb):                                    # the farther first
            image = render_rgb(BODY, person.segments(), camera, image, result=render(BODY, person.segments(), camera))
        features.append(extractor.process(noisy(image, rng)))
    return camera, features


def _start(camera, features, config: AutoStartConfig):
    finder = StartFinder([camera], DT, config)
    found = [finder.push(k, [f]) for k, f in enumerate(features)]
    return next((s for s in found if s is not None), None) or finder.finish(), finder


def test_follow_near_chooses_which_of_two_people(two_walking):
    """Of two people walking, the finder follows the larger blob (B, nearer the camera) unless told to follow
    the one near a ground point (A's start), and starts on nobody when nobody is near the point."""
    camera, features = two_walking
    first, _ = _start(camera, features, AutoStartConfig())
    assert first is not None and abs(first.position[1] - (-0.8)) < 0.25          # B
    chosen, _ = _start(camera, features, AutoStartConfig(follow_near=(-0.8, 0.0)))
    assert chosen is not None and abs(chosen.position[1]) < 0.25 and chosen.position[0] < 0.0   # A
    assert abs(chosen.heading - HEADING) < np.radians(20) and abs(chosen.speed - SPEED) < 0.3
    nobody, finder = _start(camera, features, AutoStartConfig(follow_near=(5.0, 5.0)))
    assert nobody is None and "within 1.5 m of (5, 5) m" in finder.status()


def test_config_is_checked():
    with pytest.raises(ValueError):
        AutoStartConfig(min_fraction=0.0)
    with pytest.raises(ValueError):
        AutoStartConfig(window_s=1.0, fit_window_s=0.8)
    with pytest.raises(ValueError, match="invalid settings"):
        AutoStartConfig(gate_m=0.0)
    with pytest.raises(ValueError, match="follow_near"):
        AutoStartConfig(follow_near=(np.nan, 0.0))
    with pytest.raises(ValueError, match="invalid settings"):
        AutoStartConfig(follow_near=(0.0, 0.0), follow_radius_m=0.0)


def test_the_automatic_start_follows_one_of_two_people(tmp_path):
    """Two people in view, no start and no empty frames. The start finder follows the
    first person it sees (each camera's blob nearest to where they would be now; a detection 0.5 m off
    that is someone else or two people's blobs merged), so the start is one person's position, heading
    and speed. Measured (synthesis seed 1): the second person (the first one seen) at 0.09 m and 4
    degrees (120 frames: 0.13 m, 5 degrees); before the detections were gated, the largest blob of any
    camera alternated between them: 0.40 m and 28 degrees from the first person (120 frames: 1.0 and
    2.4 m from them); gated on the last sighting without the distance check: 0.29 m and 92 degrees.
    ``--follow-near`` (AutoStartConfig.follow_near) at where the first person enters chooses them instead."""
    import yaml

    from awalker_tools import evaluation
    from awalker_tools.bagio import SequenceReader
    from awalker_tracker.vision.features import FeatureConfig

    seq = tmp_path / "seq"
    assert main(["synth", "--out", str(seq), "--background-frames", "0", "--no-descriptions", "--size", "320", "240",
                 "--seed", "1", "--from-mocap", str(MOCAP_07 / "07.asf"), str(MOCAP_07 / "07_01.amc"),
                 "--person", "dressed", "--second-person", "--frames", "70", "--cameras", "2"]) == 0
    with SequenceReader(seq / "synth.bag") as reader:
        cameras = reader.cameras
        extractors = [FeatureExtractor(FeatureConfig()) for _ in cameras]
        stamps, features = [], []
        for stamp, images in reader.frames():
            stamps.append(int(stamp))
            features.append([e.process(images[c.name]) for e, c in zip(extractors, cameras)])
    people = [evaluation.read_poses_csv(seq / csv) for csv in ("ground_truth.csv", "second_person.csv")]

    def misses(config: AutoStartConfig) -> list[tuple[float, float]]:
        """(distance m, heading error deg) of the start found from each person's pelvis track."""
        finder, found = StartFinder(cameras, 1 / 30, config), None
        for k, frame in enumerate(features):
            found = finder.push(k, frame)
            if found is not None:
                break
        found = found or finder.finish()
        assert found is not None, finder.status()
        out = []
        for person in people:
            row = int(np.flatnonzero(person.stamps_ns == stamps[found.frame])[0])
            pelvis = person.marker("pelvis")[:, :2]
            walk = pelvis[min(row + 10, len(pelvis) - 1)] - pelvis[max(row - 10, 0)]
            heading = abs(np.degrees(np.angle(np.exp(1j * (found.heading - np.arctan2(walk[1], walk[0]))))))
            out.append((float(np.linalg.norm(np.array(found.position) - pelvis[row])), heading))
        return out

    def on(miss: tuple[float, float]) -> bool:
        return miss[0] < 0.3 and miss[1] < 20.0

    first_seen = misses(AutoStartConfig())
    assert any(on(m) for m in first_seen), first_seen
    other = 0 if on(first_seen[1]) else 1                  # the person the default start did not follow
    enters = people[other].marker("pelvis")[0, :2]
    chosen = misses(AutoStartConfig(follow_near=(float(enters[0]), float(enters[1]))))
    assert on(chosen[other]) and not on(chosen[1 - other]), chosen
    # the same through the command line and the tracker node (a few particles: only the start is checked)
    out = tmp_path / "run"
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
        assert main(["track", str(seq / "synth.bag"), "--out", str(out), "--particles", "100", "--no-overlay",
                     "--follow-near", str(enters[0]), str(enters[1])]) == 0
    start = yaml.safe_load((out / "start.yaml").read_text())["start"]
    row = int(np.flatnonzero(people[other].stamps_ns == stamps[start["frame"]])[0])
    assert np.linalg.norm(np.array(start["position"]) - people[other].marker("pelvis")[row, :2]) < 0.3
