"""Grid flow: accuracy on known motion, covariance from the gradient tensor, eq. (9)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.stats import multivariate_t

from awalker_tracker.vision.flow import FlowConfig, FlowGrid, GridFlow, student_t_e2, student_t_log_ratio, to_grey
from awalker_tracker.vision.render import render
from vision_scene import BODY, background_image, render_frames, side_camera, walking_poses


def shifted_pair(dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
    cam = side_camera(400, 300)
    big = background_image(cam, seed=4)
    warp = np.float32([[1, 0, dx], [0, 1, dy]])
    return big[20:260, 20:340], cv2.warpAffine(big, warp, (400, 300), flags=cv2.INTER_CUBIC)[20:260, 20:340]


@pytest.mark.parametrize("motion", [(2.3, -1.2), (-0.6, 0.4), (5.5, 3.0)])
def test_translation_is_recovered_on_every_textured_cell(motion):
    a, b = shifted_pair(*motion)
    grid = GridFlow(FlowConfig(cell_size=16)).estimate(to_grey(a), to_grey(b))
    assert grid.shape == (15, 20)
    assert grid.valid.mean() > 0.9
    error = np.linalg.norm(grid.flow - np.asarray(motion), axis=-1)[grid.valid]
    assert np.median(error) < 0.2
    assert np.percentile(error, 90) < 0.5
    assert np.allclose(grid.centers[0, 0], [7.5, 7.5]) and np.allclose(grid.centers[1, 2], [39.5, 23.5])


def test_walker_flow_matches_rendered_motion():
    """Median endpoint error over cells the body covers (>= 70 %) in the second frame against the
    rendered motion of those pixels."""
    cam = side_camera(640, 480, 600.0)
    poses = walking_poses(4)
    frames, _ = render_frames(cam, poses, background_image(cam))
    seg_a, seg_b = poses[1].segments(), poses[2].segments()
    result = render(BODY, seg_b, cam)           # the flow belongs to the second frame's pixels
    v, u = np.nonzero(result.labels >= 0)
    part = result.labels[v, u]
    local = result.local[v, u]
    world_a = seg_a.origin[0][part] + np.einsum("kij,kj->ki", seg_a.rotation[0][part], local)
    world_b = seg_b.origin[0][part] + np.einsum("kij,kj->ki", seg_b.rotation[0][part], local)
    motion = cam.project(world_b)[0] - cam.project(world_a)[0]
    grid = GridFlow(FlowConfig(cell_size=16)).estimate(to_grey(frames[1]), to_grey(frames[2]))
    cell = (v // 16) * grid.shape[1] + (u // 16)
    counts = np.bincount(cell, minlength=grid.shape[0] * grid.shape[1])
    mean_motion = np.stack([np.bincount(cell, motion[:, i], minlength=counts.size) for i in range(2)], -1)
    covered = np.flatnonzero(counts >= 0.7 * 256)
    assert covered.size >= 15
    truth = mean_motion[covered] / counts[covered, None]
    error = np.linalg.norm(grid.flow.reshape(-1, 2)[covered] - truth, axis=1)
    assert np.median(np.linalg.norm(truth, axis=1)) > 2.0       # the body does move
    assert np.median(error) < 1.5
    # Background cells far from the body: zero motion.
    far = counts == 0
    assert np.median(np.linalg.norm(grid.flow.reshape(-1, 2)[far], axis=1)) < 0.2


def test_flow_belongs_to_the_current_frame():
    """The scene zooming in by 8 % about the image centre c: a pixel q of the current frame came from
    c + (q - c) / 1.08, so its motion is (1 - 1 / 1.08) (q - c), while the pixel p of the previous
    frame moves by 0.08 (p - c). The cells carry the first (the likelihood samples them under the
    current pose): 0.6 px apart from the second 100 px out."""
    cam = side_camera(400, 300)
    big = background_image(cam, seed=4)
    centre = np.array([159.5, 119.5]) + 20               # the 320x240 crop's centre in the big image
    zoom = 1.08
    warp = np.float32([[zoom, 0, (1 - zoom) * centre[0]], [0, zoom, (1 - zoom) * centre[1]]])
    previous, current = big[20:260, 20:340], cv2.warpAffine(big, warp, (400, 300), flags=cv2.INTER_CUBIC)[20:260, 20:340]
    grid = GridFlow(FlowConfig(cell_size=16)).estimate(to_grey(previous), to_grey(current))
    offset = grid.centers - (centre - 20)
    far = grid.valid & (np.linalg.norm(offset, axis=-1) > 60)
    far[[0, -1], :] = far[:, [0, -1]] = False           # the border cells: content enters the frame there
    assert far.sum() > 100
    of_current = np.linalg.norm(grid.flow - (1 - 1 / zoom) * offset, axis=-1)[far]
    of_previous = np.linalg.norm(grid.flow - (zoom - 1) * offset, axis=-1)[far]
    assert np.median(of_current) < 0.35                 # 0.24 (against the previous frame's model 0.69)
    assert np.median(of_previous) > 2 * np.median(of_current)


def test_covariance_follows_the_gradient_tensor():
    rng = np.random.default_rng(0)
    flat = np.full((64, 64), 120, np.uint8)
    stripes = np.tile((127 + 60 * np.sin(np.arange(64) / 2.0)).astype(np.uint8), (64, 1))  # vary along x only
    texture = cv2.GaussianBlur(rng.uniform(0, 255, (64, 64)).astype(np.uint8), (3, 3), 0)
    image = np.concatenate([flat, stripes, texture], axis=1)
    grid = GridFlow(FlowConfig(cell_size=32)).estimate(image, image)
    valid = grid.valid.reshape(2, 3, 2)
    assert not valid[:, 0].any()                    # untextured: no estimate
    assert not valid[:, 1].any()                    # 1-D texture: aperture problem
    assert valid[:, 2].all()
    # On the 1-D texture the tensor's inverse is much larger along y than along x.
    big = GridFlow(FlowConfig(cell_size=32, min_texture=0.0)).estimate(image, image)
    c = big.covariance[0, 2]
    assert c[1, 1] > 10 * c[0, 0]
    assert np.allclose(big.covariance[0, 4], big.covariance[0, 4].T)
    assert big.covariance[0, 4][0, 0] < 1.5 and big.covariance[0, 4][1, 1] < 1.5


def test_student_t_is_eq9_with_two_degrees_of_freedom():
    """The functions the likelihood kernel inlines (vision.flow.student_t_e2, student_t_log_ratio) are eq. (9):
    log p(v | u) up to a constant, and log p(v | u) - log p(v | 0) exactly; called on scalars (as in the
    kernel) and on arrays (as the flow table and the numpy reference call them) alike."""
    rng = np.random.default_rng(1)
    offsets, ratios = [], []
    for _ in range(20):
        a = rng.normal(size=(2, 2))
        cov = a @ a.T + 0.2 * np.eye(2)
        v, u = rng.normal(size=2) * 2, rng.normal(size=2)
        (i00, i01), (_, i11) = np.linalg.inv(cov)
        e2 = student_t_e2(*(v - u), i00, i01, i11)
        ours = -0.5 * np.linalg.slogdet(cov)[1] + student_t_log_ratio(e2, 0.0)
        truth = multivariate_t(loc=u, shape=cov, df=2)
        offsets.append(ours - truth.logpdf(v))
        e0 = student_t_e2(*v, i00, i01, i11)
        ratios.append(student_t_log_ratio(e2, np.log1p(e0)) - (truth.logpdf(v) - multivariate_t(
            loc=np.zeros(2), shape=cov, df=2).logpdf(v)))
        # arrays give the scalar results
        assert student_t_e2(np.array([v[0] - u[0]]), np.array([v[1] - u[1]]), np.array([i00]), np.array([i01]),
                            np.array([i11]))[0] == e2
    assert np.ptp(offsets) < 1e-9                  # equal up to the constant c
    assert np.max(np.abs(ratios)) < 1e-9
    assert student_t_log_ratio(student_t_e2(0.0, 0.0, 1.0, 0.0, 1.0), 0.0) == 0.0
    assert student_t_log_ratio(student_t_e2(1.0, 1.0, 1.0, 0.0, 1.0), 0.0) == pytest.approx(-2 * np.log(2.0))


def test_empty_grid_and_size_mismatch():
    grid = FlowGrid.empty(480, 640, 16)
    assert grid.shape == (30, 40) and not grid.valid.any()
    with pytest.raises(ValueError):
        GridFlow().estimate(np.zeros((10, 10), np.uint8), np.zeros((12, 10), np.uint8))
