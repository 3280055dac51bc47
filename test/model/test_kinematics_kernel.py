"""The compiled kinematics kernels agree with the numpy reference (``kinematics_reference.py``, the
vectorised code they replaced) on random states: heel strikes, DOFs near and at their joint limits,
swing feet low enough for the clearance bisection."""
from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest
from kinematics_reference import (
    initial_kinematics_reference,
    pose_body_reference,
    sample_posed_kinematics_reference,
    sole_point_world_reference,
)

from awalker_tracker.model.body import BodyDescription, BodyPoseBatch
from awalker_tracker.model.kinematics import (
    DOF_NAMES,
    KinematicConfig,
    KinematicState,
    initial_kinematics,
    pose_body,
    sample_kinematics,
    sample_posed_kinematics,
    sole_point_world,
)
from awalker_tracker.model.walker import WalkerState

BODY = BodyDescription.default()
PARAMS = BODY.walker_params()
TOLERANCE = 1e-9
KNEES = [DOF_NAMES.index("left_knee"), DOF_NAMES.index("right_knee")]


def random_case(seed: int, n: int = 3000) -> tuple[WalkerState, KinematicState]:
    """Random walkers and kinematic states: about half the particles strike a heel (the walker's stance
    leg differs from the contact leg), a fifth of the bounded DOFs sit at a limit or are pushed past it
    by their velocity, and many trailing swing legs are low (straight knees, swing angle behind)."""
    rng = np.random.default_rng(seed)
    walker = WalkerState.from_arrays(
        rng.uniform(-0.5, 0.5, n), rng.uniform(-0.6, 0.6, n), rng.normal(0, 1.5, n), rng.normal(0, 1.5, n),
        rng.normal(0, 2, n), rng.integers(0, 2, n))
    config = KinematicConfig()
    lower, upper = config.arrays(BODY)["lower"], config.arrays(BODY)["upper"]
    finite_lower, finite_upper = np.where(np.isfinite(lower), lower, -0.4), np.where(np.isfinite(upper), upper, 0.4)
    dofs = rng.uniform(finite_lower, finite_upper, (n, len(DOF_NAMES)))
    dofs[:, DOF_NAMES.index("heading")] = rng.uniform(-np.pi, np.pi, n)
    dofs[:, KNEES] = rng.uniform(0.0, 1.2, (n, 2)) * (rng.random((n, 2)) < 0.7)   # many straight knees
    at_limit = rng.random(dofs.shape) < 0.2
    dofs = np.where(at_limit & np.isfinite(lower) & (rng.random(dofs.shape) < 0.5), lower, dofs)
    dofs = np.where(at_limit & np.isfinite(upper) & ~np.isin(dofs, lower), upper, dofs)
    velocity = rng.normal(0, 0.05, dofs.shape) + np.where(at_limit, rng.choice([-0.3, 0.3], dofs.shape), 0.0)
    named = KinematicState.unpack(dofs)
    kin = KinematicState(
        heading=named["heading"], torso_lean=named["torso_lean"], hip_abduction=named["hip_abduction"],
        hip_rotation=named["hip_rotation"], knee=named["knee"], ankle=named["ankle"], previous=dofs - velocity,
        contact_point=rng.normal(0, 3, (n, 2)),
        contact_roll=rng.uniform(-BODY.sole_half_angle, BODY.sole_half_angle, n),
        contact_leg=rng.integers(0, 2, n).astype(np.int8), plane_origin=rng.normal(0, 3, (n, 2)),
        turn_rate=rng.normal(0, 0.5, n), leg_scale=rng.uniform(0.85, 1.1, n), torso_rest=rng.normal(0, 0.1, n),
        pelvis_ceiling=rng.uniform(0.9, 1.0, n))
    return walker, kin


def assert_states_close(actual: KinematicState, expected: KinematicState) -> None:
    for field in fields(expected):
        np.testing.assert_allclose(getattr(actual, field.name), getattr(expected, field.name), rtol=0,
                                   atol=TOLERANCE, err_msg=field.name)


def assert_poses_close(actual: BodyPoseBatch, expected: BodyPoseBatch) -> None:
    for name, a, e in (("markers", actual.markers, expected.markers),
                       ("joint_angles", actual.joint_angles, expected.joint_angles),
                       ("origin", actual.segments.origin, expected.segments.origin),
                       ("rotation", actual.segments.rotation, expected.segments.rotation)):
        assert a.shape == e.shape, name
        np.testing.assert_allclose(a, e, rtol=0, atol=TOLERANCE, err_msg=name)


