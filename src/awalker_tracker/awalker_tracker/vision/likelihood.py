"""Batched image log-likelihood of N body poses over C cameras (paper Sec. 5.1, eq. 9-12).

Each part (a tapered elliptical cylinder) is drawn, per state and camera, as its projected
silhouette: the projected axis from start a to end b, widened on both sides by the projected
half-width of its elliptical cross-section seen along the view, h = sqrt((r0 (w.e0))^2 +
(r1 (w.e1))^2) with w = unit(axis x view) (the ellipse's support function), in pixels
f h / depth at each end. Only the two axis end points are projected (exactly, with
distortion). ``points_along`` rows x ``points_across`` columns of sample points cover the
silhouette uniformly.

Appearance (eq. 10-11, footnote 1): each part in front of the camera contributes the mean
foreground/background log-likelihood ratio over its K sample points (the map pixel of the
part's class in ``FrameFeatures.llr`` that contains the point; pixel centres at integer image
coordinates): eq. 11's sum over the part's pixels, normalised by the part's own projected area.
(Normalising by a fixed expected area instead, so that a part counts in proportion to how large
it appears, rewards a body drawn larger, nearer the camera, whenever its inner sample points stay
on foreground; a real person's silhouette is wider than the model (arms, clothes), so on dressed
renders of real walks that pulled the body 0.3-0.5 m toward a single camera: 451 against 175 mm
median absolute error on CMU 07_01, 317 against 192 on 07_02.)

Above the head (our addition; ``LikelihoodConfig.head_top_weight``): with each part scored by its mean,
a body a little smaller than the person fits inside the silhouette at no cost, so size (and with one
camera, depth: a body too far is drawn too small) was seen from one side only. A row of
``points_across`` points 0.75 map pixels beyond the head's top along its image axis, at half the
head's end width across, reads the head class's ratio there; where it is positive (the person's
foreground: the head or hair continue above the model's) it counts against the head's term, its mean
times ``head_top_weight``. Clothes and arms make a person wider than the model, not taller, so
unlike a reward for covering foreground it does not pull the body toward the camera. The body fit
(``inference.bodyfit``) weighs it 1: the filter's evidence over leg lengths on our own renders
preferred legs 3 % short (7 of 12 runs) without it and the drawn length (8 of 12) with it. Tracking
leaves it off (0): on the real-walks benchmark one camera's median of the walk medians went 121 -> 142 mm
(worse on 4 walks, better on 2, within 1 mm on 6), two cameras 90 -> 88 mm (README).

Flow (eq. 9): at each row's axis point the predicted image motion u is the motion of that
point from ``prev_segments`` to ``segments``; it is compared with the measured flow v of the
grid cell it falls in now (the flow is the motion of the current frame's pixels, ``vision.flow``):
log p(v | u) - log p(v | 0), i.e. relative to the background's zero-motion model (background
cells' terms are common to all states and cancel), averaged per part like the appearance term.

Visibility: points outside the image, behind the camera, under the occlusion mask (applied to the
features beforehand, ``vision.features.occluded``: ratio 0, flow cell invalid) or hidden by a nearer
part are dropped. Self-occlusion is an analytic
per-state test between part pairs that can overlap (``occluder_table``: the legs and feet of
one side against those of the other side, the upper legs against the torso): a row of
sample points is hidden when its axis point lies within the occluder's projected band and
behind the occluder's axis depth there. Pairs whose image bounding boxes do not meet, or
whose occludee lies wholly in front, are skipped. Cameras are conditionally independent: their terms add (eq. 12).

Cost: O(N x parts x points) scalar operations in one serial numba-compiled loop over the N
states (``_score_states``): a state's projections, occlusion flags and sums stay in registers
and cache, instead of the ~100 numpy calls over (rows, parts, N) arrays a vectorised version
makes (the test oracle ``test/vision/likelihood_reference.py``). About 1.5 ms per 1000
states and camera (``benchmarks/bench_likelihood.py``, 5000 states: 7.5-7.8 ms against 19-21 ms
for the numpy version, back to back on a shared 2-core machine). Compiled on first use (~7-9 s)
and cached on disk next to this file (``cache=True``): later processes load it in ~0.3-0.4 s.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from awalker_tracker.blocks import over_blocks
from awalker_tracker.errors import InputError
from awalker_tracker.model.body import BodySegments, PartShape
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.features import FrameFeatures
from awalker_tracker.vision.flow import FlowGrid, student_t_e2, student_t_log_ratio


@dataclass(frozen=True)
class LikelihoodConfig:
    """Sampling density and term weights of the image likelihood."""

    points_along: int = 6           # sample rows along each part's axis
    points_across: int = 2          # samples per row across the silhouette
    flow_row_step: int = 3          # flow compared at every flow_row_step-th row (cells >> rows)
    appearance_weight: float = 1.0  # multiplies each part's mean log-likelihood ratio
    flow_weight: float = 1.0        # multiplies each part's mean flow log-ratio
    head_top_weight: float = 0.0    # penalty for the person's foreground just above the head's top (body fit: 1)
    self_occlusion: bool = True

    def __post_init__(self) -> None:
        if min(self.points_along, self.points_across, self.flow_row_step) < 1:
            raise ValueError("LikelihoodConfig: points_along, points_across and flow_row_step "
                             "must be >= 1")


def occluder_table(parts: tuple[PartShape, ...]) -> np.ndarray:
    """(P, 4) indices of the parts that may hide each part (-1 = none): a left leg part by the right
    leg parts and vice versa; upper legs also by the torso. Others: none."""
    names = [p.name for p in parts]
    table = np.full((len(parts), 4), -1, np.int64)
    for i, name in enumerate(names):
        for side, other in (("left_", "right_"), ("right_", "left_")):
            if name.startswith(side):
                cands = [j for j, n in enumerate(names) if n.startswith(other)]
                if name.endswith("upper_leg") and "torso" in names:
                    cands.append(names.index("torso"))
                table[i, : len(cands[:4])] = cands[:4]
    return table


def occluder_pairs(parts: tuple[PartShape, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(occludee, occluder) index pairs from ``occluder_table``."""
    table = occluder_table(parts)
    who, slot = np.nonzero(table >= 0)
    return who, table[who, slot]


