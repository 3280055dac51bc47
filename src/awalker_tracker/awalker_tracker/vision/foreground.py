"""Foreground appearance: a 3-component Gaussian mixture per part class (paper Sec. 5.1).

Each part class (head, torso, legs, feet) has a mixture over the same 5-D measurement as the
background (``background.measurements``), pixels IID within a part. The paper fitted them to
hand-labelled regions; here they are fitted automatically (``learn_foreground``) to the pixels
of one frame that (a) differ from the background model, as do their 8 neighbours (interior
pixels; edge pixels mix in the background), and (b) carry a part-class label. The
label image comes from projecting the body at the start pose (``render_labels`` mapped to
classes), from a user's label mask, or, when neither exists, from ``band_labels``: the largest
foreground blob is cut into horizontal bands at the body's proportions (head at the top, then
torso, legs, feet at the bottom) — adequate for an upright walker seen from the side or front.

EM with full covariances, a ridge on the covariances (the background floor) so mixtures stay
proper on few or uniform pixels, deterministic farthest-point initialisation.

The per-frame maps (``ForegroundModel.log_likelihood_ratios``) come from one serial numba
kernel over the map pixels (``densities.ratio_kernel``): per pixel the background density with
shadows, every class's mixture (log-sum-exp over its components), the outlier mixing and the
clip, a block of pixels at a time with no image-sized temporaries. The mixtures' Cholesky
factors are computed once per model.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from awalker_tracker.model.body import PART_CLASSES, BodyDescription
from awalker_tracker.vision.background import DEFAULT_FLOOR_STD, BackgroundModel
from awalker_tracker.vision.densities import (
    MEASUREMENT_DIM,
    GaussianFactors,
    as_channels,
    component_kernel,
    ratio_kernel,
)

NUM_COMPONENTS = 3
# log of the uniform density over the measurement range: colour 0-255 (3 dims), gradients
# -128..128 grey levels per pixel (2 dims).
OUTLIER_LOG_DENSITY = -5.0 * np.log(256.0)


@dataclass(frozen=True, eq=False)
class GaussianMixture:
    """weights (K,), means (K, 5), covariances (K, 5, 5)."""

    weights: np.ndarray
    means: np.ndarray
    covariances: np.ndarray

    @cached_property
    def factors(self) -> GaussianFactors:
        """Cholesky factors of the components (computed once per mixture)."""
        return GaussianFactors.of(self.covariances)

    def log_likelihood(self, m: np.ndarray) -> np.ndarray:
        """log p(m) for measurements (..., 5) -> (...) float32 (log-sum-exp over components)."""
        comp = _component_log_densities(m, self.means, self.factors) + np.log(self.weights)
        top = comp.max(axis=1)
        return (top + np.log(np.exp(comp - top[:, None]).sum(axis=1))).astype(np.float32).reshape(m.shape[:-1])


def _component_log_densities(x: np.ndarray, means: np.ndarray, factors: GaussianFactors) -> np.ndarray:
    """log N(x; mean_k, cov_k) for samples (..., 5) and K components -> (M, K) float64."""
    channels = as_channels(x)
    out = np.empty((len(means), channels.shape[1]))
    component_kernel(channels, np.ascontiguousarray(means, np.float64), factors.inv_chol, factors.log_norm, out)
    return out.T


def fit_mixture(samples: np.ndarray, components: int = NUM_COMPONENTS, iterations: int = 40,
                floor_std: tuple[float, ...] = DEFAULT_FLOOR_STD, seed: int = 0,
                max_samples: int = 4000) -> GaussianMixture:
    """EM fit of a full-covariance Gaussian mixture to samples (M, 5); ridge = floor_std^2."""
    x = np.asarray(samples, np.float64).reshape(-1, MEASUREMENT_DIM)
    if len(x) == 0:
        raise ValueError("fit_mixture: no samples")
    rng = np.random.default_rng(seed)
    if len(x) > max_samples:
        x = x[rng.choice(len(x), max_samples, replace=False)]
    ridge = np.diag(np.square(np.asarray(floor_std, float)))
    k = min(components, len(x))
    # Farthest-point initialisation (deterministic given the seed).
    centres = [x[rng.integers(len(x))]]
    for _ in range(1, k):
        d2 = np.min([np.sum((x - c) ** 2, axis=1) for c in centres], axis=0)
        centres.append(x[int(np.argmax(d2))])
    means = np.array(centres)
    cov0 = np.cov(x.T) + ridge if len(x) > 1 else ridge
    covs = np.repeat(cov0[None], k, axis=0)
    weights = np.full(k, 1.0 / k)
    for _ in range(iterations):
        log_r = _component_log_densities(x, means, GaussianFactors.of(covs)) + np.log(weights)
        log_r -= log_r.max(axis=1, keepdims=True)
        r = np.exp(log_r)
        r /= r.sum(axis=1, keepdims=True)
        nk = r.sum(axis=0) + 1e-9
        weights = nk / nk.sum()
        means = (r.T @ x) / nk[:, None]
        for j in range(k):
            d = x - means[j]
            covs[j] = (r[:, j, None] * d).T @ d / nk[j] + ridge
    return GaussianMixture(weights, means, covs)


@dataclass(frozen=True, eq=False)
class ForegroundModel:
    """One mixture per part class, in ``classes`` order."""

    classes: tuple[str, ...]
    mixtures: tuple[GaussianMixture, ...]

    def log_likelihood_ratios(self, m: np.ndarray, background: BackgroundModel, clip: float,
                              outlier_probability: float = 0.02) -> np.ndarray:
        """log p_fg,c(m) - log p_bg(m) per class and pixel, (C, h, w) float32.

        Both densities are mixed with a uniform outlier density over the measurement range
        (``OUTLIER_LOG_DENSITY``) with probability ``outlier_probability``: a pixel the tight
        background Gaussian cannot explain is then not worth hundreds of nats, and the ratio
        keeps discriminating between classes (a red torso pixel supports the torso class far
        more than the legs). Ratios are finally clipped to +-clip."""
        eps = float(outlier_probability)
        floor = float(np.log(eps) + OUTLIER_LOG_DENSITY)
        keep = float(np.log1p(-eps))
        means, inv_chol, log_weight_norm, log_count = self._packed
        pixels = np.asarray(m, np.float32).reshape(-1, MEASUREMENT_DIM)
        out = np.empty((len(self.classes), pixels.shape[0]), np.float32)
        ratio_kernel(pixels, *background.kernel_arguments, means, inv_chol, log_weight_norm, log_count, keep, floor,
                     float(clip), out)
        return out.reshape((len(self.classes),) + m.shape[:2])

    @cached_property
    def _packed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The classes' components for ``densities.ratio_kernel``, padded to the largest count K:
        means (C, K, 5), inverse Cholesky factors (C, K, 5, 5), log weight + log normaliser
        (C, K) (-inf = padding), log component count (C,)."""
        classes, components = len(self.mixtures), max(len(mix.weights) for mix in self.mixtures)
        means = np.zeros((classes, components, MEASUREMENT_DIM))
        inv_chol = np.zeros((classes, components, MEASUREMENT_DIM, MEASUREMENT_DIM))
        log_weight_norm = np.full((classes, components), -np.inf)
        for c, mix in enumerate(self.mixtures):
            k = len(mix.weights)
            means[c, :k] = mix.means
            inv_chol[c, :k] = mix.factors.inv_chol
            log_weight_norm[c, :k] = np.log(mix.weights) + mix.factors.log_norm
        log_count = np.log([float(len(mix.weights)) for mix in self.mixtures])
        return means, inv_chol, log_weight_norm, log_count


