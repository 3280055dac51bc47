"""Tracking accuracy on the paper-style synthetic sequences (issue 6, "Done when").

Each sequence is made with `awalker synth` (fixed seeds, into a temporary directory), tracked
with `awalker track` and scored with `awalker eval`, all through their public modules
(synth.synthesise, pipeline.run_tracking, commands.eval.run). Sequences:

    mono_straight        1 camera, straight walk
    two_camera_straight  2 cameras, straight walk
    speed_change         1 camera, slows to 70 % over the middle third
    turn                 1 camera, turns left by --turn degrees (default 75) over the middle third
    occluder             1 camera, a box hides the lower body for a stretch (occlusion masks in the bag)
    mocap                1 camera, CMU subject 07 walk 01 (test/data/mocap), motion the tracker did not produce

Prints ONE JSON document on stdout; progress and a summary table go to stderr. Errors in mm over
pelvis, thorax, hips, knees and ankles (absolute, and relative = pelvis-aligned), statistics over
frames. Stance leg: `stance_leg_correct_fraction` is `awalker eval`'s (true stance = the
planted foot, double support not scored). Speed: medians and the mean
per-frame |estimated - true| (true = the truth's pelvis by the tracker's definition, inference.speed:
horizontal displacement per frame averaged over about one step).

    .venv/bin/python benchmarks/bench_accuracy.py                  # 90 frames, 640x480, tracker default particles
    .venv/bin/python benchmarks/bench_accuracy.py --quick          # 40 frames, 320x240, 500 particles
    .venv/bin/python benchmarks/bench_accuracy.py --particles 1000 --sequences mono_straight turn --keep out/
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import sys
import tempfile
import time
from dataclasses import fields
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
MOCAP_DIR = REPO_ROOT / "test" / "data" / "mocap" / "cmu_subject07"
sys.path.insert(0, str(REPO_ROOT / "test" / "tools"))

from accuracy_helpers import speed_error  # noqa: E402  (shared with test/tools/test_accuracy.py)


def sequence_arguments(turn_deg: float) -> dict[str, dict]:
    """SynthConfig keyword arguments per sequence (besides size, frames, seed)."""
    return {
        "mono_straight": {"cameras": 1},
        "two_camera_straight": {"cameras": 2},
        "speed_change": {"cameras": 1, "speed_change": True},
        "turn": {"cameras": 1, "turn_deg": turn_deg},
        "occluder": {"cameras": 1, "occluder": True},
        "mocap": {"cameras": 1, "mocap": (MOCAP_DIR / "07.asf", MOCAP_DIR / "07_01.amc")},
    }


def log(text: str) -> None:
    print(f"bench_accuracy: {text}", file=sys.stderr, flush=True)


def synthesise_sequence(out_dir: Path, first_seed: int, tries: int, **config) -> tuple[Path, int]:
    """`awalker synth` with the first seed (from ``first_seed``) whose walker does not fall."""
    from awalker_tracker.errors import InputError

    from awalker_tools.synth import SynthConfig, synthesise

    last_error = None
    for seed in range(first_seed, first_seed + tries):
        try:
            paths = synthesise(SynthConfig(out_dir=out_dir / f"seed{seed}", seed=seed, **config), progress=False)
            return paths["bag"], seed
        except InputError as exc:     # the walker fell: the next seed
            last_error = exc
            log(f"  {exc}")
    raise RuntimeError(f"no walk without a fall in seeds {first_seed}..{first_seed + tries - 1}: {last_error}")


def evaluate_run(run_dir: Path) -> dict:
    """`awalker eval DIR` (its table goes to stderr); returns DIR/eval.json."""
    from awalker_tools.commands import eval as eval_command

    with contextlib.redirect_stdout(sys.stderr):
        eval_command.run(argparse.Namespace(dir=str(run_dir), truth=None, json=None))
    return json.loads((run_dir / "eval.json").read_text())


def summarise(result: dict, track, track_dir: Path, particles: int) -> dict:
    """The reported figures of one sequence."""
    def stats(d: dict) -> dict:
        return {k: round(d[k], 1) for k in ("median", "mean", "std", "max")}

    def rounded(d: dict) -> dict:
        return {k: round(v, 1) + 0.0 for k, v in d.items()}   # + 0.0: no "-0.0"

    feet = result["estimate_feet"]
    return {
        "frames": result["absolute_mm"]["frames"],
        "particles": particles,
        "absolute_mm": stats(result["absolute_mm"]),
        "relative_mm": stats(result["relative_mm"]),
        "foot_skate_mm": {"mean": round(feet["skate_mm"]["mean"], 2), "max": round(feet["skate_mm"]["max"], 2)},
        "penetration_mm": rounded(feet["penetration_mm"]),
        "float_mm": rounded(feet["float_mm"]),
        "truth_float_mm": rounded(result["truth_feet"]["float_mm"]),
        "stance_leg_correct_fraction": (round(result["stance_correct_fraction"], 3)
                                        if "stance_correct_fraction" in result else None),
        "stance_leg_scored_frames": result.get("stance_scored_frames", 0),
        "speed_m_s": {"true_median": round(result.get("truth_speed_m_s", float("nan")), 3),
                      "estimated_median": round(result.get("estimated_speed_m_s", float("nan")), 3),
                      "mean_abs_error": round(speed_error(track_dir, Path(result["truth_source"])), 3)},
        "wall_time_s": round(track.seconds, 2),
        "frames_per_s": round(track.frames_per_second, 2),
        "filter_frames_per_s": round(track.summaries / max(track.seconds_in_filter, 1e-9), 2),
    }


def main(argv: list[str] | None = None) -> int:
    from awalker_tools.pipeline import TrackOptions, run_tracking

    defaults = {f.name: f.default for f in fields(TrackOptions)}
    default_particles, likelihood_default = defaults["particles"], defaults["likelihood_scale"]
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="40 frames at 320x240 with 500 particles")
    parser.add_argument("--particles", type=int, help=f"particles (default {default_particles}; --quick 500)")
    parser.add_argument("--frames", type=int, help="frames with the person (default 90; --quick 40)")
    parser.add_argument("--size", nargs=2, type=int, metavar=("W", "H"),
                        help="image size (default 640 480; --quick 320 240)")
    parser.add_argument("--background-frames", type=int, default=5, help="empty frames before the person (default 5)")
    parser.add_argument("--seed", type=int, default=1, help="first synthesis seed tried (default 1)")
    parser.add_argument("--track-seed", type=int, default=0, help="tracker seed (default 0)")
    parser.add_argument("--likelihood-scale", type=float, default=likelihood_default,
                        help=f"exponent on the image likelihood (default {likelihood_default}, the tracker's)")
    parser.add_argument("--turn", type=float, default=75.0, help="turn of the turn sequence, degrees (default 75)")
    parser.add_argument("--sequences", nargs="+", choices=list(sequence_arguments(0.0)),
                        help="subset of sequences (default all)")
    parser.add_argument("--keep", type=Path, help="keep sequences and runs in this directory (default: a temp dir)")
    args = parser.parse_args(argv)
    particles = args.particles or (500 if args.quick else default_particles)
    frames = args.frames or (40 if args.quick else 90)
    width, height = args.size or ((320, 240) if args.quick else (640, 480))
    specs = sequence_arguments(args.turn)
    names = args.sequences or list(specs)

    # every node runs in this process: keep DDS discovery off so concurrent runs on the machine cannot cross-talk
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
    report: dict = {"benchmark": "accuracy", "settings": {
        "frames": frames, "background_frames": args.background_frames, "size": [width, height],
        "particles": particles, "track_seed": args.track_seed,
        "likelihood_scale": args.likelihood_scale, "turn_deg": args.turn,
        "host": platform.node(), "cpus": os.cpu_count(), "load_average_start": [round(x, 2) for x in os.getloadavg()]},
        "sequences": {}}
    with contextlib.ExitStack() as stack:
        root = args.keep or Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="bench_accuracy_")))
        root.mkdir(parents=True, exist_ok=True)
        for k, name in enumerate(names):
            log(f"[{k + 1}/{len(names)}] {name}: synthesising {frames} frames at {width}x{height}")
            started = time.monotonic()
            bag, seed = synthesise_sequence(root / name, args.seed, 10, frames=frames, width=width, height=height,
                                            background_frames=args.background_frames, **specs[name])
            synth_s = time.monotonic() - started
            log(f"[{k + 1}/{len(names)}] {name}: seed {seed} ({synth_s:.0f} s); tracking with {particles} particles")
            run_dir = root / name / "run"
            track = run_tracking(TrackOptions(bag=bag, out=run_dir, particles=particles, seed=args.track_seed,
                                              likelihood_scale=args.likelihood_scale, overlays=False, quiet=True))
            entry = summarise(evaluate_run(run_dir), track, run_dir, particles)
            entry["synth_seed"] = seed
            entry["synth_wall_time_s"] = round(synth_s, 1)
            report["sequences"][name] = entry
            log(f"[{k + 1}/{len(names)}] {name}: absolute {entry['absolute_mm']['mean']:.0f} mm, relative "
                f"{entry['relative_mm']['mean']:.0f} mm, stance {entry['stance_leg_correct_fraction']}, "
                f"{entry['frames_per_s']:.1f} frames/s")
    log("sequence              absolute median/mean+-std   relative median/mean+-std   skate  stance"
        "  speed err  frames/s")
    for name, e in report["sequences"].items():
        a, r = e["absolute_mm"], e["relative_mm"]
        log(f"{name:<21} {a['median']:8.1f} {a['mean']:7.1f} +- {a['std']:5.1f}   "
            f"{r['median']:8.1f} {r['mean']:7.1f} +- "
            f"{r['std']:5.1f}   {e['foot_skate_mm']['mean']:5.2f}  {e['stance_leg_correct_fraction']}  "
            f"{e['speed_m_s']['mean_abs_error']:8.3f}  "
            f"{e['frames_per_s']:7.2f}")
    report["settings"]["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