# Projected axis of a part, one row of an (N, P, 6) float64 array: the axis ends a = origin and
# b = origin + length * axis in pixels (``_BEHIND`` at or behind the camera) and their depths (m).
_AX, _AY, _BX, _BY, _DA, _DB = range(6)
_BEHIND = -1e6       # pixel coordinate given to points at or behind the camera
_MIN_DEPTH = 1e-6    # m: points nearer than this (or behind) are not in front of the camera

# Notes on the kernels (each measured; together ~4x faster than the first straightforward version):
# - They index the (N, P, ...) arrays with (n, p) instead of taking per-part views (origin[n, p]):
#   each view is a reference-counted array struct, and building them in the loops cost 5-15x.
# - The camera parameters are a tuple of scalars (``_camera_tuple``), not an array read in the loop.
# - Divisions, square roots, integer modulo and log1p are the slow scalar operations: the kernel
#   precomputes the sample positions along and across and which rows compare flow, divides once
#   per projected point, and computes each part's image box once per state.
# - error_model="numpy": no zero-division checks (every divisor here is bounded away from 0).
# - Fast math without its NaN and infinity assumptions (``_FAST``: LLVM may fuse multiply-adds, reorder sums, use
#   reciprocals and faster log and square root): 13-14 % less kernel time (5000 states: 6.6-6.8 ms against
#   7.6-7.8), the log-likelihoods changed by ~1e-14. NaN tests (points behind the camera, the clamped map
#   indices) keep their meaning, as "nnan" and "ninf" are not among the flags.
_FAST = {"contract", "reassoc", "arcp", "nsz", "afn"}
_jit = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
_inline = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always", fastmath=_FAST)


@_inline
def _camera_tuple(camera: np.ndarray) -> tuple:
    """The 25 camera parameters (``_CameraArrays.params``) as a tuple of scalars. Loaded once per
    kernel call: read from the array inside the loops they were reloaded after every store
    (the compiler cannot rule out that the output arrays alias it), 3-5x slower."""
    return (camera[0], camera[1], camera[2], camera[3], camera[4], camera[5], camera[6], camera[7], camera[8],
            camera[9], camera[10], camera[11], camera[12], camera[13], camera[14], camera[15], camera[16],
            camera[17], camera[18], camera[19], camera[20], camera[21], camera[22], camera[23], camera[24])


