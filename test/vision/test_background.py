"""Background model: per-pixel mean, shared covariance, robust learning with a moving person."""
from __future__ import annotations

import numpy as np
import pytest

from awalker_tracker.vision.background import (
    DEFAULT_FLOOR_STD,
    learn_background,
    learn_background_robust,
    measurements,
)
from vision_scene import background_image, noisy, side_camera

CAM = side_camera()


def test_measurements_are_colour_and_gradient():
    image = np.zeros((8, 12, 3), np.uint8)
    image[:, :, 0] = (np.arange(12) * 10)[None, :]      # red ramp: intensity slope 10/3 per px
    m = measurements(image, 1)
    assert m.shape == (8, 12, 5)
    assert np.allclose(m[:, 1:-1, 0], image[:, 1:-1, 0])
    assert np.allclose(m[:, 1:-1, 3], 10 / 3, atol=1e-5)   # dI/dx
    assert np.allclose(m[:, :, 4], 0)                       # dI/dy
    assert measurements(np.zeros((9, 13, 3), np.uint8), 2).shape == (4, 6, 5)
    with pytest.raises(ValueError):
        measurements(np.zeros((8, 8)), 1)


def test_background_mean_and_covariance_from_noisy_frames():
    rng = np.random.default_rng(0)
    clean = background_image(CAM)
    frames = [noisy(clean, rng, std=4.0) for _ in range(12)]
    model = learn_background(frames, downsample=2)
    truth = measurements(clean, 2)
    assert np.median(np.abs(model.mean[..., :3] - truth[..., :3])) < 0.6
    # Noise of std 4 averaged over 2x2 pixels -> std 2; plus the floor.
    expected_var = 4.0 ** 2 / 4 + DEFAULT_FLOOR_STD[0] ** 2
    assert np.diag(model.covariance)[:3] == pytest.approx([expected_var] * 3, rel=0.25)
    assert np.all(np.linalg.eigvalsh(model.covariance) > 0)


