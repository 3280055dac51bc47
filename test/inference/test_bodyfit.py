"""Leg length and stance leg from the evidence (inference.bodyfit), on marker observations of a walk the
model simulated (for the leg length with a body whose legs differ from the one given)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from awalker_tracker.inference.bodyfit import BodyFitConfig, fit_leg_length, fit_stance_leg
from awalker_tracker.inference.filter_model import StartDescription, TrackerConfig, marker_likelihood
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.model.walker import LEFT, RIGHT
from test_filter_model import simulate_walk


def test_the_evidence_finds_the_walkers_leg_length():
    true_body, markers, _, _ = simulate_walk(40, 1.3, 0.7, 0.4, seed=12)
    given = true_body.legs_scaled(1 / 0.94)           # a tape measure 6 % long on the legs
    obs = markers + 0.01 * np.random.default_rng(5).standard_normal(markers.shape)
    start = StartDescription(0, tuple(markers[0, 0, :2]), 0.4, 1.3, 0.7, LEFT)
    messages = []
    fit = fit_leg_length(given, start, lambda body: marker_likelihood(0.03), list(obs), TrackerConfig(dt=1 / 30),
                         BodyFitConfig(leg_factors=(0.94, 1.0, 1.06), frames=30, particles=400, seed=1),
                         progress=messages.append)
    assert fit.factor == 0.94 and fit.frames == 30 and len(messages) == 3
    assert fit.body.leg_length == pytest.approx(true_body.leg_length)
    evidence = fit.log_evidence
    # the true legs by far (fit seeds 1-3: 23-47 nats ahead of the next, with the hip-ankle chords leaning
    # back from the walker's legs and the walk started in the named leg's single support; fit seed 4 picks
    # 1.0: the 400-particle filter's evidence still swings by a hundred nats from seed to seed)
    assert evidence[0.94] > max(evidence[1.0], evidence[1.06]) + 15


def test_candidates_on_several_threads_give_what_one_thread_gives(monkeypatch):
    """The candidates run at once on the cores' threads; each is the same filter, bit for bit, as alone."""
    true_body, markers, _, _ = simulate_walk(20, 1.3, 0.7, 0.0, seed=12)
    start = StartDescription(0, tuple(markers[0, 0, :2]), 0.0, 1.3, 0.7, LEFT)
    config = BodyFitConfig(leg_factors=(0.94, 0.97, 1.0, 1.03), frames=15, particles=300, seed=2)

    def fit(threads: str):
        monkeypatch.setenv("AWALKER_THREADS", threads)
        messages: list[str] = []
        result = fit_leg_length(true_body, start, lambda body: marker_likelihood(0.03), list(markers),
                                TrackerConfig(dt=1 / 30), config, progress=messages.append)
        return result, messages

    alone, messages_alone = fit("1")
    together, messages_together = fit("3")
    assert together.log_evidence == alone.log_evidence and together.factor == alone.factor
    assert list(together.log_evidence) == list(config.leg_factors)          # in the candidates' order
    assert sorted(messages_together) == sorted(messages_alone) and len(messages_alone) == 4


@pytest.mark.parametrize("true_leg", [LEFT, RIGHT])
def test_the_evidence_finds_the_stance_leg_a_start_leaves_open(true_leg: int):
    """A start naming no stance leg: each leg's filter against the markers of a walk standing on the left
    leg (its first frames) or, later, mid-way through the right leg's stance; the true leg wins by far."""
    body, markers, legs, _ = simulate_walk(60, 1.3, 0.7, 0.4, seed=12)
    if true_leg == LEFT:
        first = 0                                         # a third into the left leg's step (simulate_walk)
    else:
        right = np.flatnonzero(legs == RIGHT)
        run_end = right[0] + int(np.argmax(np.diff(right) > 1)) if np.any(np.diff(right) > 1) else right[-1]
        first = (right[0] + run_end) // 2                 # mid-way through the right leg's first stance
    assert legs[first] == true_leg
    obs = markers[first:] + 0.01 * np.random.default_rng(5).standard_normal(markers[first:].shape)
    start = StartDescription(first, tuple(markers[first, 0, :2]), 0.4, 1.3, 0.7, None)
    messages: list[str] = []
    fit = fit_stance_leg(body, start, lambda b: marker_likelihood(0.03), list(obs), TrackerConfig(dt=1 / 30),
                         BodyFitConfig(frames=25, particles=400, seed=1, stance_repeats=2), progress=messages.append)
    assert fit.leg == true_leg and fit.frames == 25 and len(messages) == 4
    other = RIGHT if true_leg == LEFT else LEFT
    # measured (fit seeds 1-4): the true leg 420-1650 nats ahead (the markers name each leg)
    assert fit.log_evidence[true_leg] > fit.log_evidence[other] + 200


