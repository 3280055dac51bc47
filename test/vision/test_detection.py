"""Person detection: foreground blob -> ground position and height, one and two cameras."""
from __future__ import annotations

import numpy as np
import pytest

from awalker_tracker.model.kinematics import pose_body
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


def test_no_person_no_detection():
    camera = side_camera()
    features, _ = features_of(camera, [], 0)
    assert features == []
    empty = FeatureExtractor(CONFIG)
    background = background_image(camera, seed=0)
    rng = np.random.default_rng(0)
    frames = [empty.process(noisy(background, rng)) for _ in range(CONFIG.background_frames + 2)]
    assert person_blob(frames[-1]) is None and detect_person([frames[-1]], [camera]) is None