def test_robust_background_ignores_a_moving_person():
    rng = np.random.default_rng(1)
    clean = background_image(CAM)
    frames = []
    for f in range(15):
        image = noisy(clean, rng)
        x = 20 + 18 * f                                     # a red 'person' walking across
        image[60:200, x : x + 30] = (200, 40, 40)
        frames.append(image)
    truth = measurements(clean, 2)[..., :3]
    robust = learn_background_robust(frames, downsample=2)
    plain = learn_background(frames, downsample=2)
    robust_err = np.abs(robust.mean[..., :3] - truth)
    plain_err = np.abs(plain.mean[..., :3] - truth)
    assert np.percentile(robust_err, 99) < 3.0
    assert np.percentile(plain_err, 99) > 8.0            # the non-robust mean is smeared by the person
    # The person is foreground against the robust model, the background is not.
    m = measurements(frames[7], 2)
    mask = robust.foreground_mask(m)
    person = np.zeros(mask.shape, bool)
    person[30:100, (20 + 18 * 7) // 2 : (50 + 18 * 7) // 2] = True
    assert mask[person].mean() > 0.95
    assert mask[~person].mean() < 0.01


def test_robust_background_has_no_ghost_where_a_moving_person_lingers():
    """A person walking along the view (stripes moving through the same pixels) covers a block in 12 of
    20 frames: the temporal median learns the person there (a ghost), the densest colour cluster the
    background seen steadily in the other 8."""
    rng = np.random.default_rng(3)
    clean = background_image(CAM)
    frames = []
    for f in range(20):
        image = noisy(clean, rng)
        if f < 12:
            stripes = ((np.arange(100)[:, None] + 7 * f) // 6) % 2 == 0          # shifted every frame
            image[80:180, 100:140] = np.where(stripes[..., None], (250, 40, 40), (235, 150, 60)).astype(np.uint8)
        frames.append(image)
    truth = measurements(clean, 2)[..., :3]
    block = (slice(40, 90), slice(50, 70))
    median = np.median(np.stack([measurements(f, 2) for f in frames]), axis=0)[..., :3]
    assert np.median(np.abs(median[block] - truth[block])[..., 0]) > 30.0    # the median's ghost (red)
    robust = learn_background_robust(frames, downsample=2)
    assert np.percentile(np.abs(robust.mean[..., :3] - truth)[block], 99) < 3.0
    assert robust.foreground_mask(measurements(noisy(clean, rng), 2))[block].mean() < 0.01


def test_robust_background_is_learned_again_and_a_ghost_fades():
    """A person standing still in 14 of the first 20 frames is learned into the background (nothing can
    tell them apart yet); refitted from the frames so far, the background there is right again once the
    frames without them are the majority (after 30 frames here), and the foreground, learned again with it,
    finds the walking person whole."""
    from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor

    rng = np.random.default_rng(6)
    clean = background_image(CAM)
    extractor = FeatureExtractor(FeatureConfig(downsample=2, median_frames=20, refit_frames=(25, 30, 40)))
    block = (slice(40, 90), slice(20, 35))
    clean_m = measurements(clean, 2)
    ghost_at, foregrounds, foreground = {}, [], None
    for f in range(41):
        image = noisy(clean, rng)
        # stands, walks off to the right, and from frame 30 walks back into view away from where they stood
        x = 40 if f < 14 else 40 + 40 * (f - 13) if f < 30 else 150 + 4 * (f - 30)
        image[80:180, x : x + 30] = (200, 40, 40)
        last = extractor.process(image)
        if extractor.background is not None:
            ghost_at[f + 1] = extractor.background.foreground_mask(clean_m)[block].mean()
        if extractor.foreground is not foreground:
            foregrounds.append(f + 1)
            foreground = extractor.foreground
    assert ghost_at[20] > 0.9 and ghost_at[25] > 0.9       # learned at 20 frames, still 14 of 25 there
    assert ghost_at[30] < 0.01 and ghost_at[41] < 0.01     # 14 of 30: gone
    # the foreground mixtures were learned again with each background: first learned against the ghost (the
    # person's own colours in the background), they would not tell the walking person from it
    assert foregrounds == [20, 25, 30, 40]
    from awalker_tracker.vision.detection import person_blobs

    blob = person_blobs(last, threshold=2.0, min_area_fraction=0.001)[0]
    assert blob.area_px > 0.8 * 100 * 30, blob
    assert np.percentile(np.abs(extractor.background.mean[..., :3] - clean_m[..., :3]), 99) < 3.0
    with pytest.raises(ValueError):
        FeatureConfig(refit_frames=(0,))


@pytest.mark.parametrize("rate", [30.0, 60.0, 24.0])
def test_the_robust_background_keeps_the_same_seconds_at_any_frame_rate(rate: float):
    """Given the frames' stamps, the robust background is learned (and learned again) after the same camera time
    at any frame rate, from at most 30 frames a second: counted in its own frames a 60 Hz camera learned in half
    the time, before a person walking along its view had left their first pixels."""
    from awalker_tracker.vision.features import SCHEDULE_RATE_HZ, FeatureConfig, FeatureExtractor

    rng = np.random.default_rng(3)
    clean = background_image(CAM)
    extractor = FeatureExtractor(FeatureConfig(downsample=4, median_frames=6, refit_frames=(9,)))
    learned, buffered = [], []
    for k in range(int(0.5 * rate)):
        before = extractor.background
        extractor.process(noisy(clean, rng), stamp_ns=1_000_000_000 + round(k * 1e9 / rate))
        if extractor.background is not before:
            learned.append(k / rate)
            buffered.append(len(extractor._buffer))
    # 6 and 9 frames at 30 per second: at the first frame at or after 5/30 and 8/30 s of stamps (the first counts at 0 s)
    assert all(0 <= t - due < 1 / rate for t, due in zip(learned, (5 / SCHEDULE_RATE_HZ, 8 / SCHEDULE_RATE_HZ))), learned
    assert len(learned) == 2
    assert buffered[0] <= 6


def test_adaptation_moves_background_but_not_foreground_pixels():
    rng = np.random.default_rng(2)
    clean = background_image(CAM)
    model = learn_background([noisy(clean, rng) for _ in range(5)], downsample=2)
    brighter = measurements(np.clip(clean.astype(int) + 3, 0, 255).astype(np.uint8), 2)
    fg = np.zeros(model.shape, bool)
    fg[:10] = True
    adapted = model.adapt(brighter, 0.5, foreground=fg)
    assert np.allclose(adapted.mean[:10], model.mean[:10])
    assert np.median(adapted.mean[10:, :, 0] - model.mean[10:, :, 0]) == pytest.approx(1.5, abs=0.3)


def test_extractor_learns_robustly_when_no_background_frames_are_known():
    from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor
    from vision_scene import render_frames, walking_poses

    rng = np.random.default_rng(4)
    clean = background_image(CAM)
    frames = []
    for f in range(8):                        # a red block crossing the view, then the walker
        image = noisy(clean, rng)
        image[40:200, 10 + 35 * f : 40 + 35 * f] = (200, 40, 40)
        frames.append(image)
    walker, _ = render_frames(CAM, walking_poses(1), clean)
    extractor = FeatureExtractor(FeatureConfig(downsample=2, median_frames=8))
    outputs = [extractor.process(f) for f in frames]
    assert not any(o.llr.any() for o in outputs[:7])          # nothing known before the 8th frame
    assert extractor.ready and outputs[7].llr.any()
    assert np.percentile(np.abs(extractor.background.mean[..., :3] - measurements(clean, 2)[..., :3]), 99) < 3.0
    # Occlusion mask: zero ratios under it, its flow cells invalid.
    mask = np.zeros((CAM.height, CAM.width), np.uint8)
    mask[:, : CAM.width // 2] = 255
    out = extractor.process(walker[0], occlusion_mask=mask)
    assert not out.llr[:, :, : CAM.width // 4].any() and out.llr[:, :, CAM.width // 4 :].any()
    assert not out.flow.valid[:, : out.flow.shape[1] // 2].any() and out.flow.valid[:, out.flow.shape[1] // 2 + 1 :].any()



def test_occluded_masks_exactly_the_touched_map_pixels_and_flow_cells():
    """One occluded pixel occludes its whole map pixel (downsample x downsample) and its flow cell; the
    rest of the features pass unchanged, and no mask leaves the features as they are."""
    from awalker_tracker.vision.features import FrameFeatures, occluded
    from awalker_tracker.vision.flow import FlowGrid, grid_centers

    rng = np.random.default_rng(9)
    height, width, downsample, cell = 48, 64, 4, 8
    llr = rng.normal(0.0, 2.0, (4, height // downsample, width // downsample)).astype(np.float32)
    rows, cols = height // cell, width // cell
    flow = FlowGrid(grid_centers(rows, cols, cell), rng.normal(size=(rows, cols, 2)).astype(np.float32),
                    np.tile(np.eye(2, dtype=np.float32), (rows, cols, 1, 1)), np.ones((rows, cols), bool), cell)
    features = FrameFeatures(("head", "torso", "legs", "feet"), llr, downsample, width, height, flow)
    assert occluded(features, None) is features
    mask = np.zeros((height, width), np.uint8)
    mask[21, 45] = 255                       # map pixel (5, 11), flow cell (2, 5)
    out = occluded(features, mask)
    hidden = np.zeros(llr.shape[1:], bool)
    hidden[5, 11] = True
    assert np.array_equal(out.occlusion, hidden)
    assert not out.llr[:, 5, 11].any()
    assert np.array_equal(out.llr[:, ~hidden], llr[:, ~hidden])
    invalid = np.zeros((rows, cols), bool)
    invalid[2, 5] = True
    assert np.array_equal(out.flow.valid, ~invalid)
    assert np.array_equal(out.flow.flow, flow.flow)

def test_lighting_changes_are_divided_out():
    """The room brightens by 15-35 % with a tint after the background frames: with gain compensation the
    background stays background and the walker stands out; without it the background does not (a
    darkening the shadow model explains on its own: see test_shadows_are_background)."""
    import cv2

    from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor
    from awalker_tracker.vision.foreground import class_labels_from_parts
    from vision_scene import BODY, render_frames, walking_poses

    rng = np.random.default_rng(5)
    clean = background_image(CAM)
    frames, parts = render_frames(CAM, walking_poses(3), clean)
    body = cv2.dilate((parts[2] >= 0).astype(np.uint8), np.ones((9, 9), np.uint8))[1::2, 1::2] > 0
    inner = class_labels_from_parts(parts[2], tuple(p.part_class for p in BODY.parts))[1::2, 1::2] >= 0

    def lit(image, gain):
        return np.clip(image * np.asarray(gain), 0, 255).astype(np.uint8)

    results = {}
    for compensate in (True, False):
        extractor = FeatureExtractor(FeatureConfig(background_frames=4, downsample=2, compensate_gain=compensate))
        for k in range(4):
            extractor.process(noisy(lit(clean, 1.0 - 0.03 * k), rng))
        extractor.process(lit(frames[0], 0.9))                      # learns the foreground
        out = extractor.process(lit(frames[2], (1.35, 1.3, 1.15)))  # brighter, yellowish light
        best = out.llr.max(axis=0)
        results[compensate] = (np.mean(best[~body] < 0), np.mean(best[inner]))
    assert results[True][0] > 0.97 and results[True][1] > 5, results
    assert results[False][0] < 0.5, results


def test_shadows_are_background():
    """A patch of the background darkened to 60 % (a shadow) is background; one recoloured is not."""
    from awalker_tracker.vision.background import BackgroundModel, fit_background, measurements

    rng = np.random.default_rng(2)
    clean = background_image(CAM)
    model = fit_background(np.stack([measurements(noisy(clean, rng)) for _ in range(5)]))
    frame = clean.astype(np.float32)
    frame[100:140, 100:160] *= 0.6                                   # shadow
    frame[100:140, 200:260] = frame[100:140, 200:260, ::-1]          # a different colour, same brightness
    m = measurements(np.clip(frame, 0, 255).astype(np.uint8))
    with_shadows = model.log_likelihood(m)
    without = BackgroundModel(model.mean, model.covariance, shadows=False).log_likelihood(m)
    lit = with_shadows[20:60, 20:60].mean()
    assert with_shadows[105:135, 105:155].mean() > lit - 8          # explained, at the shadow prior's cost
    assert without[105:135, 105:155].mean() < lit - 50
    assert with_shadows[105:135, 205:255].mean() < lit - 50          # recoloured: still foreground


def test_soft_shadow_edges_are_background():
    """A soft shadow (a person's contact shadow: darkening to 45 % in the middle, fading over ~15 pixels)
    is background across its penumbra too, where the darkening's own gradient adds to the background's
    (with the shadow component's gradients as tight as the lit background's, the penumbra scored 28 nats
    below the lit floor on average, 56 at the 5th percentile: neither background nor foreground, so a
    model foot could rest on it); a dark patch of another colour with the same soft edge is still
    foreground. Measured on the features' 4x4 map pixels."""
    from awalker_tracker.vision.background import fit_background, measurements

    rng = np.random.default_rng(3)
    clean = background_image(CAM)
    d = 4                                                               # the features' map resolution
    model = fit_background(np.stack([measurements(noisy(clean, rng), d) for _ in range(5)]))
    rows, cols = np.mgrid[0:CAM.height, 0:CAM.width] + 0.5
    spot = np.exp(-(((rows - 120) / 10.0) ** 2 + ((cols - 130) / 24.0) ** 2))      # soft elliptical spot
    frame = clean.astype(np.float32) * (1.0 - 0.55 * spot)[..., None]
    other = np.exp(-(((rows - 120) / 10.0) ** 2 + ((cols - 250) / 24.0) ** 2))[..., None]
    frame = frame * (1 - other) + other * np.array([40.0, 60.0, 140.0])            # a dark blue patch
    m = measurements(np.clip(frame, 0, 255).astype(np.uint8), d)
    log_bg = model.log_likelihood(m)
    lit = log_bg[5:15, 5:15].mean()
    spot, other = spot[d // 2::d, d // 2::d], other[d // 2::d, d // 2::d]
    penumbra = (spot > 0.2) & (spot < 0.8)
    assert penumbra.sum() > 30
    assert log_bg[penumbra].mean() > lit - 8 and np.percentile(log_bg[penumbra], 5) > lit - 12
    assert log_bg[(other[..., 0] > 0.8)].mean() < lit - 50
