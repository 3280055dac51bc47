"""Compiled per-pixel Gaussian densities of the appearance models (background and foreground).

Serial numba kernels over pixels (parallel loops were slower on a shared 2-core host), float64
inside, float32 maps out. Measurements are channel-major (5, M) (``as_channels``) so that the
loops over pixels vectorise: ``gauss_block`` (one 5-D Gaussian, from its inverse Cholesky factor
``GaussianFactors``, computed once per model, not per frame) and ``background_block`` (the
background density with shadows, see ``background.BackgroundModel``) evaluate a block of pixels;
the kernels built from them are ``background_kernel``, ``component_kernel`` (a mixture's
components, also for EM) and ``ratio_kernel`` (the fused per-class log-likelihood ratio maps of
``foreground.ForegroundModel.log_likelihood_ratios``).

They live in one module on purpose: numba's on-disk cache is invalidated by a change of the
file that defines a kernel, not of the files whose functions it inlines.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

MEASUREMENT_DIM = 5               # (R, G, B, dI/dx, dI/dy), see ``background.measurements``
# Shadows: a background pixel darkened to between SHADOW_DARKEST and 1 times its brightness (a person's
# shadow on the floor) is still background, with this prior probability. Darker than half the floor is
# left to the foreground: dark shoes on a floor of their hue (0.3-0.45 of it on our renders) would
# otherwise pass for shadow.
SHADOW_DARKEST = 0.5
SHADOW_PRIOR = 0.1
LOG_SHADOW_PRIOR = float(np.log(SHADOW_PRIOR))
# A soft shadow's penumbra has intensity gradients of its own (background brightness times the gradient
# of the darkening), which the background's gradients scaled by the darkening cannot explain: the shadow
# component's gradient channels get this much more standard deviation (grey levels per pixel). Without it
# the contact shadow around a person's feet (colour matched to 1-2 grey levels, gradients 7-18 standard
# deviations off on dressed CMU renders) is neither background nor foreground, so a model foot can sit
# on it, below the real foot: nearer a single camera. Wider lets dark clothes with the floor's hue pass for
# shadow, their own texture no longer telling them apart. One camera, dressed CMU walks 07_01/07_02
# straight and veer-left, 5000 particles, tracker seeds 0-2, absolute median (mm): no allowance (and
# darkest 0.4) 225/178/212/-, 12 with darkest 0.4: 129/125/142/137, 6 with 0.5: 99/116/149/117, 4 with
# 0.5: 136/149/257/161.
SHADOW_EDGE_STD = 6.0


@dataclass(frozen=True, eq=False)
class GaussianFactors:
    """Per-component Gaussian constants: inverse Cholesky factors L^-1 (K, 5, 5) (lower
    triangular, Sigma = L L^T) and log normalisers -(log|Sigma| + 5 log 2 pi) / 2 (K,), float64."""

    inv_chol: np.ndarray
    log_norm: np.ndarray

    @classmethod
    def of(cls, covariances: np.ndarray) -> "GaussianFactors":
        """Factors of covariances (K, 5, 5) (K small factorisations)."""
        covs = np.asarray(covariances, np.float64)
        chol = np.linalg.cholesky(covs)
        inv_chol = np.linalg.inv(chol)
        log_det = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
        return cls(np.ascontiguousarray(inv_chol), -0.5 * (log_det + covs.shape[-1] * np.log(2 * np.pi)))


def as_channels(m: np.ndarray) -> np.ndarray:
    """(..., 5) measurements as channel-major float32 (5, M), C-contiguous: the kernels' layout
    (a channel's consecutive pixels are adjacent, so loops over pixels vectorise)."""
    flat = np.asarray(m, np.float32).reshape(-1, MEASUREMENT_DIM)
    return np.ascontiguousarray(flat.T)


# ---- kernels ----------------------------------------------------------------------------------
# A log-sum-exp term exp(x) with x below this (relative to the largest term) changes the sum's
# log by under 4.2e-8 nats, below float32 rounding of the maps (which are float32): it is skipped.
NEGLIGIBLE_LOG = -17.0
# Pixels per block of ``ratio_kernel``: its densities are computed a block at a time (vectorised
# loops over pixels), then combined pixel by pixel while the block is in cache.
BLOCK = 64


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _half_quad(L: np.ndarray, d0: float, d1: float, d2: float, d3: float, d4: float) -> float:
    """|L d|^2 / 2 for a lower-triangular 5x5 L (L = inverse Cholesky factor: the Mahalanobis term)."""
    z0 = L[0, 0] * d0
    z1 = L[1, 0] * d0 + L[1, 1] * d1
    z2 = L[2, 0] * d0 + L[2, 1] * d1 + L[2, 2] * d2
    z3 = L[3, 0] * d0 + L[3, 1] * d1 + L[3, 2] * d2 + L[3, 3] * d3
    z4 = L[4, 0] * d0 + L[4, 1] * d1 + L[4, 2] * d2 + L[4, 3] * d3 + L[4, 4] * d4
    return 0.5 * (z0 * z0 + z1 * z1 + z2 * z2 + z3 * z3 + z4 * z4)


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def logaddexp(a: float, b: float) -> float:
    """log(exp(a) + exp(b)) without overflow (a, b not both -inf); a negligible term is skipped
    (``NEGLIGIBLE_LOG``). log(1 + y) rather than log1p(y): half the cost, error below 1e-16 nats."""
    if a < b:
        a, b = b, a
    if b - a < NEGLIGIBLE_LOG:
        return a
    return a + np.log(1.0 + np.exp(b - a))


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def gauss_block(x: np.ndarray, start: int, n: int, mean: np.ndarray, inv_chol: np.ndarray, log_norm: float,
                out: np.ndarray) -> None:
    """out[b] = log_norm - |L (x_p - mean)|^2 / 2 for pixels p = start + b, b < n; x (5, M)."""
    L = inv_chol
    for b in range(n):
        p = start + b
        out[b] = log_norm - _half_quad(L, np.float64(x[0, p]) - mean[0], np.float64(x[1, p]) - mean[1],
                                       np.float64(x[2, p]) - mean[2], np.float64(x[3, p]) - mean[3],
                                       np.float64(x[4, p]) - mean[4])


def shadow_covariance(covariance: np.ndarray) -> np.ndarray:
    """The shadow component's covariance: the background's, gradient channels widened by SHADOW_EDGE_STD."""
    return np.asarray(covariance, np.float64) + np.diag([0.0, 0.0, 0.0, SHADOW_EDGE_STD ** 2, SHADOW_EDGE_STD ** 2])


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def background_block(x: np.ndarray, mean: np.ndarray, start: int, n: int, inv_chol: np.ndarray, log_norm: float,
                     shadows: bool, shadow_inv_chol: np.ndarray, shadow_log_norm: float, out: np.ndarray,
                     shaded: np.ndarray) -> None:
    """out[b] = log p_bg of pixel p = start + b (x, mean (5, M)): the Gaussian around the pixel's
    mean, mixed (prior SHADOW_PRIOR) with the one around the mean darkened by the colour scale in
    [SHADOW_DARKEST, 1] closest to x (covariance ``shadow_covariance``: factors ``shadow_inv_chol``,
    ``shadow_log_norm``). ``shaded``: scratch (>= n)."""
    L = inv_chol
    S = shadow_inv_chol
    for b in range(n):
        p = start + b
        out[b] = log_norm - _half_quad(L, np.float64(x[0, p]) - mean[0, p], np.float64(x[1, p]) - mean[1, p],
                                       np.float64(x[2, p]) - mean[2, p], np.float64(x[3, p]) - mean[3, p],
                                       np.float64(x[4, p]) - mean[4, p])
    if not shadows:
        return
    for b in range(n):
        p = start + b
        num = np.float64(x[0, p]) * mean[0, p] + np.float64(x[1, p]) * mean[1, p] + np.float64(x[2, p]) * mean[2, p]
        den = np.float64(mean[0, p]) * mean[0, p] + np.float64(mean[1, p]) * mean[1, p] + np.float64(mean[2, p]) * mean[2, p]
        s = min(max(num / max(den, 1e-6), SHADOW_DARKEST), 1.0)
        shaded[b] = shadow_log_norm + LOG_SHADOW_PRIOR - _half_quad(
            S, np.float64(x[0, p]) - s * mean[0, p], np.float64(x[1, p]) - s * mean[1, p],
            np.float64(x[2, p]) - s * mean[2, p], np.float64(x[3, p]) - s * mean[3, p],
            np.float64(x[4, p]) - s * mean[4, p])
    for b in range(n):
        out[b] = logaddexp(out[b], shaded[b])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def background_kernel(x: np.ndarray, mean: np.ndarray, inv_chol: np.ndarray, log_norm: float, shadows: bool,
                      shadow_inv_chol: np.ndarray, shadow_log_norm: float, out: np.ndarray) -> None:
    """out (M,) float32 = log p_bg of measurements x with background means ``mean`` (5, M) float32."""
    size = x.shape[1]
    block = np.empty(BLOCK)
    shaded = np.empty(BLOCK)
    for start in range(0, size, BLOCK):
        n = min(BLOCK, size - start)
        background_block(x, mean, start, n, inv_chol, log_norm, shadows, shadow_inv_chol, shadow_log_norm, block,
                         shaded)
        out[start: start + n] = block[:n]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def component_kernel(x: np.ndarray, means: np.ndarray, inv_chol: np.ndarray, log_norm: np.ndarray,
                     out: np.ndarray) -> None:
    """out[k, p] = log N(x_p; means[k], Sigma_k) for x (5, M) float32, means (K, 5) -> out (K, M)."""
    for k in range(means.shape[0]):
        gauss_block(x, 0, x.shape[1], means[k], inv_chol[k], log_norm[k], out[k])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def ratio_kernel(pixels: np.ndarray, bg_mean: np.ndarray, bg_inv_chol: np.ndarray, bg_log_norm: float,
                 shadows: bool, shadow_inv_chol: np.ndarray, shadow_log_norm: float, means: np.ndarray,
                 inv_chol: np.ndarray, log_weight_norm: np.ndarray, log_count: np.ndarray, keep: float, floor: float,
                 clip: float, out: np.ndarray) -> None:
    """Clipped log p_fg,c - log p_bg per pixel and class (see ``ForegroundModel.log_likelihood_ratios``).

    pixels (M, 5) float32: the measurements as they come (``as_channels``' layout is made here, in the same
    call: a feature thread that takes the interpreter lock back once per call waits once, not twice);
    bg_mean (5, M) float32: the background means; the background arguments as
    ``background.BackgroundModel.kernel_arguments`` gives them. Class c's components k:
    means (C, K, 5), inv_chol (C, K, 5, 5), log_weight_norm (C, K) = log weight + log
    normaliser (-inf pads classes with fewer than K), log_count (C,) = log of the real count.
    keep = log(1 - eps), floor = log eps + log uniform density. out (C, M) float32."""
    classes, components = log_weight_norm.shape
    size = pixels.shape[0]
    x = np.empty((MEASUREMENT_DIM, size), np.float32)
    for p in range(size):
        for ch in range(MEASUREMENT_DIM):
            x[ch, p] = pixels[p, ch]
    comp = np.empty((classes, components, BLOCK))
    log_bg = np.empty(BLOCK)
    shaded = np.empty(BLOCK)
    for start in range(0, size, BLOCK):
        n = min(BLOCK, size - start)
        for c in range(classes):
            for k in range(components):
                gauss_block(x, start, n, means[c, k], inv_chol[c, k], log_weight_norm[c, k], comp[c, k])
        background_block(x, bg_mean, start, n, bg_inv_chol, bg_log_norm, shadows, shadow_inv_chol, shadow_log_norm,
                         log_bg, shaded)
        for b in range(n):
            bg = logaddexp(log_bg[b] + keep, floor)
            for c in range(classes):
                top = -np.inf
                for k in range(components):
                    top = max(top, comp[c, k, b])
                if top + log_count[c] + keep - floor < NEGLIGIBLE_LOG:
                    fg = floor        # log p_fg,c <= top + log K_c: negligible next to the outliers
                else:
                    # log-sum-exp over the components; exp(0) and log(1) are not called, negligible terms skipped.
                    total = 0.0
                    for k in range(components):
                        if comp[c, k, b] == top:
                            total += 1.0
                        elif comp[c, k, b] - top >= NEGLIGIBLE_LOG:
                            total += np.exp(comp[c, k, b] - top)
                    fg = logaddexp(top + (np.log(total) if total != 1.0 else 0.0) + keep, floor)
                out[c, start + b] = min(max(fg - bg, -clip), clip)