@pytest.mark.parametrize("scripted, max_repeats, rounds, leg", [
    # 2 nats apart after two filters per leg, 9.1 after four, 9.1 after six: three rounds, capped; right
    ({LEFT: [100, 103, 90, 95, 80, 85], RIGHT: [101, 99, 110, 112, 100, 100]}, 6, [2, 2, 2], RIGHT),
    # the same capped at five filters per leg: the last round runs one
    ({LEFT: [100, 103, 90, 95, 80], RIGHT: [101, 99, 110, 112, 100]}, 5, [2, 2, 1], RIGHT),
    # 30 nats apart at once: one round
    ({LEFT: [130, 131], RIGHT: [101, 99]}, 6, [2], LEFT),
    # 2 nats apart, then 15.4 after four filters: two rounds, and the pooled evidence decides
    ({LEFT: [100, 103, 116, 117], RIGHT: [101, 99, 100, 101]}, 6, [2, 2], LEFT),
])
def test_tied_legs_are_weighed_again_with_more_filters(monkeypatch, scripted, max_repeats, rounds, leg):
    from awalker_tracker.inference import bodyfit

    calls: list[dict] = []

    def scripted_evidence(candidates, *args):
        calls.append(candidates)
        return {key: float(scripted[key[0]][key[1]]) for key in candidates}

    monkeypatch.setattr(bodyfit, "_log_evidence", scripted_evidence)
    config = BodyFitConfig(frames=5, seed=3, stance_repeats=2, stance_tie_nats=10.0, stance_max_repeats=max_repeats)
    start = StartDescription(0, (0.0, 0.0), 0.0, 1.3, 0.7, None)
    messages: list[str] = []
    fit = fit_stance_leg(BodyDescription.default(), start, lambda b: marker_likelihood(), [None] * 5, TrackerConfig(),
                         config, progress=messages.append)
    assert [len(c) // 2 for c in calls] == rounds and fit.filters == sum(rounds) and fit.leg == leg
    done = 0
    for size, candidates in zip(rounds, calls):      # each round the next filters of both legs, their own seeds
        assert sorted(candidates) == [(k, r) for k in (LEFT, RIGHT) for r in range(done, done + size)]
        assert all(seed == 3 + r and s.stance_leg == k for (k, r), (_, s, seed) in candidates.items())
        done += size
    pooled = {k: np.log(np.mean(np.exp(np.array(scripted[k][:done], float)))) for k in (LEFT, RIGHT)}
    assert fit.log_evidence == pytest.approx(pooled)
    assert sum("more filters per leg" in m for m in messages) == len(rounds) - 1


def test_bad_fit_settings_and_inputs():
    with pytest.raises(ValueError, match="leg factors"):
        BodyFitConfig(leg_factors=(0.4, 1.0))
    with pytest.raises(ValueError, match="frames"):
        BodyFitConfig(frames=1)
    with pytest.raises(ValueError, match="stance_repeats"):
        BodyFitConfig(stance_repeats=0)
    with pytest.raises(ValueError, match="stance_max_repeats"):
        BodyFitConfig(stance_repeats=3, stance_max_repeats=2)
    with pytest.raises(ValueError, match="stance_tie_nats"):
        BodyFitConfig(stance_tie_nats=-1.0)
    with pytest.raises(ValueError, match="no observations"):
        fit_leg_length(BodyDescription.default(), StartDescription(), lambda body: marker_likelihood(), [],
                       TrackerConfig())
