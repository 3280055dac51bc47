"""The compiled likelihood (numba kernels) against the numpy reference of the same model.

Random bodies near a camera: some behind it or straddling its image plane, some partly outside
the image, parts crowded together so that self-occlusion matters; random appearance maps and
flow grids; with and without occlusion mask, flow and self-occlusion; cameras with 0, 5 and 8
distortion coefficients and skew. The reference computes in float32 and the kernel in float64,
so a sample point right at a map-cell boundary may read the neighbouring cell: nearly all
states agree to ~1e-4, a few differ by one cell's worth.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from awalker_tracker.model.body import BodySegments
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.features import PART_CLASSES, FrameFeatures, occluded
from awalker_tracker.vision.flow import FlowGrid, grid_centers
from awalker_tracker.vision.likelihood import (
    LikelihoodConfig,
    SilhouetteMemo,
    _CameraArrays,
    _project_segments,
    camera_log_likelihood,
    log_likelihood,
)
from likelihood_reference import reference_log_likelihood
from vision_scene import BODY, GROUPS, perturbed, stacked, walking_poses

WIDTH, HEIGHT, DOWNSAMPLE, CELL = 640, 480, 4, 16
TARGET = np.array([0.3, 0.0, 0.9])
DISTORTIONS = {
    "none": None,
    "five": np.array([-0.28, 0.09, 0.001, -0.0015, -0.012]),
    "eight": np.array([0.3, -0.05, 0.0008, 0.0012, 0.01, 0.55, -0.02, 0.03]),   # rational model
}


def make_camera(distortion: str, skew: float = 0.0) -> Camera:
    cam = Camera.look_at(f"cam_{distortion}", WIDTH, HEIGHT, 520.0, np.array([0.6, -3.6, 1.3]), TARGET,
                         distortion=DISTORTIONS[distortion])
    K = cam.K.copy()
    K[0, 1] = skew
    return dataclasses.replace(cam, K=K)


def random_features(rng: np.random.Generator, flow: bool = True) -> FrameFeatures:
    """Random ratio maps (downsample 4) and a random flow grid (16 px cells, ~70 % valid)."""
    h, w = HEIGHT // DOWNSAMPLE, WIDTH // DOWNSAMPLE
    llr = rng.normal(0.0, 2.0, (len(PART_CLASSES), h, w)).astype(np.float32)
    rows, cols = HEIGHT // CELL, WIDTH // CELL
    if not flow:
        return FrameFeatures(PART_CLASSES, llr, DOWNSAMPLE, WIDTH, HEIGHT, FlowGrid.empty(HEIGHT, WIDTH, CELL))
    a = rng.normal(0.0, 1.0, (rows, cols, 2, 2))
    covariance = (a @ np.swapaxes(a, -1, -2) + 0.3 * np.eye(2)).astype(np.float32)
    grid = FlowGrid(grid_centers(rows, cols, CELL), rng.normal(0.0, 3.0, (rows, cols, 2)).astype(np.float32),
                    covariance, rng.random((rows, cols)) < 0.7, CELL)
    return FrameFeatures(PART_CLASSES, llr, DOWNSAMPLE, WIDTH, HEIGHT, grid)


def random_bodies(camera: Camera, n: int, rng: np.random.Generator) -> BodySegments:
    """n bodies of BODY's parts at random poses, crowded within ~0.25 m of a centre that lies
    between 0.5 m behind and 6 m in front of the camera, up to ~2.5 m off the optical axis."""
    forward, right, down = camera.rotation[:, 2], camera.rotation[:, 0], camera.rotation[:, 1]
    depth = rng.uniform(-0.5, 6.0, n)
    centre = (camera.position + depth[:, None] * forward + rng.uniform(-2.5, 2.5, (n, 1)) * right
              + rng.uniform(-1.5, 1.5, (n, 1)) * down)
    parts = len(BODY.parts)
    origin = centre[:, None, :] + rng.normal(0.0, 0.25, (n, parts, 3))
    rotation = Rotation.random(n * parts, random_state=rng).as_matrix().reshape(n, parts, 3, 3)
    return BodySegments(origin, rotation)


def walking_bodies(n: int, rng: np.random.Generator) -> BodySegments:
    """n perturbed walking poses (the legs overlap in a side view)."""
    pose = walking_poses(4)[3]
    return stacked([perturbed(pose, GROUPS[i % len(GROUPS)], rng) for i in range(n)]).segments()


def moved(segments: BodySegments, rng: np.random.Generator, scale: float = 0.03) -> BodySegments:
    """The bodies a frame earlier: each part shifted by a few cm (the flow term's motion)."""
    return BodySegments(segments.origin + rng.normal(0.0, scale, segments.origin.shape), segments.rotation.copy())


def occlusion_mask(rng: np.random.Generator) -> np.ndarray:
    mask = np.zeros((HEIGHT, WIDTH), np.uint8)
    for _ in range(4):
        r, c = rng.integers(0, HEIGHT - 60), rng.integers(0, WIDTH - 80)
        mask[r:r + rng.integers(20, 120), c:c + rng.integers(20, 160)] = 255
    return mask


def concat(*batches: BodySegments) -> BodySegments:
    return BodySegments(np.concatenate([b.origin for b in batches]), np.concatenate([b.rotation for b in batches]))


def assert_agrees(compiled: np.ndarray, reference: np.ndarray) -> None:
    """>= 99 % of the states within 1e-3 (float rounding); the rest within a few cells' worth."""
    assert np.all(np.isfinite(compiled))
    diff = np.abs(compiled - reference)
    close = diff <= 1e-3 + 1e-5 * np.abs(reference)
    assert close.mean() >= 0.99, (close.mean(), np.sort(diff)[-10:])
    assert diff.max() <= 3.0, np.sort(diff)[-10:]


CASES = [
    # distortion, skew, with mask, with flow, config
    ("none", 0.0, False, True, LikelihoodConfig()),
    ("five", 0.0, True, True, LikelihoodConfig()),
    ("eight", 1.5, True, True, LikelihoodConfig()),
    ("eight", 0.0, False, False, LikelihoodConfig()),
    ("five", 0.0, True, True, LikelihoodConfig(self_occlusion=False)),
    ("none", 0.0, True, True, LikelihoodConfig(points_along=7, points_across=3, flow_row_step=2,
                                               appearance_weight=0.7, flow_weight=2.0)),
    ("eight", 0.0, False, True, LikelihoodConfig(appearance_weight=0.0)),
    ("five", 0.0, True, True, LikelihoodConfig(head_top_weight=1.0)),
    ("none", 0.0, False, True, LikelihoodConfig(head_top_weight=2.5)),
]


@pytest.mark.parametrize("case", range(len(CASES)))
def test_compiled_likelihood_matches_numpy_reference(case):
    distortion, skew, with_mask, with_flow, config = CASES[case]
    rng = np.random.default_rng(100 + case)
    camera = make_camera(distortion, skew)
    features = random_features(rng, with_flow)
    if with_mask:
        features = occluded(features, occlusion_mask(rng))
    batch = concat(random_bodies(camera, 1500, rng), walking_bodies(300, rng))
    prev = moved(batch, rng)
    compiled = log_likelihood(BODY.parts, batch, prev, [camera], [features], config=config)
    reference = reference_log_likelihood(BODY.parts, batch, prev, [camera], [features], config=config)
    assert_agrees(compiled, reference)
    # the test bodies do exercise the cases: the head-top term, behind the camera, outside the image, hidden rows
    if config.head_top_weight > 0 and config.appearance_weight > 0:
        without = log_likelihood(BODY.parts, batch, prev, [camera], [features],
                                 config=dataclasses.replace(config, head_top_weight=0.0))
        assert np.mean(compiled < without - 1e-6) > 0.05 and np.all(compiled <= without + 1e-6)
    axes = _project_segments(BODY.parts, batch, _CameraArrays(camera))
    assert (axes[..., 4:] <= 0).any(axis=(1, 2)).mean() > 0.03
    assert ((axes[..., 0] > WIDTH) & (axes[..., 4] > 0)).any(axis=1).mean() > 0.03
    if config.self_occlusion:
        no_occlusion = log_likelihood(BODY.parts, batch, prev, [camera], [features],
                                      config=dataclasses.replace(config, self_occlusion=False))
        assert (no_occlusion != compiled).mean() > 0.2


def test_no_previous_poses_and_several_cameras():
    """prev_segments None (no motion predicted) and three cameras (terms add, eq. 12)."""
    rng = np.random.default_rng(7)
    cameras = [make_camera("none"), make_camera("five"), make_camera("eight", 0.5)]
    features = [random_features(rng) for _ in cameras]
    features[1] = occluded(features[1], occlusion_mask(rng))
    batch = concat(random_bodies(cameras[0], 600, rng), walking_bodies(200, rng))
    compiled = log_likelihood(BODY.parts, batch, None, cameras, features)
    reference = reference_log_likelihood(BODY.parts, batch, None, cameras, features)
    assert_agrees(compiled, reference)
    prev = moved(batch, rng)
    per_camera = sum(camera_log_likelihood(BODY.parts, batch, prev, c, f) for c, f in zip(cameras, features))
    np.testing.assert_allclose(log_likelihood(BODY.parts, batch, prev, cameras, features), per_camera,
                               rtol=1e-12, atol=1e-12)


def test_memo_with_flow_matches_reference():
    """The memo's stored axes serve as the next call's previous poses (flow term)."""
    rng = np.random.default_rng(8)
    camera = make_camera("eight")
    features = [random_features(rng), random_features(rng)]
    first = walking_bodies(400, rng)
    second = moved(first, rng, 0.05)
    memo = SilhouetteMemo()
    log_likelihood(BODY.parts, first, None, [camera], features[:1], memo=memo)
    with_memo = log_likelihood(BODY.parts, second, first, [camera], features[1:], memo=memo)
    np.testing.assert_array_equal(with_memo, log_likelihood(BODY.parts, second, first, [camera], features[1:]))
    assert_agrees(with_memo, reference_log_likelihood(BODY.parts, second, first, [camera], features[1:]))


@pytest.mark.parametrize("distortion", list(DISTORTIONS))
def test_projected_axes_match_camera_project(distortion):
    """The kernel's projection of the axis ends is Camera.project (with its distortion model)."""
    rng = np.random.default_rng(9)
    camera = make_camera(distortion, skew=0.8)
    batch = random_bodies(camera, 300, rng)
    axes = _project_segments(BODY.parts, batch, _CameraArrays(camera))
    for start, end in ((0, batch.origin), (2, batch.end_points(BODY.parts))):
        uv, depth = camera.project(end)
        np.testing.assert_allclose(axes[..., 4 + start // 2], depth, rtol=1e-12, atol=1e-12)
        front = depth > 1e-6
        assert front.any() and not front.all()      # both cases checked
        np.testing.assert_allclose(axes[..., start:start + 2][front], uv[front], rtol=1e-10, atol=1e-8)
        assert np.all(axes[..., start:start + 2][~front] == -1e6)
