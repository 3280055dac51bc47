"""Whether the person is in view, and when a track ends (inference/visibility.py)."""
from __future__ import annotations

import numpy as np
import pytest

from awalker_tracker.inference.visibility import (
    LEFT_EVERY_VIEW, NOT_SUPPORTED, CameraView, ViewConfig, ViewMonitor, camera_views)

from side_view import seen  # noqa: F401  (fixture)


def test_a_body_on_the_person_is_in_view(seen):
    camera, features, markers = seen
    (view,) = camera_views([camera], [features], markers)
    assert view == CameraView(camera.name, inside=True, supported=True) and view.in_view


def test_a_body_beside_the_person_is_inside_the_image_but_not_supported(seen):
    camera, features, markers = seen
    (view,) = camera_views([camera], [features], markers + np.array([1.2, 0.0, 0.0]))
    assert view.inside and not view.supported and not view.in_view


def test_a_body_out_of_the_image_is_not_inside(seen):
    camera, features, markers = seen
    gone = markers + np.array([3.0, 0.0, 0.0])
    assert not camera.in_image(gone).any()
    (view,) = camera_views([camera], [features], gone)
    assert not view.inside and not view.in_view
    # half through the border: in view while at least min_inside_fraction of the markers are inside
    edge_shift = next(dx for dx in np.arange(0.0, 3.0, 0.01)
                      if np.mean(camera.in_image(markers + np.array([dx, 0.0, 0.0]))) < 0.5)
    assert camera_views([camera], [features], markers + np.array([edge_shift - 0.02, 0, 0]),
                        ViewConfig(support_margin=10.0))[0].inside
    assert not camera_views([camera], [features], markers + np.array([edge_shift, 0, 0]))[0].inside


def views(inside: bool, supported: bool) -> tuple[CameraView, ...]:
    return (CameraView("cam0", inside, supported), CameraView("cam1", False, False))


def test_the_track_ends_after_end_after_s_out_of_every_view_with_the_reason():
    monitor = ViewMonitor(dt=0.1, config=ViewConfig(end_after_s=0.3))
    # not yet seen (a hand start before the person came in): nothing ends
    assert all(monitor.update(f, f, views(False, False)) is None for f in range(10))
    assert monitor.update(10, 10, views(True, True)) is None
    # two frames out, one back in: the run starts again
    assert monitor.update(11, 11, views(True, False)) is None and monitor.update(12, 12, views(False, False)) is None
    assert monitor.update(13, 13, views(True, True)) is None
    assert monitor.update(14, 14, views(False, False)) is None and monitor.update(15, 15, views(False, False)) is None
    end = monitor.update(16, 16, views(False, False))
    assert end is not None and (end.frame_index, end.last_in_view_frame, end.reason) == (16, 13, LEFT_EVERY_VIEW)
    # inside an image but on nobody: no longer supported by the images
    monitor = ViewMonitor(dt=0.1, config=ViewConfig(end_after_s=0.3))
    monitor.update(0, 0, views(True, True))
    ends = [monitor.update(f, f, views(True, False)) for f in (1, 2, 3)]
    assert ends[:2] == [None, None] and ends[2].reason == NOT_SUPPORTED


def test_end_after_zero_never_ends_and_no_images_judge_nothing():
    monitor = ViewMonitor(dt=0.1, config=ViewConfig(end_after_s=0.0))
    monitor.update(0, 0, views(True, True))
    assert all(monitor.update(f, f, views(False, False)) is None for f in range(1, 50))
    monitor = ViewMonitor(dt=0.1)
    assert all(monitor.update(f, f, ()) is None for f in range(50))


def test_bad_settings_are_refused():
    for bad in ({"min_inside_fraction": 0.0}, {"min_inside_fraction": 1.5}, {"support_margin": -1.0},
                {"end_after_s": -0.1}):
        with pytest.raises(ValueError, match="ViewConfig"):
            ViewConfig(**bad)
