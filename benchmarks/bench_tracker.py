"""Tracker speed: frames/s of the particle filter with look-ahead (tau = 3) at 500/1000/5000
particles, (a) excluding the image likelihood (a 3D-marker likelihood stands in, as the paper's
"30 frames per second excluding likelihood computations"), (b) with the full image likelihood
on 1 and 3 cameras (synthetic 640x480 frames, features from vision.features computed beforehand),
(c) end to end: `awalker track` on bags/walk.bag (replay, features, tracker, pose publisher,
recording). Reports where the time goes per frame (dynamics + control, kinematics with pose_body,
likelihood, filter bookkeeping and summaries). Prints JSON.

    .venv/bin/python benchmarks/bench_tracker.py [--frames 20] [--particles 500 1000 5000] [--cameras 1 3]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test" / "inference"))

from awalker_tracker.inference.smc import SMCConfig  # noqa: E402
from awalker_tracker.inference.tracker import (  # noqa: E402
    StartDescription, Tracker, TrackerConfig, TrackerModel, marker_likelihood)
from awalker_tracker.model.walker import LEFT  # noqa: E402


class Timed:
    """Wraps a callable and accumulates its wall time under ``name``."""

    def __init__(self, totals: dict[str, float], name: str, fn):
        self.totals, self.name, self.fn = totals, name, fn

    def __call__(self, *args, **kwargs):
        started = time.perf_counter()
        try:
            return self.fn(*args, **kwargs)
        finally:
            self.totals[self.name] += time.perf_counter() - started


def instrument(model: TrackerModel, totals: dict[str, float]) -> None:
    """Time the model's stages by wrapping the module functions it calls."""
    model._control = type("C", (), {"sample_transition": staticmethod(
        Timed(totals, "dynamics+control", model._control.sample_transition)),
        "initial_control": staticmethod(model._control.initial_control)})
    kin = model._kin
    model._kin = type("K", (), {
        "sample_posed_kinematics": staticmethod(Timed(totals, "kinematics+pose_body",
                                                      kin.sample_posed_kinematics)),
        "pose_body": staticmethod(Timed(totals, "kinematics+pose_body", kin.pose_body)),
        "initial_kinematics": staticmethod(kin.initial_kinematics)})
    model.likelihood = Timed(totals, "likelihood", model.likelihood)


def run_filter(body, start, likelihood, observations, n: int, seed: int = 0) -> dict:
    totals: dict[str, float] = defaultdict(float)
    model = TrackerModel(body, start, likelihood, TrackerConfig(smc=SMCConfig(num_particles=n, seed=seed)))
    instrument(model, totals)
    tracker = Tracker(model)
    started = time.perf_counter()
    count = 0
    for k, obs in enumerate(observations):
        count += len(tracker.push(k, 1 + k, obs))
    count += len(tracker.finish())
    elapsed = time.perf_counter() - started
    frames = len(observations)
    stages = {k: round(1000 * v / frames, 2) for k, v in totals.items()}
    stages["filter+summaries"] = round(1000 * elapsed / frames - sum(stages.values()), 2)
    return {"particles": n, "frames": frames, "frames_per_s": round(frames / elapsed, 2),
            "ms_per_frame": round(1000 * elapsed / frames, 2), "ms_per_frame_by_stage": stages,
            "resamples": tracker.filter.num_resamples}


def image_sequence(cameras: int, frames: int, folder: Path):
    """A synthetic 640x480 walk seen by ``cameras`` cameras -> (body, start, cameras, observations)."""
    from awalker_tracker.inference.tracker import ImageObservation
    from awalker_tracker.model.body import BodyDescription
    from awalker_tracker.vision.camera import load_calibration
    from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor
    from awalker_tools.bagio import SequenceReader
    from awalker_tools.synth import SynthConfig, synthesise

    background = 5
    for seed in range(1, 20):
        out = folder / f"cams{cameras}_seed{seed}"
        try:
            paths = synthesise(SynthConfig(out_dir=out, cameras=cameras, frames=frames, background_frames=background,
                                           seed=seed), progress=False)
            break
        except Exception as exc:  # the walker fell: next seed
            print(f"synth seed {seed}: {exc}", file=sys.stderr)
    body = BodyDescription.from_yaml(paths["body"])
    start = StartDescription.from_yaml(paths["start"])
    cams = load_calibration(paths["calibration"])
    extractors = {c.name: FeatureExtractor(FeatureConfig(background_frames=background), body) for c in cams}
    observations = []
    with SequenceReader(paths["bag"]) as reader:
        for k, (_, images) in enumerate(reader.frames()):
            feats = tuple(extractors[c.name].process(images[c.name]) for c in cams)
            if k >= background:
                observations.append(ImageObservation(feats))
    return body, StartDescription(0, start.position, start.heading, start.speed, start.step_length,
                                  start.stance_leg), cams, observations


