"""Tracker speed: frames/s of the particle filter with look-ahead (tau = 3) at 500/1000/5000
particles, (a) excluding the image likelihood (a 3D-marker likelihood stands in, as the paper's
"30 frames per second excluding likelihood computations"), (b) with the full image likelihood
on 1 and 3 cameras (synthetic 640x480 frames, features from vision.features computed beforehand),
(c) end to end: `awalker track` on bags/walk.bag (replay, features, tracker, pose publisher,
recording), in this process after the filter tables, and (d) sustained: `awalker track --no-overlay` as a
user runs it (a fresh process: loading the compiled kernels counts) on a 10 s synthetic 640x480 walk
(``--long-frames``), where the fixed costs of a 72-frame bag (start-up, kernel loading, writing the
outputs: ~0.5 s) do not dominate, and (e) with ``--defaults-grid``: `awalker track` at its defaults (no
``--particles``: what a user gets), a fresh process each, on synthetic 2 s walks with 1 and 2 cameras, 30 and
60 Hz, 640x480 and 1280x720, each with its end-to-end frames/s beside the median absolute error of that same run
against the walk's truth (our own renders: a mirror of the speed/accuracy trade, not evidence of accuracy on
people; that is bench_realwalks.py's, at the same defaults). Reports where the time goes per frame (dynamics + control, kinematics with pose_body,
likelihood, filter bookkeeping and summaries; drawing the initial particles, once per track, is
reported apart), and the same filter at 60 Hz input (dt = 1/60 s:
2 RK4 sub-steps per frame, Table 1's alpha^(1/2); 1 camera). The compiled kernels are loaded (or
compiled) by a short untimed run first; ``warm_up_s`` says how long that took.

``--baseline REV`` also runs this benchmark's filter tables on the code of git revision REV (a
temporary worktree, e.g. the last numpy implementation 831cccf) in the same run and reports
the speed-up of each entry against it. ``--repeats K`` runs the filter tables K times (with a
baseline: ours, the baseline's, ours, ... alternately) and reports each entry's median run with all
its runs' frames/s: on this shared machine the speed drifts by 10-30 % within minutes, so one run of
each is not a comparison. ``core_sin_cos_ns`` times a compiled sine-and-cosine loop on each core in
turn: a yardstick for the machine's speed at the time. Prints JSON.

    .venv/bin/python benchmarks/bench_tracker.py [--frames 20] [--particles 500 1000 5000] [--cameras 1 3]
        [--rates 30 60] [--skip-end-to-end] [--long-frames 300] [--baseline REV] [--repeats K]
    .venv/bin/python benchmarks/bench_tracker.py --defaults-grid       # (e) alone
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test" / "inference"))

from awalker_tracker.inference.filter_model import (  # noqa: E402
    StartDescription, Tracker, TrackerConfig, TrackerModel, marker_likelihood)
from awalker_tracker.inference.smc import SMCConfig  # noqa: E402
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


class OneOff(Timed):
    """Accumulates its wall time under ``name`` and keeps the stages it calls from counting it."""

    def __call__(self, *args, **kwargs):
        before = dict(self.totals)
        started = time.perf_counter()
        try:
            return self.fn(*args, **kwargs)
        finally:
            spent = time.perf_counter() - started
            for key in list(self.totals):
                self.totals[key] = before.get(key, 0.0)
            self.totals[self.name] += spent


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
        "mirrored_legs": staticmethod(Timed(totals, "kinematics+pose_body", kin.mirrored_legs)),
        "initial_kinematics": staticmethod(kin.initial_kinematics)})
    model.likelihood = Timed(totals, "likelihood", model.likelihood)
    model.initial = OneOff(totals, "initial", model.initial)


def run_filter(body, start, likelihood, observations, n: int, seed: int = 0, rate_hz: float = 30.0) -> dict:
    totals: dict[str, float] = defaultdict(float)
    config = TrackerConfig(smc=SMCConfig(num_particles=n, seed=seed), dt=1.0 / rate_hz)
    model = TrackerModel(body, start, likelihood, config)
    instrument(model, totals)
    tracker = Tracker(model)
    started = time.perf_counter()
    count = 0
    for k, obs in enumerate(observations):
        count += len(tracker.push(k, 1 + k, obs))
    count += len(tracker.finish())
    # the initial particles (drawn once per track: random gait phases) are not per-frame work
    initial = totals.pop("initial", 0.0)
    elapsed = time.perf_counter() - started - initial
    frames = len(observations)
    stages = {k: round(1000 * v / frames, 2) for k, v in totals.items()}
    stages["filter+summaries"] = round(1000 * elapsed / frames - sum(stages.values()), 2)
    return {"particles": n, "frame_rate_hz": rate_hz, "frames": frames, "frames_per_s": round(frames / elapsed, 2),
            "ms_per_frame": round(1000 * elapsed / frames, 2), "ms_per_frame_by_stage": stages,
            "initial_particles_ms": round(1000 * initial, 1), "resamples": tracker.filter.num_resamples}


def warm_up(body, start, likelihood, observations) -> float:
    """Load the compiled (numba) kernels from their disk cache, or compile them, by filtering a few
    frames with a few particles, untimed; returns the seconds that took."""
    started = time.perf_counter()
    run_filter(body, start, likelihood, observations[:6], 200)
    return round(time.perf_counter() - started, 3)


def synthesised_walk(folder: Path, name: str, cameras: int, frames: int, background: int) -> dict:
    """``synth``'s paths of a synthetic 640x480 walk (``folder``/``name``_seedS) from the first synthesis
    seed whose walker does not fall within ``frames``."""
    from awalker_tools.synth import SynthConfig, synthesise

    for seed in range(1, 20):
        try:
            return synthesise(SynthConfig(out_dir=folder / f"{name}_seed{seed}", cameras=cameras, frames=frames,
                                          background_frames=background, seed=seed), progress=False)
        except Exception as exc:  # the walker fell: next seed
            print(f"synth seed {seed}: {exc}", file=sys.stderr)
    raise RuntimeError(f"bench_tracker: no synthesis seed gave a {frames}-frame walk")


def image_sequence(cameras: int, frames: int, folder: Path):
    """A synthetic 640x480 walk seen by ``cameras`` cameras -> (body, start, cameras, observations)."""
    from awalker_tracker.inference.filter_model import ImageObservation
    from awalker_tracker.model.body import BodyDescription
    from awalker_tracker.vision.camera import load_calibration
    from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor
    from awalker_tools.bagio import SequenceReader

    background = 5
    paths = synthesised_walk(folder, f"cams{cameras}", cameras, frames, background)
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


def end_to_end(particles: int, folder: Path) -> dict:
    """`awalker track` on the sample bag (replay, features, tracker, pose publisher, recording)."""
    from awalker_tools.pipeline import TrackOptions, run_tracking

    bag = Path(__file__).resolve().parents[1] / "bags" / "walk.bag"
    result = run_tracking(TrackOptions(bag=bag, out=folder / f"track_{particles}", particles=particles,
                                       overlays=False, quiet=True))
    return {"bag": str(bag.name), "particles": particles, "frames": result.summaries,
            "end_to_end_frames_per_s": round(result.frames_per_second, 2),
            "streaming_frames_per_s": round(result.streaming_frames_per_second, 2),
            "filter_frames_per_s": round(result.summaries / max(result.seconds_in_filter, 1e-9), 2)}


def sustained(particles: int, bag: Path, folder: Path) -> dict:
    """`awalker track BAG --no-overlay` in a fresh process (as a user runs it) -> its frames/s, from the
    run.yaml it writes."""
    import subprocess

    import yaml

    from awalker_tools.pipeline import RUN_FILE

    out = folder / f"sustained_{particles}"
    subprocess.run([sys.executable, "-m", "awalker_tools.cli", "track", str(bag), "--out", str(out),
                    "--particles", str(particles), "--no-overlay"], capture_output=True, text=True, check=True)
    run = yaml.safe_load((out / RUN_FILE).read_text())
    frames = run["posteriors"]
    return {"frames": frames, "particles": particles,
            "end_to_end_frames_per_s": round(frames / run["seconds"], 2),
            "streaming_frames_per_s": round(frames / run["seconds_streaming"], 2),
            "filter_frames_per_s": round(frames / max(run["seconds_in_filter"], 1e-9), 2)}


def defaults_grid(folder: Path, seconds: float = 2.0) -> list[dict]:
    """(e): per (cameras, rate, size), `awalker track --no-overlay` at its defaults in a fresh process on a synthetic
    hand-started walk of ``seconds``, then `awalker eval`: frames/s end to end, while streaming, of the filter, and
    the median absolute / relative error (mm)."""
    import json as json_module
    import subprocess

    import yaml

    from awalker_tools.pipeline import RUN_FILE
    from awalker_tools.synth import SynthConfig, synthesise

    rows = []
    for cameras in (1, 2):
        for rate in (30.0, 60.0):
            for width, height in ((640, 480), (1280, 720)):
                name = f"grid_{cameras}cam_{rate:g}hz_{width}x{height}"
                paths = None
                for seed in range(1, 20):
                    try:
                        paths = synthesise(SynthConfig(out_dir=folder / f"{name}_seed{seed}", cameras=cameras,
                                                       rate=rate, frames=int(seconds * rate), background_frames=8,
                                                       width=width, height=height, seed=seed), progress=False)
                        break
                    except Exception as exc:  # the walker fell: next seed
                        print(f"synth seed {seed}: {exc}", file=sys.stderr)
                if paths is None:
                    raise RuntimeError(f"bench_tracker: no synthesis seed gave the {name} walk")
                out = folder / f"{name}_run"
                subprocess.run([sys.executable, "-m", "awalker_tools.cli", "track", str(paths["bag"]), "--out",
                                str(out), "--no-overlay"], capture_output=True, text=True, check=True)
                subprocess.run([sys.executable, "-m", "awalker_tools.cli", "eval", str(out)], capture_output=True,
                               text=True, check=True)
                run = yaml.safe_load((out / RUN_FILE).read_text())
                scores = json_module.loads((out / "eval.json").read_text())
                frames = run["posteriors"]
                rows.append({"cameras": cameras, "rate_hz": rate, "size": f"{width}x{height}",
                             "particles": run["particles"], "frames": frames,
                             "end_to_end_frames_per_s": round(frames / run["seconds"], 2),
                             "streaming_frames_per_s": round(frames / run["seconds_streaming"], 2),
                             "filter_frames_per_s": round(frames / max(run["seconds_in_filter"], 1e-9), 2),
                             "real_time": frames / run["seconds_streaming"] >= rate,
                             "absolute_mm_median": round(scores["absolute_mm"]["median"], 1),
                             "relative_mm_median": round(scores["relative_mm"]["median"], 1)})
                print(f"defaults grid: {rows[-1]}", file=sys.stderr)
    return rows


def core_speeds() -> list[float]:
    """ns per sine-and-cosine pair of a compiled loop, on each core this process may use in turn (the thread
    pinned to it): a yardstick for the machine's speed, which varies over time and between its two cores (one ran
    the kernels ~1.5x slower than the other), so that runs made at different times can be compared."""
    import threading

    import numba

    @numba.njit(cache=True, nogil=True)
    def trig_loop(values: np.ndarray, repeats: int) -> float:
        total = 0.0
        for _ in range(repeats):
            for x in values:
                total += np.sin(x) + np.cos(x * 1.1)
        return total

    values = np.random.default_rng(0).uniform(-1.0, 1.0, 20000)
    trig_loop(values, 1)
    speeds: list[float] = []

    def measure(cpu: int) -> None:
        os.sched_setaffinity(0, {cpu})        # this thread only (Linux)
        best = min(_timed(lambda: trig_loop(values, 5)) for _ in range(5))
        speeds.append(round(1e9 * best / (5 * values.size), 2))

    for cpu in sorted(os.sched_getaffinity(0)):
        thread = threading.Thread(target=measure, args=(cpu,))
        thread.start()
        thread.join()
    return speeds


def _timed(fn) -> float:
    started = time.perf_counter()
    fn()
    return time.perf_counter() - started


def filter_tables(args, body, start, obs, sequences: dict) -> dict:
    """One run of the filter tables: the 3D-marker stand-in and the image likelihood per camera count and
    input rate (``sequences``: camera count -> ``image_sequence``'s (body, start, cameras, observations))."""
    from awalker_tracker.inference.filter_model import image_likelihood

    tables: dict = {"excluding_image_likelihood": [], "image_likelihood": []}
    for n in args.particles:
        tables["excluding_image_likelihood"].append(run_filter(body, start, marker_likelihood(0.03), obs, n))
        print(f"marker likelihood N={n}: {tables['excluding_image_likelihood'][-1]['frames_per_s']} frames/s",
              file=sys.stderr)
    for cams, (body_i, start_i, cameras, observations) in sequences.items():
        likelihood = image_likelihood(body_i, cameras)
        tables[f"warm_up_{cams}_cameras_s"] = warm_up(body_i, start_i, likelihood, observations)
        for rate in args.rates:
            if rate != 30.0 and cams != 1:
                continue
            for n in args.particles:
                r = run_filter(body_i, start_i, likelihood, observations, n, rate_hz=rate)
                r["cameras"] = cams
                tables["image_likelihood"].append(r)
                print(f"image likelihood {cams} camera(s) {rate:g} Hz N={n}: {r['frames_per_s']} frames/s",
                      file=sys.stderr)
    return tables


TABLES = ("excluding_image_likelihood", "image_likelihood")


def _entry_key(table: str, entry: dict) -> tuple:
    return table, entry["particles"], entry.get("cameras", 0), entry.get("frame_rate_hz", 30.0)


def median_tables(runs: list[dict]) -> dict:
    """The filter tables of several runs: per entry the run of median frames/s (of two middle runs, the faster),
    with every run's frames/s (``frames_per_s_runs``); the warm-up times of the first run."""
    merged = {k: v for k, v in runs[0].items() if k not in TABLES}
    for table in TABLES:
        entries = []
        for index, first in enumerate(runs[0].get(table, [])):
            same = [run[table][index] for run in runs]
            assert all(_entry_key(table, e) == _entry_key(table, first) for e in same)
            ordered = sorted(same, key=lambda e: e["frames_per_s"])
            entry = dict(ordered[len(ordered) // 2])
            entry["frames_per_s_runs"] = [e["frames_per_s"] for e in same]
            entries.append(entry)
        merged[table] = entries
    return merged


def main() -> None:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--particles", type=int, nargs="+", default=[500, 1000, 5000])
    parser.add_argument("--cameras", type=int, nargs="+", default=[1, 3])
    parser.add_argument("--skip-end-to-end", action="store_true")
    parser.add_argument("--long-frames", type=int, default=300,
                        help="frames of the synthetic walk for the sustained end-to-end rate (0: skip it)")
    parser.add_argument("--rates", type=float, nargs="+", default=[30.0, 60.0],
                        help="input frame rates (Hz); rates other than 30 are run with 1 camera")
    parser.add_argument("--baseline", metavar="REV", help="also run the filter tables on git revision REV and "
                        "report the speed-up against it")
    parser.add_argument("--defaults-grid", action="store_true",
                        help="only (e): `awalker track` at its defaults over cameras x rates x image sizes")
    parser.add_argument("--repeats", type=int, default=1,
                        help="run the filter tables this many times (alternately with the baseline's) and report "
                        "the median of each entry: the machine's speed drifts within minutes")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    if args.defaults_grid:
        with tempfile.TemporaryDirectory() as tmp:
            grid = defaults_grid(Path(tmp))
        print(json.dumps({"machine": "2 cores shared with other jobs",
                          "load_average_1min": round(os.getloadavg()[0], 2), "defaults_grid": grid}, indent=1))
        return
    from test_filter_model import simulate_walk

    body, markers, _, _ = simulate_walk(args.frames, 1.3, 0.7, 0.0, seed=3)
    start = StartDescription(0, tuple(markers[0, 0, :2]), 0.0, 1.3, 0.7, LEFT)
    obs = markers + 0.01 * np.random.default_rng(0).standard_normal(markers.shape)
    results: dict = {"lookahead": 3, "machine": "2 cores shared with other jobs",
                     "load_average_1min": round(os.getloadavg()[0], 2),
                     "core_sin_cos_ns": core_speeds(),
                     "warm_up_s": warm_up(body, start, marker_likelihood(0.03), obs), "repeats": args.repeats,
                     "end_to_end": [], "sustained": []}
    with tempfile.TemporaryDirectory() as tmp:
        sequences = {cams: image_sequence(cams, args.frames + 5, Path(tmp)) for cams in args.cameras}
        ours, theirs = [], []
        with _baseline_tree(args.baseline) as tree:
            for repeat in range(args.repeats):
                print(f"filter tables, run {repeat + 1} of {args.repeats}", file=sys.stderr)
                ours.append(filter_tables(args, body, start, obs, sequences))
                if tree is not None:
                    theirs.append(_baseline_tables(args, tree))
        results.update(median_tables(ours))
        if args.baseline:
            results["baseline"] = compare_with_baseline(args.baseline, results, median_tables(theirs))
        if not args.skip_end_to_end:
            for n in (500, 5000):
                results["end_to_end"].append(end_to_end(n, Path(tmp)))
                print(f"end to end N={n}: {results['end_to_end'][-1]}", file=sys.stderr)
            if args.long_frames > 0:
                walk = synthesised_walk(Path(tmp), "long", 1, args.long_frames, 8)["bag"]
                for n in (500, 5000):
                    results["sustained"].append(sustained(n, walk, Path(tmp)))
                    print(f"sustained N={n}: {results['sustained'][-1]}", file=sys.stderr)
    print(json.dumps(results, indent=1))


@contextlib.contextmanager
def _baseline_tree(revision: str | None):
    """A temporary git worktree of ``revision`` (None: no baseline, yields None)."""
    import subprocess
    import tempfile

    if revision is None:
        yield None
        return
    repo = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "baseline"
        subprocess.run(["git", "-C", str(repo), "worktree", "add", "--detach", str(tree), revision],
                       check=True, capture_output=True)
        try:
            yield tree
        finally:
            subprocess.run(["git", "-C", str(repo), "worktree", "remove", "--force", str(tree)], check=False)


def _baseline_tables(args, tree: Path) -> dict:
    """One run of the baseline's own benchmark (its filter tables, no end-to-end) in a process of its own."""
    import subprocess

    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        str(tree / "src" / pkg) for pkg in ("awalker_tracker", "awalker_tools")))
    command = [sys.executable, str(tree / "benchmarks" / "bench_tracker.py"), "--skip-end-to-end",
               "--frames", str(args.frames), "--particles", *map(str, args.particles),
               "--cameras", *map(str, args.cameras), "--rates", *map(str, args.rates)]
    print(f"baseline: {' '.join(command[1:])}", file=sys.stderr)
    done = subprocess.run(command, env=env, cwd=tree, check=True, capture_output=True, text=True)
    return json.loads(done.stdout)


def compare_with_baseline(revision: str, results: dict, theirs: dict) -> dict:
    """The baseline's filter tables (``theirs``) with the speed-up of every entry measured in both
    (frames/s here / frames/s there, medians over the repeats)."""
    ours = {_entry_key(t, e): e for t in TABLES for e in results[t]}
    speedup = []
    for table in TABLES:
        for entry in theirs.get(table, []):
            mine = ours.get(_entry_key(table, entry))
            if mine is not None:
                speedup.append({"table": table, "particles": entry["particles"], "cameras": entry.get("cameras", 0),
                                "frame_rate_hz": entry.get("frame_rate_hz", 30.0), "frames_per_s": mine["frames_per_s"],
                                "baseline_frames_per_s": entry["frames_per_s"],
                                "speedup": round(mine["frames_per_s"] / entry["frames_per_s"], 2)})
    return {"revision": revision, "speedup": speedup, "figures": theirs}


if __name__ == "__main__":
    main()
