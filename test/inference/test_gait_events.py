"""Gait analytics (inference/gait_events.py) on walks with known heel strikes and step geometry."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from awalker_tracker.inference import gait_events
from awalker_tracker.model.body import MARKER_NAMES

M = {n: i for i, n in enumerate(MARKER_NAMES)}
RATE = 30.0


def stylised_walk(step_length=0.7, step_frames=15, width=0.2, steps=6, heading=0.4):
    """Markers of a walk along ``heading``: during step k (``step_frames`` frames) foot k % 2 (left first)
    stands at k * ``step_length`` ahead, ``width`` / 2 to its side; the other heel is 0.1 m up. Returns
    markers, stance (0 left / 1 right) and the frames of the heel strikes."""
    frames = (steps + 1) * step_frames
    forward = np.array([np.cos(heading), np.sin(heading)])
    left_dir = np.array([-forward[1], forward[0]])
    markers = np.zeros((frames, len(MARKER_NAMES), 3))
    stance = np.zeros(frames, np.int8)

    def spot(k: int) -> np.ndarray:
        return k * step_length * forward + (0.5 if k % 2 == 0 else -0.5) * width * left_dir

    for f in range(frames):
        k = f // step_frames
        stance[f] = k % 2
        for foot, planted in ((k % 2, k), (1 - k % 2, k + 1)):      # the swing foot is over its next spot
            side = "left" if foot == 0 else "right"
            markers[f, M[f"{side}_heel"], :2] = spot(planted)
            markers[f, M[f"{side}_toe"], :2] = spot(planted) + 0.2 * forward
            markers[f, M[f"{side}_heel"], 2] = 0.0 if planted == k else 0.1
            markers[f, M[f"{side}_toe"], 2] = 0.0 if planted == k else 0.1
    return markers, stance, [k * step_frames for k in range(1, steps + 1)]


def test_heel_strikes_and_steps_of_a_known_walk():
    markers, stance, strikes = stylised_walk()
    frames = np.arange(len(markers))
    found, fraction = gait_events.stance_from_heels(markers, frames / RATE)
    assert np.array_equal(found, stance) and np.isnan(fraction).all()     # the heels land at rest on the frames
    stamps = 1_000_000_000 + np.round(frames * 1e9 / RATE).astype(np.int64)
    walk = gait_events.steps(frames, stamps, markers, found)
    assert [s.frame for s in walk] == strikes
    assert [s.foot for s in walk] == ["right", "left"] * 3
    measured = walk[1:]
    # the second strike has no stride yet to give the direction: its step is measured along itself
    assert walk[1].step_length_m == pytest.approx(np.hypot(0.7, 0.2))
    assert all(s.step_length_m == pytest.approx(0.7, abs=1e-6) for s in walk[2:])
    assert all(s.step_width_m == pytest.approx(0.2, abs=1e-6) for s in walk[2:])
    assert all(s.step_time_s == pytest.approx(0.5, abs=1e-6) for s in measured)
    assert all(s.cadence_steps_min == pytest.approx(120.0) for s in measured)
    assert all(s.speed_m_s == pytest.approx(1.4) for s in walk[2:])
    summary = gait_events.summary(walk)
    assert summary["step_length_m"] == pytest.approx(0.7) and summary["stride_time_s"] == pytest.approx(1.0)
    assert summary["symmetry_left_over_right"]["step_length_m"] == pytest.approx(1.0)
    assert summary["stance_fraction"] == 0.5 and "impulsive" in summary["stance_note"]
    assert "0.3 x the step time - 0.1 s" in summary["stance_note"]
    assert "sides_note" not in summary
    assert gait_events.summary(walk, sides_known=False)["sides_note"] == gait_events.SIDES_NOTE


def test_a_heel_skimming_in_strikes_where_it_has_slowed_and_its_step_lies_where_it_stops():
    """Motion capture's heel skims the last centimetres over the floor still moving forward at several m/s: the
    strike is where it is both low and slow (GAIT.md; height alone fires ~0.08 s early), timed where its speed
    crossed 1 m/s, and the step lies where the heel stops."""
    markers, stance, strikes = stylised_walk(heading=0.0)
    sliding = markers.copy()
    for strike in strikes:
        side = "left" if stance[strike] == 0 else "right"
        heel = M[f"{side}_heel"]
        rest = markers[strike, heel, 0]
        # 0.6 and 0.45 m short while coming down, then low and sliding in: 0.3, 0.15, 0.05 m short
        for lag, (short, height) in enumerate(((0.6, 0.1), (0.45, 0.06), (0.3, 0.01), (0.15, 0.01), (0.05, 0.01)), -2):
            sliding[strike + lag, heel, 0] = rest - short
            sliding[strike + lag, heel, 2] = height
    frames = np.arange(len(markers))
    stamps = 1_000_000_000 + np.round(frames * 1e9 / RATE).astype(np.int64)
    found, fraction = gait_events.stance_from_heels(sliding, frames / RATE)
    # central differences: 4.5, 3.75, 2.25 then 0.75 m/s three frames after the heel came low: 1 m/s crossed
    # 0.83 of the way into that frame's period
    slowed = [f + 3 for f in strikes]
    assert [int(f) for f in np.flatnonzero(np.diff(found)) + 1] == slowed
    np.testing.assert_allclose(fraction[slowed], (2.25 - 1.0) / (2.25 - 0.75))
    at_rest = gait_events.steps(frames, stamps, sliding, found, fraction, at_rest=True)
    rest_x = [markers[f, M["left_heel" if stance[f] == 0 else "right_heel"], 0] for f in strikes]
    assert [s.x for s in at_rest] == pytest.approx(rest_x, abs=1e-9)
    assert all(s.step_length_m == pytest.approx(0.7, abs=1e-6) for s in at_rest[2:])
    assert [s.time_s for s in at_rest] == pytest.approx([(f + 2 + 0.8333333) / RATE for f in strikes], abs=1e-6)


def test_asymmetry_and_comparison_with_the_truth():
    markers, stance, _ = stylised_walk()
    frames = np.arange(len(markers))
    stamps = 1_000_000_000 + np.round(frames * 1e9 / RATE).astype(np.int64)
    truth = gait_events.steps(frames, stamps, markers, stance)
    late = np.roll(stance, 2)                    # the estimate sees every strike 2 frames late
    late[:2] = stance[0]
    shifted = markers.copy()
    shifted[:, :, :2] += np.array([0.05, 0.0])   # and 5 cm off (all markers: step lengths unchanged)
    estimate = gait_events.steps(frames, stamps, shifted, late)
    result = gait_events.compare(estimate, truth)
    assert result["matched_strikes"] == result["true_strikes"] == 6
    assert result["timing_error_s_median"] == pytest.approx(2 / RATE, abs=1e-6)
    assert result["step_length_error_m_median"] == pytest.approx(0.0, abs=0.03)
    assert result["footprint_error_m_median"] == pytest.approx(0.05, abs=1e-9)
    assert result["speed_error_m_s"] == pytest.approx(0.0, abs=0.1)
    # a limp: right steps shorter than left ones
    limp = markers.copy()
    right = [M["right_heel"], M["right_toe"]]
    limp[:, right, :2] -= 0.1 * np.array([np.cos(0.4), np.sin(0.4)])
    summary = gait_events.summary(gait_events.steps(frames, stamps, limp, stance))
    assert summary["symmetry_left_over_right"]["step_length_m"] == pytest.approx(0.8 / 0.6, rel=0.02)


def test_strikes_are_timed_within_the_frame_when_the_walker_says_when():
    """The stance changes at the first frame after a strike; the walker's strike fraction (of the period
    before that frame) moves the step's time back into that period, and so its step time and cadence."""
    markers, stance, strikes = stylised_walk()
    frames = np.arange(len(markers))
    stamps = 1_000_000_000 + np.round(frames * 1e9 / RATE).astype(np.int64)
    fraction = np.full(len(frames), np.nan)
    fraction[strikes[0]] = 0.25
    fraction[strikes[1]] = 0.75
    walk = gait_events.steps(frames, stamps, markers, stance, fraction)
    on_frames = gait_events.steps(frames, stamps, markers, stance)
    assert [s.frame for s in walk] == [s.frame for s in on_frames] == strikes
    assert walk[0].time_s == pytest.approx((strikes[0] - 1 + 0.25) / RATE, abs=1e-9)
    assert walk[1].time_s == pytest.approx((strikes[1] - 1 + 0.75) / RATE, abs=1e-9)
    assert walk[2].time_s == pytest.approx(strikes[2] / RATE, abs=1e-9)        # NaN: at the frame
    assert walk[1].step_time_s == pytest.approx(0.5 + 0.5 / RATE, abs=1e-9)


