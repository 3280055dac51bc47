"""Conditional kinematics: joint limits, rolling stance foot without slip or penetration, turns."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from awalker_tracker.model.body import JOINT_NAMES, MARKER_NAMES, BodyDescription
from awalker_tracker.model.kinematics import (
    CHORD_LEAN,
    DOF_NAMES,
    JointPrior,
    KinematicConfig,
    POSTURE_LIMIT,
    TurnPrior,
    initial_kinematics,
    leg_angles,
    pose_body,
    sample_kinematics,
    sole_point_world,
    truncated_normal,
)
from awalker_tracker.model.walker import LEFT, RIGHT, WalkerState, hip_position

BODY = BodyDescription.default()
PARAMS = BODY.walker_params()
M = {name: i for i, name in enumerate(MARKER_NAMES)}
J = {name: i for i, name in enumerate(JOINT_NAMES)}


def hand_made_walk(frames: int, n: int, half_angle: float = 0.35, step_frames: int = 16,
                   fps: float = 30.0) -> list[WalkerState]:
    """A walker-like sequence made by hand: legs swing linearly between +-a, swapping at heel strike."""
    states, leg, origin = [], LEFT, 0.0
    rate = 2 * half_angle * fps / step_frames
    for f in range(frames):
        if f > 0 and f % step_frames == 0:
            leg = 1 - leg
            origin += PARAMS.step_length(half_angle)
        s = (f % step_frames) / step_frames
        phi1 = half_angle - 2 * half_angle * s
        states.append(WalkerState.from_arrays(np.full(n, phi1), np.full(n, -phi1), np.full(n, -rate),
                                              np.full(n, rate), origin, leg))
    return states


def run(frames: int, n: int, seed: int = 0, config: KinematicConfig | None = None, heading_rate: float = 0.0,
        ceiling_spread: float = 0.0, **walk):
    """Simulate the prior over a hand-made walk; returns walkers, states, poses per frame."""
    config = config or KinematicConfig()
    rng = np.random.default_rng(seed)
    walkers = hand_made_walk(frames, n, **walk)
    kin = initial_kinematics(config, walkers[0], [1.0, 2.0], 0.3, n, rng, body=BODY, pelvis_ceiling_spread=ceiling_spread)
    kin.previous[:, DOF_NAMES.index("heading")] -= heading_rate  # an initial turning velocity
    states = [kin]
    for f in range(1, frames):
        kin = sample_kinematics(config, BODY, PARAMS, walkers[f - 1], walkers[f], None, kin, rng)
        states.append(kin)
    poses = [pose_body(BODY, PARAMS, w, k, config) for w, k in zip(walkers, states)]
    return walkers, states, poses


def test_alpha_is_square_rooted_at_60_hz():
    assert KinematicConfig(dt=1 / 60).alpha("swing_knee") == pytest.approx(np.sqrt(0.9))
    assert KinematicConfig(dt=1 / 30).alpha("torso_up") == pytest.approx(0.75)


@pytest.mark.parametrize("dof", ["heading", "left_hip_abduction", "right_ankle_flexion"])
def test_the_prior_spreads_a_joint_as_fast_per_second_at_60_as_at_30_hz(dof: str):
    """Eq. (6) is a discretised stochastic process: half a second of it moves a joint as far (in
    spread over particles) at 60 frames/s as at 30. With sigma per frame unchanged at 60 Hz (no
    ``noise_scale``) the spread is sqrt(1/2) as large."""
    n, seconds = 4000, 0.5
    spreads = {}
    for fps in (30.0, 60.0):
        config = KinematicConfig(dt=1.0 / fps)
        frames = int(round(seconds * fps)) + 1
        # one stance within the half second (no heel strike: no new turn rate)
        walkers = hand_made_walk(frames, n, step_frames=int(fps), fps=fps)
        rng = np.random.default_rng(3)
        kin = initial_kinematics(config, walkers[0], [0.0, 0.0], 0.0, n, rng, body=BODY, heading_spread=0.0,
                                 joint_spread=0.0, turn_rate_spread=0.0)
        start = kin.dofs()[:, DOF_NAMES.index(dof)].copy()
        for f in range(1, frames):
            kin = sample_kinematics(config, BODY, PARAMS, walkers[f - 1], walkers[f], None, kin, rng)
        spreads[fps] = float(np.std(kin.dofs()[:, DOF_NAMES.index(dof)] - start))
    assert spreads[30.0] > 0
    assert spreads[60.0] / spreads[30.0] == pytest.approx(1.0, abs=0.1), spreads


def test_truncated_normal_matches_scipy_and_bounds():
    rng = np.random.default_rng(1)
    lower, upper, mean, sigma = -0.2, 1.5, 0.4, 0.7
    x = truncated_normal(rng, np.full(200_000, mean), sigma, lower, upper)
    assert x.min() >= lower and x.max() <= upper
    ref = stats.truncnorm((lower - mean) / sigma, (upper - mean) / sigma, loc=mean, scale=sigma)
    assert x.mean() == pytest.approx(ref.mean(), abs=3e-3)
    assert x.std() == pytest.approx(ref.std(), abs=3e-3)
    # Interval deep in the upper tail: samples hug the lower bound, never leave the interval.
    far = truncated_normal(rng, np.zeros(1000), 1.0, 9.0, 10.0)
    assert far.min() >= 9.0 and far.max() <= 10.0 and np.median(far) < 9.2


def test_joint_limits_hold_even_when_pushed():
    config = KinematicConfig()
    n = 400
    rng = np.random.default_rng(2)
    walkers = hand_made_walk(40, n)
    kin = initial_kinematics(config, walkers[0], [0.0, 0.0], 0.0, n, rng, body=BODY, joint_spread=0.3)
    # Large initial velocities drive limited joints into their limits.
    kin.previous += rng.normal(0, 0.3, kin.previous.shape)
    arrays = config.arrays(BODY)
    limited = np.isfinite(arrays["lower"])
    hit = np.zeros(limited.sum(), bool)
    for f in range(1, 40):
        kin = sample_kinematics(config, BODY, PARAMS, walkers[f - 1], walkers[f], None, kin, rng)
        dofs = kin.dofs()
        assert np.all(dofs[:, limited] >= arrays["lower"][limited] - 1e-12)
        assert np.all(dofs[:, limited] <= arrays["upper"][limited] + 1e-12)
        hit |= np.any(np.isclose(dofs[:, limited], arrays["upper"][limited]) |
                      np.isclose(dofs[:, limited], arrays["lower"][limited]), axis=0)
    assert hit.any(), "the test must actually push joints to their limits"


def test_stance_foot_rolls_without_slip_or_penetration():
    walkers, states, poses = run(70, 200, seed=3)
    worst_slip, rolled = 0.0, 0.0
    for f in range(len(states) - 1):
        kin, nxt = states[f], states[f + 1]
        same = nxt.contact_leg == kin.contact_leg
        assert same.all() or (~same).all()  # the hand-made walk switches all particles together
        if not same.all():
            continue
        # The material sole point in contact at frame f, seen at frame f + 1.
        before = sole_point_world(BODY, walkers[f], kin, kin.contact_leg, kin.contact_roll)
        after = sole_point_world(BODY, walkers[f + 1], nxt, kin.contact_leg, kin.contact_roll)
        assert np.allclose(before[:, 2], 0.0, atol=1e-9)
        worst_slip = max(worst_slip, np.abs(after[:, :2] - before[:, :2]).max())
        rolled = max(rolled, np.abs(nxt.contact_roll - kin.contact_roll).max())
    assert worst_slip < 1e-3, f"stance foot slips {worst_slip * 1e3:.2f} mm/frame"
    assert rolled > 0.01, "the contact must actually roll along the sole"
    checked_trailing = 0
    for walker, kin, pose in zip(walkers, states, poses):
        stance = kin.contact_leg
        heel = pose.markers[np.arange(len(kin)), M["left_heel"] + stance, 2]
        toe = pose.markers[np.arange(len(kin)), M["left_toe"] + stance, 2]
        assert heel.min() >= -1e-9 and toe.min() >= -1e-9
        # Sample the whole rocker sole of both feet: the stance foot's lowest point is the
        # contact, on the ground; the swing foot clears the ground (its knee bends as needed).
        for beta in np.linspace(-BODY.sole_half_angle, BODY.sole_half_angle, 9):
            stance_z = sole_point_world(BODY, walker, kin, stance, np.full(len(kin), beta))[:, 2]
            swing_z = sole_point_world(BODY, walker, kin, 1 - stance, np.full(len(kin), beta))[:, 2]
            assert stance_z.min() >= -1e-9
            trailing = walker.stance_angle > walker.swing_angle
            if kin is not states[0]:
                assert swing_z.min() >= -1e-4
                assert np.all(swing_z[trailing] >= KinematicConfig().swing_clearance - 1e-4)
                checked_trailing += int(trailing.sum())
    assert checked_trailing > 100       # the early-swing clearance was checked on many bodies


def test_contact_rolls_heel_to_toe_and_switches_feet_continuously():
    walkers, states, poses = run(50, 50, seed=4)
    rolls = np.array([k.contact_roll.mean() for k in states[1:16]])
    assert rolls[-1] - rolls[0] > 0.5 * BODY.sole_half_angle  # heel towards toe over a step
    # At heel strike (frame 16) the contact passes to the other foot without a horizontal jump.
    before, after = states[15], states[16]
    assert np.all(after.contact_leg != before.contact_leg)
    pelvis_jump = np.linalg.norm(poses[16].markers[:, M["pelvis"], :2] - poses[15].markers[:, M["pelvis"], :2], axis=1)
    typical = np.linalg.norm(poses[15].markers[:, M["pelvis"], :2] - poses[14].markers[:, M["pelvis"], :2], axis=1)
    assert pelvis_jump.max() < 2.5 * typical.mean() + 0.01


def test_heel_rise_keeps_the_pelvis_at_most_at_the_walkers_hip():
    """Late in the stance the stance foot stands on its toe; the stance knee bends just enough that the
    pelvis stays no higher than the walker's hip (walker.hip_position), as people flex the knee before
    toe-off. On long steps (half angle 0.55 rad, ~0.95 m) the bound holds the pelvis on about a third of
    the stance frames (measured: 4232 of 11200 within 0.5 mm of it; 3802 with hip_over_ankle), so without
    the knee's projection the pelvis would rise above the walker's hip there."""
    walkers, states, poses = run(60, 200, seed=4, half_angle=0.55)
    checked = held = 0
    for f in range(1, len(walkers)):
        kept = walkers[f].stance_leg == states[f - 1].contact_leg          # no heel strike into this frame
        hip = hip_position(PARAMS, walkers[f])[1]
        pelvis = poses[f].markers[:, M["pelvis"], 2]
        assert np.all(pelvis[kept] <= hip[kept] + 1e-4)
        checked += int(kept.sum())
        held += int(np.sum(kept & (pelvis > hip - 5e-4)))
    assert checked > 5000 and held > 0.15 * checked


def test_a_pelvis_ceiling_keeps_the_pelvis_lower_with_the_stance_knee_bent():
    """``pelvis_ceiling`` 0.97: over the stance (no heel strike into the frame) the pelvis stays at most 0.97 of
    the walker's hip height, the stance knee bending for it, where with the walker's hip itself (1, the default)
    the prior's knee leaves the pelvis above that most of the time. Contact and ground stay as they were: the
    stance foot on the ground, the swing foot above it."""
    ceiling = 0.97
    outcome = {}
    for fraction in (1.0, ceiling):
        walkers, states, poses = run(48, 200, seed=6, config=KinematicConfig(pelvis_ceiling=fraction))
        above, knees, checked = 0, [], 0
        for f in range(1, len(walkers)):
            kept = walkers[f].stance_leg == states[f - 1].contact_leg
            hip = hip_position(PARAMS, walkers[f])[1]
            pelvis = poses[f].markers[:, M["pelvis"], 2]
            if fraction < 1.0:
                assert np.all(pelvis[kept] <= ceiling * hip[kept] + 1e-4)
            above += int(np.sum(kept & (pelvis > ceiling * hip + 1e-4)))
            checked += int(kept.sum())
            stance = np.where(walkers[f].stance_leg == LEFT, states[f].knee[:, 0], states[f].knee[:, 1])
            knees.append(stance[kept])
            soles = poses[f].markers[:, [M["left_heel"], M["left_toe"], M["right_heel"], M["right_toe"]], 2]
            assert soles.min() > -1e-6                                       # nothing below the ground
        outcome[fraction] = (above / checked, float(np.median(np.concatenate(knees))))
    assert outcome[1.0][0] > 0.5 and outcome[ceiling][0] == 0.0
    assert outcome[ceiling][1] > outcome[1.0][1] + 0.1                      # the stance knee bends (rad)
    with pytest.raises(ValueError, match="pelvis_ceiling"):
        KinematicConfig(pelvis_ceiling=0.5)


def test_each_particle_keeps_its_own_pelvis_ceiling():
    """Pelvis ceilings drawn around 0.97 (spread 0.02) and wandering: over the stance each particle's pelvis
    stays at most its own ceiling of the walker's hip height, the ceilings stay within PELVIS_CEILING_RANGE
    and wander, and the particles with the lower ceilings carry the pelvis lower."""
    from awalker_tracker.model.kinematics import PELVIS_CEILING_RANGE

    config = KinematicConfig(pelvis_ceiling=0.97, pelvis_ceiling_drift=0.002)
    walkers, states, poses = run(48, 400, seed=7, config=config, ceiling_spread=0.02)
    assert np.std(states[0].pelvis_ceiling) == pytest.approx(0.02, rel=0.25)
    low, high = PELVIS_CEILING_RANGE
    heights = np.zeros(400)
    for f in range(1, len(walkers)):
        ceiling = states[f].pelvis_ceiling
        assert np.all((ceiling >= low) & (ceiling <= high))
        kept = walkers[f].stance_leg == states[f - 1].contact_leg
        hip = hip_position(PARAMS, walkers[f])[1]
        pelvis = poses[f].markers[:, M["pelvis"], 2]
        assert np.all(pelvis[kept] <= ceiling[kept] * hip[kept] + 1e-4)
        heights += pelvis
    moved = np.abs(states[-1].pelvis_ceiling - states[0].pelvis_ceiling)
    assert np.median(moved) == pytest.approx(0.002 * np.sqrt(47) * 0.6745, rel=0.3)   # a random walk's
    lower = states[-1].pelvis_ceiling < np.median(states[-1].pelvis_ceiling)
    assert heights[lower].mean() < heights[~lower].mean() - 0.005 * (len(walkers) - 1)


def test_the_landing_knee_is_straightened_to_reach_the_ground():
    """At heel strike the walker's feet meet the ground together, but a landing knee still bent holds the
    kinematic foot above it: the knee is straightened until the foot touches (or fully). Measured on the
    hand-made walk: every landing knee ends less bent than it came in (0.34 -> 0.24 rad, median) and the
    pelvis drops a median 3 mm in that frame (19 mm with the chord on the walker's leg, before
    ``CHORD_LEAN``: kinematics *Knees*)."""
    walkers, states, poses = run(60, 200, seed=4)
    legs = np.array([w.stance_leg for w in walkers])
    swing_before = np.array([np.where(legs[f] == LEFT, s.knee[:, 1], s.knee[:, 0]) for f, s in enumerate(states)])
    landed = np.array([np.where(legs[f] == LEFT, s.knee[:, 0], s.knee[:, 1]) for f, s in enumerate(states)])
    strikes = legs[1:] != legs[:-1]
    assert strikes.sum() > 300
    before, knee = swing_before[:-1][strikes], landed[1:][strikes]
    assert np.median(before) > 0.1                                # the swing knee is still bent before it lands
    assert np.all(knee < before)                                  # straightened, never bent further
    assert np.median(knee) < np.median(before) - 0.05
    pelvis = np.array([p.markers[:, M["pelvis"], 2] for p in poses])
    assert np.median((pelvis[:-1] - pelvis[1:])[strikes]) < 0.01


@pytest.mark.parametrize("hip_over_ankle", [False, True])
def test_body_follows_walker_legs_and_speed(hip_over_ankle: bool):
    walkers, states, poses = run(64, 100, seed=5)
    # The hip-ankle chord has the knee's length L(knee), and the straight leg's chord leans CHORD_LEAN back from
    # the walker's leg phi. A bent knee shortens the chord along that angle, or with hip_over_ankle lowers the
    # hip straight down over the ankle, which stays (l_thigh + l_shank) sin(phi - CHORD_LEAN) ahead of it; exactly
    # so while the hip is neither abducted nor rotated (Table 1's hips, which rest unabducted). The thigh leads
    # the chord by the knee's delta and the reported hip flexion is the thigh's angle.
    upright = run(64, 100, seed=5, config=KinematicConfig(step_width=None, hip_over_ankle=hip_over_ankle))
    thigh_length, shank_length = BODY.upper_leg_length, BODY.lower_leg_length
    bent = 0
    for walker, kin, pose in zip(*(frames[::7] for frames in upright)):
        forward = np.stack([np.cos(kin.heading), np.sin(kin.heading)], axis=1)

        def sagittal(a: str, b: str) -> tuple[np.ndarray, np.ndarray]:
            """(along the walk, down) from marker a to marker b (m)."""
            axis = pose.markers[:, M[b]] - pose.markers[:, M[a]]
            return np.einsum("ij,ij->i", axis[:, :2], forward), -axis[:, 2]

        ahead, down = sagittal("left_hip", "left_ankle")
        thigh = np.arctan2(*sagittal("left_hip", "left_knee"))
        abducted = np.abs(kin.hip_abduction[:, 0]) + np.abs(kin.hip_rotation[:, 0])
        close = abducted < 0.02
        assert close.sum() >= 10
        phi, knee = leg_angles(walker)[:, 0], kin.knee[:, 0]
        chord = np.sqrt(thigh_length**2 + shank_length**2 + 2 * thigh_length * shank_length * np.cos(knee))
        straight = phi - CHORD_LEAN
        angle = np.arcsin((thigh_length + shank_length) * np.sin(straight) / chord) if hip_over_ankle else straight
        assert np.allclose(ahead[close], (chord * np.sin(angle))[close], atol=0.001)
        assert np.allclose(np.hypot(ahead, down)[close], chord[close], atol=0.002)
        delta = np.arctan2(shank_length * np.sin(knee), thigh_length + shank_length * np.cos(knee))
        assert np.allclose(thigh[close], (angle + delta)[close], atol=0.01)
        assert np.allclose(pose.joint_angles[:, J["left_hip_flexion"]], angle + delta)
        bent += int(np.sum(close & (knee > 0.2)))
    assert bent >= 10                   # the thigh's lead was checked with the knee bent
    # Segment lengths are kept.
    pose = poses[30]
    for a, b, length in [("left_hip", "left_knee", BODY.upper_leg_length),
                         ("right_knee", "right_ankle", BODY.lower_leg_length),
                         ("pelvis", "thorax", BODY.torso_length)]:
        assert np.allclose(np.linalg.norm(pose.markers[:, M[a]] - pose.markers[:, M[b]], axis=1), length)
    # The body walks at about the walker's speed (hand-made walk: step_length(0.35) per 16 frames).
    walker_speed = PARAMS.step_length(0.35) / (16 / 30)
    travel = np.linalg.norm(poses[-1].markers[:, M["pelvis"], :2] - poses[0].markers[:, M["pelvis"], :2], axis=1)
    body_speed = travel / (63 / 30)
    # At the walker's speed (0.99x here): the hip-ankle chords follow the walker's legs, so a swing knee
    # still bent at heel strike does not land the foot short of the walker's (with the thigh at the
    # walker's leg angle instead, the body walked at 0.67x).
    assert 0.95 * walker_speed < np.median(body_speed) < 1.02 * walker_speed
    # Pelvis near the leg length above the ground.
    z = np.array([p.markers[:, M["pelvis"], 2] for p in poses])
    assert 0.8 * BODY.leg_length < z.min() and z.max() < BODY.leg_length + 0.03  # toe pivot lifts the hip a little


def test_turning_rotates_about_the_stance_foot():
    rate = np.radians(2.0)  # per frame
    # A steady turn: heading velocity kept (alpha = 1), no heading noise, no turn rates drawn at strikes.
    config = KinematicConfig(table={**KinematicConfig().table, "torso_up": JointPrior(1.0, 0.0, 0.0, 0.0)},
                             turning=TurnPrior(small_sigma=0.0, large_sigma=0.0))
    walkers, states, poses = run(48, 20, seed=6, config=config, heading_rate=rate)
    heading_change = states[-1].heading - states[0].heading
    assert np.all(np.abs(heading_change) > np.radians(20))  # it does turn
    for f in range(len(states) - 1):
        kin, nxt = states[f], states[f + 1]
        if np.any(nxt.contact_leg != kin.contact_leg):
            continue
        before = sole_point_world(BODY, walkers[f], kin, kin.contact_leg, kin.contact_roll)
        after = sole_point_world(BODY, walkers[f + 1], nxt, kin.contact_leg, kin.contact_roll)
        assert np.abs(after[:, :2] - before[:, :2]).max() < 1e-3
    # The walking direction follows the heading.
    step = poses[-1].markers[:, M["pelvis"], :2] - poses[-9].markers[:, M["pelvis"], :2]
    direction = np.arctan2(step[:, 1], step[:, 0])
    mid_heading = states[-5].heading
    assert np.all(np.abs(np.angle(np.exp(1j * (direction - mid_heading)))) < np.radians(15))
    # plane_origin maps the walker's stance contact onto the contact point.
    kin, walker = states[-1], walkers[-1]
    along = np.stack([np.cos(kin.heading), np.sin(kin.heading)], axis=1)
    contact_x = walker.contact_origin - PARAMS.foot_radius * walker.stance_angle
    assert np.allclose(kin.plane_origin + contact_x[:, None] * along, kin.contact_point)


def test_turn_rate_is_drawn_per_step_and_turns_the_walk():
    """Turning per step: the rate drawn at a heel strike is kept through the step (no within-step
    noise here), the heading integrates it, eq. (6)'s velocity term does not amplify it, and most
    steps of a straight walk stay nearly straight while some turn sharply (the mixture)."""
    quiet = {**KinematicConfig().table, "torso_up": JointPrior(0.75, 0.0, 0.0, 0.0)}
    config = KinematicConfig(table=quiet)
    walkers, states, _ = run(64, 2000, seed=3, config=config)
    dt = config.dt
    for f in range(1, len(states)):
        turned = states[f].heading - states[f - 1].heading
        assert np.allclose(turned, states[f].turn_rate * dt, atol=1e-9)
        same_step = states[f].contact_leg == states[f - 1].contact_leg
        assert np.array_equal(states[f].turn_rate[same_step], states[f - 1].turn_rate[same_step])
    first_step = np.degrees(np.abs(states[20].turn_rate))            # after the first strike (frame 16)
    assert 0.5 < np.mean(first_step < 10) < 0.95 and np.mean(first_step > 45) > 0.03
    assert np.all(first_step <= 150 + 1e-6)
    # persistence: regressed on this step's rate, the next step's has slope rho = 0.9
    this, following = states[20].turn_rate, states[36].turn_rate
    assert np.cov(this, following)[0, 1] / np.var(this, ddof=1) == pytest.approx(0.9, abs=0.08)


def test_pose_body_is_vectorised_consistently():
    walkers, states, poses = run(20, 6, seed=7)
    walker, kin, pose = walkers[-1], states[-1], poses[-1]
    for i in range(6):
        single = pose_body(BODY, PARAMS, walker.take(np.array([i])), kin.take(np.array([i])))
        assert np.allclose(single.markers[0], pose.markers[i])
        assert np.allclose(single.segments.rotation[0], pose.segments.rotation[i])
    rot = pose.segments.rotation
    assert np.allclose(rot @ np.swapaxes(rot, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(rot), 1.0)
    assert pose.joint_angles.shape == (6, len(JOINT_NAMES))
    assert np.allclose(pose.joint_angles[:, J["torso_yaw"]], kin.heading)


def _mean_swing_knee(config: KinematicConfig) -> np.ndarray:
    """Mean swing knee angle (deg) per frame over the prior on the hand-made walk."""
    walkers, states, _ = run(64, 300, seed=8, config=config)
    return np.degrees([np.where(w.stance_leg == LEFT, k.knee[:, 1], k.knee[:, 0]).mean()
                       for w, k in zip(walkers, states)])


def test_swing_knee_bends_early_in_the_stride_and_straightens_late():
    # The paper's rest angle 5 psi_hip: the knee bends through it early and straightens late.
    paper = _mean_swing_knee(KinematicConfig(swing_knee_rest_gain=5.0))
    for stride in (paper[16:32], paper[32:48]):
        # bent at toe-off only to clear the floor: the foot hangs toe-down from the trailing hip-ankle
        # chord, and the knee shortens the chord until the toe clears (~50 degrees; people: 35-40)
        assert stride[0] < 55
        assert stride.max() > 45                   # bends through the rest angle 5 psi_hip
        assert np.argmax(stride) < 13              # peaks before the end of the swing
        assert stride[-1] < stride.max() - 20      # and straightens towards heel strike
    # Ours (gain 2.5): a smaller bend that still peaks before the end of the swing.
    ours = _mean_swing_knee(KinematicConfig())
    for stride, theirs in ((ours[16:32], paper[16:32]), (ours[32:48], paper[32:48])):
        assert 30 < stride.max() < theirs.max() - 10
        assert np.argmax(stride) < 13
    assert RIGHT == 1


def test_initial_spread_places_pelvis_and_heading():
    config = KinematicConfig()
    walker = hand_made_walk(1, 1)[0]
    n = 4000
    kin = initial_kinematics(config, walker, [1.0, -2.0], 0.5, n, np.random.default_rng(9), body=BODY,
                             position_spread=0.1, heading_spread=0.2, joint_spread=0.3)
    pose = pose_body(BODY, PARAMS, walker.take(np.zeros(n, np.intp)), kin)
    pelvis = pose.markers[:, M["pelvis"], :2]
    assert np.allclose(pelvis.mean(axis=0), [1.0, -2.0], atol=0.01)
    assert np.allclose(pelvis.std(axis=0), 0.1, rtol=0.1)
    assert kin.heading.mean() == pytest.approx(0.5, abs=0.01) and kin.heading.std() == pytest.approx(0.2, rel=0.1)
    limits = config.arrays(BODY)
    dofs = kin.dofs()
    limited = np.isfinite(limits["lower"])
    assert np.all(dofs[:, limited] >= limits["lower"][limited]) and np.all(dofs[:, limited] <= limits["upper"][limited])
    assert np.all(np.abs(kin.previous - dofs) == 0)  # starts at rest
    # The stance foot is on the ground at its contact point.
    contact = sole_point_world(BODY, walker.take(np.zeros(n, np.intp)), kin, kin.contact_leg, kin.contact_roll)
    assert np.allclose(contact[:, 2], 0.0, atol=1e-9) and np.allclose(contact[:, :2], kin.contact_point)


@pytest.mark.parametrize("step_width", [0.10, None])
def test_the_feet_tread_the_step_width_apart(step_width):
    """KinematicConfig.step_width: with the hips resting adducted the ankles pass 0.10 m apart across the
    walking direction (people's step width, ~0.1 m) instead of the hip joints' 0.18 m (Table 1's rest,
    step_width None), through the walk and not only at its start pose."""
    config = KinematicConfig(step_width=step_width)
    walkers, states, poses = run(60, 100, seed=5, config=config)
    widths = []
    for kin, pose in zip(states[20:], poses[20:]):
        across = np.stack([-np.sin(kin.heading), np.cos(kin.heading)], axis=1)       # the person's left
        ankles = pose.markers[:, [M["left_ankle"], M["right_ankle"]], :2]
        widths.append(np.sum((ankles[:, 0] - ankles[:, 1]) * across, axis=1))
    expected = BODY.hip_width if step_width is None else step_width
    assert np.median(widths) == pytest.approx(expected, abs=0.015)
    rest = config.hip_abduction_rest(BODY)
    thigh, shank, knee = BODY.upper_leg_length, BODY.lower_leg_length, config.stance_knee_rest
    chord = np.sqrt(thigh**2 + shank**2 + 2 * thigh * shank * np.cos(knee))      # hip to ankle, knee at rest
    assert rest == 0.0 if step_width is None else rest == pytest.approx(-np.arcsin(0.04 / chord))


def test_leg_scale_shortens_thigh_and_shank_and_lowers_the_body():
    """KinematicState.leg_scale: thigh and shank x the scale, the stance foot still on the ground, so the
    pelvis rides lower by about (1 - scale) x (thigh + shank) with the legs near vertical; feet, torso and
    head keep their sizes."""
    walker = hand_made_walk(9, 50)[8]                      # mid-stance: legs near vertical
    kin = initial_kinematics(KinematicConfig(), walker, [0.0, 0.0], 0.0, 50, np.random.default_rng(11), body=BODY)
    assert np.all(kin.leg_scale == 1.0)                    # the body's own legs unless a spread is asked for
    short = kin.copy()
    short.leg_scale = np.linspace(0.85, 1.1, 50)
    full, scaled = pose_body(BODY, PARAMS, walker, kin), pose_body(BODY, PARAMS, walker, short)
    m = scaled.markers
    for a, b, length in (("left_hip", "left_knee", BODY.upper_leg_length),
                         ("right_knee", "right_ankle", BODY.lower_leg_length)):
        np.testing.assert_allclose(np.linalg.norm(m[:, M[a]] - m[:, M[b]], axis=1), short.leg_scale * length)
    for a, b in (("pelvis", "thorax"), ("left_ankle", "left_toe"), ("right_heel", "right_toe")):
        np.testing.assert_allclose(np.linalg.norm(m[:, M[a]] - m[:, M[b]], axis=1),
                                   np.linalg.norm(full.markers[:, M[a]] - full.markers[:, M[b]], axis=1))
    drop = full.markers[:, M["pelvis"], 2] - m[:, M["pelvis"], 2]
    knee = kin.knee[np.arange(50), kin.contact_leg]        # the stance knee, resting bent: the hip-ankle chord
    thigh, shank = BODY.upper_leg_length, BODY.lower_leg_length
    chord = np.sqrt(thigh**2 + shank**2 + 2 * thigh * shank * np.cos(knee))
    np.testing.assert_allclose(drop, (1 - short.leg_scale) * chord, atol=2e-3)
    stance = sole_point_world(BODY, walker, short, short.contact_leg, short.contact_roll)
    np.testing.assert_allclose(stance[:, 2], 0.0, atol=1e-9)


def test_leg_scales_spread_and_wander_only_when_asked():
    """initial_kinematics(leg_scale_spread) draws log-normal scales within KinematicConfig.leg_scale_range;
    each frame they wander by leg_scale_drift, and stay put without it."""
    walkers = hand_made_walk(20, 4000)
    rng = np.random.default_rng(12)
    config = KinematicConfig(leg_scale_drift=0.01, leg_scale_range=(0.9, 1.08))
    kin = initial_kinematics(config, walkers[0], [0.0, 0.0], 0.0, 4000, rng, body=BODY, leg_scale_spread=0.04)
    assert np.std(np.log(kin.leg_scale)) == pytest.approx(0.04, rel=0.1)
    assert kin.leg_scale.min() >= 0.9 and kin.leg_scale.max() <= 1.08
    start = kin.leg_scale.copy()
    still = sample_kinematics(KinematicConfig(), BODY, PARAMS, walkers[0], walkers[1], None, kin, rng)
    assert np.array_equal(still.leg_scale, start)
    for f in range(1, 20):
        kin = sample_kinematics(config, BODY, PARAMS, walkers[f - 1], walkers[f], None, kin, rng)
    step = np.log(kin.leg_scale / start)
    inside = (kin.leg_scale > 0.9) & (kin.leg_scale < 1.08)
    assert np.std(step[inside]) == pytest.approx(0.01 * np.sqrt(19), rel=0.15)
    assert kin.leg_scale.min() >= 0.9 and kin.leg_scale.max() <= 1.08


def test_each_particle_leans_towards_its_own_posture():
    """initial_kinematics(posture_spread) gives each particle its own rest pitch of the torso (Table 1's
    upright rest plus N(0, spread^2), within +- POSTURE_LIMIT) and starts the torso at it; eq. (6) then keeps
    each torso near its own rest, where the upright rest would pull every torso back to 0 within a second.
    Without drift the postures stay put; with it they wander as a random walk."""
    n, frames = 2000, 60
    walkers = hand_made_walk(frames, n)
    rng = np.random.default_rng(13)
    kin = initial_kinematics(KinematicConfig(), walkers[0], [0.0, 0.0], 0.0, n, rng, body=BODY, posture_spread=0.1)
    assert np.std(kin.torso_rest) == pytest.approx(0.1, rel=0.1)
    assert np.abs(kin.torso_rest).max() <= POSTURE_LIMIT
    np.testing.assert_array_equal(kin.torso_lean[:, 0], kin.torso_rest)
    start, state = kin.torso_rest.copy(), kin
    for f in range(1, frames):
        state = sample_kinematics(KinematicConfig(), BODY, PARAMS, walkers[f - 1], walkers[f], None, state, rng)
    np.testing.assert_array_equal(state.torso_rest, start)
    pitch = state.torso_lean[:, 0]
    assert np.median(np.abs(pitch - start)) < 0.02            # each near its own rest after 2 s
    assert np.std(pitch) > 0.08 and np.corrcoef(pitch, start)[0, 1] > 0.95
    upright = initial_kinematics(KinematicConfig(), walkers[0], [0.0, 0.0], 0.0, n, rng, body=BODY)
    np.testing.assert_array_equal(upright.torso_rest, 0.0)
    drifting, config = kin, KinematicConfig(posture_drift=0.01)
    for f in range(1, 21):
        drifting = sample_kinematics(config, BODY, PARAMS, walkers[f - 1], walkers[f], None, drifting, rng)
    assert np.std(drifting.torso_rest - start) == pytest.approx(0.01 * np.sqrt(20), rel=0.15)
