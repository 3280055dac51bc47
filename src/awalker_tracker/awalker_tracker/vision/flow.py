"""Optical flow on a grid of non-overlapping cells, with covariances, and eq. (9).

Dense flow from OpenCV's DIS (ultrafast preset) between consecutive grey frames, computed backward
(current -> previous) and negated, so that each vector is the motion that brought a pixel of the
*current* frame where it is (the likelihood samples the cells under the current pose), computed at
``scale`` (1 = full resolution; 0.5 halves the cost and doubles the error) and scaled back to full-resolution pixels. Each cell
(``cell_size`` px square) then gets a robust M-estimate of its motion: starting at the
texture-weighted mean, a few iterations of Cauchy-weighted means over the cell's dense vectors (scale
``robust_scale_px``), weighted also by the gradient magnitude (flow is only measured where
there is texture). Every 2nd vector per axis is used when the cell's side in the flow image is even.

Per-cell work runs in serial numba kernels, each one pass over the image with no
temporaries: ``_gradient_tensors`` (3x3 Sobel gradients of the grey frame, the cell sums of the
gradient tensor, the gradient magnitude where the M-estimator samples it) and
``_robust_cell_means`` (all IRLS iterations of a cell while its vectors are in cache), whose
``_cell_estimates`` adds each cell's validity and covariance. At full scale the two passes are one
call (``_direct_cell_flow``): with DIS, two releases of the interpreter lock per frame, where numpy's
array operations on the grid took a dozen more, and each time a thread takes the lock back it may
wait a switch interval behind another thread's Python (the tracker's, in `awalker track`).

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

import functools
from dataclasses import dataclass

import cv2
import numba
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
    return _grid_centers(rows, cols, cell_size).copy()


@functools.lru_cache(maxsize=8)
def _grid_centers(rows: int, cols: int, cell_size: int) -> np.ndarray:
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
        """Grid flow (px/frame, full-resolution pixels) from ``prev_grey`` to ``grey`` (uint8 (H, W)), in
        ``grey``'s pixels: cell k's vector is the motion of the pixels that cell k shows in ``grey``."""
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
        # Backward flow, negated: a cell's vector belongs to the current frame's pixels, where the
        # likelihood samples it (under the current pose) and whose texture gives its covariance below.
        # Forward flow belongs to the previous frame's pixels, which differ wherever the body moved in
        # or out of a cell (one camera, real walks, tracker seeds 0-9: a median 6 mm better per run; README).
        dense = self._dis.calc(b, a, None)     # a flow passed in would be taken as the initial flow
        sub = max(int(round(size * cfg.scale)), 1)         # a cell in the flow image
        if dense.shape[0] < rows * sub or dense.shape[1] < cols * sub:
            dense = cv2.resize(dense, (cols * sub, rows * sub), interpolation=cv2.INTER_LINEAR)
        stride = 2 if sub % 2 == 0 else 1                 # every 2nd vector per axis is plenty
        # Gradient tensor per cell at full resolution and the texture weights of the dense vectors
        # (gradient magnitude at the flow image's resolution, sampled as the vectors are).
        tensor = np.empty((rows, cols, 3))
        direct = sub == size
        step = stride if direct else 1
        magnitude = np.empty((rows * size // step, cols * size // step), np.float32)
        flow = np.empty((rows, cols, 2), np.float32)
        cov = np.empty((rows, cols, 2, 2), np.float32)
        valid = np.empty((rows, cols), np.bool_)
        # The backward flow is negated by scaling it with minus the image scale (exact: rounding is symmetric).
        estimates = (dense[: rows * sub : stride, : cols * sub : stride], sub // stride, -width / a.shape[1],
                     -height / a.shape[0], 1.0 / cfg.robust_scale_px ** 2, cfg.robust_iterations, float(size * size),
                     cfg.noise_std ** 2, cfg.floor_std ** 2, cfg.min_texture, flow, cov, valid)
        grey = np.ascontiguousarray(grey, np.uint8)
        if direct:
            _direct_cell_flow(grey, size, step, tensor, magnitude, *estimates)
        else:   # the texture weights at the flow image's resolution
            _gradient_tensors(grey, size, step, tensor, magnitude)
            magnitude = cv2.resize(magnitude, (cols * sub, rows * sub), interpolation=cv2.INTER_AREA)[::stride, ::stride]
            _cell_estimates(estimates[0], magnitude, *estimates[1:6], tensor, *estimates[6:])
        return FlowGrid(grid_centers(rows, cols, size), flow, cov, valid, size)


# ---- per-cell kernels (numba, serial) -------------------------------------------------------
# Sums may be reassociated (vectorised): only their rounding changes.
_SUMS = {"reassoc", "contract"}


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _sobel(top: np.ndarray, mid: np.ndarray, bottom: np.ndarray, left: int, x: int, right: int) -> tuple:
    """3x3 Sobel (gx, gy) / 8 at column x of three uint8 image rows, float32 grey levels / px."""
    tl, tc, tr = np.int32(top[left]), np.int32(top[x]), np.int32(top[right])
    ml, mr = np.int32(mid[left]), np.int32(mid[right])
    bl, bc, br = np.int32(bottom[left]), np.int32(bottom[x]), np.int32(bottom[right])
    return (np.float32(tr - tl + 2 * (mr - ml) + br - bl) * np.float32(0.125),
            np.float32(bl - tl + 2 * (bc - tc) + br - tr) * np.float32(0.125))


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=_SUMS)
def _gradient_tensors(grey: np.ndarray, size: int, step: int, tensor: np.ndarray, magnitude: np.ndarray) -> None:
    """Sobel 3x3 gradients gx, gy (grey levels / px: the kernel / 8) of ``grey`` (uint8 (H, W))
    cropped to the cells (rows * size, cols * size), borders reflected without the edge pixel
    (OpenCV's default). Writes tensor (rows, cols, 3) = per-cell sums of (gx^2, gx gy, gy^2) and
    magnitude = sqrt(gx^2 + gy^2) at every ``step``-th pixel per axis (``step`` divides ``size``),
    float32. Row by row: the row's gradients first (a vectorisable loop), then its cell sums."""
    rows, cols = tensor.shape[0], tensor.shape[1]
    height, width = rows * size, cols * size
    if size % step != 0 or magnitude.shape[0] != height // step or magnitude.shape[1] != width // step:
        raise ValueError("_gradient_tensors: magnitude must be (rows * size / step, cols * size / step)")
    tensor[:] = 0.0
    if height == 0 or width == 0:
        return
    gx = np.empty(width, np.float32)
    gy = np.empty(width, np.float32)
    for y in range(height):
        top = grey[y - 1 if y > 0 else 1]
        mid = grey[y]
        bottom = grey[y + 1 if y < height - 1 else height - 2]
        gx[0], gy[0] = _sobel(top, mid, bottom, 1, 0, 1)
        for x in range(1, width - 1):
            gx[x], gy[x] = _sobel(top, mid, bottom, x - 1, x, x + 1)
        gx[width - 1], gy[width - 1] = _sobel(top, mid, bottom, width - 2, width - 1, width - 2)
        r = y // size
        for k in range(cols):
            sxx = 0.0
            sxy = 0.0
            syy = 0.0
            for x in range(k * size, (k + 1) * size):
                sxx += gx[x] * gx[x]
                sxy += gx[x] * gy[x]
                syy += gy[x] * gy[x]
            tensor[r, k, 0] += sxx
            tensor[r, k, 1] += sxy
            tensor[r, k, 2] += syy
        if y % step == 0:
            for x in range(0, width, step):
                magnitude[y // step, x // step] = np.sqrt(gx[x] * gx[x] + gy[x] * gy[x])


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=_SUMS)
def _robust_cell_means(dense: np.ndarray, magnitude: np.ndarray, n: int, scale_x: float, scale_y: float,
                       inv_c2: float, iterations: int, out: np.ndarray) -> None:
    """Cauchy M-estimate (IRLS) of each cell's motion from its n x n dense vectors.

    dense (rows * n, cols * n, 2) flow vectors (flow-image px, scaled by scale_x, scale_y to
    full-resolution px), magnitude (rows * n, cols * n) texture; a vector's weight is
    (magnitude + 1e-3) / (1 + |v - estimate|^2 inv_c2), starting from the texture-weighted mean,
    ``iterations`` reweightings. out (rows, cols, 2) px/frame. A cell's vectors are copied to
    contiguous buffers once and iterated there."""
    u = np.empty(n * n)
    v = np.empty(n * n)
    texture = np.empty(n * n)
    for r in range(out.shape[0]):
        for c in range(out.shape[1]):
            for i in range(n):
                for j in range(n):
                    u[i * n + j] = dense[r * n + i, c * n + j, 0] * scale_x
                    v[i * n + j] = dense[r * n + i, c * n + j, 1] * scale_y
                    texture[i * n + j] = magnitude[r * n + i, c * n + j] + 1e-3
            est_u = 0.0
            est_v = 0.0
            for iteration in range(iterations + 1):
                total = 0.0
                sum_u = 0.0
                sum_v = 0.0
                for i in range(n * n):
                    w = texture[i]
                    if iteration > 0:
                        w /= 1.0 + ((u[i] - est_u) ** 2 + (v[i] - est_v) ** 2) * inv_c2
                    total += w
                    sum_u += w * u[i]
                    sum_v += w * v[i]
                est_u = sum_u / total
                est_v = sum_v / total
            out[r, c, 0] = est_u
            out[r, c, 1] = est_v


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _cell_estimates(dense: np.ndarray, magnitude: np.ndarray, n: int, scale_x: float, scale_y: float, inv_c2: float,
                    iterations: int, tensor: np.ndarray, area: float, noise_var: float, floor_var: float,
                    min_texture: float, flow: np.ndarray, cov: np.ndarray, valid: np.ndarray) -> None:
    """Each cell's flow, validity and covariance in one call (one release of the interpreter lock, not one per
    array operation: the feature thread waits for this thread's result, and each time a thread takes the lock
    back it may wait a switch interval behind the tracker's Python).

    ``_robust_cell_means`` of the dense vectors (arguments as there) -> flow (rows, cols, 2) float32 (NaN as 0);
    from the cell gradient tensors T = tensor (rows, cols, 3) = sums of (Ix^2, IxIy, Iy^2) over ``area`` px:
    valid (rows, cols) = smallest eigenvalue of T / area >= ``min_texture`` and a finite flow;
    cov (rows, cols, 2, 2) float32 = noise_var T^-1 + floor_var I where valid (det T floored at 1e-12),
    else 1e4 I."""
    means = np.empty((flow.shape[0], flow.shape[1], 2))
    _robust_cell_means(dense, magnitude, n, scale_x, scale_y, inv_c2, iterations, means)
    for r in range(flow.shape[0]):
        for c in range(flow.shape[1]):
            txx, txy, tyy = tensor[r, c, 0], tensor[r, c, 1], tensor[r, c, 2]
            gap = txx - tyy
            eig_min = (0.5 * (txx + tyy) - np.sqrt(0.25 * (gap * gap) + txy * txy)) / area
            u, v = means[r, c, 0], means[r, c, 1]
            ok = eig_min >= min_texture and np.isfinite(u) and np.isfinite(v)
            det = txx * tyy - txy * txy
            scale = noise_var / (det if det > 1e-12 else 1e-12)
            cov[r, c, 0, 0] = scale * tyy + floor_var if ok else 1e4
            cov[r, c, 1, 1] = scale * txx + floor_var if ok else 1e4
            cov[r, c, 0, 1] = cov[r, c, 1, 0] = -scale * txy if ok else 0.0
            valid[r, c] = ok
            flow[r, c, 0] = 0.0 if np.isnan(u) else u
            flow[r, c, 1] = 0.0 if np.isnan(v) else v


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _direct_cell_flow(grey: np.ndarray, size: int, step: int, tensor: np.ndarray, magnitude: np.ndarray,
                      dense: np.ndarray, n: int, scale_x: float, scale_y: float, inv_c2: float, iterations: int,
                      area: float, noise_var: float, floor_var: float, min_texture: float, flow: np.ndarray,
                      cov: np.ndarray, valid: np.ndarray) -> None:
    """``_gradient_tensors`` then ``_cell_estimates`` in one call, when the flow image is the grey image's size
    (the texture weights need no resizing between them)."""
    _gradient_tensors(grey, size, step, tensor, magnitude)
    _cell_estimates(dense, magnitude, n, scale_x, scale_y, inv_c2, iterations, tensor, area, noise_var, floor_var,
                    min_texture, flow, cov, valid)


# Eq. (9), the one implementation: compiled scalar functions the likelihood kernel inlines (there they take
# its fast-math flags) and numpy callers call on arrays (compiled for them without fast math, so the same
# operations as numpy's own in the same order).
_scalar = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")


@_scalar
def student_t_e2(du: float, dv: float, i00: float, i01: float, i11: float) -> float:
    """e^2 of eq. (9): the squared Mahalanobis distance of the flow difference d = v - u = (du, dv) (px)
    under Sigma^-1 = [[i00, i01], [i01, i11]] (1/px^2), over n: d^T Sigma^-1 d / n. Scalars or arrays."""
    return (du * (i00 * du + 2.0 * i01 * dv) + i11 * dv * dv) / STUDENT_T_DOF


@_scalar
def student_t_log_ratio(e2: float, log1p_e0: float) -> float:
    """log p(v | u) - log p(v | 0) of eq. (9) (its -log|Sigma| / 2 and constant cancel): -(n + 2) / 2
    (log(1 + e2) - log(1 + e0^2)), from e2 = ``student_t_e2`` of v - u and ``log1p_e0`` = log(1 + e0^2) of v
    itself (a grid cell's, computed once per frame). With ``log1p_e0`` = 0 it is log p(v | u) + log|Sigma| / 2
    up to eq. (9)'s constant. Scalars or arrays."""
    return -0.5 * (STUDENT_T_DOF + 2.0) * (np.log(1.0 + e2) - log1p_e0)