def test_a_persons_double_support_grows_as_the_steps_slow():
    """Half a double support, the walker's strike's delay: the step time less the swing time (0.2 s + 0.4 x the
    step time), halved. At 110 steps/min (0.545 s steps) a person stands on both feet 10-12 % of the stride each
    time, as gait labs report for normal walking (stance about 62 %); at 60 steps/min (1 s) 20 % (stance 70 %);
    none for steps as short as the swing; a step that held a pause counts as 1.2 s."""
    delay = gait_events.walker_strike_delay_s
    assert 0.10 <= 2 * delay(0.545) / (2 * 0.545) <= 0.12
    assert 2 * delay(1.0) / 2.0 == pytest.approx(0.20)
    assert delay(1.0) == pytest.approx(0.3 * 1.0 - 0.1)
    assert delay(0.3) == 0.0 and delay(1 / 3) == pytest.approx(0.0, abs=1e-12)
    assert delay(5.0) == delay(gait_events.LONGEST_STEP_TIME_S) == pytest.approx(0.26)
    times = np.linspace(0.3, 1.5, 25)
    assert np.all(np.diff([delay(t) for t in times]) >= 0.0)


def test_the_walkers_strike_is_dated_early_by_half_a_double_support():
    """The walker passes support from foot to foot in one instant, a person over a double support: the heel
    struck half a double support (``walker_strike_delay_s`` of the step time) before the walker's strike. Step
    times and lengths are the walker's; steps from heel markers are not shifted."""
    markers, stance, strikes = stylised_walk()
    frames = np.arange(len(markers))
    stamps = 1_000_000_000 + np.round(frames * 1e9 / RATE).astype(np.int64)
    plain = gait_events.steps(frames, stamps, markers, stance)
    walker = gait_events.steps(frames, stamps, markers, stance, walker_strikes=True)
    delay = gait_events.walker_strike_delay_s(0.5)
    assert delay == pytest.approx(0.05)
    # the first step has no step time yet: a typical one (0.55 s)
    first = gait_events.walker_strike_delay_s(gait_events.TYPICAL_STEP_TIME_S)
    assert walker[0].time_s == pytest.approx(plain[0].time_s - first)
    assert all(w.time_s == pytest.approx(p.time_s - delay) for w, p in zip(walker[1:], plain[1:]))
    assert [w.step_time_s for w in walker[1:]] == pytest.approx([p.step_time_s for p in plain[1:]])
    assert [w.step_length_m for w in walker[1:]] == pytest.approx([p.step_length_m for p in plain[1:]])
    # against heel-marker truth the walker's events are now on time but for the shift itself
    result = gait_events.compare(walker, plain)
    assert result["timing_error_s_median"] == pytest.approx(delay, abs=1e-6)


