"""Pixel measurements and the background appearance model (paper Sec. 5.1, Fig. 6).

Measurement per pixel (``measurements``): m = (R, G, B, dI/dx, dI/dy), colour in grey levels
(0-255) and the intensity gradient I = (R + G + B) / 3 in grey levels per pixel, computed on the
image after area-averaging it down by ``downsample`` (the likelihood maps' resolution).

Background (``BackgroundModel``): a per-pixel mean of m and one shared 5x5 covariance. It is
learned either from background-only frames (``learn_background``: per-pixel mean, pooled
covariance of the residuals) or, when the sequence has none, robustly from frames in which
the person moves (``learn_background_robust``: the temporal median, then pixels whose
Mahalanobis residual exceeds a chi-square threshold are rejected as outliers and the mean and
covariance are re-estimated from the inliers). A covariance floor keeps the model from
becoming over-confident on perfectly static synthetic frames. ``adapt`` blends in a new frame
where it is classified as background (optional slow adaptation). ``illumination_gains``
estimates a global per-channel gain between a frame and the background, so that lighting
changes (camera auto-exposure, clouds) can be divided out before comparing.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

MEASUREMENT_DIM = 5
# Per-dimension noise floor (grey levels): RGB, then gradients (grey levels / pixel).
DEFAULT_FLOOR_STD = (3.0, 3.0, 3.0, 2.0, 2.0)
# 99.9 % quantile of chi-square with 5 degrees of freedom: residuals beyond it are outliers.
CHI2_5_999 = 20.515


def downsample_image(rgb: np.ndarray, downsample: int) -> np.ndarray:
    """Area-average an (H, W, 3) image by an integer factor -> (H // d, W // d, 3) float32."""
    image = np.asarray(rgb)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) RGB image, got shape {image.shape}")
    if downsample < 1:
        raise ValueError(f"downsample must be >= 1, got {downsample}")
    h, w = image.shape[0] // downsample, image.shape[1] // downsample
    image = image[: h * downsample, : w * downsample].astype(np.float32)
    if downsample == 1:
        return image
    return cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)


def measurements(rgb: np.ndarray, downsample: int = 1) -> np.ndarray:
    """The 5-D measurement (R, G, B, dI/dx, dI/dy) per pixel of the downsampled image, (h, w, 5) float32."""
    small = downsample_image(rgb, downsample)
    grey = small.mean(axis=2)
    # Central differences (grey levels per downsampled pixel); replicated border.
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=1, borderType=cv2.BORDER_REPLICATE) * 0.5
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=1, borderType=cv2.BORDER_REPLICATE) * 0.5
    return np.concatenate([small, gx[..., None], gy[..., None]], axis=2)


# Shadows: a background pixel darkened to between SHADOW_DARKEST and 1 times its brightness (a person's
# shadow on the floor) is still background, with this prior probability.
SHADOW_DARKEST = 0.4
SHADOW_PRIOR = 0.1


@dataclass(frozen=True, eq=False)
class BackgroundModel:
    """Per-pixel mean (h, w, 5) and shared covariance (5, 5) of the background measurement.

    ``log_likelihood`` also explains shadows: the background scaled by the factor in
    [SHADOW_DARKEST, 1] that best matches the measurement (colour and gradients alike), mixed in with
    prior SHADOW_PRIOR. A person's contact shadow is then not foreground, so it does not pull the
    body's feet toward the camera; a real colour change still is."""

    mean: np.ndarray
    covariance: np.ndarray
    shadows: bool = True

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.mean.shape[0]), int(self.mean.shape[1])

    def log_likelihood(self, m: np.ndarray) -> np.ndarray:
        """log p_bg(m) per pixel for measurements (h, w, 5) -> (h, w) float32 (with shadows, see the class)."""
        lit = gaussian_log_density(m - self.mean, self.covariance)
        if not self.shadows:
            return lit
        colour = self.mean[..., :3]
        scale = np.sum(m[..., :3] * colour, axis=-1) / np.maximum(np.sum(colour * colour, axis=-1), 1e-6)
        scale = np.clip(scale, SHADOW_DARKEST, 1.0)[..., None]
        shaded = gaussian_log_density(m - scale * self.mean, self.covariance) + np.float32(np.log(SHADOW_PRIOR))
        return np.logaddexp(lit, shaded).astype(np.float32)

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


def illumination_gains(m: np.ndarray, reference: np.ndarray, stride: int = 3) -> np.ndarray:
    """Per-channel gains (5,) mapping ``reference`` measurements (h, w, 5) to ``m``: the median
    ratio of each colour channel over every ``stride``-th pixel (robust to the person, who covers
    a small part of the image), the mean colour gain for the two gradient channels."""
    sample = m[::stride, ::stride, :3].reshape(-1, 3)
    ref = reference[::stride, ::stride, :3].reshape(-1, 3)
    gains = np.ones(MEASUREMENT_DIM, np.float32)
    for c in range(3):
        bright = ref[:, c] > 8.0
        if np.count_nonzero(bright) >= 16:
            gains[c] = np.median(sample[bright, c] / ref[bright, c])
    gains[3:] = gains[:3].mean()
    return np.clip(gains, 0.05, 20.0)


def gaussian_log_density(residual: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """log N(residual; 0, covariance) over the last axis (5-D), float32."""
    chol = np.linalg.cholesky(covariance)
    inv_chol = np.linalg.inv(chol).astype(np.float32)
    dim = covariance.shape[0]
    flat = np.ascontiguousarray(residual.reshape(-1, dim), np.float32)
    z = cv2.gemm(flat, np.ascontiguousarray(inv_chol.T), 1.0, None, 0.0)    # single-threaded
    quad = cv2.gemm(z * z, np.ones((dim, 1), np.float32), 1.0, None, 0.0)[:, 0]
    log_det = 2.0 * np.sum(np.log(np.diag(chol)))
    out = -0.5 * quad - np.float32(0.5 * (log_det + dim * np.log(2 * np.pi)))
    return out.reshape(residual.shape[:-1]).astype(np.float32, copy=False)


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
    """Background from frames that may show the moving person: temporal median, then the
    inlier mean and covariance after rejecting residuals beyond the 99.9 % chi-square bound."""
    return fit_background_robust(_stack(frames, downsample), floor_std, iterations)


def fit_background_robust(stack: np.ndarray, floor_std: tuple[float, ...] = DEFAULT_FLOOR_STD,
                          iterations: int = 2) -> BackgroundModel:
    """``learn_background_robust`` on a measurement stack (F, h, w, 5)."""
    mean = np.median(stack, axis=0).astype(np.float32)
    residual = (stack - mean).reshape(-1, MEASUREMENT_DIM).astype(np.float64)
    # Start from a robust (MAD) per-dimension scale, then refine with inlier statistics.
    mad = 1.4826 * np.median(np.abs(residual), axis=0)
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


def _stack(frames: list[np.ndarray] | np.ndarray, downsample: int) -> np.ndarray:
    frames = list(frames)
    if not frames:
        raise ValueError("background learning needs at least one frame")
    return np.stack([measurements(f, downsample) for f in frames])
