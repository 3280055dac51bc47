"""Pixel measurements and the background appearance model (paper Sec. 5.1, Fig. 6).

Measurement per pixel (``measurements``): m = (R, G, B, dI/dx, dI/dy), colour in grey levels
(0-255) and the intensity gradient I = (R + G + B) / 3 in grey levels per pixel, computed on the
image after area-averaging it down by ``downsample`` (the likelihood maps' resolution).

Background (``BackgroundModel``): a per-pixel mean of m and one shared 5x5 covariance. It is
learned either from background-only frames (``learn_background``: per-pixel mean, pooled
covariance of the residuals) or, when the sequence has none, robustly from frames in which
the person moves (``learn_background_robust``: per pixel the densest cluster of colours over the
frames (``_densest_colour``), then pixels whose Mahalanobis residual exceeds a chi-square threshold
are rejected as outliers and the mean and covariance are re-estimated from the inliers). The
densest cluster rather than the temporal median: where a person walks along a camera's view or
plants a foot, they cover a pixel in more than half of the frames, and the median learns them into
the background (a "ghost" that stays foreground after they leave); the background, unlike a moving
person, shows the same colour in every frame it is seen, so its cluster is the tightest even when
it is seen in fewer frames. A covariance floor keeps the model from
becoming over-confident on perfectly static synthetic frames. ``adapt`` blends in a new frame
where it is classified as background (optional slow adaptation). ``illumination_gains``
estimates a global per-channel gain between a frame and the background, so that lighting
changes (camera auto-exposure, clouds) can be divided out before comparing.

Measurements come from one serial numba kernel over the downsampled pixels (``_measurement_kernel``,
no full-resolution float copy), the densest colours from another (``_densest_colour_kernel``);
densities from the compiled kernels of ``vision.densities``, with a model's Cholesky factors
computed once per model, not per frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np

from awalker_tracker.vision.densities import (  # noqa: F401 (constants re-exported)
    MEASUREMENT_DIM,
    SHADOW_DARKEST,
    SHADOW_EDGE_STD,
    SHADOW_PRIOR,
    GaussianFactors,
    as_channels,
    background_kernel,
    component_kernel,
    shadow_covariance,
)

# Per-dimension noise floor (grey levels): RGB, then gradients (grey levels / pixel).
DEFAULT_FLOOR_STD = (3.0, 3.0, 3.0, 2.0, 2.0)
# 99.9 % quantile of chi-square with 5 degrees of freedom: residuals beyond it are outliers.
CHI2_5_999 = 20.515
# Every GAIN_STRIDE-th measurement per axis gives the illumination gains (``illumination_gains``).
GAIN_STRIDE = 3


def measurements(rgb: np.ndarray, downsample: int = 1, reference: np.ndarray | None = None) -> np.ndarray:
    """The 5-D measurement (R, G, B, dI/dx, dI/dy) per pixel of the downsampled image, (h, w, 5) float32.
    With ``reference`` measurements (h, w, 5): expressed in the reference's lighting, i.e. divided by
    ``illumination_gains(m, reference)``, in the same compiled call."""
    image = np.asarray(rgb)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) RGB image, got shape {image.shape}")
    if downsample < 1:
        raise ValueError(f"downsample must be >= 1, got {downsample}")
    if image.dtype != np.uint8:
        image = image.astype(np.float32)
    height, width = image.shape[:2]
    out = np.empty((height // downsample, width // downsample, MEASUREMENT_DIM), np.float32)
    rows = np.ascontiguousarray(image).reshape(height, width * 3)
    if reference is None:
        _measurement_kernel(rows, downsample, out)
    else:
        if np.shape(reference) != out.shape:
            raise ValueError(f"reference measurements of shape {np.shape(reference)}; expected {out.shape}")
        _compensated_measurement_kernel(rows, downsample, np.asarray(reference, np.float32), GAIN_STRIDE, out)
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _measurement_kernel(image: np.ndarray, d: int, out: np.ndarray) -> None:
    """out (h, w, 5) = per d x d block of ``image`` (H, W * 3: RGB rows, channels interleaved)
    its mean colour, then the central differences of the intensity I = (R + G + B) / 3 along x
    and y (grey levels per block; replicated border), all float32."""
    h, w = out.shape[0], out.shape[1]
    inv_area = np.float32(1.0 / (d * d))
    columns = np.empty(w * d * 3, np.float32)     # a row of blocks summed over its d image rows
    for i in range(h):
        columns[:] = 0.0
        for y in range(i * d, (i + 1) * d):
            row = image[y]
            for q in range(w * d * 3):
                columns[q] += row[q]
        for j in range(w):
            for ch in range(3):
                total = np.float32(0.0)
                for x in range(j * d, (j + 1) * d):
                    total += columns[3 * x + ch]
                out[i, j, ch] = total * inv_area
    grey = np.empty((h, w), np.float32)
    for i in range(h):
        for j in range(w):
            grey[i, j] = (out[i, j, 0] + out[i, j, 1] + out[i, j, 2]) / np.float32(3.0)
    half = np.float32(0.5)
    for i in range(h):
        up, down = max(i - 1, 0), min(i + 1, h - 1)
        for j in range(w):
            left, right = max(j - 1, 0), min(j + 1, w - 1)
            out[i, j, 3] = (grey[i, right] - grey[i, left]) * half
            out[i, j, 4] = (grey[down, j] - grey[up, j]) * half


@dataclass(frozen=True, eq=False)
class BackgroundModel:
    """Per-pixel mean (h, w, 5) and shared covariance (5, 5) of the background measurement.

    ``log_likelihood`` also explains shadows: the background scaled by the factor in
    [SHADOW_DARKEST, 1] that best matches the measurement's colour, mixed in with prior SHADOW_PRIOR,
    its gradient channels wider by SHADOW_EDGE_STD (a soft shadow's penumbra has gradients of its own).
    A person's contact shadow is then not foreground, so it does not pull the body's feet toward the
    camera; a real colour change still is."""

    mean: np.ndarray
    covariance: np.ndarray
    shadows: bool = True

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.mean.shape[0]), int(self.mean.shape[1])

    @cached_property
    def kernel_arguments(self) -> tuple:
        """The model as ``densities.background_block`` takes it (computed once per model): the mean in the
        kernels' layout (5, h * w) float32, the inverse Cholesky factor and log normaliser of the
        covariance, ``shadows``, and those of the shadow component (``densities.shadow_covariance``)."""
        lit = GaussianFactors.of(self.covariance[None])
        shaded = GaussianFactors.of(shadow_covariance(self.covariance)[None])
        return (as_channels(self.mean), lit.inv_chol[0], float(lit.log_norm[0]), bool(self.shadows),
                shaded.inv_chol[0], float(shaded.log_norm[0]))

    def log_likelihood(self, m: np.ndarray) -> np.ndarray:
        """log p_bg(m) per pixel for measurements (h, w, 5) -> (h, w) float32 (with shadows, see the class)."""
        x = as_channels(m)
        out = np.empty(x.shape[1], np.float32)
        background_kernel(x, *self.kernel_arguments, out)
        return out.reshape(m.shape[:-1])

    def mahalanobis2(self, m: np.ndarray) -> np.ndarray:
        """Squared Mahalanobis distance of each pixel's measurement from the background, (h, w)."""
        d = (m - self.mean).reshape(-1, MEASUREMENT_DIM)
        inv = np.linalg.inv(self.covariance).astype(np.float32)
        return np.einsum("ki,ij,kj->k", d, inv, d).reshape(m.shape[:2])

    def foreground_mask(self, m: np.ndarray, threshold: float = CHI2_5_999) -> np.ndarray:
        """Pixels that differ from the background beyond a chi-square threshold, (h, w) bool."""
        return self.mahalanobis2(m) > threshold

    def adapt(self, m: np.ndarray, rate: float, foreground: np.ndarray | None = None) -> "BackgroundModel":
        """Blend measurements into the mean at ``rate`` (0-1) where not ``foreground`` (default:
        where the pixel matches the background)."""
        keep = self.foreground_mask(m) if foreground is None else foreground
        weight = np.where(keep, 0.0, rate).astype(np.float32)[..., None]
        return BackgroundModel(self.mean + weight * (m - self.mean), self.covariance, self.shadows)


def illumination_gains(m: np.ndarray, reference: np.ndarray, stride: int = GAIN_STRIDE) -> np.ndarray:
    """Per-channel gains (5,) float32 mapping ``reference`` measurements (h, w, 5) to ``m``: the median
    ratio of each colour channel over every ``stride``-th pixel (robust to the person, who covers
    a small part of the image), the mean colour gain for the two gradient channels, within [0.05, 20]."""
    gains = np.empty(MEASUREMENT_DIM, np.float32)
    _gains_kernel(np.asarray(m, np.float32), np.asarray(reference, np.float32), stride, gains)
    return gains


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _gains_kernel(m: np.ndarray, reference: np.ndarray, stride: int, gains: np.ndarray) -> None:
    """``illumination_gains`` into gains (5,) float32 (float32 arithmetic, as numpy's on float32 arrays)."""
    gains[:] = 1.0
    _colour_gains(m, reference, stride, gains)
    gains[3] = gains[4] = (gains[0] + gains[1] + gains[2]) / np.float32(3.0)
    for c in range(MEASUREMENT_DIM):
        gains[c] = min(max(gains[c], np.float32(0.05)), np.float32(20.0))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _compensated_measurement_kernel(image: np.ndarray, d: int, reference: np.ndarray, stride: int,
                                    out: np.ndarray) -> None:
    """``_measurement_kernel``'s measurements divided by their ``illumination_gains`` against ``reference``:
    one call, so that a thread taking the interpreter lock back after each call waits once."""
    _measurement_kernel(image, d, out)
    gains = np.empty(MEASUREMENT_DIM, np.float32)
    _gains_kernel(out, reference, stride, gains)
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            for c in range(MEASUREMENT_DIM):
                out[i, j, c] = out[i, j, c] / gains[c]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _colour_gains(m: np.ndarray, reference: np.ndarray, stride: int, gains: np.ndarray) -> None:
    """gains[c] = median of m / reference in colour channel c over every ``stride``-th pixel per
    axis where the reference is brighter than 8 grey levels (left as is below 16 such pixels)."""
    ratios = np.empty(((m.shape[0] + stride - 1) // stride) * ((m.shape[1] + stride - 1) // stride), np.float32)
    for c in range(3):
        count = 0
        for i in range(0, m.shape[0], stride):
            for j in range(0, m.shape[1], stride):
                if reference[i, j, c] > 8.0:
                    ratios[count] = m[i, j, c] / reference[i, j, c]
                    count += 1
        if count >= 16:
            gains[c] = np.median(ratios[:count])


def gaussian_log_density(residual: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """log N(residual; 0, covariance) over the last axis (5-D), float32."""
    f = GaussianFactors.of(np.asarray(covariance)[None])
    x = as_channels(residual)
    out = np.empty((1, x.shape[1]))
    component_kernel(x, np.zeros((1, MEASUREMENT_DIM)), f.inv_chol, f.log_norm, out)
    return out[0].astype(np.float32).reshape(residual.shape[:-1])


def _floored(cov: np.ndarray, floor_std: tuple[float, ...]) -> np.ndarray:
    return cov + np.diag(np.square(np.asarray(floor_std, float)))


def learn_background(frames: list[np.ndarray] | np.ndarray, downsample: int = 1,
                     floor_std: tuple[float, ...] = DEFAULT_FLOOR_STD) -> BackgroundModel:
    """Background from background-only RGB frames: per-pixel mean, pooled residual covariance + floor."""
    return fit_background(_stack(frames, downsample), floor_std)


def fit_background(stack: np.ndarray, floor_std: tuple[float, ...] = DEFAULT_FLOOR_STD) -> BackgroundModel:
    """``learn_background`` on a measurement stack (F, h, w, 5)."""
    mean = stack.mean(axis=0)
    residual = (stack - mean).reshape(-1, MEASUREMENT_DIM).astype(np.float64)
    dof = max(len(stack) - 1, 1)
    cov = residual.T @ residual / (dof * stack.shape[1] * stack.shape[2])
    return BackgroundModel(mean.astype(np.float32), _floored(cov, floor_std))


def learn_background_robust(frames: list[np.ndarray] | np.ndarray, downsample: int = 1,
                            floor_std: tuple[float, ...] = DEFAULT_FLOOR_STD,
                            iterations: int = 2) -> BackgroundModel:
    """Background from frames that may show the moving person: per pixel the densest colour cluster,
    then the inlier mean and covariance after rejecting residuals beyond the 99.9 % chi-square bound."""
    return fit_background_robust(_stack(frames, downsample), floor_std, iterations)


def fit_background_robust(stack: np.ndarray, floor_std: tuple[float, ...] = DEFAULT_FLOOR_STD,
                          iterations: int = 2) -> BackgroundModel:
    """``learn_background_robust`` on a measurement stack (F, h, w, 5)."""
    mean = _densest_colour(stack)
    residual = (stack - mean).reshape(-1, MEASUREMENT_DIM)
    # Start from a robust (MAD) per-dimension scale (over at most ~200k samples: it is only a start),
    # then refine with inlier statistics.
    mad = 1.4826 * np.median(np.abs(residual[:: max(1, len(residual) // 200_000)]), axis=0).astype(np.float64)
    cov = _floored(np.diag(np.square(mad)), floor_std)
    for _ in range(iterations):
        model = BackgroundModel(mean, cov)
        inlier = np.stack([~model.foreground_mask(frame) for frame in stack])  # (F, h, w)
        counts = inlier.sum(axis=0)
        summed = np.where(inlier[..., None], stack, 0.0).sum(axis=0)
        mean = np.where(counts[..., None] > 0, summed / np.maximum(counts, 1)[..., None], mean).astype(np.float32)
        resid = (stack - mean)[inlier].astype(np.float64)
        if len(resid) > MEASUREMENT_DIM:
            cov = _floored(resid.T @ resid / len(resid), floor_std)
    return BackgroundModel(mean, cov)


def colour_noise_radius(stack: np.ndarray, factor: float = 3.0, floor: float = 6.0) -> float:
    """Distance (grey levels, RGB) within which two frames' colours of a static pixel fall: ``factor``
    times the robust scale of frame-to-frame colour differences (most pixels are static
    background), at least ``floor``."""
    if len(stack) < 2:
        return floor
    diff = np.abs(np.diff(stack[..., :3], axis=0)).reshape(-1, 3)
    scale = 1.4826 * np.median(diff, axis=0)
    return max(factor * float(np.sqrt(np.sum(np.square(scale)))), floor)


def _densest_colour(stack: np.ndarray) -> np.ndarray:
    """Per pixel of a measurement stack (F, h, w, 5) the mean (h, w, 5) float32 of the frames whose
    colour lies within ``colour_noise_radius`` of the frame with the most such neighbours (the
    latest such frame on a tie): the pixel's most often seen steady colour."""
    frames = np.ascontiguousarray(stack, np.float32)
    out = np.empty(frames.shape[1:], np.float32)
    _densest_colour_kernel(frames, np.float32(colour_noise_radius(frames) ** 2), out)
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _colour_distance2(frames: np.ndarray, a: int, b: int, i: int, j: int) -> float:
    """Squared RGB distance between frames a and b of a stack (F, h, w, 5) at pixel (i, j)."""
    d0 = frames[a, i, j, 0] - frames[b, i, j, 0]
    d1 = frames[a, i, j, 1] - frames[b, i, j, 1]
    d2 = frames[a, i, j, 2] - frames[b, i, j, 2]
    return d0 * d0 + d1 * d1 + d2 * d2


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _densest_colour_kernel(frames: np.ndarray, radius2: np.float32, out: np.ndarray) -> None:
    """``_densest_colour`` of frames (F, h, w, 5) into out (h, w, 5): per pixel, count for each frame j
    the frames whose RGB lies within sqrt(radius2) of frame j's; average all 5 measurements over the
    frames near the best j."""
    count_frames, h, w, dims = frames.shape
    near = np.empty(count_frames, np.bool_)
    for i in range(h):
        for j in range(w):
            best, best_count = 0, -1
            for a in range(count_frames):
                count = 0
                for b in range(count_frames):
                    if _colour_distance2(frames, a, b, i, j) < radius2:
                        count += 1
                if count >= best_count:
                    best, best_count = a, count
            members = 0
            for b in range(count_frames):
                near[b] = _colour_distance2(frames, best, b, i, j) < radius2
                members += near[b]
            for k in range(dims):
                total = np.float32(0.0)
                for b in range(count_frames):
                    if near[b]:
                        total += frames[b, i, j, k]
                out[i, j, k] = total / np.float32(members)


def _stack(frames: list[np.ndarray] | np.ndarray, downsample: int) -> np.ndarray:
    frames = list(frames)
    if not frames:
        raise ValueError("background learning needs at least one frame")
    return np.stack([measurements(f, downsample) for f in frames])