def test_strikes_are_matched_one_to_one_and_swapped_feet_are_counted():
    """GAIT.md's scoring: each true strike matched once to an estimated strike of the same foot within 0.25 s;
    the rest are missed or extra, and a missed strike met by the other foot's counts as swapped."""
    markers, stance, _ = stylised_walk()
    frames = np.arange(len(markers))
    stamps = 1_000_000_000 + np.round(frames * 1e9 / RATE).astype(np.int64)
    truth = gait_events.steps(frames, stamps, markers, stance)
    doubled = sorted(truth + [replace(s, time_s=s.time_s + 0.1) for s in truth[:2]], key=lambda s: s.time_s)
    result = gait_events.compare(doubled, truth)
    assert (result["matched_strikes"], result["missed_strikes"], result["extra_strikes"]) == (6, 0, 2)
    assert result["timing_error_s_median"] == pytest.approx(0.0)
    swapped = [replace(s, foot="left" if s.foot == "right" else "right") for s in truth]
    result = gait_events.compare(swapped, truth)
    assert (result["matched_strikes"], result["missed_strikes"], result["swapped_strikes"]) == (0, 6, 6)


def lineage_window(stance: list[int], first: int = 0):
    """A lineage window's per-frame arrays from frame ``first`` on (LineageSteps.add's, and the stamps' times in s):
    30 Hz stamps, the left heel at x = 0 and the right at x = 0.7 m, every strike halfway through its frame's
    period, the person in view."""
    n = len(stance) - first
    frames = np.arange(first, len(stance))
    stamps = 1_000_000_000 + np.round(frames * 1e9 / RATE).astype(np.int64)
    heels = np.zeros((n, 2, 2))
    heels[:, 1, 0] = 0.7
    return (first, frames, stamps, stamps * 1e-9, heels, np.asarray(stance[first:]), np.full(n, 0.5),
            np.ones(n, bool))


