"""Silhouette extent (vision/extent.py): the feet and head rows against the person's blob fix depth."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from awalker_tracker.model.kinematics import pose_body
from awalker_tracker.vision.detection import PersonBlob, person_blob
from awalker_tracker.vision.extent import ExtentConfig, extent_log_likelihood
from test_detection import features_of
from vision_scene import BODY, PARAMS, side_camera, stacked, walking_poses


ON = ExtentConfig(weight=4.0)        # off by default


@pytest.fixture(scope="module")
def seen():
    camera = side_camera()
    poses = walking_poses(3, x0=0.4)
    features, _ = features_of(camera, poses, 0)
    return camera, person_blob(features[-1], camera.name), poses[-1]


def _moved(pose, dx: float, dy: float):
    kin = pose.kin.copy()
    kin.contact_point = kin.contact_point + np.array([dx, dy])
    return replace(pose, kin=kin)


def test_the_true_depth_scores_best(seen):
    camera, blob, pose = seen
    # the side camera looks along +y from 4 m: move the body 0.4 m nearer / farther, and sideways
    offsets = [(0.0, 0.0), (0.0, -0.4), (0.0, 0.4), (0.0, -0.15), (0.0, 0.15)]
    batch = stacked([_moved(pose, dx, dy) for dx, dy in offsets])
    posed = pose_body(BODY, PARAMS, batch.walker, batch.kin)
    score = extent_log_likelihood(posed.markers, posed.segments, BODY.parts, [camera], [blob], ON)
    with_head = extent_log_likelihood(posed.markers, posed.segments, BODY.parts, [camera], [blob],
                                      ExtentConfig(weight=4.0, head=True))
    assert np.argmax(with_head) == 0 and np.all(with_head <= score)
    assert np.argmax(score) == 0
    assert score[1] < score[3] < score[0] and score[2] < score[4] < score[0]   # the farther off, the worse
    # bounded: a 0.4 m depth error costs a few nats per row, not hundreds (heavy tails)
    assert score[0] - score[1] < ON.weight * np.log1p(100.0 ** 2)
    assert np.all(extent_log_likelihood(posed.markers, posed.segments, BODY.parts, [camera], [blob]) == 0)


def test_no_person_or_a_cut_blob_gives_no_evidence(seen):
    camera, blob, pose = seen
    batch = stacked([_moved(pose, 0.0, dy) for dy in (0.0, 0.5)])
    posed = pose_body(BODY, PARAMS, batch.walker, batch.kin)
    assert np.all(extent_log_likelihood(posed.markers, posed.segments, BODY.parts, [camera], [None], ON) == 0)
    cut = PersonBlob(blob.camera, (blob.box[0], 0.0, blob.box[2], blob.box[3]), blob.area_px, blob.feet_uv, blob.head_uv)
    assert np.all(extent_log_likelihood(posed.markers, posed.segments, BODY.parts, [camera], [cut], ON) == 0)
