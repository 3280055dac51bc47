"""Where is the person? Foreground blobs in the appearance maps, placed on the ground plane.

The features of every camera carry per-class log-likelihood ratios (foreground vs background,
``FrameFeatures.llr``). A pixel whose best class beats the background by ``threshold`` nats is
foreground; the largest connected blob covering at least ``min_area_fraction`` of the image is the person
(``person_blob``), or, when the caller knows roughly where the person followed is (``near``: a tracked
pelvis), the blob nearest to where that point projects (``blob_near``), so that a second person in
view is not mixed into the detection. Its image is placed in the world with the calibrated camera and
the ground plane z = 0 (``detect_person``):

The blob's column is the mean column of its upper half (head, shoulders, trunk): the pelvis is
under it, while the lower half follows the stride (a planted foot, a trailing leg), the contact
shadow and what is left of a ghost in a background learned from the walk itself.

- one camera: the ray through the blob's column at its lowest row (the feet) meets the ground
  at the near edge of the feet; the person stands ``near_edge_m`` (0.12 m: half a stride's width
  of feet and hips, measured on renders) farther along the ray;
- several cameras: each blob's column, seen from its camera, is a vertical plane; the
  person stands on the line where these planes meet (least squares over the cameras), which
  does not depend on where the feet end in the image. With two cameras looking nearly along the
  same line the planes are close to parallel; then the feet rows decide, as with one camera.

The height is where the ray through the blob's column at its top row passes over the ground
point (median over cameras). ``GroundTrack`` keeps the positions of the frames where the person
was wholly in view of some camera and fits their ground velocity. Used to re-acquire a lost track
(``inference.recovery``) and to start the tracker without a start description (``inference.autostart``).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.features import FrameFeatures


@dataclass(frozen=True)
class PersonBlob:
    """The person's blob in one camera's image (pixels of the full image)."""

    camera: str
    box: tuple[float, float, float, float]   # u0, v0, u1, v1 (px)
    area_px: float
    feet_uv: tuple[float, float]             # the blob's column (module docstring), lowest row
    head_uv: tuple[float, float]             # the blob's column, highest row
    row_px: float = 1.0                      # height of one row of the map the blob was found in (px)


@dataclass(frozen=True)
class PersonDetection:
    """A person seen in the images: ground position (m, world xy), height (m) and the blobs."""

    position: np.ndarray
    height: float
    blobs: tuple[PersonBlob, ...]
    triangulated: bool = False        # position from several cameras' planes (~0.1 m), not one feet row
    row_depth_m: float = 0.0          # feet-row positions: how far over the ground one map row lower moves
                                      # the position (m; the feet row's resolution: ~d^2 / h per radian of row);
                                      # 0 when triangulated


#: Pieces of one person ``_join_stacked`` joins, as fractions of the upper piece's height in map rows (and of the
#: smallest person blob's area): a skirt, shorts or trousers near the floor's colour leave the legs as a piece of
#: their own a few rows under the trunk (a gap up to 30 % of the trunk piece's height), or as fragments whose top
#: rows reach up beside the hem (overlapping up to 15 %), often smaller than a whole person blob (a quarter of it).
STACK_MAX_GAP = 0.3
STACK_MAX_OVERLAP = 0.15
STACK_LOWER_AREA = 0.25
STACK_LOWER_ASPECT = 0.7     # the lower piece is at least this tall for its width: legs, not a flat shadow
LEGS_START = 0.6             # legs start this far down a person-sized piece: in its lowest 40 % of rows (the hips)


def _join_stacked(labels: np.ndarray, stats: np.ndarray, min_pixels: float) -> None:
    """Relabel (in place) each component lying under another as that one, when the upper one has at least
    ``min_pixels`` map pixels, the lower at least ``STACK_LOWER_AREA`` of that and is upright (``STACK_LOWER_ASPECT``),
    they share at least half the narrower one's columns, the lower starts in the upper's lowest 40 % of rows
    and ends below it, and between them lies a gap of at most ``STACK_MAX_GAP`` of the upper's height in rows
    (at least one row) or an overlap of at most ``STACK_MAX_OVERLAP``: a belt, a waist or a skirt whose colours
    are near the background's leaves rows of the body below the threshold and would cut the person in two,
    and the feet row of the trunk alone puts them metres away. Measured on the broad development set's tuning
    recordings, one camera (``benchmarks/bench_detection.py --set tuning --seeds 0 1``: 44 recordings, the blob
    nearest the true pelvis, every background learned from the walk): positions more than 0.5 m off in 1603 of
    8325 frames against 1806 of 8319 when only pieces one row apart joined (07_01 seed 0, a grey skirt on a grey
    floor: median 3.41 -> 0.21 m), the median error of no recording worse by more than 0.03 m; a ghost under a
    walk's first frames was joined in one (07_01 seed 1, hands off: 21 -> 30 frames). Pieces side by side, far
    apart, small, or flat (a contact shadow) stay apart."""
    count = stats.shape[0]
    area = stats[:, cv2.CC_STAT_AREA]
    pieces = 1 + np.flatnonzero(area[1:] >= STACK_LOWER_AREA * min_pixels)      # labels of the candidates
    if pieces.size < 2:
        return
    left, top = stats[pieces, cv2.CC_STAT_LEFT], stats[pieces, cv2.CC_STAT_TOP]
    width, height = stats[pieces, cv2.CC_STAT_WIDTH], stats[pieces, cv2.CC_STAT_HEIGHT]
    bottom = top + height                                  # first row below each piece
    shared = np.minimum.outer(left + width, left + width) - np.maximum.outer(left, left)
    # [upper, lower]: rows between the lower's top and the upper's bottom (< 0: they overlap)
    gap = top[None, :] - bottom[:, None]
    stacked = ((area[pieces] >= min_pixels)[:, None] & (height >= STACK_LOWER_ASPECT * width)[None, :]
               & (shared >= 0.5 * np.minimum.outer(width, width))
               & (top[None, :] >= (top + LEGS_START * height)[:, None]) & (bottom[None, :] > bottom[:, None])
               & (gap >= -np.floor(STACK_MAX_OVERLAP * height)[:, None])
               & (gap <= np.maximum(1, np.floor(STACK_MAX_GAP * height))[:, None]))
    if not stacked.any():
        return
    parent = np.arange(count)

    def root(k: int) -> int:
        while parent[k] != k:
            k = int(parent[k])
        return k

    for upper, lower in zip(*np.nonzero(stacked)):
        parent[root(int(pieces[lower]))] = root(int(pieces[upper]))
    roots = np.array([root(k) for k in range(count)])
    labels[...] = roots[labels]
    for k in np.flatnonzero(roots != np.arange(count)):
        r = roots[k]
        x0, y0 = min(stats[r, 0], stats[k, 0]), min(stats[r, 1], stats[k, 1])
        x1 = max(stats[r, 0] + stats[r, 2], stats[k, 0] + stats[k, 2])
        y1 = max(stats[r, 1] + stats[r, 3], stats[k, 1] + stats[k, 3])
        stats[r, :4] = (x0, y0, x1 - x0, y1 - y0)
        stats[r, cv2.CC_STAT_AREA] += stats[k, cv2.CC_STAT_AREA]
        stats[k, cv2.CC_STAT_AREA] = 0


#: Legs broken into fragments under a person-sized piece (``_join_trailing``), as fractions of that piece's height in
#: map rows (and width, and area): trousers near the floor's colour leave the legs as specks and strips a row or
#: three apart, each too small or too far up beside the trunk to join as a stacked piece.
TRAIL_MAX_GAP = 0.15         # empty rows from the lowest row reached so far to the next fragment (at least 2)
TRAIL_MARGIN = 0.5           # fragments may lie this far beside the piece's columns, on either side (a stride)
TRAIL_MIN_DROP = 0.3         # the fragments carry the lowest row down by at least this much (a contact shadow: less)
TRAIL_MIN_AREA = 0.1         # ... and hold at least this much of the piece's area (not a trail of specks)
TRAIL_MAX_AREA = 1.5         # a fragment larger than this is someone else (a nearer person is larger)


def _join_trailing(labels: np.ndarray, stats: np.ndarray, min_pixels: float) -> None:
    """Relabel (in place) the pieces trailing under each person-sized piece (at least ``min_pixels`` map pixels,
    topmost first) as that piece: starting in its lowest 40 % of rows, within its columns widened by
    ``TRAIL_MARGIN`` of its width, each the next one down at most ``TRAIL_MAX_GAP`` of its height (at least 2
    rows) below the lowest row reached so far, none larger than ``TRAIL_MAX_AREA`` x its area. They join only
    together, when they reach at least ``TRAIL_MIN_DROP`` of its height lower, hold ``TRAIL_MIN_AREA`` of its area
    and stand upright (``STACK_LOWER_ASPECT``): legs in fragments, whose piece's own lowest row is the waist and
    puts a person a few metres farther along the camera's ray (a reporting-set recording, light trousers on a
    light floor: 3-4 m in most frames of the walk's first second). A contact shadow (a few rows), a speck
    and a piece farther below than the gap stay apart."""
    area, top, left = stats[:, cv2.CC_STAT_AREA], stats[:, cv2.CC_STAT_TOP], stats[:, cv2.CC_STAT_LEFT]  # views
    live = 1 + np.flatnonzero(area[1:] > 0)
    if live.size < 2:
        return
    below = top + stats[:, cv2.CC_STAT_HEIGHT]             # first row under each piece
    right = left + stats[:, cv2.CC_STAT_WIDTH]             # first column right of each piece
    by_top = live[np.argsort(top[live], kind="stable")]
    joined = np.zeros(stats.shape[0], bool)
    for upper in by_top[area[by_top] >= min_pixels]:
        if joined[upper]:
            continue
        height, width = float(stats[upper, cv2.CC_STAT_HEIGHT]), float(stats[upper, cv2.CC_STAT_WIDTH])
        band = (left[upper] - TRAIL_MARGIN * width, right[upper] + TRAIL_MARGIN * width)
        gap = max(2, int(TRAIL_MAX_GAP * height))
        reach, chain = int(below[upper]), []
        for piece in by_top:
            if (piece == upper or joined[piece] or top[piece] < top[upper] + LEGS_START * height
                    or right[piece] <= band[0] or left[piece] >= band[1] or below[piece] <= reach
                    or area[piece] > TRAIL_MAX_AREA * area[upper]):
                continue
            if top[piece] - reach > gap:
                break
            chain.append(piece)
            reach = int(below[piece])
        if not chain:
            continue
        chain_width = right[chain].max() - left[chain].min()
        if (reach - below[upper] < TRAIL_MIN_DROP * height or area[chain].sum() < TRAIL_MIN_AREA * area[upper]
                or reach - top[chain].min() < STACK_LOWER_ASPECT * chain_width):
            continue
        for piece in chain:
            labels[labels == piece] = upper
            joined[piece] = True
        x0, y0 = min(left[upper], left[chain].min()), min(top[upper], top[chain].min())
        x1 = max(right[upper], right[chain].max())
        stats[upper, :4] = (x0, y0, x1 - x0, reach - y0)
        stats[upper, cv2.CC_STAT_AREA] += area[chain].sum()
        stats[chain, cv2.CC_STAT_AREA] = 0
        right, below = left + stats[:, cv2.CC_STAT_WIDTH], top + stats[:, cv2.CC_STAT_HEIGHT]


def _fill_row_gaps(labels: np.ndarray, stats: np.ndarray) -> None:
    """Give (in place) each background map pixel with one blob's pixels right above and below it to that
    blob: a notch a row high across a limb or the waist, as a vertical closing would fill, but without
    joining two blobs."""
    above, below = labels[:-2], labels[2:]
    gap = (labels[1:-1] == 0) & (above == below) & (above != 0)
    rows, cols = np.nonzero(gap)
    if rows.size:
        filled = above[rows, cols]
        labels[rows + 1, cols] = filled
        np.add.at(stats[:, cv2.CC_STAT_AREA], filled, 1)


def person_blobs(features: FrameFeatures, camera_name: str = "", threshold: float = 2.0,
                 min_area_fraction: float = 0.0015) -> list[PersonBlob]:
    """Every foreground blob big enough to be a person (``threshold`` nats, at least ``min_area_fraction``
    of the image: 460 px of 640x480), largest first; pieces of one person stacked one under the other (a
    waist or a skirt of the background's colour between them) are one blob (``_join_stacked``) and its one-row
    notches are filled (``_fill_row_gaps``)."""
    mask = (np.max(features.llr, axis=0) > threshold).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    d = float(features.downsample)
    min_area = min_area_fraction * features.image_width * features.image_height
    _join_stacked(labels, stats, min_area / (d * d))
    _join_trailing(labels, stats, min_area / (d * d))
    _fill_row_gaps(labels, stats)
    order = 1 + np.argsort(-stats[1:, cv2.CC_STAT_AREA])
    blobs = []
    for label in order:
        area = float(stats[label, cv2.CC_STAT_AREA]) * d * d
        if area < min_area:
            break
        rows, cols = np.nonzero(labels == label)
        top, bottom = rows.min(), rows.max()
        # map pixel j covers image pixels d j .. d j + d - 1 (centre d j + (d - 1) / 2)
        centre = lambda j: d * j + 0.5 * (d - 1)  # noqa: E731
        # the upper half's mean column (module docstring)
        middle = centre(float(np.mean(cols[rows <= 0.5 * (top + bottom)])))
        box = (d * cols.min() - 0.5, d * top - 0.5, d * (cols.max() + 1) - 0.5, d * (bottom + 1) - 0.5)
        blobs.append(PersonBlob(camera_name, box, area, (middle, centre(bottom)), (middle, centre(top)), d))
    return blobs


def person_blob(features: FrameFeatures, camera_name: str = "", threshold: float = 2.0,
                min_area_fraction: float = 0.0015) -> PersonBlob | None:
    """The largest of ``person_blobs``, or None."""
    blobs = person_blobs(features, camera_name, threshold, min_area_fraction)
    return blobs[0] if blobs else None


def blob_near(blobs: list[PersonBlob], camera: Camera, point: np.ndarray) -> PersonBlob | None:
    """The blob whose box is nearest (px; 0 inside) to where the world ``point`` (3,) projects, the
    larger on a tie, if that is within the blob's own height; else (or with no blobs, or the point
    behind the camera) None."""
    uv, depth = camera.project(np.asarray(point, float)[None])
    if not blobs or depth[0] <= 0:
        return None
    u, v = uv[0]

    def gap(blob: PersonBlob) -> float:
        u0, v0, u1, v1 = blob.box
        return float(np.hypot(max(u0 - u, 0.0, u - u1), max(v0 - v, 0.0, v - v1)))

    best = min(blobs, key=lambda b: (gap(b), -b.area_px))
    return best if gap(best) <= best.box[3] - best.box[1] else None


def on_blob(camera: Camera, point: np.ndarray, blob: PersonBlob, margin: float) -> bool:
    """Whether the world ``point`` (3,) projects, in front of ``camera``, inside ``blob``'s box widened by
    ``margin`` x its size on each side."""
    uv, depth = camera.project(np.asarray(point, float)[None])
    u0, v0, u1, v1 = blob.box
    du, dv = margin * (u1 - u0), margin * (v1 - v0)
    return bool(depth[0] > 0 and u0 - du <= uv[0, 0] <= u1 + du and v0 - dv <= uv[0, 1] <= v1 + dv)


def ends_on_occlusion(blob: PersonBlob, features: FrameFeatures, rows: int = 2, fraction: float = 0.5) -> bool:
    """Whether most (``fraction``) of the map pixels just under ``blob`` (``rows`` rows, within its columns)
    lie under the camera's occlusion mask (``FrameFeatures.occlusion``; none: False): the blob's lowest row is
    then the top edge of something known to stand in front of the person, not their feet."""
    if features.occlusion is None:
        return False
    d = features.downsample
    u0, _, u1, v1 = blob.box
    bottom = int(round((v1 + 0.5) / d)) - 1
    first, last = int(round((u0 + 0.5) / d)), int(round((u1 + 0.5) / d))
    below = features.occlusion[bottom + 1: bottom + 1 + rows, first:last]
    return bool(below.size and below.mean() >= fraction)


def _ray(camera: Camera, uv: tuple[float, float]) -> np.ndarray:
    """World direction (3,) of the ray through pixel ``uv``."""
    xy = camera.pixels_to_normalised(np.asarray([uv], float))[0]
    return camera.rotation @ np.array([xy[0], xy[1], 1.0])


def ground_point(camera: Camera, uv: tuple[float, float]) -> np.ndarray | None:
    """World xy (m) where the ray through ``uv`` meets the ground z = 0; None if it does not."""
    d = _ray(camera, uv)
    if d[2] >= -1e-9:
        return None
    t = -camera.position[2] / d[2]
    return camera.position[:2] + t * d[:2]


def _height_over(camera: Camera, uv: tuple[float, float], xy: np.ndarray) -> float:
    """Height (m) at which the ray through ``uv`` passes over the ground point ``xy``."""
    d = _ray(camera, uv)
    horizontal = np.linalg.norm(d[:2])
    if horizontal < 1e-9:
        return float("nan")
    t = np.linalg.norm(xy - camera.position[:2]) / horizontal
    return float(camera.position[2] + t * d[2])


def detect_person(features: list[FrameFeatures], cameras: list[Camera], threshold: float = 2.0,
                  min_area_fraction: float = 0.0015, min_plane_angle_deg: float = 20.0,
                  near_edge_m: float = 0.12, near: np.ndarray | None = None) -> PersonDetection | None:
    """The person's ground position and height from every camera's largest blob, or with ``near`` (a world
    point (3,) on the person followed) the blob nearest to it (module docstring); when no camera has a
    blob near it, as without ``near``."""
    seen = [person_blobs(feats, camera.name, threshold, min_area_fraction) for feats, camera in zip(features, cameras)]
    return locate_person(seen, cameras, min_plane_angle_deg, near_edge_m, near)


def locate_person(seen: list[list[PersonBlob]], cameras: list[Camera], min_plane_angle_deg: float = 20.0,
                  near_edge_m: float = 0.12, near: np.ndarray | None = None) -> PersonDetection | None:
    """``detect_person`` from every camera's blobs already found (``person_blobs``, in camera order)."""
    if near is not None and all(blob_near(c, camera, near) is None for c, camera in zip(seen, cameras)):
        near = None
    if near is None and len(cameras) > 1:
        # several cameras and nothing known: the largest blob of any camera is the person; the other
        # cameras' blobs are those nearest to where its feet row puts them (not their own largest:
        # with two people in view each camera's largest may be a different person)
        largest = [(b.area_px, k) for k, bs in enumerate(seen) for b in bs[:1]]
        if largest:
            k = max(largest)[1]
            ground = ground_point(cameras[k], seen[k][0].feet_uv)
            if ground is not None:
                near = np.append(ground, 0.9)
    blobs, planes = [], []
    for candidates, camera in zip(seen, cameras):
        blob = (candidates[0] if candidates else None) if near is None else blob_near(candidates, camera, near)
        if blob is None:
            continue
        blobs.append(blob)
        # vertical plane through the camera and the blob's column: normal n, n . x = n . c
        d = _ray(camera, (blob.feet_uv[0], 0.5 * (blob.box[1] + blob.box[3])))[:2]
        if np.linalg.norm(d) > 1e-9:
            normal = np.array([-d[1], d[0]]) / np.linalg.norm(d)
            planes.append((normal, float(normal @ camera.position[:2]), camera, blob))
    if not blobs:
        return None
    position, triangulated = None, False
    if len(planes) >= 2:
        normals = np.array([p[0] for p in planes])
        cosines = np.abs(normals @ normals.T)           # planes meet at the angle between their normals
        spread = np.degrees(np.arccos(np.clip(cosines.min(), 0.0, 1.0)))
        if spread >= min_plane_angle_deg:
            position = np.linalg.lstsq(normals, np.array([p[1] for p in planes]), rcond=None)[0]
            triangulated = True
    by_camera = {c.name: c for c in cameras}
    row_depth = 0.0
    if position is None:
        points, row_depths = [], []
        for b in blobs:
            camera = by_camera[b.camera]
            point = ground_point(camera, b.feet_uv)
            if point is not None:
                away = point - camera.position[:2]
                points.append(point + near_edge_m * away / max(float(np.linalg.norm(away)), 1e-9))
                lower = ground_point(camera, (b.feet_uv[0], b.feet_uv[1] + b.row_px))
                row_depths.append(float(np.linalg.norm(point - lower)) if lower is not None else 0.0)
        if not points:
            return None
        position = np.mean(points, axis=0)
        row_depth = float(np.mean(row_depths))
    heights = [_height_over(by_camera[b.camera], b.head_uv, position) for b in blobs]
    return PersonDetection(np.asarray(position, float), float(np.nanmedian(heights)), tuple(blobs), triangulated,
                           row_depth)


