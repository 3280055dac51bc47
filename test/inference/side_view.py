"""The side camera's view of a walking person, shared by the recovery and visibility tests (import the fixture)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vision"))


@pytest.fixture(scope="module")
def seen():
    """The side camera, its features of a walking person (the last of 3 rendered frames) and the person's 13
    markers (world m)."""
    from awalker_tracker.model.kinematics import pose_body
    from test_detection import features_of
    from vision_scene import BODY, PARAMS, side_camera, walking_poses

    camera = side_camera()
    poses = walking_poses(3, x0=0.4)
    features, _ = features_of(camera, poses, 0)
    markers = pose_body(BODY, PARAMS, poses[-1].walker, poses[-1].kin).markers[0]
    return camera, features[-1], markers
