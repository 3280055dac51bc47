"""Calibrated pinhole cameras with OpenCV distortion, and the calibration YAML.

World frame: z up, ground at z = 0 (REP 103). Camera (optical) frame: z forward, x right,
y down. A camera's pose is ``world_from_camera``: its optical frame's rotation and position
in the world.

Calibration YAML schema (one file, one or more cameras)::

    cameras:
      - name: cam0                    # [A-Za-z0-9_]+, used in topic names (/cam0/image_raw)
        width: 640                    # pixels
        height: 480
        K: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]   # 3x3 intrinsics (a flat list of 9 also works)
        distortion: [k1, k2, p1, p2, k3]           # OpenCV order; 0, 4, 5 or 8 values
        pose:                         # the optical frame in the world frame
          position: [x, y, z]         # metres
          orientation: [qx, qy, qz, qw]   # unit quaternion (world_from_camera)
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numba
import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from awalker_tracker.errors import InputError, parse_yaml, read_text_file

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_DISTORTION_SIZES = (0, 4, 5, 8)


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated camera. Arrays: K (3, 3), distortion (D,), rotation (3, 3), position (3,)."""

    name: str
    width: int
    height: int
    K: np.ndarray
    distortion: np.ndarray
    rotation: np.ndarray  # world_from_camera rotation: columns are the camera axes in the world
    position: np.ndarray  # camera centre in the world (m)

    @property
    def frame_id(self) -> str:
        """The camera's optical frame name."""
        return f"{self.name}_optical_frame"

    @property
    def quaternion(self) -> np.ndarray:
        """world_from_camera orientation as (qx, qy, qz, qw)."""
        return Rotation.from_matrix(self.rotation).as_quat()

    @classmethod
    def look_at(
        cls,
        name: str,
        width: int,
        height: int,
        focal_length: float,
        position: np.ndarray,
        target: np.ndarray,
        distortion: np.ndarray | None = None,
    ) -> "Camera":
        """A camera at ``position`` (m) looking at ``target`` (m) with the image x axis level."""
        position = np.asarray(position, float)
        forward = np.asarray(target, float) - position
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        if np.linalg.norm(right) < 1e-9:
            raise ValueError("Camera.look_at: viewing direction is vertical; heading undefined")
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        K = np.array([[focal_length, 0, (width - 1) / 2], [0, focal_length, (height - 1) / 2], [0, 0, 1]])
        dist = np.zeros(0) if distortion is None else np.asarray(distortion, float)
        return cls(name, int(width), int(height), K, dist, np.stack([right, down, forward], axis=1), position)

    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) -> camera-frame points (..., 3), metres."""
        return (np.asarray(points) - self.position) @ self.rotation

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points (..., 3) to pixels (..., 2) and depth along the optical axis (...).

        Points at or behind the camera get depth <= 0 and pixel coordinates of NaN.
        Any leading shape works, e.g. (N particles, M points, 3).
        """
        pc = self.world_to_camera(points)
        depth = pc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(depth > 1e-9, 1.0 / depth, np.nan)
        x = pc[..., 0] * inv
        y = pc[..., 1] * inv
        x, y = self._distort(x, y)
        K = self.K
        u = K[0, 0] * x + K[0, 1] * y + K[0, 2]
        v = K[1, 1] * y + K[1, 2]
        return np.stack([u, v], axis=-1), depth

    def in_image(self, points: np.ndarray) -> np.ndarray:
        """Whether world points (..., 3) project in front of the camera and inside the image (...) bool."""
        uv, depth = self.project(points)
        with np.errstate(invalid="ignore"):
            return ((depth > 0) & (uv[..., 0] >= 0) & (uv[..., 0] <= self.width - 1)
                    & (uv[..., 1] >= 0) & (uv[..., 1] <= self.height - 1))

    def pixels_to_normalised(self, uv: np.ndarray, iterations: int = 30) -> np.ndarray:
        """Pixels (..., 2) -> undistorted normalised coordinates (..., 2): the ray through a
        pixel is (x, y, 1) in the camera frame. Inverts the distortion by fixed-point iteration
        (as OpenCV does, with more iterations, stopping once no point moves by more than 1e-12; compiled,
        ``_undistort_kernel``); accurate to ~1e-9 for ordinary lenses."""
        uv = np.asarray(uv, float)
        K = self.K
        yd = (uv[..., 1] - K[1, 2]) / K[1, 1]
        xd = (uv[..., 0] - K[0, 2] - K[0, 1] * yd) / K[0, 0]
        d = self.distortion_coefficients()
        if not d.any():
            return np.stack([xd, yd], axis=-1)
        out = np.empty(xd.shape + (2,))
        _undistort_kernel(np.ascontiguousarray(xd).reshape(-1), np.ascontiguousarray(yd).reshape(-1), d,
                          int(iterations), out.reshape(-1, 2))
        return out

    def distortion_coefficients(self) -> np.ndarray:
        """The distortion as OpenCV's 8 coefficients (k1 k2 p1 p2 k3 k4 k5 k6), zeros where not given."""
        d = np.zeros(8)
        d[: self.distortion.size] = self.distortion
        return d

    def _distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = self.distortion_coefficients()
        if not d.any():
            return x, y
        k1, k2, p1, p2, k3, k4, k5, k6 = d
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return xd, yd

    def to_dict(self) -> dict[str, Any]:
        """This camera as an entry of the calibration YAML."""
        return {
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "K": self.K.tolist(),
            "distortion": self.distortion.tolist(),
            "pose": {"position": self.position.tolist(), "orientation": self.quaternion.tolist()},
        }


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _undistort_kernel(xd: np.ndarray, yd: np.ndarray, d: np.ndarray, iterations: int, out: np.ndarray) -> None:
    """Undistorted (x, y) of distorted normalised points (xd, yd) into ``out`` (M, 2): the fixed point of
    x = (xd - tangential_x(x, y)) / radial(x, y) (OpenCV's model, d = k1 k2 p1 p2 k3 k4 k5 k6), all points
    stepped together until none moves by 1e-12 or more, or ``iterations`` steps."""
    k1, k2, p1, p2, k3, k4, k5, k6 = d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]
    for i in range(xd.size):
        out[i, 0], out[i, 1] = xd[i], yd[i]
    for _ in range(iterations):
        moved = 0.0
        for i in range(xd.size):
            x, y = out[i, 0], out[i, 1]
            r2 = x * x + y * y
            inverse_radial = (1 + r2 * (k4 + r2 * (k5 + r2 * k6))) / (1 + r2 * (k1 + r2 * (k2 + r2 * k3)))
            dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
            x_new, y_new = (xd[i] - dx) * inverse_radial, (yd[i] - dy) * inverse_radial
            moved = max(moved, abs(x_new - x), abs(y_new - y))
            out[i, 0], out[i, 1] = x_new, y_new
        if moved < 1e-12:
            break


