"""Test pictures of the tracker's body model (awalker_tools.model_render): the body's pixels drawn, textured,
over an untouched background."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from awalker_tools.model_render import render_rgb
from awalker_tracker.vision.render import render

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vision"))
from vision_scene import BODY, side_camera, walking_poses  # noqa: E402


def test_whole_body_rgb():
    segments, cam = walking_poses(1)[0].segments(), side_camera()
    cast = render(BODY, segments, cam)
    background = np.full((cam.height, cam.width, 3), 17, np.uint8)
    image = render_rgb(BODY, segments, cam, background)
    labels = cast.labels
    assert np.count_nonzero(labels >= 0) > 1000
    assert np.all(image[labels < 0] == 17)
    assert np.mean(np.any(image[labels >= 0] != 17, axis=1)) > 0.99
    # Texture: the torso is not a flat colour.
    assert image[labels == 0].std(axis=0).max() > 5
    # drawn from a given ray casting, the same picture
    np.testing.assert_array_equal(render_rgb(BODY, segments, cam, background, result=cast), image)
    with pytest.raises(ValueError, match="background"):
        render_rgb(BODY, segments, cam, background[:10])