def band_labels(foreground: np.ndarray, body: BodyDescription | None = None) -> np.ndarray:
    """Part-class labels (h, w) int8 (-1 = none, else index into ``PART_CLASSES``) from a
    foreground mask: the largest blob cut into horizontal bands at the body's proportions."""
    body = body or BodyDescription.default()
    mask = np.asarray(foreground, np.uint8)
    labels = np.full(mask.shape, -1, np.int8)
    count, comp, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if count <= 1:
        return labels
    blob = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    top = stats[blob, cv2.CC_STAT_TOP]
    height = stats[blob, cv2.CC_STAT_HEIGHT]
    # Fractions of the standing height from the top: head, torso, legs (to the ankle), feet.
    total = body.height
    cuts = np.cumsum([body.head_length, body.torso_length,
                      body.upper_leg_length + body.lower_leg_length]) / total
    rows = (np.arange(mask.shape[0]) - top + 0.5) / max(height, 1)
    band = np.searchsorted(cuts, rows)           # 0 head, 1 torso, 2 legs, 3 feet
    order = [PART_CLASSES.index(n) for n in ("head", "torso", "legs", "feet")]
    row_class = np.asarray(order)[np.clip(band, 0, 3)]
    inside = comp == blob
    labels[inside] = np.broadcast_to(row_class[:, None], mask.shape)[inside]
    return labels


