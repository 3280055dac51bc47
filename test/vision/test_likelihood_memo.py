"""SilhouetteMemo: reusing the previous call's projections gives the same likelihood."""
from __future__ import annotations

import numpy as np

from awalker_tracker.model.body import BodySegments
from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor
from awalker_tracker.vision.flow import FlowConfig
from awalker_tracker.vision.likelihood import SilhouetteMemo, log_likelihood
from vision_scene import BODY, GROUPS, background_image, noisy, perturbed, render_frames, side_camera, stacked, \
    walking_poses


def test_memo_reuses_previous_projection_with_identical_values():
    camera = side_camera()
    poses = walking_poses(3)
    config = FeatureConfig(background_frames=2, downsample=2, flow=FlowConfig(cell_size=8))
    rng = np.random.default_rng(0)
    bg = background_image(camera, seed=0)
    frames, _ = render_frames(camera, poses, bg, seed=0)
    extractor = FeatureExtractor(config)
    for _ in range(config.background_frames):
        extractor.process(noisy(bg, rng))
    features = [extractor.process(f) for f in frames]
    # 30 perturbed bodies per frame; frame k+1 is scored against frame k's bodies (the flow term).
    batches = [stacked([perturbed(p, GROUPS[i % len(GROUPS)], rng) for i in range(30)]).segments() for p in poses]
    memo = SilhouetteMemo()
    first = log_likelihood(BODY.parts, batches[0], None, [camera], [features[0]], memo=memo)
    assert memo.lookup(batches[0], 0) is not None and memo.lookup(batches[1], 0) is None
    for k in (1, 2):
        with_memo = log_likelihood(BODY.parts, batches[k], batches[k - 1], [camera], [features[k]], memo=memo)
        without = log_likelihood(BODY.parts, batches[k], batches[k - 1], [camera], [features[k]])
        np.testing.assert_array_equal(with_memo, without)
    np.testing.assert_array_equal(first, log_likelihood(BODY.parts, batches[0], None, [camera], [features[0]]))
    # Identity, not equality: equal poses in another object are projected afresh, and a
    # memo entry for other poses is never used for these.
    copy = BodySegments(batches[2].origin.copy(), batches[2].rotation.copy())
    assert memo.lookup(copy, 0) is None
    stale = SilhouetteMemo()
    log_likelihood(BODY.parts, batches[0], None, [camera], [features[0]], memo=stale)
    np.testing.assert_array_equal(
        log_likelihood(BODY.parts, batches[2], batches[1], [camera], [features[2]], memo=stale),
        log_likelihood(BODY.parts, batches[2], batches[1], [camera], [features[2]]))
