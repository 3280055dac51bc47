"""Walking speed (inference/speed.py): one definition for the tracker's particles and the evaluation's truth."""
from __future__ import annotations

import numpy as np
import pytest

from awalker_tracker.inference.speed import SPEED_TIME_CONSTANT_S, update_speed, walking_speed

DT_NS = 33_333_333


def test_a_steady_walk_has_its_speed_from_the_first_frame():
    stamps = np.arange(40) * DT_NS
    xy = np.column_stack([1.3 * stamps * 1e-9, np.full(40, 2.0)]) @ np.array([[0.6, 0.8], [-0.8, 0.6]])
    np.testing.assert_allclose(walking_speed(xy, stamps), 1.3, rtol=1e-9)


def test_a_change_of_pace_is_followed_within_about_a_time_constant():
    """From 1.0 to 1.5 m/s: the exponential average over SPEED_TIME_CONSTANT_S, frame by frame update_speed."""
    steps = np.r_[np.full(30, 1.0), np.full(60, 1.5)] * DT_NS * 1e-9          # m per frame
    xy = np.column_stack([np.r_[0.0, np.cumsum(steps)], np.zeros(91)])
    stamps = np.arange(91) * DT_NS
    speed = walking_speed(xy, stamps)
    expected = [1.0]
    for moved in steps:
        expected.append(update_speed(expected[-1], moved, DT_NS * 1e-9))
    np.testing.assert_allclose(speed, expected, rtol=1e-12)
    gain = DT_NS * 1e-9 / SPEED_TIME_CONSTANT_S
    after = 1.5 - 0.5 * (1 - gain) ** 15                                       # 15 frames = one time constant
    assert speed[45] == pytest.approx(after) and 1.30 < speed[45] < 1.35 and speed[-1] == pytest.approx(1.5, abs=0.01)
    # the sideways sway of the pelvis counts: the path, not the chord
    zigzag = np.column_stack([np.arange(31) * 0.04, 0.01 * (-1) ** np.arange(31)])
    assert walking_speed(zigzag, np.arange(31) * DT_NS)[-1] == pytest.approx(np.hypot(0.04, 0.02) / (DT_NS * 1e-9))


def test_given_start_speed_and_bad_input():
    xy = np.column_stack([np.arange(5) * 0.04, np.zeros(5)])
    speed = walking_speed(xy, np.arange(5) * DT_NS, initial=0.0)
    assert speed[0] == 0.0 and 0 < speed[1] < speed[-1] < 1.2
    assert np.isnan(walking_speed(xy[:1], np.zeros(1, np.int64))).all()
    with pytest.raises(ValueError, match="increase strictly"):
        walking_speed(xy, np.array([0, 1, 1, 2, 3]))
    with pytest.raises(ValueError, match=r"\(F, 2\)"):
        walking_speed(xy[:, :1], np.arange(5))


def test_the_tracker_and_the_evaluation_use_it():
    """The tracker's particles move their speed by update_speed (fallen ones keep theirs), and `awalker eval` /
    the accuracy tests take the truth's by walking_speed."""
    import sys
    from pathlib import Path

    from awalker_tools import evaluation
    from awalker_tracker.inference.filter_model import StartDescription, TrackerConfig, TrackerModel, marker_likelihood
    from awalker_tracker.inference.smc import SMCConfig
    from awalker_tracker.model.body import BodyDescription
    from awalker_tracker.model.walker import LEFT

    body = BodyDescription.default()
    config = TrackerConfig(smc=SMCConfig(num_particles=64, seed=0), dt=1 / 30)
    model = TrackerModel(body, StartDescription(0, (0.0, 0.0), 0.0, 1.3, 0.7, LEFT), marker_likelihood(), config)
    rng = np.random.default_rng(0)
    states = model.initial(64, rng)
    new, events = model.transition(states, rng)
    pelvis = 0
    moved = np.linalg.norm(new.pose.markers[:, pelvis, :2] - states.pose.markers[:, pelvis, :2], axis=1)
    walking = ~(states.fallen | np.asarray(events.fallen, bool))
    assert walking.any()
    np.testing.assert_array_equal(new.speed[walking], update_speed(states.speed, moved, 1 / 30)[walking])

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from test_eval import walking_truth

    truth = walking_truth()
    np.testing.assert_array_equal(evaluation.track_speed(truth),
                                  walking_speed(truth.marker("pelvis")[:, :2], truth.stamps_ns))