def _matrix(value: Any, shape: tuple[int, ...], where: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: expected numbers of shape {shape}, got {value!r}") from exc
    if arr.size != int(np.prod(shape)):
        raise InputError(f"{where}: expected {int(np.prod(shape))} numbers (shape {shape}), got shape {arr.shape}")
    arr = arr.reshape(shape)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{where}: contains NaN or infinity")
    return arr


def _size(width: Any, height: Any, where: str) -> tuple[int, int]:
    """Image width and height (px), positive integers."""
    if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v > 0 for v in (width, height)):
        raise InputError(f"{where}: width and height must be positive integers, got {width!r}, {height!r}")
    return int(width), int(height)


def _intrinsics(value: Any, where: str) -> np.ndarray:
    """K (3, 3): finite, [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0."""
    K = _matrix(value, (3, 3), where)
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
        raise InputError(f"{where}: K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {K.tolist()}")
    return K


def _rotation(value: Any, where: str) -> np.ndarray:
    """world_from_camera rotation (3, 3) from a quaternion (qx, qy, qz, qw) whose norm is 1 within 1e-3 (then
    normalised); a zero or otherwise non-unit quaternion is an error."""
    quat = _matrix(value, (4,), where)
    norm = float(np.linalg.norm(quat))
    if norm < 1e-6:
        raise InputError(f"{where}: a zero quaternion is no rotation; expected a unit quaternion [qx, qy, qz, qw]")
    if abs(norm - 1.0) > 1e-3:
        raise InputError(f"{where}: must be a unit quaternion [qx, qy, qz, qw], norm is {norm:.4f}")
    return Rotation.from_quat(quat / norm).as_matrix()


def _name(name: Any, where: str) -> str:
    if not isinstance(name, str) or not _NAME.match(name):
        raise InputError(f"{where}: name must match [A-Za-z][A-Za-z0-9_]*, got {name!r}")
    return name


