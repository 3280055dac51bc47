"""Cameras: projection against OpenCV, pixel back-projection, calibration YAML and its errors."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from awalker_tracker.errors import InputError
from awalker_tracker.vision.camera import Camera, load_calibration, save_calibration


def make_camera(distortion) -> Camera:
    # No skew: cv2.projectPoints ignores K[0, 1] (Camera.project honours it).
    K = np.array([[610.0, 0.0, 322.0], [0.0, 605.0, 241.0], [0.0, 0.0, 1.0]])
    rotation = Rotation.from_euler("xyz", [-100, 5, 30], degrees=True).as_matrix()
    return Camera("cam0", 640, 480, K, np.asarray(distortion, float), rotation, np.array([0.5, -4.0, 1.2]))


DISTORTIONS = [[], [-0.2, 0.05, 0.001, -0.002], [-0.2, 0.05, 0.001, -0.002, 0.01],
               [-0.2, 0.05, 0.001, -0.002, 0.01, 0.02, -0.01, 0.005]]


@pytest.mark.parametrize("distortion", DISTORTIONS)
def test_project_matches_cv2_project_points(distortion):
    cam = make_camera(distortion)
    rng = np.random.default_rng(0)
    # Points in front of the camera, within the field of view, batched as (particles, points, 3).
    local = np.column_stack([rng.uniform(-1, 1, 60), rng.uniform(-0.7, 0.7, 60), rng.uniform(2, 8, 60)])
    world = (local @ cam.rotation.T + cam.position).reshape(3, 20, 3)
    uv, depth = cam.project(world)
    assert uv.shape == (3, 20, 2) and depth.shape == (3, 20)
    rvec, _ = cv2.Rodrigues(cam.rotation.T)  # camera_from_world
    tvec = -cam.rotation.T @ cam.position
    dist = np.asarray(distortion, float) if distortion else None
    expected, _ = cv2.projectPoints(world.reshape(-1, 3), rvec, tvec, cam.K, dist)
    assert np.allclose(uv.reshape(-1, 2), expected.reshape(-1, 2), atol=1e-6)
    assert np.allclose(depth.ravel(), local[:, 2])


@pytest.mark.parametrize("distortion", DISTORTIONS)
def test_pixels_to_normalised_inverts_projection(distortion):
    cam = make_camera(distortion)
    rng = np.random.default_rng(1)
    local = np.column_stack([rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.4, 0.4, 50), np.ones(50)])
    uv, _ = cam.project(local @ cam.rotation.T + cam.position)
    assert np.allclose(cam.pixels_to_normalised(uv), local[:, :2], atol=1e-8)


@pytest.mark.parametrize("distortion", DISTORTIONS[1:])
def test_pixels_to_normalised_matches_opencv_on_any_grid_shape(distortion):
    """The compiled inversion against OpenCV's iterative undistortion, on an (H, W, 2) grid that
    reaches the image corners, and the same for a single (2,) pixel."""
    cam = make_camera(distortion)
    v, u = np.mgrid[0:cam.height:37, 0:cam.width:41].astype(float)
    grid = np.stack([u, v], axis=-1)
    ours = cam.pixels_to_normalised(grid)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    expected = cv2.undistortPoints(grid.reshape(-1, 1, 2), cam.K, np.asarray(distortion, float),
                                   criteria=criteria).reshape(grid.shape)
    assert ours.shape == grid.shape
    np.testing.assert_allclose(ours, expected, atol=1e-9)
    np.testing.assert_allclose(cam.pixels_to_normalised(grid[2, 3]), expected[2, 3], atol=1e-9)


def test_points_behind_the_camera_are_nan():
    cam = make_camera([])
    behind = cam.position - 2.0 * cam.rotation[:, 2]
    uv, depth = cam.project(behind)
    assert depth < 0 and np.all(np.isnan(uv))


def test_look_at_puts_the_target_on_the_principal_point():
    cam = Camera.look_at("c", 640, 480, 500.0, np.array([3.0, -4.0, 1.5]), np.array([0.0, 0.0, 1.0]))
    uv, depth = cam.project(np.array([0.0, 0.0, 1.0]))
    assert np.allclose(uv, cam.K[:2, 2]) and depth == pytest.approx(np.sqrt(9 + 16 + 0.25))
    uv_up, _ = cam.project(np.array([0.0, 0.0, 2.0]))
    assert uv_up[1] < uv[1]  # world up is image up
    assert np.allclose(cam.rotation.T @ cam.rotation, np.eye(3)) and np.linalg.det(cam.rotation) == pytest.approx(1)


def test_calibration_round_trip(tmp_path):
    cams = [make_camera(DISTORTIONS[2]), Camera.look_at("side", 320, 240, 300.0, np.array([4.0, 0, 1]), np.zeros(3))]
    path = tmp_path / "calibration.yaml"
    save_calibration(cams, path)
    loaded = load_calibration(path)
    assert [c.name for c in loaded] == ["cam0", "side"]
    for a, b in zip(cams, loaded):
        assert np.allclose(a.K, b.K) and np.allclose(a.distortion, b.distortion)
        assert np.allclose(a.rotation, b.rotation, atol=1e-9) and np.allclose(a.position, b.position)
        assert (a.width, a.height) == (b.width, b.height)


GOOD = """cameras:
  - name: cam0
    width: 640
    height: 480
    K: [[500, 0, 320], [0, 500, 240], [0, 0, 1]]
    distortion: [0, 0, 0, 0, 0]
    pose: {position: [0, -4, 1], orientation: [0, 0, 0, 1]}
