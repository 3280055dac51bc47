"""Foreground mixtures learned without labels; class maps discriminate parts and background."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from awalker_tracker.model.body import PART_CLASSES
from awalker_tracker.vision.background import learn_background, measurements
from awalker_tracker.vision.foreground import band_labels, class_labels_from_parts, fit_mixture, learn_foreground
from vision_scene import BODY, background_image, noisy, render_frames, side_camera, walking_poses

PART_CLASS_NAMES = tuple(p.part_class for p in BODY.parts)


def test_mixture_recovers_separated_clusters():
    rng = np.random.default_rng(0)
    centres = np.array([[20, 20, 20, 0, 0], [120, 60, 200, 5, -5], [230, 180, 30, -10, 10]], float)
    samples = np.concatenate([c + rng.normal(0, 4, (n, 5)) for c, n in zip(centres, (300, 500, 200))])
    mixture = fit_mixture(samples)
    order = np.argsort(mixture.means[:, 0])
    assert np.allclose(mixture.means[order], centres, atol=1.5)
    assert mixture.weights[order] == pytest.approx([0.3, 0.5, 0.2], abs=0.02)
    # Densities: a cluster centre is far likelier than a point between clusters.
    assert mixture.log_likelihood(centres[1]) > mixture.log_likelihood(centres[:2].mean(axis=0)) + 20


def test_band_labels_follow_body_proportions():
    mask = np.zeros((220, 60), bool)
    mask[20:195, 20:40] = True                           # a 175-row blob
    mask[5:8, 50:52] = True                              # a speck: not the largest blob
    labels = band_labels(mask, BODY)
    column = labels[:, 30]
    head_rows = np.flatnonzero(column == PART_CLASSES.index("head"))
    feet_rows = np.flatnonzero(column == PART_CLASSES.index("feet"))
    assert head_rows.min() == 20
    assert len(head_rows) == pytest.approx(175 * BODY.head_length / BODY.height, abs=1.5)
    assert feet_rows.max() == 194
    assert np.all(labels[5:8, 50:52] == -1) and np.all(labels[~mask] == -1)


def test_class_labels_from_parts():
    parts = np.array([[-1, 0, 1], [2, 6, 7]])
    labels = class_labels_from_parts(parts, PART_CLASS_NAMES)
    idx = PART_CLASSES.index
    assert labels.tolist() == [[-1, idx("torso"), idx("head")], [idx("legs"), idx("feet"), idx("feet")]]


@pytest.mark.parametrize("use_labels", [False, True])
def test_foreground_learned_without_labels_discriminates_parts(use_labels):
    cam = side_camera()
    rng = np.random.default_rng(3)
    bg = background_image(cam)
    background = learn_background([noisy(bg, rng) for _ in range(4)], downsample=2)
    frames, part_labels = render_frames(cam, walking_poses(4), bg)
    true_classes = [class_labels_from_parts(p, PART_CLASS_NAMES)[1::2, 1::2] for p in part_labels]
    m0 = measurements(frames[0], 2)
    model = learn_foreground(m0, background, true_classes[0] if use_labels else None, BODY)
    # Evaluate on a later frame (a different pose).
    m = measurements(frames[3], 2)
    llr = model.log_likelihood_ratios(m, background, clip=25.0)
    truth = true_classes[3]
    body = truth >= 0
    assert llr.max(axis=0)[body].mean() > 5.0
    far = cv2.dilate(body.astype(np.uint8), np.ones((5, 5), np.uint8)) == 0   # away from mixed border pixels
    assert np.percentile(llr.max(axis=0)[far], 99) < 0.0
    # Each body pixel's best class is its own class (interior pixels, away from part borders:
    # a border pixel mixes the part with its neighbour or the background).
    best = np.argmax(llr, axis=0)
    for c in ("head", "torso", "legs"):
        own = cv2.erode((truth == PART_CLASSES.index(c)).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        assert np.mean(best[own] == PART_CLASSES.index(c)) > 0.8, c


def test_start_pose_projection_labels_the_feet_better_than_bands():
    """The body projected at the start description's pose (legs in double support, phase unknown),
    with the foreground it misses filled by bands, learns the feet class; bands alone hardly do."""
    from awalker_tracker.model.kinematics import pose_body
    from awalker_tracker.vision.foreground import start_pose_labels
    from vision_scene import PARAMS

    cam = side_camera()
    rng = np.random.default_rng(3)
    bg = background_image(cam)
    background = learn_background([noisy(bg, rng) for _ in range(4)], downsample=2)
    poses = walking_poses(6)
    frames, part_labels = render_frames(cam, poses, bg)
    truth = [class_labels_from_parts(p, PART_CLASS_NAMES)[1::2, 1::2] for p in part_labels]
    pelvis = pose_body(BODY, PARAMS, poses[0].walker, poses[0].kin).markers[0, 0, :2]
    start = start_pose_labels(BODY, cam, pelvis, 0.0, 0.7, 0)
    assert start.shape == (cam.height, cam.width) and set(np.unique(start)) == {-1, 0, 1, 2, 3}
    m0 = measurements(frames[0], 2)
    feet = PART_CLASSES.index("feet")
    accuracy = {}
    for name, labels in (("bands", None), ("start", start[1::2, 1::2])):
        model = learn_foreground(m0, background, labels, BODY, fill_with_bands=True)
        llr = model.log_likelihood_ratios(measurements(frames[5], 2), background, clip=25.0)
        accuracy[name] = float(np.mean(np.argmax(llr, axis=0)[truth[5] == feet] == feet))
    # start 0.67, bands 0.18 (0.76, 0.24 when the thigh, not the hip-ankle chord, followed the walker's leg)
    assert accuracy["start"] > 0.6 and accuracy["start"] > accuracy["bands"] + 0.3, accuracy
