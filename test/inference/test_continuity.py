"""The published paths do not jump: the MAP trajectory spreads a re-seeding's jump over the frames before it
(``smooth_jumps``) and the live pose follows the filtering MAP through a settling offset (``PublishedPath``)."""
from __future__ import annotations

import numpy as np

from awalker_tracker.inference.filter_model import (
    JUMP_SPREAD_M_S, JUMP_SPREAD_MIN_S, MAX_PUBLISHED_SPEED_M_S, PublishedPath, smooth_jumps)
from awalker_tracker.inference.recovery import RESEEDED_FALLEN
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


def test_overlapping_jumps_are_spread_no_faster_than_one():
    """Two re-acquisitions 0.3 s apart, each 1 m to the left: the ramps of both overlap, but their sum moves the
    path no faster than the walk plus the spreading speed (summed, it reached twice that)."""
    markers = walk(120)
    jumps = np.zeros((120, 3))
    for frame in (90, 99):
        markers[frame:, :, :2] += [0.0, 1.0]
        jumps[frame] = [0.0, 1.0, 0.0]
    angles = np.zeros((120, len(JOINT_NAMES)))
    smoothed, _ = smooth_jumps(markers, angles, jumps, DT)
    assert step_speeds(smoothed).max() <= np.hypot(1.2, JUMP_SPREAD_M_S) + 1e-6
    np.testing.assert_array_equal(smoothed[99:], markers[99:])
    # 2 m at 1 m/s: the path leaves its old walk about 2 s before the last jump, and not before
    start = 99 - int(np.ceil(2.0 / JUMP_SPREAD_M_S / DT)) - 1
    np.testing.assert_allclose(smoothed[:start], markers[:start])
    assert np.linalg.norm(smoothed[start + 3, PELVIS, :2] - markers[start + 3, PELVIS, :2]) > 0.0


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
    assert steps.max() <= min(speed + JUMP_SPREAD_M_S, MAX_PUBLISHED_SPEED_M_S) + 1e-6
    # a walk that itself moves too fast for a person (a particle's own stumble) is published no faster than that
    fast = PublishedPath(DT)
    out = [np.array([0.0, 0.0]) - fast.update(np.array([[0.0, 0.0]]), np.array([0]), np.zeros((1, 3)), 0)]
    for frame in range(1, 10):
        x = np.array([[0.2 * frame, 0.0]])                         # 6 m/s
        out.append(x[0] - fast.update(x, np.array([0]), np.zeros((1, 3)), 0))
    assert np.max(np.linalg.norm(np.diff(out, axis=0), axis=1)) / DT <= MAX_PUBLISHED_SPEED_M_S + 1e-9
    # a MAP that stays on one lineage is published as it is
    still = PublishedPath(DT)
    for frame in range(5):
        assert not still.update(np.array([[0.05 * frame, 0.0]]), np.array([0]), np.zeros((1, 3)), 0).any()


def _walking_particles(n: int, frames: int, seed: int = 0):
    """Tracker particles walked ``frames`` frames by the prior (no images)."""
    from awalker_tracker.inference.filter_model import StartDescription, TrackerConfig, TrackerModel, marker_likelihood
    from awalker_tracker.model.body import BodyDescription

    model = TrackerModel(BodyDescription.default(), StartDescription(0, (0.0, 0.0), 0.7, 1.3, None, None),
                         marker_likelihood(), TrackerConfig())
    rng = np.random.default_rng(seed)
    states = model.initial(n, rng)
    out = [states]
    for _ in range(frames - 1):
        states, _ = model.transition(states, rng)
        out.append(states)
    return model, out


