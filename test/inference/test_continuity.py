"""The published paths do not jump: the MAP trajectory spreads a re-seeding's jump over the frames before it
(``smooth_jumps``) and the live pose follows the filtering MAP through a settling offset (``PublishedPath``)."""
from __future__ import annotations

import numpy as np

from awalker_tracker.inference.tracker import (
    JUMP_SPREAD_M_S, JUMP_SPREAD_MIN_S, PublishedPath, smooth_jumps)
from awalker_tracker.model.body import JOINT_NAMES, MARKER_NAMES

DT = 1 / 30
PELVIS = MARKER_NAMES.index("pelvis")


def walk(frames: int, speed: float = 1.2) -> np.ndarray:
    """Markers (F, 13, 3) of a rigid body walking along +x, its other markers around the pelvis."""
    offsets = np.random.default_rng(0).normal(0.0, 0.2, (len(MARKER_NAMES), 3))
    offsets[PELVIS] = 0.0
    x = speed * DT * np.arange(frames)
    return np.stack([x, np.zeros(frames), np.full(frames, 0.9)], axis=1)[:, None, :] + offsets[None]


def step_speeds(markers: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(markers[:, PELVIS, :2], axis=0), axis=1) / DT


def test_a_reseeding_jump_is_spread_over_the_frames_before_it():
    markers = walk(90)
    jumps = np.zeros((90, 3))
    markers[60:, :, :2] += [0.0, 1.2]                # re-acquired 1.2 m to the left at frame 60, turned 0.5 rad
    jumps[60] = [0.0, 1.2, 0.5]
    angles = np.zeros((90, len(JOINT_NAMES)))
    assert step_speeds(markers).max() > 30.0           # the raw lineage teleports
    smoothed, smoothed_angles = smooth_jumps(markers, angles, jumps, DT)
    spread = max(JUMP_SPREAD_MIN_S, 1.2 / JUMP_SPREAD_M_S)
    # no faster than the walk plus the spreading speed, the frames after the jump and long before it untouched
    assert step_speeds(smoothed).max() <= np.hypot(1.2, 1.2 / spread) + 1e-6
    np.testing.assert_array_equal(smoothed[60:], markers[60:])
    early = 60 - int(np.ceil(spread / DT)) - 1
    np.testing.assert_allclose(smoothed[:early], markers[:early])
    # just before the jump the pose is (nearly) where the jump put it, turned with it about its pelvis
    yaw = JOINT_NAMES.index("torso_yaw")
    assert np.linalg.norm(smoothed[59, PELVIS, :2] - (markers[59, PELVIS, :2] + [0.0, 1.2])) < 1.2 * DT / spread + 1e-9
    assert abs(smoothed_angles[59, yaw] - 0.5 * (1 - DT / spread)) < 1e-9
    body = smoothed[59, :, :2] - smoothed[59, PELVIS, :2]
    original = markers[59, :, :2] - markers[59, PELVIS, :2]
    turned = np.arctan2(body[:, 1], body[:, 0]) - np.arctan2(original[:, 1], original[:, 0])
    np.testing.assert_allclose(np.angle(np.exp(1j * turned[np.linalg.norm(original, axis=1) > 0.05])),
                               0.5 * (1 - DT / spread), atol=1e-9)


def test_the_live_pose_follows_a_map_that_swaps_between_particles_without_jumping():
    """Two walkers 0.8 m apart walk side by side; the MAP swaps between them every 10 frames. The published pelvis
    never moves faster than the walk plus the settling speed, and it settles on the MAP between swaps."""
    path = PublishedPath(DT)
    published, speed = [], 1.2
    for frame in range(60):
        x = speed * DT * frame
        pelvis = np.array([[x, 0.0], [x, 0.8]])
        best = (frame // 10) % 2
        offset = path.update(pelvis, np.array([0, 1]), np.zeros((2, 3)), best)
        published.append(pelvis[best] - offset)
        if frame % 10 == 9:                            # 9 frames after a swap: 0.8 m takes 0.67 s at 1.2 m/s
            assert np.linalg.norm(offset) < 0.8 - 8 * JUMP_SPREAD_M_S * DT + 1e-9
    steps = np.linalg.norm(np.diff(np.array(published), axis=0), axis=1) / DT
    assert steps.max() <= speed + JUMP_SPREAD_M_S + 1e-6
    # a MAP that stays on one lineage is published as it is
    still = PublishedPath(DT)
    for frame in range(5):
        assert not still.update(np.array([[0.1 * frame, 0.0]]), np.array([0]), np.zeros((1, 3)), 0).any()
