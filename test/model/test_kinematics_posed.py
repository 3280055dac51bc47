"""sample_posed_kinematics (the tracker's transition) = sample_kinematics followed by pose_body."""
from __future__ import annotations

from dataclasses import fields

import numpy as np

from awalker_tracker.model.body import BodyDescription
from awalker_tracker.model.kinematics import (
    KinematicConfig,
    initial_kinematics,
    pose_body,
    sample_kinematics,
    sample_posed_kinematics,
)
from awalker_tracker.model.walker import LEFT, WalkerState

BODY = BodyDescription.default()
PARAMS = BODY.walker_params()


def test_posed_sampling_matches_sampling_then_posing_through_heel_strikes():
    """Over 40 frames with two heel strikes and the swing-foot clearance active (trailing leg
    through the floor; without re-posing the knees it bends, this test fails), the one-pass
    result equals the two-pass one bit for bit."""
    n, config = 400, KinematicConfig()
    rng = np.random.default_rng(4)
    # legs swing linearly between +-0.4 rad, swapping at every 16th frame (heel strike)
    walkers, leg, origin = [], LEFT, 0.0
    for f in range(40):
        if f and f % 16 == 0:
            leg, origin = 1 - leg, origin + PARAMS.step_length(0.4)
        phi1 = 0.4 - 0.8 * (f % 16) / 16 + 0.02 * rng.standard_normal(n)
        walkers.append(WalkerState.from_arrays(phi1, -phi1, np.full(n, -1.5), np.full(n, 1.5), origin, leg))
    kin = initial_kinematics(config, walkers[0], [0.0, 0.0], 0.2, n, rng, body=BODY, joint_spread=0.05)
    legs_seen = set()
    for f in range(1, 40):
        state = rng.bit_generator.state
        one_pass, posed = sample_posed_kinematics(config, BODY, PARAMS, walkers[f], kin, rng)
        rng.bit_generator.state = state
        two_pass = sample_kinematics(config, BODY, PARAMS, walkers[f - 1], walkers[f], None, kin, rng)
        for field in fields(two_pass):
            np.testing.assert_array_equal(getattr(one_pass, field.name), getattr(two_pass, field.name))
        expected = pose_body(BODY, PARAMS, walkers[f], two_pass)
        np.testing.assert_array_equal(posed.markers, expected.markers)
        np.testing.assert_array_equal(posed.joint_angles, expected.joint_angles)
        np.testing.assert_array_equal(posed.segments.origin, expected.segments.origin)
        np.testing.assert_array_equal(posed.segments.rotation, expected.segments.rotation)
        legs_seen.update(np.unique(one_pass.contact_leg).tolist())
        kin = one_pass
    assert legs_seen == {0, 1}   # heel strikes happened (the contact passed to the other foot)
