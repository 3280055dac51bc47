"""Ray casting: silhouettes against independent geometry, depth, self-occlusion, a whole body's labels."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from awalker_tracker.model.body import PART_NAMES, BodyDescription, PartShape
from awalker_tracker.model.kinematics import KinematicConfig, initial_kinematics, pose_body
from awalker_tracker.model.walker import WalkerState
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.render import render_labels, render_parts


def camera(distortion=None, focal=600.0, width=320, height=240) -> Camera:
    return Camera.look_at("cam", width, height, focal, np.array([0.0, -4.0, 1.0]), np.array([0.0, 0.0, 1.0]),
                          distortion=distortion)


def shape(length=0.6, r0=(0.15, 0.08), r1=(0.07, 0.05)) -> PartShape:
    return PartShape("p", "legs", length, np.array(r0, float), np.array(r1, float))


def hull_area(part: PartShape, origin: np.ndarray, rotation: np.ndarray, cam: Camera) -> float:
    """Silhouette area (px^2) of a convex part: convex hull of its densely sampled, projected surface."""
    z = np.linspace(0, part.length, 200)
    angle = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    s = (z / part.length)[:, None, None]
    radii = part.radii_start + (part.radii_end - part.radii_start) * s  # (Z, 1, 2)
    pts = np.stack([radii[..., 0] * np.cos(angle), radii[..., 1] * np.sin(angle),
                    np.broadcast_to(z[:, None], (200, 720))], axis=-1).reshape(-1, 3)
    uv, _ = cam.project(origin + pts @ rotation.T)
    hull = cv2.convexHull(uv.astype(np.float32))
    return float(cv2.contourArea(hull))


@pytest.mark.parametrize("seed", range(4))
def test_silhouette_area_matches_projected_convex_hull(seed):
    rng = np.random.default_rng(seed)
    cam = camera()
    part = shape()
    rotation = Rotation.random(random_state=seed).as_matrix()
    origin = np.array([0.0, 0.0, 1.0]) + rng.uniform(-0.2, 0.2, 3) - rotation[:, 2] * part.length / 2
    result = render_parts((part,), origin[None], rotation[None], cam)
    area = np.count_nonzero(result.labels == 0)
    expected = hull_area(part, origin, rotation, cam)
    assert expected > 500
    assert area == pytest.approx(expected, rel=0.03)
    assert np.all(np.isfinite(result.depth[result.labels == 0]))
    assert np.all(np.isinf(result.depth[result.labels < 0]))


def test_end_on_cylinder_is_an_exact_ellipse_at_the_right_depth():
    cam = camera(focal=500.0, width=200, height=200)
    part = shape(length=0.5, r0=(0.2, 0.1), r1=(0.2, 0.1))
    near = 3.0
    forward = cam.rotation[:, 2]
    origin = cam.position + forward * near
    # Segment axis along the optical axis (away from the camera), ellipse axes along image x and y.
    rotation = np.stack([cam.rotation[:, 0], cam.rotation[:, 1], forward], axis=1)
    result = render_parts((part,), origin[None], rotation[None], cam)
    area = np.count_nonzero(result.labels == 0)
    expected = np.pi * (500 * 0.2 / near) * (500 * 0.1 / near)
    assert area == pytest.approx(expected, rel=0.015)
    assert np.min(result.depth) == pytest.approx(near, abs=1e-6)
    assert result.depth[100, 100] == pytest.approx(near, abs=1e-6)  # the flat near cap


def test_nearer_part_occludes_and_depth_is_the_nearest_surface():
    cam = camera()
    part = shape(length=0.8, r0=(0.1, 0.1), r1=(0.1, 0.1))
    up = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1]])
    # Two vertical cylinders on the camera's line of sight (camera looks along +y).
    origins = np.array([[0.0, 0.5, 0.6], [0.05, -0.5, 0.6]])
    result = render_parts((part, part), origins, np.stack([up, up]), cam)
    uv, depth = cam.project(np.array([0.05, -0.5, 1.0]))
    u, v = np.round(uv).astype(int)
    assert result.labels[v, u] == 1
    assert result.depth[v, u] == pytest.approx(depth - 0.1, abs=2e-3)  # front surface, radius 0.1
    assert np.count_nonzero(result.labels == 0) > 0  # the far one still peeks out


def test_distorted_camera_labels_agree_with_projection():
    cam = camera(distortion=[-0.25, 0.08, 0.001, -0.002, 0.0])
    part = shape(length=1.2, r0=(0.05, 0.05), r1=(0.05, 0.05))
    rotation = np.eye(3)
    origin = np.array([0.9, 0.0, 0.2])  # near the image edge where distortion is strong
    result = render_parts((part,), origin[None], rotation[None], cam)
    axis_points = origin + np.linspace(0.05, 1.15, 12)[:, None] * rotation[:, 2]
    uv, _ = cam.project(axis_points - np.array([0.0, 0.05, 0.0]))  # front surface points
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < cam.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height - 1)
    assert inside.sum() >= 6
    for u, v in np.round(uv[inside]).astype(int):
        assert result.labels[v, u] == 0


def test_whole_body_labels():
    body = BodyDescription.default()
    params = body.walker_params()
    walker = WalkerState.from_arrays(0.2, -0.2, -1.0, 1.0)
    kin = initial_kinematics(KinematicConfig(), walker, [0.0, 0.0], 0.0, 1, np.random.default_rng(0), body=body)
    pose = pose_body(body, params, walker, kin)
    cam = Camera.look_at("cam", 320, 240, 300.0, np.array([0.5, -4.0, 1.0]), np.array([0.0, 0.0, 0.9]))
    labels, depth = render_labels(body, pose.segments, cam)
    seen = set(np.unique(labels)) - {-1}
    assert {PART_NAMES.index(p) for p in ("torso", "head", "left_upper_leg", "right_lower_leg")} <= seen
    (u, v), _ = cam.project(pose.markers[0, 1])  # thorax marker lies inside the torso
    assert labels[int(round(v)), int(round(u))] == PART_NAMES.index("torso")
    assert np.all(np.isfinite(depth[labels >= 0])) and np.all(np.isinf(depth[labels < 0]))
