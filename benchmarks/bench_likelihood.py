"""Image likelihood evaluations per second: N = 5000 and 20000 states, 1 and 3 cameras (640x480,
default features: 4x downsampled maps, 16 px flow cells). Prints JSON; ``ms_per_camera`` is the
figure to compare with the issue's target (20000 states in <= 30 ms per camera); wall-clock
minimum over repeats, plus the process CPU time (less sensitive to other jobs on the host;
the likelihood is single-threaded: a serial numba loop).

    .venv/bin/python benchmarks/bench_likelihood.py [--repeats 3]

States: the rendered walker's pose with its joints, position and heading jittered.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test" / "vision"))
from vision_scene import (  # noqa: E402
    BODY,
    GROUPS,
    background_image,
    front_camera,
    noisy,
    perturbed,
    render_frames,
    side_camera,
    stacked,
    walking_poses,
)

from awalker_tracker.model.body import BodySegments  # noqa: E402
from awalker_tracker.vision.camera import Camera  # noqa: E402
from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor  # noqa: E402
from awalker_tracker.vision.likelihood import LikelihoodConfig, log_likelihood  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cameras = [side_camera(640, 480, 600.0, "side"), front_camera(640, 480, 600.0, "front"),
               Camera.look_at("diag", 640, 480, 600.0, np.array([3.0, -3.5, 1.5]), np.array([0.3, 0.0, 0.9]))]
    poses = walking_poses(4)
    features = []
    for index, cam in enumerate(cameras):
        print(f"rendering camera {cam.name} ...", file=sys.stderr, flush=True)
        bg = background_image(cam, index)
        frames, _ = render_frames(cam, poses, bg, seed=index)
        extractor = FeatureExtractor(FeatureConfig(background_frames=2))
        rng = np.random.default_rng(index)
        for _ in range(2):
            extractor.process(noisy(bg, rng))
        features.append([extractor.process(f) for f in frames][3])
    rng = np.random.default_rng(0)
    base = [perturbed(poses[3], GROUPS[i % len(GROUPS)], rng) for i in range(500)]
    results = []
    for n in (5000, 20000):
        batch = stacked([base[i % len(base)] for i in range(n)]).segments()
        prev = poses[2].segments()
        prev = BodySegments(np.repeat(prev.origin, n, 0), np.repeat(prev.rotation, n, 0))
        for cams in (1, 3):
            log_likelihood(BODY.parts, batch, prev, cameras[:cams], features[:cams])   # warm-up
            times, cpu = [], []
            for _ in range(args.repeats):
                t0, c0 = time.perf_counter(), time.process_time()
                log_likelihood(BODY.parts, batch, prev, cameras[:cams], features[:cams])
                times.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            best = min(times)
            results.append({"states": n, "cameras": cams, "seconds": best, "evaluations_per_s": n / best,
                            "ms_per_camera": 1e3 * best / cams, "cpu_ms_per_camera": 1e3 * min(cpu) / cams})
            print(f"N={n} cameras={cams}: {1e3 * best:.1f} ms", file=sys.stderr, flush=True)
    config = LikelihoodConfig()
    print(json.dumps({"benchmark": "likelihood", "width": 640, "height": 480,
                      "load_average_1min": os.getloadavg()[0], "cpus": os.cpu_count(),
                      "points_per_part": config.points_along * config.points_across,
                      "parts": len(BODY.parts), "results": results}, indent=2))


if __name__ == "__main__":
    main()
