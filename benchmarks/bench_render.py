"""Body model speed and the Table 1 sigma-unit evidence. Prints JSON.

    .venv/bin/python benchmarks/bench_render.py [--particles 5000] [--repeats 5]

- pose_body / sample_kinematics time for N particles (ms), also at 20000;
- render_labels and render_rgb time for one 640x480 frame (ms);
- "sigma_units": the kinematic prior (eq. 6, Table 1) simulated on the walker's cyclic gait
  (1.3 m/s, 0.7 m, 30 Hz, 2000 particles, 60 frames) with sigma read as deg/s^2 and as rad/s^2:
  median and 95th percentile per-frame change of each DOF (deg), heading drift after 2 s (deg),
  and the swing-knee peak (deg).
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from awalker_tracker.model import dynamics, cyclic_gaits
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.model.kinematics import (
    DOF_NAMES,
    KinematicConfig,
    initial_kinematics,
    pose_body,
    sample_kinematics,
)
from awalker_tracker.model.walker import LEFT
from awalker_tracker.vision.camera import Camera
from awalker_tracker.vision.render import render_labels

from awalker_tools.model_render import render_rgb

BODY = BodyDescription.default()
PARAMS = BODY.walker_params()


def walk(n: int, frames: int, dt: float):
    """Walker states on the 1.3 m/s, 0.7 m cyclic gait (with the heel strikes' events)."""
    table = cyclic_gaits.GaitTable.load()
    _, _, stiffness, impulse = table.lookup(1.3, 0.7)
    walker = cyclic_gaits.gait_initial_state(PARAMS, 1.3, 0.7, stance_leg=LEFT, table=table).take(np.zeros(n, np.intp))
    states, events, since = [walker], [None], None
    for _ in range(frames - 1):
        walker, ev = dynamics.advance(PARAMS, walker, stiffness, impulse, dt, time_since_strike=since)
        since = ev.time_since_strike
        states.append(walker)
        events.append(ev)
    return states, events


def timed(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * float(np.median(times))


def prior_statistics(sigma_unit: float, walkers, events, n: int) -> dict:
    config = KinematicConfig(sigma_unit=sigma_unit)
    rng = np.random.default_rng(0)
    kin = initial_kinematics(config, walkers[0], [0.0, 0.0], 0.0, n, rng, body=BODY, params=PARAMS)
    dofs = [kin.dofs()]
    for f in range(1, len(walkers)):
        kin = sample_kinematics(config, BODY, PARAMS, walkers[f - 1], walkers[f], events[f], kin, rng)
        dofs.append(kin.dofs())
    dofs = np.array(dofs)  # (F, N, 13)
    change = np.degrees(np.abs(np.diff(dofs, axis=0)))
    swing_knee = np.where(np.array([w.stance_leg for w in walkers]) == LEFT, dofs[..., 8], dofs[..., 7])
    return {
        "median_change_deg_per_frame": {k: round(float(np.median(change[..., i])), 3) for i, k in enumerate(DOF_NAMES)},
        "p95_change_deg_per_frame": {k: round(float(np.percentile(change[..., i], 95)), 3) for i, k in enumerate(DOF_NAMES)},
        "heading_drift_after_2s_deg_std": round(float(np.degrees(np.std(dofs[-1, :, 2] - dofs[0, :, 2]))), 2),
        "swing_knee_peak_deg_median": round(float(np.degrees(np.median(swing_knee.max(axis=0)))), 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    n = args.particles
    walkers, events = walk(n, 10, 1 / 30)
    config = KinematicConfig()
    rng = np.random.default_rng(1)
    kin = initial_kinematics(config, walkers[0], [0.0, 0.0], 0.0, n, rng, body=BODY, params=PARAMS)
    big_walkers, big_events = walk(20000, 2, 1 / 30)
    big_kin = initial_kinematics(config, big_walkers[0], [0.0, 0.0], 0.0, 20000, rng, body=BODY, params=PARAMS)
    one = pose_body(BODY, PARAMS, walkers[5].take(np.array([0])), kin.take(np.array([0])))
    camera = Camera.look_at("cam0", 640, 480, 525.0, np.array([0.0, -4.8, 1.4]), np.array([0.0, 0.0, 0.9]),
                            distortion=np.array([-0.04, 0.01, 0.0, 0.0, 0.0]))
    background = np.full((480, 640, 3), 120, np.uint8)
    render_labels(BODY, one.segments, camera)  # warm the pixel-ray cache
    labels, _ = render_labels(BODY, one.segments, camera)
    walkers60, events60 = walk(2000, 60, 1 / 30)
    result = {
        "particles": n,
        "pose_body_ms": round(timed(lambda: pose_body(BODY, PARAMS, walkers[5], kin), args.repeats), 2),
        "pose_body_20000_ms": round(timed(lambda: pose_body(BODY, PARAMS, big_walkers[1], big_kin), args.repeats), 2),
        "sample_kinematics_ms": round(timed(lambda: sample_kinematics(
            config, BODY, PARAMS, walkers[4], walkers[5], events[5], kin, rng), args.repeats), 2),
        "render_labels_640x480_ms": round(timed(lambda: render_labels(BODY, one.segments, camera), args.repeats), 2),
        "render_rgb_640x480_ms": round(timed(lambda: render_rgb(BODY, one.segments, camera, background), args.repeats), 2),
        "body_pixels": int(np.count_nonzero(labels >= 0)),
        "sigma_units": {
            "deg_per_s2 (chosen)": prior_statistics(np.pi / 180, walkers60, events60, 2000),
            "rad_per_s2": prior_statistics(1.0, walkers60, events60, 2000),
        },
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