def warm_up_likelihood(body, cameras, observations) -> float:
    """Load the image likelihood's compiled (numba) kernels from their disk cache, or compile
    them, before anything is timed; returns the seconds that took (once per process)."""
    from awalker_tracker.model.body import BodySegments
    from awalker_tracker.vision.likelihood import log_likelihood

    parts = len(body.parts)
    segments = BodySegments(np.zeros((1, parts, 3)), np.broadcast_to(np.eye(3), (1, parts, 3, 3)).copy())
    moved = BodySegments(segments.origin + 0.01, segments.rotation)
    started = time.perf_counter()
    for obs in observations[:2]:      # the second frame has flow: the previous poses get projected too
        log_likelihood(body.parts, segments, moved, cameras, list(obs.features))
    return time.perf_counter() - started


def end_to_end(particles: int, folder: Path) -> dict:
    """`awalker track` on the sample bag (replay, features, tracker, pose publisher, recording)."""
    from awalker_tools.pipeline import TrackOptions, run_tracking

    bag = Path(__file__).resolve().parents[1] / "bags" / "walk.bag"
    result = run_tracking(TrackOptions(bag=bag, out=folder / f"track_{particles}", particles=particles,
                                       overlays=False, quiet=True))
    return {"bag": str(bag.name), "particles": particles, "frames": result.summaries,
            "end_to_end_frames_per_s": round(result.frames_per_second, 2),
            "filter_frames_per_s": round(result.summaries / max(result.seconds_in_filter, 1e-9), 2)}


def main() -> None:
    import tempfile

    from awalker_tracker.inference.tracker import image_likelihood

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--particles", type=int, nargs="+", default=[500, 1000, 5000])
    parser.add_argument("--cameras", type=int, nargs="+", default=[1, 3])
    parser.add_argument("--skip-end-to-end", action="store_true")
    args = parser.parse_args()
    from test_tracker_model import simulate_walk

    body, markers, _, _ = simulate_walk(args.frames, 1.3, 0.7, 0.0, seed=3)
    start = StartDescription(0, tuple(markers[0, 0, :2]), 0.0, 1.3, 0.7, LEFT)
    obs = markers + 0.01 * np.random.default_rng(0).standard_normal(markers.shape)
    results: dict = {"lookahead": 3, "machine": "2 cores shared with other jobs",
                     "excluding_image_likelihood": [], "image_likelihood": [], "end_to_end": []}
    for n in args.particles:
        results["excluding_image_likelihood"].append(run_filter(body, start, marker_likelihood(0.03), obs, n))
        print(f"marker likelihood N={n}: {results['excluding_image_likelihood'][-1]['frames_per_s']} frames/s",
              file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp:
        for cams in args.cameras:
            body_i, start_i, cameras, observations = image_sequence(cams, args.frames + 5, Path(tmp))
            results.setdefault("likelihood_warm_up_s", []).append(
                round(warm_up_likelihood(body_i, cameras, observations), 3))
            for n in args.particles:
                r = run_filter(body_i, start_i, image_likelihood(body_i, cameras), observations, n)
                r["cameras"] = cams
                results["image_likelihood"].append(r)
                print(f"image likelihood {cams} camera(s) N={n}: {r['frames_per_s']} frames/s", file=sys.stderr)
        if not args.skip_end_to_end:
            for n in (500, 5000):
                results["end_to_end"].append(end_to_end(n, Path(tmp)))
                print(f"end to end N={n}: {results['end_to_end'][-1]}", file=sys.stderr)
    print(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
