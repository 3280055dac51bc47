"""Batched image likelihood on rendered frames with known truth (issue 5 section 6)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from awalker_tracker.errors import InputError
from awalker_tracker.model.body import BodySegments, PartShape
from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor, FrameFeatures, occluded
from awalker_tracker.vision.flow import FlowConfig, FlowGrid
from awalker_tracker.vision.likelihood import LikelihoodConfig, log_likelihood, occluder_table
from vision_scene import (
    BODY,
    GROUPS,
    Pose,
    background_image,
    front_camera,
    noisy,
    perturbed,
    render_frames,
    side_camera,
    stacked,
    walking_poses,
)

FRAME = 3
# 320x240 images with downsample 2 and 8 px cells = 640x480 with the defaults 4 and 16.
CONFIG = FeatureConfig(background_frames=3, downsample=2, flow=FlowConfig(cell_size=8))


@pytest.fixture(scope="module")
def scene():
    cameras = [side_camera(), front_camera()]
    poses = walking_poses(FRAME + 1)
    features = []
    for index, cam in enumerate(cameras):
        rng = np.random.default_rng(10 + index)
        bg = background_image(cam, seed=index)
        frames, _ = render_frames(cam, poses, bg, seed=index)
        extractor = FeatureExtractor(CONFIG)
        for _ in range(CONFIG.background_frames):
            extractor.process(noisy(bg, rng))
        features.append([extractor.process(f) for f in frames][FRAME])
    return cameras, poses, features


def repeat(segments: BodySegments, n: int) -> BodySegments:
    return BodySegments(np.repeat(segments.origin, n, 0), np.repeat(segments.rotation, n, 0))


def test_true_pose_beats_perturbed_poses(scene):
    """200 random perturbations over the DOF groups (3-10 cm / 5-20 deg), two cameras."""
    cameras, poses, features = scene
    rng = np.random.default_rng(0)
    groups = [GROUPS[i % len(GROUPS)] for i in range(200)]
    batch = stacked([poses[FRAME]] + [perturbed(poses[FRAME], g, rng) for g in groups])
    prev = repeat(poses[FRAME - 1].segments(), len(groups) + 1)
    values = log_likelihood(BODY.parts, batch.segments(), prev, cameras, features)
    assert values.shape == (201,)
    wins = values[1:] < values[0]
    assert wins.mean() >= 0.95, {g: float(wins[np.array(groups) == g].mean()) for g in GROUPS}
    # One camera alone: depth and heading are weakly observed in a side view, still mostly right.
    mono = log_likelihood(BODY.parts, batch.segments(), prev, cameras[:1], features[:1])
    assert (mono[1:] < mono[0]).mean() >= 0.9
    # Each term alone also prefers the truth most of the time.
    for config in (LikelihoodConfig(flow_weight=0.0), LikelihoodConfig(appearance_weight=0.0)):
        only = log_likelihood(BODY.parts, batch.segments(), prev, cameras, features, config=config)
        assert (only[1:] < only[0]).mean() >= 0.8


def depth_posterior_std(values: np.ndarray, shifts: np.ndarray) -> float:
    w = np.exp(values - values.max())
    w /= w.sum()
    mean = np.sum(w * shifts)
    return float(np.sqrt(np.sum(w * (shifts - mean) ** 2)))


def test_two_cameras_sharpen_the_depth_peak(scene):
    cameras, poses, features = scene
    side = cameras[0]
    shifts = np.linspace(-0.5, 0.5, 21)
    depth_axis = side.rotation[:, 2][:2] / np.linalg.norm(side.rotation[:, 2][:2])
    shifted = []
    for s in shifts:
        pose = Pose(poses[FRAME].walker.copy(), poses[FRAME].kin.copy())
        pose.kin.contact_point = pose.kin.contact_point + s * depth_axis
        shifted.append(pose)
    batch = stacked(shifted).segments()
    # The previous pose moves along with each hypothesis: only the position differs, not the motion.
    offset = batch.origin - repeat(poses[FRAME].segments(), len(shifts)).origin
    previous = repeat(poses[FRAME - 1].segments(), len(shifts))
    prev = BodySegments(previous.origin + offset, previous.rotation)
    mono = log_likelihood(BODY.parts, batch, prev, cameras[:1], features[:1])
    both = log_likelihood(BODY.parts, batch, prev, cameras, features)
    assert abs(shifts[np.argmax(both)]) <= 0.05
    assert depth_posterior_std(both, shifts) < 0.5 * depth_posterior_std(mono, shifts)
    # The monocular peak along the viewing ray is much flatter than across it (the ambiguity).
    assert np.ptp(mono) < np.ptp(both)


def test_occlusion_mask_removes_its_pixels_and_cells(scene):
    cameras, poses, features = scene
    cam = cameras[0]
    true = poses[FRAME]
    bent = Pose(true.walker.copy(), true.kin.copy())
    bent.kin.knee[:, 1] += 0.4                      # only the right leg moves (the thigh leads the chord)
    batch = stacked([true, bent]).segments()
    prev = repeat(poses[FRAME - 1].segments(), 2)
    hip_v = cam.project(true.segments().origin[0, 3])[0][1]    # right upper leg starts at the hip
    mask = np.zeros((cam.height, cam.width), np.uint8)
    mask[int(hip_v) - 12:, :] = 255
    free = log_likelihood(BODY.parts, batch, prev, cameras[:1], features[:1])
    masked = log_likelihood(BODY.parts, batch, prev, cameras[:1], [occluded(features[0], mask)])
    assert free[0] - free[1] > 1.0                   # visible: bending the knee is detected
    assert masked[0] == pytest.approx(masked[1], abs=1e-9)   # under the mask: contributes nothing


def test_hidden_part_contributes_nothing():
    """A part entirely behind another (in depth order) adds nothing; moved into view it does."""
    cam = side_camera()
    front = PartShape("torso", "torso", 0.8, np.array([0.2, 0.2]), np.array([0.2, 0.2]))
    back = PartShape("left_upper_leg", "legs", 0.6, np.array([0.05, 0.05]), np.array([0.05, 0.05]))
    leg = PartShape("right_upper_leg", "legs", 0.6, np.array([0.05, 0.05]), np.array([0.05, 0.05]))
    parts = (front, back, leg)
    assert occluder_table(parts)[1].tolist() == [2, 0, -1, -1]
    up = np.eye(3)
    h, w = cam.height // 2, cam.width // 2
    llr = np.zeros((4, h, w), np.float32)
    llr[2] = 5.0                                     # 'legs' ratio +5 everywhere, others 0
    features = FrameFeatures(("head", "torso", "legs", "feet"), llr, 2, cam.width, cam.height,
                             FlowGrid.empty(cam.height, cam.width, 8))
    far = np.array([[[0.3, 0.0, 0.5], [0.3, 0.5, 0.6], [5.0, 0.0, 0.6]]])   # leg parked out of view
    beside = far.copy()
    beside[0, 1, 0] = 1.2                            # the back leg moved out from behind the torso
    origins = np.concatenate([far, beside])
    segments = BodySegments(origins, np.broadcast_to(up, (2, 3, 3, 3)).copy())
    values = log_likelihood(parts, segments, None, [cam], [features])
    assert values[0] == pytest.approx(0.0, abs=1e-9)
    assert values[1] > 1.0
    no_occlusion = log_likelihood(parts, segments, None, [cam], [features],
                                  config=LikelihoodConfig(self_occlusion=False))
    assert no_occlusion[0] > 1.0


def test_bad_inputs(scene):
    cameras, poses, features = scene
    seg = poses[FRAME].segments()
    with pytest.raises(ValueError, match="cameras"):
        log_likelihood(BODY.parts, seg, seg, cameras, features[:1])
    with pytest.raises(ValueError, match="parts"):
        log_likelihood(BODY.parts[:3], seg, seg, cameras, features)
    small = dataclasses.replace(cameras[0], width=cameras[0].width // 2, height=cameras[0].height // 2)
    with pytest.raises(InputError, match=f"features of camera {small.name} are .* calibration says"):
        log_likelihood(BODY.parts, seg, seg, [small, *cameras[1:]], features)


def test_sampling_settings_are_validated():
    with pytest.raises(ValueError, match="points_along"):
        LikelihoodConfig(points_along=0)


def test_cut_batches_score_the_same_bit_for_bit(scene, monkeypatch):
    """2500 poses cut into two blocks on two threads (``awalker_tracker.blocks``): the same
    log-likelihoods, appearance and flow, as in one block."""
    from awalker_tracker import blocks

    cameras, poses, features = scene
    rng = np.random.default_rng(5)
    batch = stacked([perturbed(poses[FRAME], GROUPS[i % len(GROUPS)], rng) for i in range(2500)])
    prev = repeat(poses[FRAME - 1].segments(), 2500)
    assert len(blocks.block_bounds(2500, 2)) == 2
    values = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("AWALKER_THREADS", threads)
        values[threads] = log_likelihood(BODY.parts, batch.segments(), prev, cameras, features)
    assert np.isfinite(values["1"]).all() and np.ptp(values["1"]) > 0
    np.testing.assert_array_equal(values["1"], values["2"])