def learn_foreground(m: np.ndarray, background: BackgroundModel, class_labels: np.ndarray | None = None,
                     body: BodyDescription | None = None, classes: tuple[str, ...] = PART_CLASSES,
                     min_pixels: int = 8, seed: int = 0, fill_with_bands: bool = False) -> ForegroundModel:
    """Fit one mixture per class to the interior pixels of the foreground (``class_labels``
    (h, w) int: class index or -1; None -> ``band_labels``; ``fill_with_bands``: foreground
    pixels the label image leaves at -1 take their band label).

    Interior: pixels that differ from the background and whose 8 neighbours do too. The
    gradient part of a map pixel's measurement is a central difference over its neighbours
    (``background.measurements``), so the background pixels bordering the person differ from
    the background as well: the foreground mask is the silhouette plus a one-pixel ring of
    background. Fitted as foreground (the bands label it), that ring teaches the mixtures that
    background next to the person is foreground, and the likelihood then prefers silhouettes
    drawn too large — bodies too close to the camera (issue 6: ~10 cm on a monocular walk,
    where the ring was 38 % of the training pixels). Eroding the mask by one pixel removes it.
    A class with too few interior pixels falls back to its labelled foreground pixels, then to
    all its labelled pixels, then to all foreground pixels."""
    moving = background.foreground_mask(m)
    labels = band_labels(moving, body) if class_labels is None else np.asarray(class_labels)
    if labels.shape != m.shape[:2]:
        raise ValueError(f"label image shape {labels.shape} does not match the measurement map {m.shape[:2]}")
    if class_labels is not None and fill_with_bands:
        labels = np.where(labels >= 0, labels, band_labels(moving, body))
    interior = cv2.erode(moving.astype(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                         borderValue=0).astype(bool)
    fallback = (m[interior] if interior.sum() >= min_pixels else m[moving] if moving.sum() >= min_pixels
                else m.reshape(-1, MEASUREMENT_DIM))
    mixtures = []
    for c in range(len(classes)):
        labelled = labels == c
        for pool in (labelled & interior, labelled & moving, labelled):
            if np.count_nonzero(pool) >= min_pixels:
                chosen = m[pool]
                break
        else:
            chosen = fallback
        mixtures.append(fit_mixture(chosen, seed=seed + c))
    return ForegroundModel(tuple(classes), tuple(mixtures))


def class_labels_from_parts(part_labels: np.ndarray, part_classes: tuple[str, ...],
                            classes: tuple[str, ...] = PART_CLASSES) -> np.ndarray:
    """Map a part-index image (e.g. ``render_labels``; -1 = background) to class indices (int8, -1 = none);
    ``part_classes[i]`` is the class name of part i."""
    lookup = np.array([classes.index(c) for c in part_classes] + [-1], np.int8)
    labels = np.asarray(part_labels).astype(np.int64)
    return lookup[np.where(labels < 0, len(part_classes), labels)]


def start_pose_labels(body: BodyDescription, camera, position_xy: tuple[float, float], heading: float,
                      step_length: float, stance_leg: int) -> np.ndarray:
    """Class labels (H, W) int8 (-1 = none) of the body projected at a start description's pose:
    pelvis above ``position_xy`` (m), walking along ``heading`` (rad), legs in double support
    for ``step_length`` (m), with self-occlusion (``render_labels``). The leg phase of a real
    start is unknown, so callers fill foreground pixels the projection misses with bands."""
    from awalker_tracker.model.cyclic_gaits import double_support_angle
    from awalker_tracker.model.kinematics import KinematicConfig, initial_kinematics, pose_body
    from awalker_tracker.model.walker import WalkerState
    from awalker_tracker.vision.render import render_labels

    params = body.walker_params()
    angle = double_support_angle(params, step_length)
    walker = WalkerState.from_arrays(angle, -angle, 0.0, 0.0, 0.0, stance_leg)
    kin = initial_kinematics(KinematicConfig(), walker, np.asarray(position_xy, float), heading, 1,
                             np.random.default_rng(0), body=body, params=params)
    parts, _ = render_labels(body, pose_body(body, params, walker, kin).segments, camera)
    return class_labels_from_parts(parts, tuple(p.part_class for p in body.parts))
