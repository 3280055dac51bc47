"""Optical flow on a grid of non-overlapping cells, with covariances, and eq. (9).

Dense flow from OpenCV's DIS (ultrafast preset) between consecutive grey frames, computed at
``scale`` (1 = full resolution; 0.5 halves the cost and doubles the error) and scaled back to full-resolution pixels. Each cell
(``cell_size`` px square) then gets a robust M-estimate of its motion: starting at the
texture-weighted mean, a few iterations of Cauchy-weighted means over the cell's dense vectors (scale
``robust_scale_px``), weighted also by the gradient magnitude (flow is only measured where
there is texture).

Covariance (paper: "eigenvalues/vectors of the local gradient tensor in each region of
support"): Sigma = noise_std^2 * T^-1 + floor_std^2 * I with T = sum over the cell of
[Ix^2, IxIy; IxIy, Iy^2] (grey levels^2 / px^2) — the Cramer-Rao bound of a translation
estimate under image noise ``noise_std`` — plus a floor for the estimator's own error. Cells
whose smallest eigenvalue of T (per pixel) is below ``min_texture`` are marked invalid (the
aperture problem leaves their motion unconstrained).

Eq. (9), Student's t with n = 2 degrees of freedom:
    log p(v | u) = -log|Sigma| / 2 - (n + 2) / 2 * log(1 + e^2) + c,   e^2 = (v - u)^T Sigma^-1 (v - u) / n.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

STUDENT_T_DOF = 2.0


@dataclass(frozen=True)
class FlowConfig:
    """Grid flow settings (pixels of the full-resolution image)."""

    cell_size: int = 16            # px, side of a cell
    scale: float = 1.0             # dense flow computed at this image scale
    robust_scale_px: float = 1.0   # Cauchy scale of the per-cell M-estimator (px)
    robust_iterations: int = 3
    noise_std: float = 3.0         # image noise (grey levels) for the covariance
    floor_std: float = 1.0         # px, added to the covariance's standard deviation
    min_texture: float = 4.0       # smallest eigenvalue of the per-pixel gradient tensor (grey^2/px^2)

    def __post_init__(self) -> None:
        if self.cell_size < 2 or not 0 < self.scale <= 1 or self.robust_scale_px <= 0 or self.noise_std <= 0:
            raise ValueError(f"invalid FlowConfig {self}")


@dataclass(frozen=True, eq=False)
class FlowGrid:
    """Per-cell flow: centers (rows, cols, 2) px (x, y); flow (rows, cols, 2) px/frame;
    covariance (rows, cols, 2, 2) px^2; valid (rows, cols) bool; cell_size px."""

    centers: np.ndarray
    flow: np.ndarray
    covariance: np.ndarray
    valid: np.ndarray
    cell_size: int

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.flow.shape[0]), int(self.flow.shape[1])

    @classmethod
    def empty(cls, height: int, width: int, cell_size: int) -> "FlowGrid":
        """An all-invalid grid (e.g. for the first frame, which has no predecessor)."""
        rows, cols = height // cell_size, width // cell_size
        return cls(grid_centers(rows, cols, cell_size), np.zeros((rows, cols, 2), np.float32),
                   np.broadcast_to(np.eye(2, dtype=np.float32), (rows, cols, 2, 2)).copy(),
                   np.zeros((rows, cols), bool), cell_size)

    def information(self) -> tuple[np.ndarray, np.ndarray]:
        """Inverse covariance (rows, cols, 2, 2) and log-determinant of the covariance (rows, cols)."""
        return np.linalg.inv(self.covariance), np.linalg.slogdet(self.covariance)[1]


def grid_centers(rows: int, cols: int, cell_size: int) -> np.ndarray:
    """Centres (rows, cols, 2) of cells [c*s, (c+1)*s) in pixel coordinates (pixel centres at integers)."""
    x = (np.arange(cols) + 0.5) * cell_size - 0.5
    y = (np.arange(rows) + 0.5) * cell_size - 0.5
    return np.stack(np.meshgrid(x, y), axis=-1).astype(np.float32)


def to_grey(rgb: np.ndarray) -> np.ndarray:
    """uint8 grey image of an (H, W, 3) RGB uint8 image (or pass-through if already (H, W))."""
    image = np.asarray(rgb)
    if image.ndim == 2:
        return image.astype(np.uint8, copy=False)
    return cv2.cvtColor(image.astype(np.uint8, copy=False), cv2.COLOR_RGB2GRAY)


class GridFlow:
    """Stateful grid-flow estimator; ``estimate(prev_grey, grey)`` -> ``FlowGrid``."""

    def __init__(self, config: FlowConfig = FlowConfig()) -> None:
        self.config = config
        self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)

    def estimate(self, prev_grey: np.ndarray, grey: np.ndarray) -> FlowGrid:
        cfg = self.config
        if prev_grey.shape != grey.shape:
            raise ValueError(f"flow: frame sizes differ {prev_grey.shape} vs {grey.shape}")
        height, width = grey.shape
        size = cfg.cell_size
        rows, cols = height // size, width // size
        if cfg.scale < 1:
            sw, sh = max(int(round(width * cfg.scale)), 8), max(int(round(height * cfg.scale)), 8)
            a = cv2.resize(prev_grey, (sw, sh), interpolation=cv2.INTER_AREA)
            b = cv2.resize(grey, (sw, sh), interpolation=cv2.INTER_AREA)
        else:
            a, b = prev_grey, grey
        dense = self._dis.calc(a, b, None)
        sub = max(int(round(size * cfg.scale)), 1)         # a cell in the flow image
        factor = np.float32([width / a.shape[1], height / a.shape[0]])
        if dense.shape[0] < rows * sub or dense.shape[1] < cols * sub:
            dense = cv2.resize(dense, (cols * sub, rows * sub), interpolation=cv2.INTER_LINEAR)
        dense = dense[: rows * sub, : cols * sub] * factor
        # Gradient tensor per cell at full resolution (grey levels / px), summed over the cell.
        g = grey[: rows * size, : cols * size].astype(np.float32)
        gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) * np.float32(1 / 8)
        gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) * np.float32(1 / 8)
        area = np.float32(size * size)
        txx = _cell_sums(gx * gx, rows, cols).astype(np.float64) * area
        txy = _cell_sums(gx * gy, rows, cols).astype(np.float64) * area
        tyy = _cell_sums(gy * gy, rows, cols).astype(np.float64) * area
        # Texture weights of the dense vectors (gradient magnitude at the flow image's resolution).
        magnitude = cv2.magnitude(gx, gy)
        if sub != size:
            magnitude = cv2.resize(magnitude, (cols * sub, rows * sub), interpolation=cv2.INTER_AREA)
        stride = 2 if sub % 2 == 0 else 1                 # every 2nd vector per axis is plenty
        flow = self._robust_mean(dense[::stride, ::stride], magnitude[::stride, ::stride] + np.float32(1e-3),
                                 rows, cols, sub // stride)
        # Smallest eigenvalue per pixel and Sigma = noise^2 T^-1 + floor^2 I (2x2 in closed form).
        eig_min = (0.5 * (txx + tyy) - np.sqrt(0.25 * (txx - tyy) ** 2 + txy ** 2)) / area
        valid = (eig_min >= cfg.min_texture) & np.all(np.isfinite(flow), axis=-1)
        det = np.maximum(txx * tyy - txy * txy, 1e-12)
        scale = cfg.noise_std ** 2 / det
        floor = cfg.floor_std ** 2
        cov = np.stack([np.stack([scale * tyy + floor, -scale * txy], -1),
                        np.stack([-scale * txy, scale * txx + floor], -1)], -2)
        cov = np.where(valid[..., None, None], cov, np.eye(2) * 1e4)
        return FlowGrid(grid_centers(rows, cols, size), np.nan_to_num(flow).astype(np.float32),
                        cov.astype(np.float32), valid, size)

    def _robust_mean(self, dense: np.ndarray, weights: np.ndarray, rows: int, cols: int, sub: int) -> np.ndarray:
        """Cauchy M-estimate (IRLS) of each cell's motion from its dense vectors; texture-weighted.

        Cell sums by area averaging (cv2.resize INTER_AREA), so each iteration is a few passes
        over the image; starts from the texture-weighted mean."""
        inv_c2 = np.float32(1.0 / self.config.robust_scale_px ** 2)
        u, v = np.ascontiguousarray(dense[..., 0]), np.ascontiguousarray(dense[..., 1])
        w = weights
        shape = (u.shape[1], u.shape[0])
        for iteration in range(self.config.robust_iterations + 1):
            total = _cell_sums(w, rows, cols)
            est_u = _cell_sums(u * w, rows, cols) / total
            est_v = _cell_sums(v * w, rows, cols) / total
            if iteration == self.config.robust_iterations:
                break
            du = u - cv2.resize(est_u, shape, interpolation=cv2.INTER_NEAREST)
            dv = v - cv2.resize(est_v, shape, interpolation=cv2.INTER_NEAREST)
            w = weights / (np.float32(1) + (du * du + dv * dv) * inv_c2)
        return np.stack([est_u, est_v], axis=-1)


def _cell_sums(image: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """Mean of each cell of an (rows*s, cols*s[, C]) float32 image -> (rows, cols[, C]) (area averaging)."""
    out = cv2.resize(image, (cols, rows), interpolation=cv2.INTER_AREA)
    return out.reshape((rows, cols) + image.shape[2:])


def student_t_log_likelihood(v: np.ndarray, u: np.ndarray, information: np.ndarray,
                             log_det_cov: np.ndarray, dof: float = STUDENT_T_DOF) -> np.ndarray:
    """Eq. (9) without its constant: measured flow v (..., 2), predicted u (..., 2), inverse
    covariance (..., 2, 2), log|Sigma| (...) -> (...)."""
    d = v - u
    e2 = np.einsum("...i,...ij,...j->...", d, information, d) / dof
    return -0.5 * log_det_cov - 0.5 * (dof + 2.0) * np.log1p(e2)
