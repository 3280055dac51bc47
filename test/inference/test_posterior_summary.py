"""Posterior summaries from a weighted particle set with hand-computable answers."""
from __future__ import annotations

import numpy as np
import pytest

from awalker_tracker.inference.posterior import LEFT, RIGHT, WALKER_FIELDS, ParticleOutputs, summarize

NAMES = ("pelvis", "thorax", "head", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
         "right_ankle", "left_heel", "right_heel", "left_toe", "right_toe")


def outputs(n: int, rng) -> ParticleOutputs:
    return ParticleOutputs(
        markers=rng.normal(size=(n, 13, 3)), joint_angles=rng.normal(size=(n, 5)),
        torso_position=rng.normal(size=(n, 3)), torso_rotation=np.tile(np.eye(3), (n, 1, 1)),
        speed=rng.uniform(1, 2, n), stance_leg=rng.integers(0, 2, n).astype(np.int8),
        contact_point=rng.normal(size=(n, 3)), heel_strike=np.zeros(n, bool), strike_point=np.zeros((n, 3)),
        strike_fraction=np.full(n, np.nan),
        walker={k: rng.normal(size=n) for k in WALKER_FIELDS}, reseeded=np.zeros(n, np.int8))


def test_summary_statistics_match_hand_computation():
    rng = np.random.default_rng(0)
    out = outputs(4, rng)
    out.stance_leg[:] = [LEFT, LEFT, RIGHT, RIGHT]
    out.speed[:] = [1.0, 2.0, 3.0, 4.0]
    out.heel_strike[:] = [False, False, True, True]
    w = np.array([0.1, 0.2, 0.3, 0.4])
    out.reseeded[:] = [0, 1, 2, 2]
    s = summarize(7, 123, np.log(w) + 50.0, out, NAMES, tuple("abcde"), resampled=True, cloud_size=2)
    assert s.frame_index == 7 and s.stamp_ns == 123 and s.resampled and s.num_particles == 4
    assert s.reseeded_fallen == 1 and s.reacquired == 2
    assert np.allclose(s.map_markers, out.markers[3])
    assert np.allclose(s.mean_markers, np.einsum("n,nmk->mk", w, out.markers))
    assert s.speed == pytest.approx(3.0)
    assert s.speed_std == pytest.approx(np.sqrt(np.sum(w * (out.speed - 3.0) ** 2)))
    assert s.stance_left_probability == pytest.approx(0.3)
    assert s.effective_sample_size == pytest.approx(1 / np.sum(w**2))
    left, right = s.contacts
    assert left.foot == LEFT and left.probability == pytest.approx(0.3) and not left.heel_strike
    assert right.heel_strike and s.heel_strike_foot == "right"
    assert np.allclose(right.position, (0.3 * out.contact_point[2] + 0.4 * out.contact_point[3]) / 0.7)
    assert s.map_walker["stiffness"] == pytest.approx(out.walker["stiffness"][3])
    head = [c for c in s.clouds if c.marker_name == "head"][0]
    assert sorted(head.weights.tolist()) == pytest.approx([0.3, 0.4])       # the two heaviest particles


def test_take_keeps_rows_together():
    out = outputs(5, np.random.default_rng(1))
    sub = out.take(np.array([4, 0]))
    assert np.array_equal(sub.markers[0], out.markers[4]) and np.array_equal(sub.walker["stance_rate"],
                                                                              out.walker["stance_rate"][[4, 0]])
