"""Variants of a motion-capture walk for test sequences: level floor, longer walks, speed and turns.

All functions work on points (F, P, 3) in the world frame (z up, m) at ``rate`` Hz, with the 13
markers (``MARKER_NAMES``) first, so that any other skeleton points (arms, head) move with them.

- ``level_floor``: CMU walks drift in height (07_01: the pelvis rises 8 cm over 3.6 m); the lowest
  foot point per frame, fitted by a straight line in time over its lower envelope, is made level, and
  then the floor is put ``FOOT_LINE_HEIGHT`` under the heel-toe line of a foot lying flat
  (``model.acclaim.flat_foot_frames``): the skeleton's heel and toe points lie inside the foot, ~3 cm over
  the sole, and dip that much lower only while the foot rolls (heel strike, toe-off: the lowest point is
  reached there), so a floor at the lowest point floated every flat foot ~3 cm over it.
- ``loop_to_duration``: repeats the walk from a frame that matches a later one (pose relative to the
  pelvis, and velocity), continuing the ground translation, until it lasts long enough.
- ``time_warp``: plays the walk faster or slower (a factor of 1.2 is 20 % faster: the same steps,
  taken more often).
- ``bend``: turns the walk's heading progressively by ``angle`` over ``[start, start + duration]`` s.
  People turn by pivoting on the stance foot, so the whole body is rotated about the current stance
  foot's ground contact (its lower end, heel or toe), which therefore stays put (no foot skate
  added); as the foot rolls, or the other heel strikes (``inference.gait_events.stance_from_heels``), the
  pivot moves with the contact and the transform stays continuous.
"""
from __future__ import annotations

import numpy as np

from awalker_tracker.inference.gait_events import stance_from_heels
from awalker_tracker.model.acclaim import flat_foot_frames
from awalker_tracker.model.body import MARKER_NAMES

_M = {n: i for i, n in enumerate(MARKER_NAMES)}
#: Height (m) of the heel-toe line over the floor while the foot lies flat: where ``level_floor`` puts the
#: floor, and how far under that line ``person_render`` draws the shoe's sole (CMU subject 7's walks: the
#: line stands 3.1-3.4 cm over the lowest foot point of the stride).
FOOT_LINE_HEIGHT = 0.033
FOOT_POINTS = {"left": [_M["left_heel"], _M["left_toe"]], "right": [_M["right_heel"], _M["right_toe"]]}


def _rotation_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(np.shape(angle) + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1], out[..., 2, 2] = c, -s, s, c, 1.0
    return out


def level_floor(points: np.ndarray, rate: float) -> np.ndarray:
    """Points with the floor under the feet moved to z = 0: level (a straight-line fit in time to the lowest
    foot point, using the frames in the lower quarter of its residuals), ``FOOT_LINE_HEIGHT`` under the
    heel-toe line of a foot lying flat (module docstring)."""
    feet = points[:, FOOT_POINTS["left"] + FOOT_POINTS["right"], 2].min(axis=1)
    t = np.arange(len(points)) / rate
    fit = np.polyfit(t, feet, 1)
    for _ in range(3):            # the swing phase lifts nothing below the foot: keep the lower envelope
        residual = feet - np.polyval(fit, t)
        low = residual <= np.percentile(residual, 25)
        fit = np.polyfit(t[low], feet[low], 1)
    out = points.copy()
    out[..., 2] -= np.polyval(fit, t)[:, None]
    markers = out[:, : len(MARKER_NAMES)]
    lines = [0.5 * (markers[flat, _M[f"{side}_heel"], 2] + markers[flat, _M[f"{side}_toe"], 2])
             for side in ("left", "right") if (flat := flat_foot_frames(markers, side)).any()]
    if lines:
        out[..., 2] += FOOT_LINE_HEIGHT - float(np.median(np.concatenate(lines)))
    return out


def _pose_distance(points: np.ndarray, i: np.ndarray, j: int, rate: float) -> np.ndarray:
    """Distance between the pelvis-relative poses (and velocities) of frames ``i`` and frame ``j``."""
    pelvis = points[:, _M["pelvis"]] * np.array([1.0, 1.0, 0.0])
    relative = points[:, : len(MARKER_NAMES)] - pelvis[:, None]
    velocity = np.gradient(points[:, : len(MARKER_NAMES)], axis=0) * rate
    return (np.linalg.norm(relative[i] - relative[j], axis=-1).mean(axis=-1)
            + 0.1 * np.linalg.norm(velocity[i] - velocity[j], axis=-1).mean(axis=-1))


