"""The compiled feature kernels against straightforward numpy / scipy / OpenCV references.

The references are the plain formulas (per-component scipy densities, log-sum-exp, the
OpenCV resize and Sobel calls the measurements and flow were defined with); they live here only
as oracles. Random inputs cover background, foreground, clipped and floor-dominated pixels."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal

from awalker_tracker.vision.background import (
    SHADOW_DARKEST,
    SHADOW_EDGE_STD,
    SHADOW_PRIOR,
    BackgroundModel,
    gaussian_log_density,
    illumination_gains,
    measurements,
)
from awalker_tracker.vision.flow import FlowConfig, GridFlow, _gradient_tensors, _robust_cell_means
from awalker_tracker.vision.foreground import OUTLIER_LOG_DENSITY, ForegroundModel, GaussianMixture


def random_covariance(rng: np.random.Generator, scale: float) -> np.ndarray:
    a = rng.normal(0, scale, (5, 5))
    return a @ a.T + np.diag(np.square([3.0, 3.0, 3.0, 2.0, 2.0]))


def random_mixture(rng: np.random.Generator, components: int) -> GaussianMixture:
    weights = rng.uniform(0.2, 1.0, components)
    means = np.column_stack([rng.uniform(0, 255, (components, 3)), rng.normal(0, 10, (components, 2))])
    covs = np.stack([random_covariance(rng, rng.uniform(2, 15)) for _ in range(components)])
    return GaussianMixture(weights / weights.sum(), means, covs)


def random_scene(rng: np.random.Generator, h: int = 23, w: int = 31):
    """Background model, foreground model (one class with 2 components: padding) and measurements
    mixing background pixels, shadowed ones, samples of the mixtures and uniform outliers."""
    mean = np.concatenate([rng.uniform(20, 240, (h, w, 3)), rng.normal(0, 5, (h, w, 2))], axis=2).astype(np.float32)
    background = BackgroundModel(mean, random_covariance(rng, 3.0))
    mixtures = tuple(random_mixture(rng, k) for k in (3, 3, 2, 3))
    foreground = ForegroundModel(("head", "torso", "legs", "feet"), mixtures)
    kind = rng.integers(0, 4, (h, w))
    m = mean + rng.normal(0, 3, (h, w, 5)).astype(np.float32)                         # background
    m = np.where((kind == 1)[..., None], mean * rng.uniform(0.3, 1.0, (h, w, 1)).astype(np.float32), m)  # shadows
    samples = np.concatenate([rng.multivariate_normal(mix.means[0], mix.covariances[0], h * w) for mix in mixtures])
    m = np.where((kind == 2)[..., None], samples[rng.integers(0, len(samples), h * w)].reshape(h, w, 5), m)
    uniform = np.concatenate([rng.uniform(0, 255, (h, w, 3)), rng.uniform(-128, 128, (h, w, 2))], axis=2)
    m = np.where((kind == 3)[..., None], uniform, m).astype(np.float32)
    return background, foreground, m


def reference_mixture(mixture: GaussianMixture, x: np.ndarray) -> np.ndarray:
    comp = np.stack([np.log(w) + multivariate_normal(mu, cov).logpdf(x)
                     for w, mu, cov in zip(mixture.weights, mixture.means, mixture.covariances)], axis=-1)
    return logsumexp(comp, axis=-1)


def reference_background(model: BackgroundModel, m: np.ndarray) -> np.ndarray:
    x, mean = m.reshape(-1, 5).astype(np.float64), model.mean.reshape(-1, 5).astype(np.float64)
    gauss = multivariate_normal(np.zeros(5), model.covariance)
    lit = gauss.logpdf(x - mean)
    if not model.shadows:
        return lit.reshape(m.shape[:2])
    scale = np.sum(x[:, :3] * mean[:, :3], axis=1) / np.maximum(np.sum(mean[:, :3] ** 2, axis=1), 1e-6)
    scale = np.clip(scale, SHADOW_DARKEST, 1.0)[:, None]
    widened = model.covariance + np.diag([0.0, 0.0, 0.0, SHADOW_EDGE_STD ** 2, SHADOW_EDGE_STD ** 2])
    shaded = multivariate_normal(np.zeros(5), widened).logpdf(x - scale * mean) + np.log(SHADOW_PRIOR)
    return np.logaddexp(lit, shaded).reshape(m.shape[:2])


def reference_ratios(foreground: ForegroundModel, background: BackgroundModel, m: np.ndarray, clip: float,
                     eps: float) -> np.ndarray:
    floor = np.log(eps) + OUTLIER_LOG_DENSITY
    keep = np.log1p(-eps)
    log_bg = np.logaddexp(reference_background(background, m).reshape(-1) + keep, floor)
    x = m.reshape(-1, 5).astype(np.float64)
    out = [np.clip(np.logaddexp(reference_mixture(mix, x) + keep, floor) - log_bg, -clip, clip)
           for mix in foreground.mixtures]
    return np.stack(out).reshape((len(out),) + m.shape[:2])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("shadows", [True, False])
def test_ratio_kernel_matches_the_reference(seed, shadows):
    rng = np.random.default_rng(seed)
    background, foreground, m = random_scene(rng)
    background = BackgroundModel(background.mean, background.covariance, shadows)
    for clip, eps in ((25.0, 0.02), (10.0, 0.02), (5.0, 0.2)):
        llr = foreground.log_likelihood_ratios(m, background, clip, eps)
        truth = reference_ratios(foreground, background, m, clip, eps)
        assert llr.dtype == np.float32 and llr.shape == (4,) + m.shape[:2]
        assert np.max(np.abs(llr - truth)) < 1e-4
        # the inputs exercise the clip, the outlier floor and unclipped ratios of both signs
        assert np.any((np.abs(truth) < clip) & (truth > 0)) and np.any((np.abs(truth) < clip) & (truth < 0))
        assert clip == 25.0 or (np.any(truth == clip) and np.any(truth == -clip))


@pytest.mark.parametrize("shadows", [True, False])
def test_background_log_likelihood_matches_the_reference(shadows):
    background, _, m = random_scene(np.random.default_rng(3))
    background = BackgroundModel(background.mean, background.covariance, shadows)
    truth = reference_background(background, m)
    got = background.log_likelihood(m)
    assert got.dtype == np.float32 and got.shape == m.shape[:2]
    assert np.max(np.abs(got - truth) / np.maximum(1.0, np.abs(truth))) < 1e-6


def test_mixture_and_gaussian_densities_match_scipy():
    rng = np.random.default_rng(4)
    mixture = random_mixture(rng, 3)
    x = np.concatenate([rng.multivariate_normal(mu, cov, 50) for mu, cov in zip(mixture.means, mixture.covariances)])
    x = x.astype(np.float32).reshape(10, 15, 5)
    truth = reference_mixture(mixture, x.astype(np.float64))
    assert np.max(np.abs(mixture.log_likelihood(x) - truth)) < 1e-4
    cov = random_covariance(rng, 5.0)
    got = gaussian_log_density(x - 100.0, cov)
    assert got.shape == (10, 15)
    assert np.allclose(got, multivariate_normal(np.zeros(5), cov).logpdf(x.astype(np.float64) - 100.0), rtol=1e-6)


def reference_measurements(rgb: np.ndarray, d: int) -> np.ndarray:
    """The OpenCV definition: area-average the float image, central differences of the grey mean."""
    h, w = rgb.shape[0] // d, rgb.shape[1] // d
    small = rgb[: h * d, : w * d].astype(np.float32)
    if d > 1:
        small = cv2.resize(small, (w, h), interpolation=cv2.INTER_AREA)
    grey = small.mean(axis=2)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=1, borderType=cv2.BORDER_REPLICATE) * 0.5
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=1, borderType=cv2.BORDER_REPLICATE) * 0.5
    return np.concatenate([small, gx[..., None], gy[..., None]], axis=2)


@pytest.mark.parametrize("d", [1, 2, 3, 4])
def test_measurements_match_the_opencv_definition(d):
    rng = np.random.default_rng(d)
    rgb = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    got = measurements(rgb, d)
    assert got.dtype == np.float32 and got.shape == (37 // d, 53 // d, 5)
    assert np.allclose(got, reference_measurements(rgb, d), atol=1e-4)
    readonly = rgb.copy()
    readonly.setflags(write=False)                       # images decoded from messages are read-only
    assert np.array_equal(measurements(readonly, d), got)
    assert np.allclose(measurements(rgb.astype(np.float64), d), got, atol=1e-4)


def test_densest_colour_matches_the_reference():
    """Per pixel: the frame with the most frames within the radius (RGB distance; the latest on a tie),
    and the mean of all five measurements over the frames within the radius of it."""
    from awalker_tracker.vision.background import _densest_colour, colour_noise_radius

    rng = np.random.default_rng(3)
    steady = rng.uniform(0, 255, (1, 6, 7, 5)).astype(np.float32)
    stack = np.repeat(steady, 12, axis=0) + rng.normal(0, 2, (12, 6, 7, 5)).astype(np.float32)
    # a person passing: each pixel covered in one run of 0-8 of the 12 frames, in changing colours
    begin, length = rng.integers(0, 12, (6, 7)), rng.integers(0, 9, (6, 7))
    frame = np.arange(12)[:, None, None]
    visits = (frame >= begin) & (frame < begin + length)
    stack[visits] = rng.uniform(0, 255, (visits.sum(), 5)).astype(np.float32)
    radius2 = colour_noise_radius(stack) ** 2
    rgb = stack[..., :3].astype(np.float64)
    distance2 = np.sum(np.square(rgb[:, None] - rgb[None, :]), axis=-1)     # (F, F, h, w)
    counts = (distance2 < radius2).sum(axis=1)                               # (F, h, w)
    best = len(stack) - 1 - np.argmax(counts[::-1], axis=0)                  # the latest of the most
    near = np.take_along_axis(distance2, best[None, None], axis=1)[:, 0] < radius2
    reference = (np.where(near[..., None], stack, 0.0).sum(axis=0) / near.sum(axis=0)[..., None])
    assert 0 < near.sum() < near.size and len(np.unique(best)) > 3      # the inputs exercise the choice
    assert np.allclose(_densest_colour(stack), reference, atol=1e-3)


def test_illumination_gains_are_median_ratios():
    rng = np.random.default_rng(5)
    reference = rng.uniform(0, 255, (40, 60, 5)).astype(np.float32)
    m = (reference * np.float32([1.3, 0.8, 1.1, 1.0, 1.0]) + rng.normal(0, 1, reference.shape)).astype(np.float32)
    gains = illumination_gains(m, reference)
    sample, ref = m[::3, ::3, :3].reshape(-1, 3), reference[::3, ::3, :3].reshape(-1, 3)
    truth = [np.median(sample[ref[:, c] > 8, c] / ref[ref[:, c] > 8, c]) for c in range(3)]
    assert np.allclose(gains[:3], truth, rtol=1e-6)
    assert np.allclose(gains[3:], np.mean(truth), rtol=1e-6)
    assert np.all(illumination_gains(m, np.zeros_like(reference)) == 1.0)    # too dark: no estimate
    dim = illumination_gains(reference * np.float32(0.01), reference)     # far darker: clipped at 0.05
    assert np.all(dim == np.float32(0.05))


@pytest.mark.parametrize("d", [1, 4])
def test_measurements_in_the_reference_lighting_are_one_call_of_the_two(d):
    """measurements(image, d, reference) is measurements(image, d) / illumination_gains(m, reference), bit for bit."""
    rng = np.random.default_rng(11)
    image = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    lit = np.clip(image * np.float32([1.25, 0.9, 1.05]), 0, 255).astype(np.uint8)
    reference = measurements(image, d)
    m = measurements(lit, d)
    gains = illumination_gains(m, reference)
    assert not np.allclose(gains, 1.0)
    assert np.array_equal(measurements(lit, d, reference), m / gains)
    with pytest.raises(ValueError, match="reference measurements"):
        measurements(lit, d, reference[1:])


def reference_tensors(grey: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = grey.shape[0] // size, grey.shape[1] // size
    g = grey[: rows * size, : cols * size].astype(np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8
    sums = [(p.astype(np.float64)).reshape(rows, size, cols, size).sum(axis=(1, 3)) for p in (gx * gx, gx * gy, gy * gy)]
    return np.stack(sums, -1), cv2.magnitude(gx, gy)


@pytest.mark.parametrize("shape, size", [((96, 128), 16), ((70, 90), 8), ((33, 47), 5)])
def test_gradient_tensors_match_opencv_sobel(shape, size):
    grey = np.random.default_rng(6).integers(0, 256, shape, dtype=np.uint8)
    truth, magnitude = reference_tensors(grey, size)
    rows, cols = truth.shape[:2]
    for step in (1, 2) if size % 2 == 0 else (1,):
        tensor = np.empty((rows, cols, 3))
        got = np.empty((rows * size // step, cols * size // step), np.float32)
        _gradient_tensors(grey, size, step, tensor, got)
        assert np.allclose(tensor, truth, rtol=1e-6)
        assert np.allclose(got, magnitude[::step, ::step], rtol=1e-6)
    with pytest.raises(ValueError):
        _gradient_tensors(grey, size, 3, np.empty((rows, cols, 3)), np.empty((rows * size, cols * size), np.float32))


def reference_robust_means(dense: np.ndarray, weights: np.ndarray, rows: int, cols: int, inv_c2: float,
                           iterations: int) -> np.ndarray:
    """Cauchy IRLS with the cell means as plain reshaped sums."""
    n = dense.shape[0] // rows

    def cell_sum(a: np.ndarray) -> np.ndarray:
        return a.reshape(rows, n, cols, n).sum(axis=(1, 3))

    u, v, w = dense[..., 0].astype(np.float64), dense[..., 1].astype(np.float64), weights.astype(np.float64)
    for iteration in range(iterations + 1):
        est_u, est_v = cell_sum(u * w) / cell_sum(w), cell_sum(v * w) / cell_sum(w)
        du = u - np.kron(est_u, np.ones((n, n)))
        dv = v - np.kron(est_v, np.ones((n, n)))
        w = weights / (1.0 + (du * du + dv * dv) * inv_c2)
    return np.stack([est_u, est_v], -1)


def test_robust_cell_means_match_the_reference():
    rng = np.random.default_rng(7)
    rows, cols, n = 5, 7, 8
    dense = rng.normal(2.0, 0.3, (rows * n, cols * n, 2)).astype(np.float32)
    outliers = rng.random((rows * n, cols * n)) < 0.2
    dense[outliers] += rng.normal(0, 8, (outliers.sum(), 2)).astype(np.float32)
    magnitude = rng.uniform(0, 30, (rows * n, cols * n)).astype(np.float32)
    for iterations in (0, 3):
        out = np.empty((rows, cols, 2))
        _robust_cell_means(dense, magnitude, n, 1.0, 1.0, 1.0, iterations, out)
        truth = reference_robust_means(dense, magnitude + np.float32(1e-3), rows, cols, 1.0, iterations)
        assert np.allclose(out, truth, atol=1e-5)
    # strided views and a flow image at another scale
    out = np.empty((rows, cols, 2))
    _robust_cell_means(dense[::2, ::2], magnitude[::2, ::2], n // 2, 2.0, 0.5, 0.25, 3, out)
    scaled = dense[::2, ::2] * np.float32([2.0, 0.5])
    assert np.allclose(out, reference_robust_means(scaled, magnitude[::2, ::2] + np.float32(1e-3), rows, cols, 0.25, 3),
                       atol=1e-5)


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_grid_flow_matches_the_opencv_reference(scale):
    """GridFlow.estimate against the same model written with OpenCV calls and numpy (same DIS)."""
    rng = np.random.default_rng(8)
    base = cv2.GaussianBlur(rng.integers(0, 256, (200, 260), dtype=np.uint8), (5, 5), 1.5)
    a, b = (np.ascontiguousarray(x) for x in (base[10:170, 10:250], base[12:172, 7:247]))  # shift (3, -2) px
    cfg = FlowConfig(cell_size=16, scale=scale)
    got = GridFlow(cfg).estimate(a, b)
    size, (height, width) = cfg.cell_size, a.shape
    rows, cols = height // size, width // size
    if scale < 1:
        sw, sh = int(round(width * scale)), int(round(height * scale))
        a_s, b_s = (cv2.resize(x, (sw, sh), interpolation=cv2.INTER_AREA) for x in (a, b))
    else:
        a_s, b_s = a, b
    dense = -cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST).calc(b_s, a_s, None)   # backward, negated
    sub = int(round(size * scale))
    dense = dense[: rows * sub, : cols * sub] * np.float32([width / a_s.shape[1], height / a_s.shape[0]])
    tensor, magnitude = reference_tensors(b, size)
    if sub != size:
        magnitude = cv2.resize(magnitude, (cols * sub, rows * sub), interpolation=cv2.INTER_AREA)
    flow = reference_robust_means(dense[::2, ::2], magnitude[::2, ::2] + np.float32(1e-3), rows, cols, 1.0, 3)
    assert np.allclose(got.flow, flow, atol=1e-4)
    txx, txy, tyy = tensor[..., 0], tensor[..., 1], tensor[..., 2]
    eig_min = (0.5 * (txx + tyy) - np.sqrt(0.25 * (txx - tyy) ** 2 + txy ** 2)) / size ** 2
    assert np.array_equal(got.valid, eig_min >= cfg.min_texture) and got.valid.mean() > 0.5
    k = cfg.noise_std ** 2 / (txx * tyy - txy ** 2)
    cov = np.stack([np.stack([k * tyy + 1, -k * txy], -1), np.stack([-k * txy, k * txx + 1], -1)], -2)
    assert np.allclose(got.covariance[got.valid], cov[got.valid], rtol=1e-5)
    assert np.all(got.covariance[~got.valid] == np.diag([1e4, 1e4]).astype(np.float32))
