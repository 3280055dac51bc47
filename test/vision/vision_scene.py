"""Rendered test scenes with known truth for the image-likelihood tests (not a test module)."""
from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from awalker_tracker.model.body import BodyDescription, BodySegments
from awalker_tracker.model.kinematics import KinematicConfig, KinematicState, initial_kinematics, pose_body
from awalker_tracker.model.walker import WalkerState
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.render import render

from awalker_tools.model_render import render_rgb

BODY = BodyDescription.default()
PARAMS = BODY.walker_params()


def side_camera(width: int = 320, height: int = 240, focal: float = 300.0, name: str = "side") -> Camera:
    """Looks along +y at the walker (walking along +x) from 4 m."""
    return Camera.look_at(name, width, height, focal, np.array([0.3, -4.0, 1.1]), np.array([0.3, 0.0, 0.9]))


def front_camera(width: int = 320, height: int = 240, focal: float = 300.0, name: str = "front") -> Camera:
    """Looks along -x at the walker, 4 m ahead of it (slightly off-axis)."""
    return Camera.look_at(name, width, height, focal, np.array([4.3, -0.8, 1.2]), np.array([0.3, 0.0, 0.9]))


def background_image(camera: Camera, seed: int = 0) -> np.ndarray:
    """A smooth random colour texture with fine detail (so background flow is measurable)."""
    rng = np.random.default_rng(seed)
    coarse = rng.uniform(40, 215, (camera.height // 12 + 1, camera.width // 12 + 1, 3)).astype(np.float32)
    image = cv2.resize(coarse, (camera.width, camera.height), interpolation=cv2.INTER_CUBIC)
    fine = rng.normal(0, 12, (camera.height // 3 + 1, camera.width // 3 + 1, 1)).astype(np.float32)
    image += cv2.resize(fine, (camera.width, camera.height), interpolation=cv2.INTER_LINEAR)[..., None]
    return np.clip(image, 0, 255).astype(np.uint8)


def noisy(image: np.ndarray, rng: np.random.Generator, std: float = 2.0) -> np.ndarray:
    return np.clip(image + rng.normal(0, std, image.shape), 0, 255).astype(np.uint8)


@dataclass
class Pose:
    walker: WalkerState
    kin: KinematicState

    def segments(self) -> BodySegments:
        return pose_body(BODY, PARAMS, self.walker, self.kin).segments


def walking_poses(frames: int, x0: float = 0.0) -> list[Pose]:
    """A stance phase: the stance leg sweeps from 0.25 to -0.2 rad, the swing leg forward. The hips at
    Table 1's rest (the feet the hip joints' distance apart), as ``synth`` draws its walks; with the
    tracker's narrower step width the depth profile's flat top moves from 0.00-0.03 to 0.01-0.05 m (a
    map row here is ~3 cm of depth)."""
    walker0 = WalkerState.from_arrays(0.25, -0.25, -1.2, 1.5)
    kin0 = initial_kinematics(KinematicConfig(step_width=None), walker0, [x0, 0.0], 0.0, 1, np.random.default_rng(0),
                              body=BODY)
    poses = []
    for f in range(frames):
        phi1 = 0.25 - 0.035 * f
        phi2 = -0.25 + 0.06 * f
        walker = WalkerState.from_arrays(phi1, phi2, -1.2, 1.5)
        kin = kin0.copy()
        kin.knee[:, 1] = np.clip(0.6 - 0.05 * f, 0.05, 0.6)   # swing (right) knee straightens
        poses.append(Pose(walker, kin))
    return poses


def render_frames(camera: Camera, poses: list[Pose], background: np.ndarray, seed: int = 1,
                  noise: float = 2.0) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """RGB frames and part-label images of the poses over the background (with pixel noise)."""
    rng = np.random.default_rng(seed)
    frames, labels = [], []
    for pose in poses:
        result = render(BODY, pose.segments(), camera)
        frames.append(noisy(render_rgb(BODY, pose.segments(), camera, background, result=result), rng, noise))
        labels.append(result.labels)
    return frames, labels


def stacked(poses: list[Pose]) -> Pose:
    """N poses as one batch."""
    walker = WalkerState(*(np.concatenate([getattr(p.walker, f) for p in poses])
                           for f in WalkerState.__dataclass_fields__))
    kin = KinematicState(*(np.concatenate([getattr(p.kin, f) for p in poses])
                           for f in KinematicState.__dataclass_fields__))
    return Pose(walker, kin)


def perturbed(pose: Pose, group: str, rng: np.random.Generator) -> Pose:
    """The pose with one DOF group moved by 3-10 cm (position) or 5-20 degrees (angles)."""
    walker, kin = pose.walker.copy(), pose.kin.copy()
    angle = np.deg2rad(rng.uniform(5, 20)) * rng.choice([-1, 1])
    if group == "position":
        direction = rng.normal(size=2)
        kin.contact_point = kin.contact_point + rng.uniform(0.03, 0.10) * direction / np.linalg.norm(direction)
    elif group == "heading":
        kin.heading = kin.heading + angle
    elif group == "torso":
        kin.torso_lean[:, rng.integers(2)] += angle
    elif group == "stance_leg":
        walker = replace(walker, stance_angle=walker.stance_angle + angle)
    elif group == "swing_leg":
        walker = replace(walker, swing_angle=walker.swing_angle + angle)
    elif group == "knee":
        kin.knee[:, rng.integers(2)] += abs(angle)
    elif group == "hip_abduction":
        kin.hip_abduction[:, rng.integers(2)] += angle
    else:
        raise ValueError(group)
    return Pose(walker, kin)


GROUPS = ("position", "heading", "torso", "stance_leg", "swing_leg", "knee", "hip_abduction")