def loop_to_duration(points: np.ndarray, rate: float, duration: float) -> np.ndarray:
    """At least ``duration`` s of walking: the stretch between two matching frames repeated, moved on
    by the ground distance it covers (the walk must be roughly straight)."""
    frames = int(round(duration * rate)) + 1
    if len(points) >= frames:
        return points[:frames]
    n = len(points)
    end = n - 1 - int(0.1 * n)                                   # a little before the end (end effects)
    candidates = np.arange(int(0.05 * n), end - int(0.6 * rate))  # the loop lasts at least 0.6 s
    start = int(candidates[np.argmin(_pose_distance(points, candidates, end, rate))])
    out = [points[: end + 1]]
    shift = points[end, _M["pelvis"]] - points[start, _M["pelvis"]]
    shift[2] = 0.0
    total = end + 1
    k = 1
    while total < frames:
        piece = points[start + 1: end + 1] + k * shift
        out.append(piece)
        total += len(piece)
        k += 1
    return np.concatenate(out)[:frames]


def time_warp(points: np.ndarray, factor: float) -> np.ndarray:
    """The walk played ``factor`` times as fast (linear interpolation in time; same frame rate)."""
    if factor <= 0:
        raise ValueError(f"time_warp: factor must be > 0, got {factor}")
    source = np.arange(len(points))
    times = np.arange(0.0, len(points) - 1 + 1e-9, factor)
    flat = points.reshape(len(points), -1)
    out = np.stack([np.interp(times, source, flat[:, k]) for k in range(flat.shape[1])], axis=1)
    return out.reshape(len(times), *points.shape[1:])


def pause(points: np.ndarray, rate: float, start: float, duration: float) -> np.ndarray:
    """The walk with the person standing still for ``duration`` s: from ``start`` s, the first frame
    within half a second whose higher foot is lowest (both feet on the floor, as when stopping with
    the feet apart) is held, then the walk goes on from there."""
    first = int(round(start * rate))
    window = slice(first, min(len(points), first + max(int(0.5 * rate), 1)))
    feet = points[window][:, FOOT_POINTS["left"] + FOOT_POINTS["right"], 2]
    left, right = (feet[:, : len(FOOT_POINTS["left"])].min(axis=1), feet[:, len(FOOT_POINTS["left"]):].min(axis=1))
    if feet.size == 0:
        raise ValueError(f"pause: the walk is shorter than {start:g} s")
    hold = first + int(np.argmin(np.maximum(left, right)))
    still = np.repeat(points[hold: hold + 1], int(round(duration * rate)), axis=0)
    return np.concatenate([points[: hold + 1], still, points[hold + 1:]])


def bend(points: np.ndarray, rate: float, angle: float, start: float, duration: float) -> np.ndarray:
    """The walk turned left by ``angle`` rad (right if negative), smoothly over ``duration`` s from ``start`` s,
    pivoting on the stance foot (module docstring)."""
    t = np.arange(len(points)) / rate
    ramp = np.clip((t - start) / max(duration, 1e-9), 0.0, 1.0)
    heading = angle * (0.5 - 0.5 * np.cos(np.pi * ramp))     # smooth start and end
    stance, _ = stance_from_heels(points[:, : len(MARKER_NAMES)], t)
    out = np.empty_like(points)
    pivot = offset = None          # T_f(p) = R(heading_f) (p - pivot_f) + offset_f
    for f in range(len(points)):
        foot = points[f, FOOT_POINTS["left" if stance[f] == 0 else "right"]]
        contact = foot[np.argmin(foot[:, 2])] * np.array([1.0, 1.0, 0.0])   # heel or toe, the lower
        if pivot is None:
            offset = contact.copy()
        else:   # the new pivot goes where the last frame's transform put it: continuous, and the contact stays
            offset = _rotation_z(heading[f - 1]) @ (contact - pivot) + offset
        pivot = contact
        out[f] = (points[f] - pivot) @ _rotation_z(heading[f]).T + offset
    return out


def facing(points: np.ndarray) -> np.ndarray:
    """(F,) heading (rad) the body faces: the hip line turned by +90 degrees."""
    across = points[:, _M["right_hip"], :2] - points[:, _M["left_hip"], :2]
    return np.arctan2(across[:, 0], -across[:, 1])
