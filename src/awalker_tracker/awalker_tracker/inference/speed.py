"""Walking speed: the horizontal pelvis displacement per frame, averaged over about one step.

The one definition, for the tracker and its evaluation alike: each frame the speed moves towards the
frame's horizontal pelvis displacement over its duration (m/s) by dt / ``SPEED_TIME_CONSTANT_S`` (an
exponential moving average, causal, so it lags a change of pace by about a time constant). The tracker
keeps one per particle (``inference.filter_model``: ``TrackerModel.transition``) and reports their weighted
mean per frame; the evaluation (``awalker eval``, the accuracy tests) computes the truth's the same way
with ``walking_speed``, so that the two are compared like with like.
"""
from __future__ import annotations

import numpy as np

#: s: the averaging time constant, about one step.
SPEED_TIME_CONSTANT_S = 0.5


def update_speed(speed: np.ndarray | float, moved_m: np.ndarray | float, dt_s: float,
                 time_constant_s: float = SPEED_TIME_CONSTANT_S) -> np.ndarray | float:
    """The walking speed (m/s) after one more frame of ``dt_s`` seconds in which the pelvis moved ``moved_m``
    metres horizontally, from the speed before it (arrays: one per walker)."""
    gain = min(1.0, dt_s / time_constant_s)
    return speed + gain * (moved_m / dt_s - speed)


def walking_speed(pelvis_xy: np.ndarray, stamps_ns: np.ndarray, time_constant_s: float = SPEED_TIME_CONSTANT_S,
                  initial: float | None = None) -> np.ndarray:
    """Walking speed (F,) m/s of a pelvis track: horizontal positions (F, 2) m at strictly increasing stamps
    (F,) ns, ``update_speed`` frame after frame from ``initial`` at the first frame (None: the mean per-frame
    speed over the first time constant, as a start description states the speed the person walks at)."""
    xy = np.asarray(pelvis_xy, float)
    stamps_s = np.asarray(stamps_ns, np.int64) * 1e-9
    if xy.ndim != 2 or xy.shape[1] != 2 or len(stamps_s) != len(xy):
        raise ValueError(f"walking_speed: expected positions (F, 2) and stamps (F,), got {xy.shape} and "
                         f"{stamps_s.shape}")
    speed = np.full(len(xy), np.nan)
    if len(xy) < 2:
        return speed
    dt = np.diff(stamps_s)
    if np.any(dt <= 0):
        raise ValueError("walking_speed: stamps must increase strictly")
    moved = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    if initial is None:
        first = max(1, int(np.searchsorted(np.cumsum(dt), time_constant_s, side="right")))
        initial = float(np.sum(moved[:first]) / np.sum(dt[:first]))
    speed[0] = initial
    for i in range(1, len(xy)):
        speed[i] = update_speed(speed[i - 1], moved[i - 1], float(dt[i - 1]), time_constant_s)
    return speed