"""


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("cameras: [", "not valid YAML"),
        ("cams: []", "top-level 'cameras:' list"),
        (GOOD.replace("    width: 640\n", ""), "missing field(s) width"),
        (GOOD.replace("name: cam0", "name: 0cam"), "name must match"),
        (GOOD.replace("width: 640", "width: -3"), "width and height must be positive integers"),
        (GOOD.replace("[0, 0, 1]]", "[0, 1, 1]]"), "K must be"),
        (GOOD.replace("K: [[500, 0, 320], [0, 500, 240], [0, 0, 1]]", "K: [1, 2, 3]"), "expected 9 numbers"),
        (GOOD.replace("[0, 0, 0, 0, 0]", "[0, 0, 0]"), "distortion must be a list of 0, 4, 5 or 8"),
        (GOOD.replace("[0, 0, 0, 1]", "[0, 0, 0, 2]"), "unit quaternion"),
        (GOOD.replace("position: [0, -4, 1]", "position: [0, .nan, 1]"), "NaN"),
        (GOOD + GOOD.replace("cameras:\n", ""), "camera names must be unique"),
    ],
)
def test_bad_calibration_names_file_and_problem(tmp_path, text, message):
    path = tmp_path / "calib.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        load_calibration(path)
    assert str(path) in str(err.value) and message in str(err.value)


def test_missing_calibration_file(tmp_path):
    with pytest.raises(InputError, match="calibration file not found"):
        load_calibration(tmp_path / "none.yaml")


def test_skew_is_honoured_both_ways():
    cam = make_camera(DISTORTIONS[1])
    skewed = Camera(cam.name, cam.width, cam.height, cam.K + np.array([[0, 2.0, 0], [0, 0, 0], [0, 0, 0]]),
                    cam.distortion, cam.rotation, cam.position)
    point = cam.position + cam.rotation @ np.array([0.3, 0.2, 1.0])
    (u0, v0), _ = cam.project(point)
    (u1, v1), _ = skewed.project(point)
    assert v1 == pytest.approx(v0) and u1 != pytest.approx(u0)
    assert np.allclose(skewed.pixels_to_normalised(np.array([u1, v1])), cam.pixels_to_normalised(np.array([u0, v0])))


def _info(**change):
    """A CameraInfo as the messages carry it (width, height, k, distortion_model, d), with ``change`` applied."""
    from types import SimpleNamespace

    fields = dict(width=640, height=480, k=[610.0, 0.0, 322.0, 0.0, 605.0, 241.0, 0.0, 0.0, 1.0],
                  distortion_model="plumb_bob", d=[-0.2, 0.05, 0.001, -0.002, 0.01])
    fields.update(change)
    return SimpleNamespace(**fields)


QUAT = Rotation.from_euler("xyz", [-100, 5, 30], degrees=True).as_quat()


def test_camera_from_info_builds_what_the_calibration_yaml_builds():
    from awalker_tracker.vision.camera import camera_from_dict, camera_from_info

    cam = camera_from_info("cam0", _info(), [0.5, -4.0, 1.2], QUAT, "/cam0/camera_info", "/cam0/camera_pose")
    want = camera_from_dict(make_camera(DISTORTIONS[2]).to_dict(), "yaml")
    for field in ("K", "distortion", "rotation", "position"):
        np.testing.assert_allclose(getattr(cam, field), getattr(want, field), atol=1e-12, err_msg=field)
    assert (cam.name, cam.width, cam.height) == ("cam0", 640, 480)
    # each model with the coefficient counts it takes
    for model, d in (("plumb_bob", []), ("plumb_bob", [0.1, 0, 0, 0]), ("rational_polynomial", [0.1] * 8), ("", [])):
        assert camera_from_info("c", _info(distortion_model=model, d=d), [0, 0, 1], QUAT, "i", "p").distortion.size == len(d)
    # a quaternion off unit by float rounding is normalised
    near = camera_from_info("c", _info(), [0, 0, 1], QUAT * 1.0005, "i", "p")
    np.testing.assert_allclose(near.rotation @ near.rotation.T, np.eye(3), atol=1e-12)


NAN, INF = float("nan"), float("inf")
K_GOOD = [610.0, 0.0, 322.0, 0.0, 605.0, 241.0, 0.0, 0.0, 1.0]


@pytest.mark.parametrize(("info", "position", "quat", "where", "message"), [
    (dict(width=0), None, None, "/cam0/camera_info", "width and height must be positive integers, got 0, 480"),
    (dict(height=0), None, None, "/cam0/camera_info", "width and height must be positive integers"),
    (dict(k=[NAN] + K_GOOD[1:]), None, None, "/cam0/camera_info: k", "NaN or infinity"),
    (dict(k=K_GOOD[:4] + [INF] + K_GOOD[5:]), None, None, "/cam0/camera_info: k", "NaN or infinity"),
    (dict(k=[0.0] + K_GOOD[1:]), None, None, "/cam0/camera_info: k", "with fx, fy > 0"),
    (dict(k=K_GOOD[:4] + [-605.0] + K_GOOD[5:]), None, None, "/cam0/camera_info: k", "with fx, fy > 0"),
    (dict(k=[0.0] * 9), None, None, "/cam0/camera_info: k", "with fx, fy > 0"),        # an uncalibrated driver's
    (dict(k=K_GOOD[:8]), None, None, "/cam0/camera_info: k", "expected 9 numbers"),
    (dict(distortion_model="equidistant", d=[0.1, 0, 0, 0]), None, None, "/cam0/camera_info",
     "distortion model 'equidistant' is not one this camera model takes; expected 'plumb_bob', 'rational_polynomial', ''"),
    (dict(d=[0.1, 0.0, 0.0]), None, None, "/cam0/camera_info", "'plumb_bob' takes 0 or 4 or 5 finite coefficients"),
    (dict(distortion_model="rational_polynomial"), None, None, "/cam0/camera_info", "'rational_polynomial' takes 8"),
    (dict(distortion_model="", d=[0.1] * 5), None, None, "/cam0/camera_info", "model '' takes 0 finite"),
    (dict(d=[0.1, NAN, 0, 0, 0]), None, None, "/cam0/camera_info", "'plumb_bob' takes 0 or 4 or 5 finite"),
    ({}, [0.0, NAN, 1.0], None, "/cam0/camera_pose: position", "NaN or infinity"),
    ({}, [0.0, INF, 1.0], None, "/cam0/camera_pose: position", "NaN or infinity"),
    ({}, [0.0, 1.0], None, "/cam0/camera_pose: position", "expected 3 numbers"),
    ({}, None, [0.0, 0.0, 0.0, 0.0], "/cam0/camera_pose: orientation", "a zero quaternion is no rotation"),
    ({}, None, [0.0, 0.0, 0.0, 2.0], "/cam0/camera_pose: orientation", "must be a unit quaternion [qx, qy, qz, qw], norm is 2.0"),
    ({}, None, [0.0, 0.0, NAN, 1.0], "/cam0/camera_pose: orientation", "NaN or infinity"),
])
def test_camera_from_info_names_the_topic_and_what_was_expected(info, position, quat, where, message):
    from awalker_tracker.vision.camera import camera_from_info

    with pytest.raises(InputError) as err:
        camera_from_info("cam0", _info(**info), [0.5, -4.0, 1.2] if position is None else position,
                         QUAT if quat is None else quat, "/cam0/camera_info", "/cam0/camera_pose")
    assert str(err.value).startswith(where + ": ") and message in str(err.value), str(err.value)