@_inline
def _project_point(px: float, py: float, pz: float, cam: tuple, distorted: bool) -> tuple[float, float, float]:
    """A world point (m) -> pixel u, v (``_BEHIND`` if not in front) and depth along the optical axis (m).

    ``cam``: ``_camera_tuple``; the distortion is the OpenCV rational radial and tangential
    model of ``Camera._distort`` (applied only if ``distorted``)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22, ox, oy, oz, fx, skew, cx, fy, cy = cam[:17]
    k1, k2, p1, p2, k3, k4, k5, k6 = cam[17:]
    dx, dy, dz = px - ox, py - oy, pz - oz
    x = dx * r00 + dy * r10 + dz * r20          # camera frame = rotation^T (point - centre)
    y = dx * r01 + dy * r11 + dz * r21
    z = dx * r02 + dy * r12 + dz * r22
    if not z > _MIN_DEPTH:
        return _BEHIND, _BEHIND, z
    inv_z = 1.0 / z
    x *= inv_z
    y *= inv_z
    if distorted:
        r2 = x * x + y * y
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x, y = xd, yd
    return fx * x + skew * y + cx, fy * y + cy, z


@_inline
def _project_axis(origin: np.ndarray, rotation: np.ndarray, n: int, p: int, length: float, cam: tuple,
                  distorted: bool, out: np.ndarray) -> None:
    """State n's part p: its axis ends a = origin, b = origin + length * axis (rotation column 2)
    projected into ``out[n, p]`` (layout ``_AX`` .. ``_DB``). ``origin`` (N, P, 3) m, ``rotation``
    (N, P, 3, 3), ``out`` (N, P, 6)."""
    ox, oy, oz = origin[n, p, 0], origin[n, p, 1], origin[n, p, 2]
    u, v, z = _project_point(ox, oy, oz, cam, distorted)
    out[n, p, _AX], out[n, p, _AY], out[n, p, _DA] = u, v, z
    u, v, z = _project_point(ox + length * rotation[n, p, 0, 2], oy + length * rotation[n, p, 1, 2],
                             oz + length * rotation[n, p, 2, 2], cam, distorted)
    out[n, p, _BX], out[n, p, _BY], out[n, p, _DB] = u, v, z


@_jit
def _project_axes(origin: np.ndarray, rotation: np.ndarray, lengths: np.ndarray, camera: np.ndarray,
                  distorted: bool, out: np.ndarray) -> None:
    """Projected axes (N, P, 6) of all parts of N states into ``out`` (the flow term's previous poses)."""
    cam = _camera_tuple(camera)
    for n in range(origin.shape[0]):
        for p in range(origin.shape[1]):
            _project_axis(origin, rotation, n, p, lengths[p], cam, distorted, out)


@_inline
def _lateral(rotation: np.ndarray, n: int, p: int, view_x: float, view_y: float, view_z: float
             ) -> tuple[float, float]:
    """Components (w.e0, w.e1) of w = unit(axis x view) for state n's part p (axis = rotation
    column 2, e0, e1 = columns 0, 1; ``view`` from the part towards the camera). The part's
    half-width seen from the camera is then sqrt((r0 (w.e0))^2 + (r1 (w.e1))^2) (the support
    function of its elliptical cross-section, semi-axes r0, r1)."""
    ax, ay, az = rotation[n, p, 0, 2], rotation[n, p, 1, 2], rotation[n, p, 2, 2]
    lx, ly, lz = ay * view_z - az * view_y, az * view_x - ax * view_z, ax * view_y - ay * view_x   # axis x view
    c0 = lx * rotation[n, p, 0, 0] + ly * rotation[n, p, 1, 0] + lz * rotation[n, p, 2, 0]
    c1 = lx * rotation[n, p, 0, 1] + ly * rotation[n, p, 1, 1] + lz * rotation[n, p, 2, 1]
    norm = np.sqrt(c0 * c0 + c1 * c1)          # the lateral direction lies in the e0-e1 plane
    if norm < 1e-9:                            # looking along the axis: any lateral direction
        return 1.0, 0.0
    inv_norm = 1.0 / norm
    return c0 * inv_norm, c1 * inv_norm


@_inline
def _clamp_index(x: float, top: int) -> int:
    """floor(x) clamped to [0, top] (x < 0 and NaN give 0: the zero border)."""
    return int(min(float(top), max(0.0, x)))   # max(0.0, NaN) is 0.0 (Python's max keeps the first)


@_jit
def _score_states(origin: np.ndarray, rotation: np.ndarray, lengths: np.ndarray, radii: np.ndarray,
                  camera: np.ndarray, distorted: bool, focal: float,
                  occludees: np.ndarray, occluders: np.ndarray, self_occlusion: bool,
                  points_along: int, points_across: int, flow_row_step: int,
                  llr: np.ndarray, map_h: int, map_w: int, inv_downsample: float, class_offsets: np.ndarray,
                  use_flow: bool, prev_axes: np.ndarray, flow_u: np.ndarray, flow_v: np.ndarray,
                  info00: np.ndarray, info01: np.ndarray, info11: np.ndarray, log_zero: np.ndarray,
                  cell_valid: np.ndarray, flow_rows: int, flow_cols: int, inv_cell: float,
                  appearance_weight: float, flow_weight: float, top_part: int, top_weight: float,
                  axes: np.ndarray, out: np.ndarray) -> None:
    """Appearance + flow log-likelihood (eq. 9-11) of each of N states in one camera into ``out`` (N,).

    Inputs: the states' part poses ``origin`` (N, P, 3) m and ``rotation`` (N, P, 3, 3); per part
    ``lengths`` (P,) m and ``radii`` (P, 4) m (start semi-axes, end semi-axes); the camera
    (``_CameraArrays``; ``focal`` px for the half-widths); occluder pairs (Q,) each; the sampling
    config; the zero-bordered appearance maps ``llr`` (flat, classes x (map_h + 2) x (map_w + 2))
    with each part's class offset; the flow table (``_FlowTable``: per cell + a last invalid
    cell) and the previous poses' projected axes ``prev_axes`` (N, P, 6) (read only if
    ``use_flow``). Writes each state's projected axes to ``axes`` (N, P, 6) (a SilhouetteMemo
    keeps them: next frame's previous poses); ``prev_axes`` may be ``axes`` itself (no motion).
    """
    n_states, n_parts = origin.shape[0], origin.shape[1]
    A, J = points_along, points_across
    # sample positions: rows at t along the axis (0..1), points at ``across`` half-widths (-1..1)
    row_t = (np.arange(A) + 0.5) / A
    across = 2.0 * (np.arange(J) + 0.5) / J - 1.0
    flow_row = np.arange(A) % flow_row_step == 0                 # rows 0, step, 2 step, ... compare flow
    n_flow_rows = flow_row.sum()
    appearance_scale = appearance_weight / (A * J)               # eq. 11: mean over the part's samples
    flow_scale = flow_weight / n_flow_rows
    map_stride = map_w + 2
    cam = _camera_tuple(camera)
    cam_x, cam_y, cam_z = cam[9], cam[10], cam[11]             # camera centre (m)
    half = np.empty((n_parts, 2))                 # this state's projected half-widths at a, b (px)
    box = np.empty((n_parts, 6))                  # its x0, x1, y0, y1 (px), near, far (m) per part
    hidden = np.zeros((n_parts, A), np.bool_)     # this state's rows hidden by another part
    for n in range(n_states):
        # ---- silhouettes: projected axis ends and half-widths -------------------------------------
        for p in range(n_parts):
            _project_axis(origin, rotation, n, p, lengths[p], cam, distorted, axes)
            middle = 0.5 * lengths[p]             # view: from the axis midpoint towards the camera (m)
            c0, c1 = _lateral(rotation, n, p, cam_x - (origin[n, p, 0] + middle * rotation[n, p, 0, 2]),
                              cam_y - (origin[n, p, 1] + middle * rotation[n, p, 1, 2]),
                              cam_z - (origin[n, p, 2] + middle * rotation[n, p, 2, 2]))
            h0 = np.sqrt((radii[p, 0] * c0) ** 2 + (radii[p, 1] * c1) ** 2)     # m, at a
            h1 = np.sqrt((radii[p, 2] * c0) ** 2 + (radii[p, 3] * c1) ** 2)     # m, at b
            half[p, 0] = focal * h0 / max(axes[n, p, _DA], _MIN_DEPTH)
            half[p, 1] = focal * h1 / max(axes[n, p, _DB], _MIN_DEPTH)
            # image bounding box of the silhouette (px) and depth range (m), for the occlusion test
            h = max(half[p, 0], half[p, 1])
            box[p, 0] = min(axes[n, p, _AX], axes[n, p, _BX]) - h
            box[p, 1] = max(axes[n, p, _AX], axes[n, p, _BX]) + h
            box[p, 2] = min(axes[n, p, _AY], axes[n, p, _BY]) - h
            box[p, 3] = max(axes[n, p, _AY], axes[n, p, _BY]) + h
            box[p, 4] = min(axes[n, p, _DA], axes[n, p, _DB])
            box[p, 5] = max(axes[n, p, _DA], axes[n, p, _DB])
        # ---- self-occlusion (module docstring), tested at even rows; a pair of rows shares it -----
        hidden[:, :] = False
        if self_occlusion:
            for q in range(occludees.shape[0]):
                i, j = occludees[q], occluders[q]
                # skip pairs whose image boxes do not meet or whose occludee is wholly in front
                if not (box[i, 0] < box[j, 1] and box[j, 0] < box[i, 1] and box[i, 2] < box[j, 3]
                        and box[j, 2] < box[i, 3] and box[i, 5] > box[j, 4]):
                    continue
                iax, iay, ibx, iby, ida, idb = (axes[n, i, _AX], axes[n, i, _AY], axes[n, i, _BX],
                                                axes[n, i, _BY], axes[n, i, _DA], axes[n, i, _DB])
                jax, jay, jbx, jby, jda, jdb = (axes[n, j, _AX], axes[n, j, _AY], axes[n, j, _BX],
                                                axes[n, j, _BY], axes[n, j, _DA], axes[n, j, _DB])
                sx, sy = jbx - jax, jby - jay                       # occluder's image axis (px)
                inv_sq = 1.0 / max(sx * sx + sy * sy, 1e-6)
                for a in range(0, A, 2):
                    t = row_t[a]
                    px = iax + t * (ibx - iax) - jax                # occludee's row point from occluder's a
                    py = iay + t * (iby - iay) - jay
                    depth = ida + t * (idb - ida)
                    tau = min(max((px * sx + py * sy) * inv_sq, 0.0), 1.0)   # nearest occluder axis point
                    ex, ey = px - tau * sx, py - tau * sy
                    radius = half[j, 0] + tau * (half[j, 1] - half[j, 0])
                    if ex * ex + ey * ey < radius * radius and depth > jda + tau * (jdb - jda):
                        hidden[i, a] = True
                        if a + 1 < A:
                            hidden[i, a + 1] = True
        # ---- appearance (eq. 10-11) and flow (eq. 9), each a mean over the part's samples --------
        appearance = 0.0
        flow = 0.0
        for p in range(n_parts):
            ax, ay, bx, by = axes[n, p, _AX], axes[n, p, _AY], axes[n, p, _BX], axes[n, p, _BY]
            if not (axes[n, p, _DA] > _MIN_DEPTH and axes[n, p, _DB] > _MIN_DEPTH):
                continue                          # not wholly in front of the camera: no term
            dx, dy = bx - ax, by - ay
            length = np.sqrt(dx * dx + dy * dy)
            if length > 1e-3:                     # unit normal of the image axis
                nx, ny = -dy / length, dx / length
            else:
                nx, ny = 1.0, 0.0
            prev_in_front = use_flow and prev_axes[n, p, _DA] > _MIN_DEPTH and prev_axes[n, p, _DB] > _MIN_DEPTH
            offset = class_offsets[p]
            for a in range(A):
                if hidden[p, a]:
                    continue
                t = row_t[a]
                cx, cy = ax + t * dx, ay + t * dy     # row centre (px)
                h = half[p, 0] + t * (half[p, 1] - half[p, 0])
                # Map coordinates (+1 for the zero border): pixel centres are at integer image
                # coordinates, map pixel k spans [d k - 0.5, d k + d - 0.5): floor((u + 0.5) / d).
                base_col = (cx + 0.5) * inv_downsample + 1.0
                base_row = (cy + 0.5) * inv_downsample + 1.0
                step_col = h * nx * inv_downsample
                step_row = h * ny * inv_downsample
                for k in range(J):
                    col = _clamp_index(base_col + across[k] * step_col, map_w + 1)
                    row = _clamp_index(base_row + across[k] * step_row, map_h + 1)
                    appearance += llr[offset + row * map_stride + col]
                if not (prev_in_front and flow_row[a]):
                    continue
                fcol = (cx + 0.5) * inv_cell              # cell k spans [k c - 0.5, k c + c - 0.5) px
                frow = (cy + 0.5) * inv_cell
                if not (fcol >= 0.0 and fcol < flow_cols and frow >= 0.0 and frow < flow_rows):
                    continue
                cell = int(frow) * flow_cols + int(fcol)
                if not cell_valid[cell]:
                    continue
                # predicted motion u of the row's axis point (px/frame) against the measured v
                pax, pay = prev_axes[n, p, _AX], prev_axes[n, p, _AY]
                mu = cx - (pax + t * (prev_axes[n, p, _BX] - pax))
                mv = cy - (pay + t * (prev_axes[n, p, _BY] - pay))
                du, dv = flow_u[cell] - mu, flow_v[cell] - mv
                # eq. 9: Student-t log p(v | u) - log p(v | 0) (vision.flow; log(1 + e2) there rather than
                # log1p: ~3x faster, and its absolute error is ~1e-16)
                flow += student_t_log_ratio(student_t_e2(du, dv, info00[cell], info01[cell], info11[cell]),
                                            log_zero[cell])
            if p == top_part and length > 1e-3:
                # just above the end of the head (b), 0.75 map pixels out along the image axis: the
                # person's foreground there means the body is drawn too small or too far
                margin = 0.75 / (inv_downsample * length)
                tx, ty = bx + margin * dx, by + margin * dy
                base_col = (tx + 0.5) * inv_downsample + 1.0
                base_row = (ty + 0.5) * inv_downsample + 1.0
                step_col = 0.5 * half[p, 1] * nx * inv_downsample
                step_row = 0.5 * half[p, 1] * ny * inv_downsample
                above = 0.0
                for k in range(J):
                    col = _clamp_index(base_col + across[k] * step_col, map_w + 1)
                    row = _clamp_index(base_row + across[k] * step_row, map_h + 1)
                    above += max(llr[offset + row * map_stride + col], 0.0)
                appearance -= top_weight * A * above
        out[n] = appearance_scale * appearance + flow_scale * flow


class SilhouetteMemo:
    """The last ``keep`` calls' projected axes per camera ((N, P, 6) arrays). A tracker's next frame scores
    new poses against these poses as its previous ones (the flow term), so with a memo they are
    projected once instead of twice; two are kept, as the tracker also scores a few mirrored poses between
    its frames (``TrackerConfig.naming_test_particles``). Matched by object identity of the ``BodySegments``."""

    def __init__(self, keep: int = 2) -> None:
        self.keep = int(keep)
        self._entries: list[tuple[BodySegments, list[np.ndarray]]] = []

    def lookup(self, segments: BodySegments, camera_index: int) -> np.ndarray | None:
        """The stored projected axes of ``segments`` in camera ``camera_index``, or None."""
        for stored, axes in self._entries:
            if segments is stored and camera_index < len(axes):
                return axes[camera_index]
        return None

    def store(self, segments: BodySegments, axes: list[np.ndarray]) -> None:
        """Remember ``segments``' projected axes, one (N, P, 6) array per camera (the oldest entry goes)."""
        self._entries = [(segments, axes)] + [e for e in self._entries if e[0] is not segments][: self.keep - 1]


def _check_inputs(parts: tuple[PartShape, ...], segments: BodySegments, camera: Camera,
                  features: FrameFeatures) -> None:
    p = segments.origin.shape[1]
    if p != len(parts):
        raise ValueError(f"likelihood: segments have {p} parts, body has {len(parts)}")
    if (features.image_width, features.image_height) != (camera.width, camera.height):
        raise InputError(f"likelihood: features of camera {camera.name} are {features.image_width}x"
                         f"{features.image_height}, calibration says {camera.width}x{camera.height}")


class _CameraArrays:
    """A camera as the kernels take it: ``params`` (25,) float64 = world_from_camera rotation
    (row-major, 9), centre (3, m), intrinsics fx, skew, cx, fy, cy (px), the 8 OpenCV distortion
    coefficients k1, k2, p1, p2, k3, k4, k5, k6 (missing ones 0); ``distorted``: any nonzero;
    ``focal``: the mean focal length (px)."""

    def __init__(self, camera: Camera):
        K = camera.K
        distortion = camera.distortion_coefficients()
        self.params = np.concatenate([np.asarray(camera.rotation, np.float64).reshape(9),
                                      np.asarray(camera.position, np.float64).reshape(3),
                                      [K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]], distortion])
        self.distorted = bool(distortion.any())
        self.focal = float(0.5 * (K[0, 0] + K[1, 1]))