def _mirror(markers: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Markers (N, M, 3) reflected about each body's sagittal plane (through its pelvis along ``heading``) with
    left and right rows swapped."""
    side = np.stack([-np.sin(heading), np.cos(heading)], axis=1)[:, None, :]
    out = markers.copy()
    out[..., :2] -= 2 * np.sum((markers[..., :2] - markers[:, PELVIS, None, :2]) * side, axis=-1, keepdims=True) * side
    swap = [MARKER_NAMES.index(n.replace("left", "#").replace("right", "left").replace("#", "right")) for n in MARKER_NAMES]
    return out[:, swap]


def test_a_body_with_its_legs_named_the_other_way_is_its_mirror_image():
    from awalker_tracker.model import kinematics

    model, walk = _walking_particles(40, 9)
    s = walk[-1]
    walker, kin = kinematics.mirrored_legs(s.walker, s.kin, s.pose.markers[:, PELVIS, :2], model.body, model.params,
                                           model.kin_config)
    posed = kinematics.pose_body(model.body, model.params, walker, kin, model.kin_config).markers
    np.testing.assert_allclose(posed, _mirror(s.pose.markers, s.kin.heading), atol=1e-12)
    assert np.array_equal(walker.stance_leg, 1 - s.walker.stance_leg)


def test_a_body_drawn_standing_brings_its_feet_together_under_the_kept_pelvis():
    """``kinematics.standing_body``: mid-stride bodies taken the whole way stand with both legs vertical, both knees
    straight and both feet flat, side by side under the pelvis and on the ground, the pelvis where it was; taken part
    of the way, the feet come that far together; each body by its own fraction; the walker's hip stays put in its
    own plane and the rates and eq. (6)'s previous joint angles are the originals'."""
    from awalker_tracker.model import kinematics
    from awalker_tracker.model.walker import hip_position

    model, walk = _walking_particles(60, 12)
    s = walk[-1]
    pelvis = s.pose.markers[:, PELVIS, :2]
    ankles = [MARKER_NAMES.index("left_ankle"), MARKER_NAMES.index("right_ankle")]
    along = np.stack([np.cos(s.kin.heading), np.sin(s.kin.heading)], axis=1)

    def feet_apart(markers: np.ndarray, rows: np.ndarray = np.ones(60, bool)) -> np.ndarray:
        return np.abs(np.sum((markers[:, ankles[0], :2] - markers[:, ankles[1], :2]) * along[rows], axis=1))

    def other_foot_up(markers: np.ndarray) -> np.ndarray:
        return np.ptp(markers[:, ankles, 2], axis=1)

    apart = feet_apart(s.pose.markers)
    assert np.median(apart) > 0.1 and np.median(other_foot_up(s.pose.markers)) > 0.05   # mid-stride, a foot up
    fraction = np.where(np.arange(60) % 2 == 0, 1.0, 0.5)
    walker, kin = kinematics.standing_body(s.walker, s.kin, pelvis, fraction, model.body, model.params,
                                           model.kin_config)
    posed = kinematics.pose_body(model.body, model.params, walker, kin, model.kin_config).markers
    np.testing.assert_allclose(posed[:, PELVIS, :2], pelvis, atol=1e-9)
    np.testing.assert_allclose(hip_position(model.params, walker)[0], hip_position(model.params, s.walker)[0],
                               atol=1e-12)
    np.testing.assert_allclose(walker.stance_angle, (1 - fraction) * s.walker.stance_angle)
    np.testing.assert_array_equal(walker.stance_rate, s.walker.stance_rate)
    np.testing.assert_array_equal(kin.previous, s.kin.previous)
    sole = kinematics.sole_point_world(model.body, walker, kin, kin.contact_leg, kin.contact_roll, model.kin_config)
    np.testing.assert_allclose(sole[:, :2], kin.contact_point, atol=1e-9)
    assert np.all(np.abs(sole[:, 2]) < 1e-9)             # the contact on the ground
    whole, half = fraction == 1.0, fraction == 0.5
    assert np.all(feet_apart(posed[whole], whole) < 0.03)
    np.testing.assert_allclose(kin.dofs()[whole][:, 7:13], 0.0)
    # what is left is the hips' roll and the legs' sideways spread, which standing leaves alone
    assert np.all(other_foot_up(posed[whole]) < 0.03) and np.median(other_foot_up(posed[whole])) < 0.01
    assert np.all(feet_apart(posed[half], half) < 0.75 * apart[half] + 0.02)


def _renamed_walk(at: int, frames: int = 12):
    """One particle's walk (markers, joint angles, stance legs per frame) and the same walk with its legs renamed
    from frame ``at`` on (``kinematics.mirrored_legs``), as a lineage that flipped there records it, with the
    flip flags."""
    from awalker_tracker.model import kinematics

    model, walk = _walking_particles(1, frames, seed=3)
    markers = np.array([s.pose.markers[0] for s in walk])
    angles = np.array([s.pose.joint_angles[0] for s in walk])
    stance = np.array([s.walker.stance_leg[0] for s in walk])
    renamed = [kinematics.pose_body(model.body, model.params, *kinematics.mirrored_legs(
        s.walker, s.kin, s.pose.markers[:, PELVIS, :2], model.body, model.params, model.kin_config),
        model.kin_config) for s in walk[at:]]
    lineage, lineage_angles, lineage_stance = markers.copy(), angles.copy(), stance.copy()
    lineage[at:] = [r.markers[0] for r in renamed]
    lineage_angles[at:] = [r.joint_angles[0] for r in renamed]
    lineage_stance[at:] = 1 - stance[at:]
    flipped = np.zeros(frames, bool)
    flipped[at] = True
    return (markers, angles, stance), (lineage, lineage_angles, lineage_stance), flipped


def test_a_lineage_that_renamed_its_legs_is_named_throughout_as_it_ends():
    """A walk whose particle renamed its legs at frame 6: the lineage's earlier frames are mirrored and renamed
    too, so its feet do not swap sides at the flip, and the frames after it are left as they are."""
    from awalker_tracker.inference.filter_model import relabel_lineage

    (markers, angles, stance), (lineage, lineage_angles, lineage_stance), flipped = _renamed_walk(6)
    left_ankle = MARKER_NAMES.index("left_ankle")
    assert np.linalg.norm(lineage[6, left_ankle, :2] - lineage[5, left_ankle, :2]) > 0.05     # the raw lineage: a jump
    out, out_angles, out_stance = relabel_lineage(lineage, lineage_angles, lineage_stance, flipped)
    expected = np.concatenate([_mirror(markers[:6], angles[:6, JOINT_NAMES.index("torso_yaw")]), lineage[6:]])
    np.testing.assert_allclose(out, expected, atol=1e-9)
    assert np.array_equal(out_stance, 1 - stance) and np.array_equal(out[6:], lineage[6:])
    assert np.linalg.norm(out[6, left_ankle, :2] - out[5, left_ankle, :2]) < 0.05
    # two flips cancel: the frames before both are named as they were
    twice = flipped.copy()
    twice[9] = True
    again, _, again_stance = relabel_lineage(lineage, lineage_angles, lineage_stance, twice)
    np.testing.assert_allclose(again[:6], lineage[:6])
    np.testing.assert_array_equal(again_stance[:6], stance[:6])


def test_walkers_replaced_after_a_fall_or_renamed_continue_their_own_lineage_and_record_the_jump():
    """A fallen walker's replacement (and a particle that renamed its legs) stays in its row's lineage
    (``continues`` is each row itself) and records how far it moved (the MAP trajectory spreads it): caught by its
    other leg where it fell, not at all over the ground."""
    from dataclasses import replace

    model, walk = _walking_particles(30, 5)
    model.config = replace(model.config, label_flip_rate_hz=10.0)    # a third of the particles each frame
    states = walk[-1]
    fallen = np.zeros(30, bool)
    fallen[::3] = True
    states = replace(states, fallen=fallen)
    moved, _ = model.transition(states, np.random.default_rng(1))
    np.testing.assert_array_equal(moved.continues, np.arange(30))
    assert (moved.reseeded[fallen] == RESEEDED_FALLEN).all() and not moved.fallen.any()
    assert np.abs(moved.jump[fallen, :2]).max() < 1e-9 and not moved.jump[~fallen].any()
    assert 0 < moved.flipped.sum() < 30


def test_the_lineage_takes_the_naming_the_posterior_favoured():
    """Where the last particle's naming is a coin toss, the posterior's frames decide: a lineage that renamed its
    legs at frame 9 of 12, while the posterior kept favouring its first naming, keeps that naming throughout (the
    frames after the flip are mirrored back); a posterior that agrees with the last naming keeps it."""
    from awalker_tracker.inference.filter_model import relabel_lineage

    (markers, _, stance), (lineage, lineage_angles, lineage_stance), flipped = _renamed_walk(9)
    first_naming = np.where(stance == 0, 0.9, 0.1)                 # the posterior's P(left) per frame
    out, _, out_stance = relabel_lineage(lineage, lineage_angles, lineage_stance, flipped, first_naming)
    np.testing.assert_allclose(out, markers, atol=1e-9)
    np.testing.assert_array_equal(out_stance, stance)
    last_naming = 1.0 - first_naming
    out, _, out_stance = relabel_lineage(lineage, lineage_angles, lineage_stance, flipped, last_naming)
    np.testing.assert_array_equal(out_stance, 1 - stance)
    np.testing.assert_allclose(out[9:], lineage[9:])


def test_a_renaming_of_the_whole_posterior_names_anew_only_the_frames_since_its_evidence_rose():
    """Every particle renamed its legs at frame 9 (the naming test), the evidence for it rising since frame 6: the
    frames 6-8 are named as after the renaming (mirrored, the posterior's probabilities there read the other way
    round), the frames before 6 keep their naming (the walker went wrong at 6), and the posterior's frames, read
    so, keep that labelling rather than mirroring the whole path."""
    from awalker_tracker.inference.filter_model import mirror_poses, relabel_lineage

    (markers, angles, stance), (lineage, lineage_angles, lineage_stance), flipped = _renamed_walk(9)
    posterior = np.where(np.arange(len(stance)) < 9, np.where(stance == 0, 0.9, 0.1),
                         np.where(lineage_stance == 0, 0.7, 0.3))  # as measured: in the naming of the time
    since = np.zeros(len(stance), bool)
    since[6:9] = True
    out, _, out_stance = relabel_lineage(lineage, lineage_angles, lineage_stance, np.zeros_like(flipped), posterior,
                                         since)
    np.testing.assert_array_equal(out_stance, np.where(np.arange(len(stance)) < 6, stance, 1 - stance))
    np.testing.assert_allclose(out[:6], markers[:6], atol=1e-9)
    np.testing.assert_allclose(out[6:9], mirror_poses(lineage, lineage_angles, since)[0][6:9], atol=1e-9)
    np.testing.assert_allclose(out[9:], lineage[9:])


class _OrderingMonitor:
    """A lost-track monitor that orders a re-acquisition at ``position`` (m) every frame."""

    def __init__(self, position: tuple[float, float]) -> None:
        self.position = np.asarray(position, float)

    def update(self, frame, features, pelvis):
        from awalker_tracker.inference.recovery import Reacquisition

        return Reacquisition(self.position.copy(), None, None)

    def depth_band(self, frame):
        return None

    def heading_band(self, frame):
        return None

    def still(self, frame):
        return False


def test_a_reacquired_copy_of_a_walker_reseeded_after_a_fall_records_both_jumps():
    """A fall and a re-acquisition in the same frame: the re-acquisition copies walkers that were themselves just
    re-seeded after their fall. Every particle's recorded jump is then how far it lies from the walk it continues
    (``continues``), the fall's re-seeding and the re-acquisition's move together; with one of them dropped the
    MAP trajectory kept a 0.6 m step in one frame (a slow tuning walk, one camera)."""
    from dataclasses import replace

    from awalker_tracker.inference.filter_model import ImageObservation

    model, walk = _walking_particles(40, 5)
    states = replace(walk[-1], fallen=np.arange(40) % 2 == 0)      # every other walker fell
    config = model.config
    model.config = replace(config, recovery=replace(config.recovery, reseed_fallen=False))
    walked_on, _ = model.transition(states, np.random.default_rng(1))
    model.config = config
    reseeded, _ = model.transition(states, np.random.default_rng(1))
    fell = reseeded.reseeded == 1
    # caught by the other leg where they fell: the fall's own move is none over the ground (a fall re-seeded over
    # the stance foot moved 0.5-0.7 m back; either way ``moved`` below is measured from the walk continued)
    assert fell.sum() == 20 and np.abs(reseeded.jump[fell, :2]).max() < 1e-9
    model.monitor = _OrderingMonitor((3.0, 2.0))                   # the person is 3-4 m away
    log_weights = np.where(fell, 0.0, -50.0)                       # the copies come from re-seeded walkers
    w = np.exp(log_weights) / np.exp(log_weights).sum()
    out = model._recovered(5, log_weights, w, walk[-1], reseeded, ImageObservation(features=()),
                           np.random.default_rng(2))
    copies = out.continues != np.arange(40)
    assert copies.sum() == 10 and np.all(fell[out.continues[copies]])
    # from the walk each particle continues (the frame's walker as the prior moved it, before any re-seeding)
    moved = out.pose.markers[:, PELVIS, :2] - walked_on.pose.markers[out.continues, PELVIS, :2]
    np.testing.assert_allclose(out.jump[:, :2], moved, atol=1e-9)
    assert np.all(np.linalg.norm(out.jump[out.reseeded == 2, :2], axis=1) > 2.0)


def test_renaming_the_legs_keeps_each_particles_lineage_and_jump():
    """The naming test renames every particle's legs after the recovery has run (``rejuvenate``): a frame's
    re-acquired copies keep the walk they continue (``continues``) and their recorded jump through the renaming;
    reset to each row itself, the MAP lineage of a copy went on through the row it overwrote."""
    from awalker_tracker.inference.filter_model import ImageObservation

    model, walk = _walking_particles(40, 5)
    model.monitor = _OrderingMonitor((3.0, 2.0))
    log_weights = np.zeros(40)
    out = model._recovered(5, log_weights, np.full(40, 1 / 40), walk[-2], walk[-1], ImageObservation(features=()),
                           np.random.default_rng(2))
    assert np.any(out.continues != np.arange(40))
    for rows in (np.arange(40), np.arange(0, 40, 3)):
        renamed = model._flip_labels(out, rows)
        np.testing.assert_array_equal(renamed.continues, out.continues)
        np.testing.assert_array_equal(renamed.jump, out.jump)
        np.testing.assert_array_equal(renamed.reseeded, out.reseeded)
        assert renamed.flipped[rows].all() and not np.delete(renamed.flipped, rows).any()
        np.testing.assert_array_equal(renamed.walker.stance_leg[rows], 1 - out.walker.stance_leg[rows])