def wholly_in_view(detection: PersonDetection, cameras: list[Camera], border_px: float = 2.0) -> bool:
    """The person is wholly in view of some camera: a blob touching the image border misplaces the feet."""
    by_name = {c.name: c for c in cameras}
    for blob in detection.blobs:
        camera = by_name[blob.camera]
        u0, v0, u1, v1 = blob.box
        if u0 > border_px and v0 > border_px and u1 < camera.width - 1 - border_px and v1 < camera.height - 1 - border_px:
            return True
    return False


class GroundTrack:
    """Detected ground positions per frame (None: no reliable detection) and their recent velocity. A frame
    may also hold the person seen without a position (``add(..., seen=True)``: their feet hidden), which
    counts towards a window's frames but not into its fit."""

    def __init__(self, dt: float, keep_frames: int = 300) -> None:
        self.dt = float(dt)
        self.keep_frames = keep_frames
        self.positions: dict[int, np.ndarray | None] = {}
        self.seen_without_position: set[int] = set()

    def add(self, frame: int, position: np.ndarray | None, seen: bool = False) -> None:
        """Frame ``frame``'s ground position (m), or None; ``seen`` with None: the person was there, unplaced."""
        self.positions[frame] = None if position is None else np.asarray(position, float)
        if seen and position is None:
            self.seen_without_position.add(frame)
        for old in [f for f in self.positions if f < frame - self.keep_frames]:
            del self.positions[old]
            self.seen_without_position.discard(old)

    def span(self, window_s: float) -> int:
        """Frames in a window of ``window_s`` (at least 2)."""
        return max(2, int(round(window_s / self.dt)))

    def _window(self, frame: int, window_s: float) -> tuple[int, list[tuple[int, np.ndarray]]]:
        """(frames in the ``window_s`` up to ``frame``, its (frame, position) pairs with a position)."""
        span = self.span(window_s)
        return span, [(f, p) for f in range(frame - span, frame + 1) if (p := self.positions.get(f)) is not None]

    def velocity(self, frame: int, window_s: float, min_fraction: float = 0.8) -> np.ndarray | None:
        """Ground velocity (m/s) of the line fit (``_line_fit``) over the ``window_s`` up to ``frame``, or None
        when fewer than ``min_fraction`` of its frames (and fewer than 3) saw the person, or fewer than half of
        those had a position."""
        span, points = self._window(frame, window_s)
        needed = max(3, int(min_fraction * span))
        unplaced = sum(1 for f in range(frame - span, frame + 1) if f in self.seen_without_position)
        if len(points) + unplaced < needed or len(points) < max(3, int(0.5 * min_fraction * span)):
            return None
        return self._line_fit(points, frame)[0] / self.dt

    def central_frame(self, frame: int, window_s: float) -> int | None:
        """The mean (rounded) of the frames with a position in the ``window_s`` up to ``frame``: where a
        straight-line fit of them is most precise (None if there is none)."""
        _, points = self._window(frame, window_s)
        return int(round(float(np.mean([f for f, _ in points])))) if points else None

    def fitted_position(self, frame: int, window_s: float, at: int | None = None) -> np.ndarray | None:
        """The line fit (``_line_fit``) of the positions in the window up to ``frame``, evaluated at frame
        ``at`` (default ``frame``; steadier than one detection)."""
        _, points = self._window(frame, window_s)
        if len(points) < 2:
            return None
        return self._line_fit(points, frame if at is None else at)[1]

    @staticmethod
    def _line_fit(points: list[tuple[int, np.ndarray]], at: int, outlier_floor_m: float = 0.5,
                  iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
        """Straight-line fit of (frame, position) pairs: (slope m/frame, value at frame ``at``). Positions
        farther from the line than 3 robust standard deviations of the distances (at least
        ``outlier_floor_m``) are dropped and the line fitted again: a blob broken in two or merged
        with something else misplaces one frame's person by metres."""
        t = np.array([f for f, _ in points], float) - at
        xy = np.array([p for _, p in points])

        def fit(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """Least squares over ``rows``: (slope, value at ``at``), each (2,)."""
            t_mean, xy_mean = t[rows].mean(), xy[rows].mean(axis=0)
            centred = t[rows] - t_mean
            slope = centred @ (xy[rows] - xy_mean) / (centred @ centred)
            return slope, xy_mean - slope * t_mean

        keep = np.ones(len(t), bool)
        for _ in range(iterations):
            slope, value = fit(keep)
            distance = np.linalg.norm(xy - (slope * t[:, None] + value), axis=1)
            bound = max(3.0 * 1.4826 * float(np.median(distance[keep])), outlier_floor_m)
            inside = distance <= bound
            if inside.sum() < 2 or np.array_equal(inside, keep):
                break
            keep = inside
        return fit(keep)