def _pose_arrays(segments: BodySegments) -> tuple[np.ndarray, np.ndarray]:
    """The segments' origin (N, P, 3) and rotation (N, P, 3, 3) as C-contiguous float64 (no copy if already)."""
    return (np.ascontiguousarray(segments.origin, np.float64), np.ascontiguousarray(segments.rotation, np.float64))


def _project_segments(parts: tuple[PartShape, ...], segments: BodySegments, camera: _CameraArrays) -> np.ndarray:
    """Projected axes (N, P, 6) of the parts of ``segments`` (layout ``_AX`` .. ``_DB``)."""
    origin, rotation = _pose_arrays(segments)
    lengths = np.array([p.length for p in parts], np.float64)
    out = np.empty(origin.shape[:2] + (6,))
    _project_axes(origin, rotation, lengths, camera.params, camera.distorted, out)
    return out


def camera_log_likelihood(parts: tuple[PartShape, ...], segments: BodySegments, prev_segments: BodySegments,
                          camera: Camera, features: FrameFeatures, config: LikelihoodConfig = LikelihoodConfig(),
                          silhouettes: np.ndarray | None = None, prev_silhouettes: np.ndarray | None = None
                          ) -> np.ndarray:
    """Log-likelihood (N,) of one camera's features (see the module docstring).

    ``silhouettes``: optional (N, P, 6) float64 array that receives the poses' projected axes
    (for a ``SilhouetteMemo``). ``prev_silhouettes``: ``prev_segments`` already projected into this
    camera (such an array from an earlier call; may be ``silhouettes`` itself when
    ``prev_segments`` is ``segments``), if known."""
    _check_inputs(parts, segments, camera, features)
    origin, rotation = _pose_arrays(segments)
    n, n_parts = origin.shape[:2]
    cam = _CameraArrays(camera)
    axes = np.empty((n, n_parts, 6)) if silhouettes is None else silhouettes
    if axes.shape != (n, n_parts, 6) or axes.dtype != np.float64 or not axes.flags.c_contiguous:
        raise ValueError(f"likelihood: silhouettes must be a C-contiguous float64 array of shape {(n, n_parts, 6)}")
    appearance = _AppearanceTable(parts, features)
    flow = _FlowTable(features.flow) if config.flow_weight > 0 else None
    if flow is not None and not flow.any:
        flow = None
    prev_axes = axes                         # not read without flow
    if flow is not None:
        if prev_silhouettes is not None:
            prev_axes = prev_silhouettes
        elif prev_segments is not segments:
            prev_axes = _project_segments(parts, prev_segments, cam)
        if prev_axes.shape != axes.shape:
            raise ValueError(f"likelihood: {prev_axes.shape[0]} previous states for {n} states")
    table = flow if flow is not None else _FlowTable.EMPTY
    lengths = np.array([p.length for p in parts], np.float64)
    radii = np.array([[*p.radii_start, *p.radii_end] for p in parts], np.float64).reshape(n_parts, 4)
    occludees, occluders = (np.ascontiguousarray(a) for a in occluder_pairs(parts))
    names = [p.name for p in parts]
    top_part = names.index("head") if "head" in names and config.head_top_weight > 0 else -1
    out = np.empty(n)
    prev_axes = np.ascontiguousarray(prev_axes)

    def score(rows: slice) -> None:
        _score_states(origin[rows], rotation[rows], lengths, radii,
                      cam.params, cam.distorted, cam.focal,
                      occludees, occluders, bool(config.self_occlusion),
                      int(config.points_along), int(config.points_across), int(config.flow_row_step),
                      appearance.values, appearance.h, appearance.w, appearance.inv_ds, appearance.offsets,
                      flow is not None, prev_axes[rows], table.fx, table.fy,
                      table.i00, table.i01, table.i11, table.log0, table.valid, table.rows, table.cols,
                      table.inv_cell, float(config.appearance_weight), float(config.flow_weight),
                      top_part, float(config.head_top_weight), axes[rows], out[rows])

    over_blocks(n, score)
    return out