@pytest.mark.parametrize("hip_over_ankle", [False, True])
@pytest.mark.parametrize("seed, dt", [(0, 1 / 30), (1, 1 / 30), (2, 1 / 60)])
def test_sample_posed_kinematics_matches_numpy_reference(seed, dt, hip_over_ankle):
    walker, kin = random_case(seed)
    wander = seed == 1      # leg scales, postures and pelvis ceilings wandering or kept
    config = KinematicConfig(dt=dt, leg_scale_drift=0.01 if wander else 0.0, posture_drift=0.01 if wander else 0.0,
                             pelvis_ceiling_drift=0.005 if wander else 0.0, hip_over_ankle=hip_over_ankle)
    state, pose = sample_posed_kinematics(config, BODY, PARAMS, walker, kin, np.random.default_rng(seed))
    expected_state, expected_pose = sample_posed_kinematics_reference(config, BODY, PARAMS, walker, kin,
                                                                      np.random.default_rng(seed))
    assert_states_close(state, expected_state)
    assert_poses_close(pose, expected_pose)
    # the random case exercised what it is meant to
    switched = walker.stance_leg != kin.contact_leg
    assert 0.3 < switched.mean() < 0.7
    cleared = np.any(state.previous[:, KNEES] != kin.dofs()[:, KNEES], axis=1)   # knees bent by the bisection
    assert cleared.mean() > 0.1 and (cleared & switched).any() and (cleared & ~switched).any()
    limits = KinematicConfig().arrays(BODY)
    new = state.dofs()
    assert np.sum(new == limits["lower"]) > 100 and np.sum(new == limits["upper"]) > 100


def test_sample_kinematics_with_scripted_heading_matches_numpy_reference():
    walker, kin = random_case(3, n=500)
    config, heading = KinematicConfig(), np.linspace(-3.0, 3.0, 500)
    state = sample_kinematics(config, BODY, PARAMS, None, walker, None, kin, np.random.default_rng(3), heading)
    expected, _ = sample_posed_kinematics_reference(config, BODY, PARAMS, walker, kin, np.random.default_rng(3),
                                                    heading)
    assert_states_close(state, expected)


@pytest.mark.parametrize("hip_over_ankle", [False, True])
def test_pose_body_and_sole_points_match_numpy_reference(hip_over_ankle):
    walker, kin = random_case(4)
    config = KinematicConfig(hip_over_ankle=hip_over_ankle)
    assert_poses_close(pose_body(BODY, PARAMS, walker, kin, config),
                       pose_body_reference(BODY, PARAMS, walker, kin, config))
    rng = np.random.default_rng(4)
    leg, beta = rng.integers(0, 2, len(kin)).astype(np.int8), rng.uniform(-0.3, 0.3, len(kin))
    np.testing.assert_allclose(sole_point_world(BODY, walker, kin, leg, beta, config),
                               sole_point_world_reference(BODY, walker, kin, leg, beta, config), rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(sole_point_world(BODY, walker, kin, 1, 0.1, config),      # scalar leg and roll
                               sole_point_world_reference(BODY, walker, kin, 1, 0.1, config), rtol=0, atol=TOLERANCE)


def test_initial_kinematics_matches_numpy_reference():
    walker, _ = random_case(5, n=400)
    config = KinematicConfig(pelvis_ceiling=0.97, hip_over_ankle=True)
    spreads = dict(position_spread=0.1, heading_spread=0.2, joint_spread=0.3, turn_rate_spread=0.1,
                   leg_scale_spread=0.05, posture_spread=0.1, pelvis_ceiling_spread=0.02)
    actual = initial_kinematics(config, walker, [1.0, -2.0], 0.4, 400, np.random.default_rng(5), body=BODY,
                                **spreads)
    expected = initial_kinematics_reference(config, walker, [1.0, -2.0], 0.4, 400, np.random.default_rng(5),
                                            body=BODY, **spreads)
    assert_states_close(actual, expected)


def test_a_walk_of_sampled_frames_matches_numpy_reference_frame_by_frame():
    """40 frames of the prior on a walker whose legs swing between +-0.4 rad with heel strikes: every
    frame, compiled and reference agree from the same previous state, which then carries on."""
    n, config = 300, KinematicConfig(leg_scale_drift=0.005, posture_drift=0.003, pelvis_ceiling=0.97,
                                     pelvis_ceiling_drift=0.002, hip_over_ankle=True)
    rng = np.random.default_rng(6)
    walkers, leg, origin = [], 0, 0.0
    for f in range(40):
        if f and f % 16 == 0:
            leg, origin = 1 - leg, origin + PARAMS.step_length(0.4)
        phi1 = 0.4 - 0.8 * (f % 16) / 16 + 0.02 * rng.standard_normal(n)
        walkers.append(WalkerState.from_arrays(phi1, -phi1, -1.5, 1.5, origin, leg))
    kin = initial_kinematics(config, walkers[0], [0.0, 0.0], 0.2, n, rng, body=BODY, joint_spread=0.05,
                             leg_scale_spread=0.04, posture_spread=0.08, pelvis_ceiling_spread=0.02)
    assert 0.02 < np.std(kin.leg_scale) < 0.06 and 0.06 < np.std(kin.torso_rest) < 0.1
    assert 0.01 < np.std(kin.pelvis_ceiling) < 0.025 and np.max(kin.pelvis_ceiling) == 1.0
    for f in range(1, 40):
        seed = 100 + f
        state, pose = sample_posed_kinematics(config, BODY, PARAMS, walkers[f], kin, np.random.default_rng(seed))
        expected_state, expected_pose = sample_posed_kinematics_reference(config, BODY, PARAMS, walkers[f], kin,
                                                                          np.random.default_rng(seed))
        assert_states_close(state, expected_state)
        assert_poses_close(pose, expected_pose)
        kin = state
