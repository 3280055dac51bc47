"""Gait analytics from a tracked (or true) walk: heel strikes, steps and their parameters.

A step ends at a heel strike: the frame where the stance leg changes to the other foot (the
walker's own event for the tracker's MAP trajectory, timed within the frame where the walker's
strike time is given; for marker data without stance labels, where a heel comes down after a
swing and stops: ``heel_strikes``; live, the MAP lineage's strikes at a lag: ``LineageSteps``).
Per step: time (s),
foot, ground position (the striking heel's xy, m; for marker data where that heel comes to rest,
``heel_at_rest``); step length = the displacement from the
previous strike along the walking direction (the stride from the same foot's previous strike,
else the step itself); step width = across it; step time, stride time (s), cadence
(steps/min) and speed (step length / step time, m/s).

Stance and swing: the walker's toe-off is an impulse at the other foot's heel strike, so each
foot stands from its own strike to the other foot's next one: stance is exactly half the stride
and there is no double support (people: about 60 % and 20 %). ``summary`` says so rather than
reporting a measured proportion.

Heel-strike time of a walker's step: a person's support passes from foot to foot over a double support (heel
strike to the other foot's toe-off), the walker's in one instant. Fitted to a person's images, the walker's
transfer falls within that double support; the tracker dates the heel strike half a double support before it
(``walker_strike_delay_s``; ``StepCounter(walker_strikes=True)``; the first step, with no step time yet, uses
``TYPICAL_STEP_TIME_S``). A double support lasts the step time less the swing time, and the swing time changes
less with the pace than the stance does: ``SWING_TIME_S`` + ``SWING_PER_STEP_TIME`` x the step time (0.42 s of a
1.1 s stride at 110 steps/min, stance 62 %; 0.6 s of a 2 s stride at 60 steps/min, stance 70 %: slow walkers
stand longer on both feet), so the delay is 0.3 x the step time - 0.1 s (0.065 s at 0.55 s steps, 0.2 s at 1 s).
The two constants were chosen on the development set's tuning subjects (``docs/tracking.md``, *Gait events*);
a step longer than ``LONGEST_STEP_TIME_S`` held a pause and counts as that long. Steps from heel markers
(``heel_strikes``) are not shifted.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from awalker_tracker.model.body import MARKER_NAMES
from awalker_tracker.model.walker import LEFT

_M = {n: i for i, n in enumerate(MARKER_NAMES)}
_FOOT = {0: ("left_heel", "left_toe"), 1: ("right_heel", "right_toe")}

SWING_TIME_S = 0.2             # s: a person's swing time at a step time of 0 (module docstring)
SWING_PER_STEP_TIME = 0.4      # the swing time's share of each second of step time
LONGEST_STEP_TIME_S = 1.2      # s, 50 steps/min: a longer step held a pause, and its double support is this one's
TYPICAL_STEP_TIME_S = 0.55     # s, 110 steps/min: the first step's, before one is measured


def walker_strike_delay_s(step_time_s: float) -> float:
    """How long (s) after a person's heel strike the walker's instant support transfer falls: half a double
    support, which lasts the step time (s) less the swing time (module docstring); 0 for steps shorter than
    the swing."""
    step = min(float(step_time_s), LONGEST_STEP_TIME_S)
    double_support = step - (SWING_TIME_S + SWING_PER_STEP_TIME * step)
    return max(0.5 * double_support, 0.0)


@dataclass(frozen=True)
class Step:
    """One step, ending at the heel strike of ``foot`` ("left"/"right") at ``time_s``."""

    index: int
    frame: int
    stamp_ns: int
    time_s: float                  # from the first frame of the track
    foot: str
    x: float                       # the striking heel, world m
    y: float
    step_length_m: float           # NaN for the first strike
    step_width_m: float            # NaN for the first two strikes
    step_time_s: float
    stride_time_s: float           # NaN until the same foot struck before
    cadence_steps_min: float
    speed_m_s: float


def heel_strikes(markers: np.ndarray, times_s: np.ndarray, contact_m: float = 0.03, swing_m: float = 0.05,
                 slow_m_s: float = 1.0) -> list[tuple[float, int, int]]:
    """Heel strikes of marker data without stance labels (e.g. motion capture) as gait labs time them from
    markers (``../shared/design/GAIT.md``): after a swing (the heel ``swing_m`` above its own low level, the
    5th percentile of its height over the walk, so that an uneven capture floor does not matter), the first
    frame where the heel is within ``contact_m`` of that level *and* its speed over the ground has dropped
    below ``slow_m_s``, the time interpolated where the speed crossed it. Height alone fires ~0.08 s early:
    the heel skims the last centimetres still moving forward at 3-4 m/s. Markers (F, 13, 3), times (F,) s;
    returns (time s, first frame at or after it, foot LEFT 0 / RIGHT 1) in time order."""
    heels = markers[:, [_M["left_heel"], _M["right_heel"]]]
    height = heels[..., 2] - np.percentile(heels[..., 2], 5, axis=0)
    times = np.asarray(times_s, float)
    speed = (np.linalg.norm(np.gradient(heels[..., :2], times, axis=0), axis=2) if len(times) > 1
             else np.zeros(height.shape))
    events = []
    for foot in (0, 1):
        swinging = False
        for f in range(len(times)):
            if height[f, foot] > swing_m:
                swinging = True
            elif swinging and height[f, foot] < contact_m and speed[f, foot] < slow_m_s:
                when = times[f]
                before = speed[f - 1, foot] if f > 0 else 0.0
                if before > slow_m_s:          # the heel slowed down within this frame's period
                    when = times[f - 1] + (before - slow_m_s) / (before - speed[f, foot]) * (times[f] - times[f - 1])
                events.append((float(when), f, foot))
                swinging = False
    return sorted(events)


def stance_from_heels(markers: np.ndarray, times_s: np.ndarray, **strike_options: float) -> tuple[np.ndarray, np.ndarray]:
    """(stance (F,) LEFT 0 / RIGHT 1, strike fraction (F,)) of marker data from its ``heel_strikes``: the stance
    passes to a foot at the first frame at or after its strike, which happened that share of the period before
    the frame (NaN where no strike; the ``strike_fraction`` of ``steps``). Before the first strike: the foot
    whose heel is lower."""
    times = np.asarray(times_s, float)
    heels = markers[:, [_M["left_heel"], _M["right_heel"]], 2]
    ground = np.percentile(heels, 5, axis=0)
    stance = np.full(len(markers), 0 if heels[0, 0] - ground[0] <= heels[0, 1] - ground[1] else 1, np.int8)
    fraction = np.full(len(markers), np.nan)
    for when, f, foot in heel_strikes(markers, times, **strike_options):
        stance[f:] = foot
        if f > 0 and times[f - 1] < when < times[f]:
            fraction[f] = (when - times[f - 1]) / (times[f] - times[f - 1])
    return stance, fraction


class StepCounter:
    """Steps from heel strikes as they come (online: the tracker's events while it runs); ``steps``
    feeds it a whole walk. Times in s, positions world xy (m)."""

    def __init__(self, walker_strikes: bool = False) -> None:
        self.walker_strikes = bool(walker_strikes)     # the walker's support transfers: dated back to the heel's
        self.strikes: list[tuple[float, np.ndarray]] = []      # (time, heel xy) of every strike so far

    def add(self, frame: int, stamp_ns: int, time_s: float, foot: int, heel_xy: np.ndarray) -> Step:
        """The step that ends with this strike of ``foot`` (LEFT 0 / RIGHT 1) at ``time_s``; for the walker's
        strikes its reported time is the heel strike, ``walker_strike_delay_s`` of the step time before (module
        docstring)."""
        heel = np.asarray(heel_xy, float)[:2]
        k = len(self.strikes)
        length = width = step_time = stride_time = cadence = speed = float("nan")
        if k >= 1:
            previous_time, previous = self.strikes[-1]
            step = heel - previous
            along = heel - self.strikes[-2][1] if k >= 2 else step
            direction = along / max(float(np.linalg.norm(along)), 1e-9)
            length = float(step @ direction)
            if k >= 2:    # across the stride direction (the step's own direction has no width)
                width = float(abs(step[0] * direction[1] - step[1] * direction[0]))
                stride_time = float(time_s - self.strikes[-2][0])
            step_time = float(time_s - previous_time)
            cadence = 60.0 / step_time if step_time > 0 else float("nan")
            speed = length / step_time if step_time > 0 else float("nan")
        self.strikes.append((float(time_s), heel))
        heel_strike = time_s - (walker_strike_delay_s(step_time if step_time > 0 else TYPICAL_STEP_TIME_S)
                                if self.walker_strikes else 0.0)
        return Step(k, int(frame), int(stamp_ns), float(heel_strike), "left" if foot == LEFT else "right",
                    float(heel[0]), float(heel[1]), length, width, step_time, stride_time, cadence, speed)


def steps(frames: np.ndarray, stamps_ns: np.ndarray, markers: np.ndarray, stance_leg: np.ndarray,
          strike_fraction: np.ndarray | None = None, walker_strikes: bool = False,
          at_rest: bool = False) -> list[Step]:
    """The steps of a walk: markers (F, 13, 3) in MARKER_NAMES order, stance leg per frame (0/1) and,
    if known, when in the period before each frame the strike happened (0-1; NaN: at the frame);
    ``walker_strikes`` as for ``StepCounter``. A step's position is the striking heel's at the strike, or
    with ``at_rest`` (marker data, strikes from ``stance_from_heels``) where that heel comes to rest
    (``heel_at_rest``)."""
    stance = np.asarray(stance_leg).astype(int)
    t = (np.asarray(stamps_ns, np.int64) - int(stamps_ns[0])) * 1e-9
    fraction = np.full(len(stance), np.nan) if strike_fraction is None else np.asarray(strike_fraction, float)
    counter = StepCounter(walker_strikes)
    heels = markers[:, [_M[_FOOT[0][0]], _M[_FOOT[1][0]]], :2]          # (F, 2 feet, xy)
    # over-the-ground speed of each heel (central differences), once for all strikes
    heel_speed = np.linalg.norm(np.gradient(heels, t, axis=0), axis=2) if at_rest and len(t) >= 2 else None
    walk = []
    for f in range(1, len(stance)):
        if stance[f] == stance[f - 1]:
            continue
        foot = int(stance[f])
        where = (heels[f, foot] if heel_speed is None else
                 heel_at_rest(heels[:, foot], heel_speed[:, foot], stance, f))
        walk.append(counter.add(int(frames[f]), int(stamps_ns[f]), strike_time(t, fraction, f), foot, where))
    return walk


def strike_time(times_s: np.ndarray, strike_fraction: np.ndarray, frame: int) -> float:
    """When (s) the strike seen at ``frame`` happened: during the period from the frame before, that share of it
    (``strike_fraction``; NaN: at the frame)."""
    share = strike_fraction[frame]
    return float(times_s[frame - 1] + share * (times_s[frame] - times_s[frame - 1]) if np.isfinite(share)
                 else times_s[frame])


def heel_at_rest(heel_xy: np.ndarray, heel_speed: np.ndarray, stance: np.ndarray, strike: int) -> np.ndarray:
    """Where a heel that struck at frame ``strike`` comes to rest (xy, m): its position (F, 2) at its slowest
    frame (``heel_speed`` (F,), m/s over the ground) while its foot stands, from the strike to the other foot's
    next strike. A heel found striking by its height (``stance_from_heels``) may still be sliding in: motion
    capture's heel skims within ``contact_m`` of the floor for a few frames before it stops (CMU 07_02 at
    30 Hz: found at 4 m/s, 0.33 m short of where it stops)."""
    end = strike + 1
    while end < len(stance) and stance[end] == stance[strike]:
        end += 1
    return heel_xy[strike + int(np.argmin(heel_speed[strike:end]))]


#: gait.json's ``sides_note`` when which foot is which was not observed (``summary(sides_known=False)``).
SIDES_NOTE = ("one camera and no stance leg in the start: which foot is the left one was chosen from weak "
              "evidence (seen from one side the near and the far leg look alike; `awalker track` weighs the two "
              "in its first pass), so the feet may be named the other way round: the left/right columns and the "
              "symmetry swapped (real-walks benchmark, one camera, automatic start, tracker seeds 0-4: 6 of 60 "
              "runs); name the standing foot in a start description (stance_leg) or add a camera to be sure")


class LineageSteps:
    """Steps as the live tracker publishes them: the heel strikes of the MAP lineage (the trajectory gait.csv is
    made of), each taken once the lineage has carried it for a lag (``TrackerConfig.step_lag_s``): particle
    lineages coalesce within a few frames, so the lineage that far back is, most of the time, the one the whole
    track ends with, but for where in a few frames each strike falls: from frame to frame the lineage's strike
    moves by a frame or two either way, so each call looks for strikes from the last one taken on, not from the
    frame the last call reached. Fed the lineage's latest frames each frame (``add``). A strike of the foot that
    struck last is that strike again (the MAP moved to a particle whose strike fell a frame later, or the legs
    were renamed), not a step."""

    def __init__(self) -> None:
        self.counter = StepCounter(walker_strikes=True)
        self.taken_until = 0                  # the frame (push index) up to which the strikes were looked for
        self.last_strike = 0                  # the frame (push index) of the last strike taken
        self.foot: int | None = None          # the foot that struck last

    def add(self, first: int, until: int, frames: np.ndarray, stamps_ns: np.ndarray, heels_xy: np.ndarray,
            stance_leg: np.ndarray, strike_fraction: np.ndarray, in_view: np.ndarray) -> list[Step]:
        """The steps of the frames after ``last_strike`` up to ``until`` (push indices), from a lineage window that
        starts at push index ``first``: per frame its index, stamp (ns; the steps are timed in s of its clock),
        heels (W, 2 feet, xy m), stance leg, strike fraction (``steps``) and whether the person was in view. A step
        whose strike frame had the person out of view is counted (the next step's length is from it) but not
        returned."""
        times_s = np.asarray(stamps_ns, np.int64) * 1e-9
        walk = []
        for f in range(max(self.last_strike, first) + 1, until + 1):
            i = f - first
            foot = int(stance_leg[i])
            if foot == int(stance_leg[i - 1]) or foot == self.foot:
                continue
            self.foot, self.last_strike = foot, f
            step = self.counter.add(int(frames[i]), int(stamps_ns[i]), strike_time(times_s, strike_fraction, i),
                                    foot, heels_xy[i, foot])
            if in_view[i]:
                walk.append(step)
        self.taken_until = max(self.taken_until, until)
        return walk


def summary(walk: list[Step], sides_known: bool = True) -> dict[str, object]:
    """Medians over steps, left/right symmetry (left / right medians) and the stance/swing note; with
    ``sides_known`` False (one camera, no stance leg given) also ``sides_note``: left and right may be swapped."""
    def median(key: str, foot: str | None = None) -> float | None:
        values = [getattr(s, key) for s in walk if (foot is None or s.foot == foot) and np.isfinite(getattr(s, key))]
        return float(np.median(values)) if values else None

    out: dict[str, object] = {"steps": len(walk)}
    for key in ("step_length_m", "step_width_m", "step_time_s", "stride_time_s", "cadence_steps_min", "speed_m_s"):
        out[key] = median(key)
    symmetry = {}
    for key in ("step_length_m", "step_time_s"):
        left, right = median(key, "left"), median(key, "right")
        symmetry[key] = left / right if left is not None and right else None
    out["symmetry_left_over_right"] = symmetry
    out["stance_fraction"] = 0.5
    out["double_support_fraction"] = 0.0
    out["stance_note"] = ("impulsive toe-off: each foot stands from its heel strike to the other foot's next one, "
                          "so stance is half the stride and there is no double support (people: ~60 % and ~20 %); "
                          "the tracker dates each heel strike half a person's double support "
                          f"({(1 - SWING_PER_STEP_TIME) / 2:g} x the step time - {SWING_TIME_S / 2:g} s) before its "
                          "walker's instant support transfer, where a person's heel comes down")
    if not sides_known:
        out["sides_note"] = SIDES_NOTE
    return out


def as_rows(walk: list[Step]) -> list[dict[str, object]]:
    """Steps as dicts (CSV rows)."""
    return [asdict(s) for s in walk]


def compare(estimate: list[Step], truth: list[Step], window_s: float = 0.25) -> dict[str, object]:
    """The estimate's heel strikes against the truth's (``../shared/design/GAIT.md``): each true strike matched one
    to one to an estimated strike of the same foot within ``window_s``, nearest pairs first; matched, missed
    (true strikes left over) and extra (estimated ones left over) counts; of the missed, how many match an
    unmatched strike of the other foot (left and right swapped); the median size and the median signed timing
    error (s, later than the truth > 0), the median step length error (m) and the median distance between where
    the feet came down (m, the footprints: the estimate's contacts against the true ones) of the matched strikes;
    the median speeds' difference (m/s)."""
    pairs = sorted((abs(e.time_s - t.time_s), i, j) for i, t in enumerate(truth) for j, e in enumerate(estimate)
                   if e.foot == t.foot and abs(e.time_s - t.time_s) <= window_s)
    matched: dict[int, int] = {}
    used: set[int] = set()
    for _, i, j in pairs:
        if i not in matched and j not in used:
            matched[i] = j
            used.add(j)
    timing = [estimate[j].time_s - truth[i].time_s for i, j in matched.items()]
    footprint = [float(np.hypot(estimate[j].x - truth[i].x, estimate[j].y - truth[i].y)) for i, j in matched.items()]
    length = [estimate[j].step_length_m - truth[i].step_length_m for i, j in matched.items()
              if np.isfinite(estimate[j].step_length_m) and np.isfinite(truth[i].step_length_m)]
    spare = [j for j in range(len(estimate)) if j not in used]
    swapped = 0
    for i, t in enumerate(truth):
        if i in matched:
            continue
        other = [j for j in spare if estimate[j].foot != t.foot and abs(estimate[j].time_s - t.time_s) <= window_s]
        if other:
            spare.remove(min(other, key=lambda j: abs(estimate[j].time_s - t.time_s)))
            swapped += 1
    est_speed, true_speed = summary(estimate)["speed_m_s"], summary(truth)["speed_m_s"]
    return {
        "true_strikes": len(truth), "estimated_strikes": len(estimate), "matched_strikes": len(matched),
        "missed_strikes": len(truth) - len(matched), "extra_strikes": len(estimate) - len(matched),
        "swapped_strikes": swapped,
        "timing_error_s_median": float(np.median(np.abs(timing))) if timing else None,
        "timing_bias_s_median": float(np.median(timing)) if timing else None,     # > 0: reported late
        "step_length_error_m_median": float(np.median(np.abs(length))) if length else None,
        "footprint_error_m_median": float(np.median(footprint)) if footprint else None,
        "speed_error_m_s": (abs(est_speed - true_speed) if est_speed is not None and true_speed is not None
                            else None),
    }