class _AppearanceTable:
    """Log-likelihood-ratio maps with a zero border (indices clamped into it contribute nothing),
    flattened (float32), and each part's class offset into them."""

    def __init__(self, parts: tuple[PartShape, ...], features: FrameFeatures):
        llr = features.llr
        self.h, self.w = features.map_shape
        padded = np.zeros((len(features.classes), self.h + 2, self.w + 2), np.float32)
        padded[:, 1:-1, 1:-1] = llr
        self.values = padded.reshape(-1)
        self.inv_ds = 1.0 / features.downsample
        classes = np.array([features.classes.index(q.part_class) for q in parts], np.int64)
        self.offsets = classes * ((self.h + 2) * (self.w + 2))


class _FlowTable:
    """Per-cell measured flow (px/frame), inverse covariance (1/px^2) and log(1 + e0^2) (the
    zero-motion term), flat float32 arrays with a trailing 'invalid' cell (the grid's invalid cells,
    among them those under an occlusion mask, read as it)."""

    EMPTY: "_FlowTable"        # a table without valid cells (the kernel's flow arguments when flow is off)

    def __init__(self, grid: FlowGrid):
        valid = grid.valid
        self.any = bool(valid.any())
        self.rows, self.cols = grid.shape
        self.inv_cell = 1.0 / grid.cell_size
        cov = grid.covariance.astype(np.float64)
        det = cov[..., 0, 0] * cov[..., 1, 1] - cov[..., 0, 1] * cov[..., 1, 0]
        i00, i01, i11 = cov[..., 1, 1] / det, -cov[..., 0, 1] / det, cov[..., 0, 0] / det
        fx, fy = grid.flow[..., 0].astype(np.float64), grid.flow[..., 1].astype(np.float64)
        e0 = student_t_e2(fx, fy, i00, i01, i11)

        def padded(a: np.ndarray) -> np.ndarray:
            return np.append(np.where(valid, a, 0).reshape(-1), 0).astype(np.float32)

        self.fx, self.fy, self.i00, self.i01, self.i11, self.log0 = (
            padded(a) for a in (fx, fy, i00, i01, i11, np.log1p(e0)))
        self.valid = np.append(valid.reshape(-1), False)