def camera_from_dict(entry: Any, where: str) -> Camera:
    """One camera from a calibration YAML entry; ``where`` names the file and entry in errors."""
    if not isinstance(entry, dict):
        raise InputError(f"{where}: expected a mapping with name, width, height, K, distortion, pose")
    missing = [k for k in ("name", "width", "height", "K", "pose") if k not in entry]
    if missing:
        raise InputError(f"{where}: missing field(s) {', '.join(missing)}")
    name = _name(entry["name"], where)
    where = f"{where} (camera {name})"
    width, height = _size(entry["width"], entry["height"], where)
    K = _intrinsics(entry["K"], f"{where}: K")
    dist_value = entry.get("distortion") or []
    dist = np.asarray(dist_value, float).ravel() if isinstance(dist_value, list) else None
    if dist is None or dist.size not in _DISTORTION_SIZES or not np.all(np.isfinite(dist)):
        raise InputError(f"{where}: distortion must be a list of 0, 4, 5 or 8 numbers, got {dist_value!r}")
    pose = entry["pose"]
    if not isinstance(pose, dict) or "position" not in pose or "orientation" not in pose:
        raise InputError(f"{where}: pose must have position [x, y, z] and orientation [qx, qy, qz, qw]")
    position = _matrix(pose["position"], (3,), f"{where}: pose.position")
    rotation = _rotation(pose["orientation"], f"{where}: pose.orientation")
    return Camera(name, width, height, K, dist, rotation, position)


#: sensor_msgs/CameraInfo distortion models the camera model takes (OpenCV's radial-tangential family) and the
#: numbers of coefficients each may carry: plumb_bob k1 k2 p1 p2 [k3] (or none: an uncalibrated driver's zero
#: distortion), rational_polynomial k1 k2 p1 p2 k3 k4 k5 k6, and an empty model with no coefficients.
DISTORTION_MODELS: dict[str, tuple[int, ...]] = {"plumb_bob": (0, 4, 5), "rational_polynomial": (8,), "": (0,)}


def camera_from_info(name: str, info: Any, position: Any, orientation: Any, info_where: str,
                     pose_where: str) -> Camera:
    """A validated Camera from a sensor_msgs/CameraInfo (rclpy or rosbags message: width, height, k,
    distortion_model, d) and the pose of its optical frame in the world: ``position`` (x, y, z) m and
    ``orientation`` (qx, qy, qz, qw). The one builder of cameras from messages (bag reader, tracker and
    features nodes). Checked: a positive size, finite intrinsics with fx, fy > 0, a distortion model of
    ``DISTORTION_MODELS`` with as many finite coefficients as it takes, a unit quaternion (normalised) and a
    finite position; an InputError names ``info_where`` (the camera_info topic) or ``pose_where`` (where the
    pose came from) and what was expected."""
    name = _name(name, info_where)
    width, height = _size(info.width, info.height, info_where)
    K = _intrinsics(info.k, f"{info_where}: k")
    model = str(info.distortion_model)
    if model not in DISTORTION_MODELS:
        raise InputError(f"{info_where}: distortion model {model!r} is not one this camera model takes; expected "
                         f"{', '.join(repr(m) for m in DISTORTION_MODELS)}")
    dist = np.asarray(info.d, float).ravel()
    if dist.size not in DISTORTION_MODELS[model] or not np.all(np.isfinite(dist)):
        counts = " or ".join(str(n) for n in DISTORTION_MODELS[model])
        raise InputError(f"{info_where}: distortion model {model!r} takes {counts} finite coefficients in d, "
                         f"got {dist.tolist()}")
    position = _matrix(position, (3,), f"{pose_where}: position")
    rotation = _rotation(orientation, f"{pose_where}: orientation")
    return Camera(name, width, height, K, dist, rotation, position)


def load_calibration(path: str | Path) -> list[Camera]:
    """Read a calibration YAML (schema in this module's docstring) into cameras."""
    path = Path(path)
    text = read_text_file(path, "calibration file")
    data = parse_yaml(text, str(path))
    if not isinstance(data, dict) or not isinstance(data.get("cameras"), list) or not data["cameras"]:
        raise InputError(f"{path}: expected a top-level 'cameras:' list with at least one camera")
    cameras = [camera_from_dict(entry, f"{path}: cameras[{i}]") for i, entry in enumerate(data["cameras"])]
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise InputError(f"{path}: camera names must be unique, got {names}")
    return cameras


def save_calibration(cameras: list[Camera], path: str | Path) -> None:
    """Write cameras as a calibration YAML that ``load_calibration`` reads back."""
    Path(path).write_text(yaml.safe_dump({"cameras": [c.to_dict() for c in cameras]}, sort_keys=False))