def test_the_live_steps_are_the_lineages_strikes_taken_once():
    """LineageSteps: fed the lineage frame by frame, each strike is taken once, when the frames up to it are settled
    (``until``), timed where the walker struck less its strike delay, and they are the steps ``steps`` finds in
    the whole lineage."""
    stance = [0] * 10 + [1] * 16 + [0] * 16 + [1] * 6
    live = gait_events.LineageSteps()
    taken = []
    for until in range(len(stance)):
        first, frames, stamps, times, heels, legs, fraction, in_view = lineage_window(stance, max(0, until - 20))
        taken += [(until, s) for s in live.add(first, until, frames, stamps, heels, legs, fraction, in_view)]
    assert [(u, s.frame, s.foot) for u, s in taken] == [(10, 10, "right"), (26, 26, "left"), (42, 42, "right")]
    _, frames, stamps, times, heels, legs, fraction, _ = lineage_window(stance)
    markers = np.zeros((len(stance), len(MARKER_NAMES), 3))
    markers[:, MARKER_NAMES.index("right_heel"), 0] = 0.7
    whole = gait_events.steps(frames, stamps, markers, legs, fraction, walker_strikes=True)
    assert [(s.frame, s.foot, s.x) for _, s in taken] == [(s.frame, s.foot, s.x) for s in whole]
    np.testing.assert_allclose([s.step_length_m for _, s in taken], [s.step_length_m for s in whole])
    delay = gait_events.walker_strike_delay_s
    assert taken[0][1].time_s == pytest.approx(times[9] + 0.5 / RATE - delay(gait_events.TYPICAL_STEP_TIME_S))
    assert taken[1][1].time_s - times[0] == pytest.approx(whole[1].time_s)


def test_a_strike_the_lineage_moves_later_is_no_second_step():
    """Once a strike is taken, a later lineage whose strike of the same foot falls a frame later (the MAP moved to
    another particle) adds no step; a strike while the person was out of view is counted, not returned."""
    live = gait_events.LineageSteps()
    first, frames, stamps, times, heels, legs, fraction, in_view = lineage_window([0] * 10 + [1] * 10)
    assert [s.frame for s in live.add(first, 12, frames, stamps, heels, legs, fraction, in_view)] == [10]
    first, frames, stamps, times, heels, legs, fraction, in_view = lineage_window([0] * 11 + [1] * 9 + [0] * 5)
    assert live.add(first, 18, frames, stamps, heels, legs, fraction, in_view) == []
    in_view[20] = False
    assert live.add(first, 24, frames, stamps, heels, legs, fraction, in_view) == []
    assert live.counter.strikes[-1][0] == pytest.approx(times[19] + 0.5 / RATE)      # counted
    back = [0] * 11 + [1] * 9 + [0] * 10 + [1] * 5
    first, frames, stamps, times, heels, legs, fraction, in_view = lineage_window(back)
    (step,) = live.add(first, 34, frames, stamps, heels, legs, fraction, in_view)
    assert (step.frame, step.foot, step.index) == (30, "right", 2)


def test_a_strike_the_lineage_moves_earlier_is_still_taken():
    """The lineage's strike moves by a frame or two as the particles' lineages coalesce: a strike that lay after the
    frames looked at and then moves back into them is taken when it is next seen."""
    live = gait_events.LineageSteps()
    first, frames, stamps, times, heels, legs, fraction, in_view = lineage_window([0] * 12 + [1] * 8)
    assert live.add(first, 11, frames, stamps, heels, legs, fraction, in_view) == []
    first, frames, stamps, times, heels, legs, fraction, in_view = lineage_window([0] * 10 + [1] * 10)
    assert [s.frame for s in live.add(first, 12, frames, stamps, heels, legs, fraction, in_view)] == [10]