_FlowTable.EMPTY = _FlowTable(FlowGrid.empty(1, 1, 1))


def log_likelihood(parts: tuple[PartShape, ...], segments: BodySegments, prev_segments: BodySegments | None,
                   cameras: list[Camera], features: list[FrameFeatures], config: LikelihoodConfig = LikelihoodConfig(),
                   memo: SilhouetteMemo | None = None) -> np.ndarray:
    """log p(z_t | s_t) (N,) up to a constant, summed over cameras (eq. 12). ``memo`` (optional)
    reuses the previous call's projections when ``prev_segments`` is that call's ``segments``."""
    if len(cameras) != len(features):
        raise ValueError(f"likelihood: {len(cameras)} cameras but {len(features)} feature frames")
    prev = segments if prev_segments is None else prev_segments
    total = np.zeros(len(segments))
    projected = []
    for index, (camera, feats) in enumerate(zip(cameras, features)):
        _check_inputs(parts, segments, camera, feats)
        axes = np.empty((len(segments), segments.origin.shape[1], 6))
        prev_axes = axes if prev is segments else (memo.lookup(prev, index) if memo is not None else None)
        total += camera_log_likelihood(parts, segments, prev, camera, feats, config, axes, prev_axes)
        projected.append(axes)
    if memo is not None:
        memo.store(segments, projected)
    return total
