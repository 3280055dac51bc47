"""Tracking real human walks the tracker did not draw (issue 10): the development benchmark.

Sequences: the two CMU subject-07 walks (07_01, 07_02; test/data/mocap) as `awalker synth
--person dressed` renders them (arms, hair, striped shirt, jeans of one colour, shoes, shading, a
contact shadow, blur and sensor noise; per-person widths), in the variants straight, slow / fast
(time-warped -/+20 %), veer-left / veer-right (35 degrees over 2.5 s) and u-turn (180 degrees within
2 s), seen by one camera or two, with start descriptions as a user would write them (--user-start:
position within 5 cm, heading within 5 degrees, speed within 10 %, no step length) and tape-measured
body sizes (--tape-measure). Each is tracked over tracker seeds with `awalker track` and scored with
`awalker eval`; "dead reckoning" is the motion prior alone from the start description: the tracker
with the images unused (--likelihood-scale 0, no recovery; walkers that fall are still dropped), over
the same seeds, the median reported. (With the likelihood only scaled down, e.g. 1e-9, the weights
still rank the particles by the images and the MAP lineage is the best of the prior's walks by image
evidence: that was this baseline before 2026-11-25, 130-1014 mm.)

Per sequence x setting x seed: absolute and relative median errors (mm, pelvis, thorax, hips, knees,
ankles), the facing-direction error one second after a turn ends (degrees), left/right swaps, frames
fallen or off the person, whether the run ended on the person, recovery counts, and the gait against the
truth's heel strikes (median timing error and signed timing, s, later > 0; step length error, m; speed
error, m/s). Summary: median
and worst over seeds. Prints ONE JSON document; progress and tables on stderr.

    .venv/bin/python benchmarks/bench_realwalks.py --out bench_rw/                 # everything (~25 min on 2 cores)
    .venv/bin/python benchmarks/bench_realwalks.py --out bench_rw/ --walks 07_01 --variants straight u-turn \\
        --settings mono --seeds 0 1
    .venv/bin/python benchmarks/bench_realwalks.py --out bench_rw/ --hands-off     # after the line above

--hands-off (issue 12): the same walks as a user's own video: no background-only frames, no start and no
body description (`synth --no-descriptions --background-frames 0`), tracked with the automatic start.
Adds the start delay (s after the first frame, where the person is already in view) and, where the
hand-started runs of the same --out exist, their absolute error for comparison. The hands-off runs are
scored from the frame the tracker started at; the hand-started ones from the first frame.

--carry backpack|shoulder-bag (issue 10 §4, unmodelled foreground): the same walks with the person carrying
a bag the tracker's body does not have (`synth --carry`; the sequences and runs get the bag's name).

--true-body (a diagnosis, not what a user has): track with the drawn person's own segment sizes
(``ground_truth_body.yaml`` beside the sequence) instead of the tape's; runs named ..._truebody_sN. Sequences
synthesised before synth wrote that file must be made again (delete their directory under OUT/sequences).

--likelihood-scale S, --lookahead T, --pelvis-ceiling F: `awalker track`'s tempering exponent, look-ahead and
pelvis ceiling for the tracked runs (dead reckoning keeps 0 and the defaults); runs other than the defaults are
named ..._lsS / ..._laT / ..._pcF, so they sit beside the default runs of the same --out and reuse its sequences.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
MOCAP_DIR = REPO_ROOT / "test" / "data" / "mocap" / "cmu_subject07"
sys.path.insert(0, str(REPO_ROOT / "benchmarks"))

from awalker_tools.evaluation import OFFSET_AXES, OFFSET_GROUPS, group_offsets  # noqa: E402
from awalker_tools.person_render import CARRIED  # noqa: E402
from bench_accuracy import evaluate_run  # noqa: E402  (one `awalker eval` wrapper for both benchmarks)

WALKS = ("07_01", "07_02")
VARIANT_NAMES = ("straight", "slow", "fast", "veer-left", "veer-right", "u-turn")
SETTINGS = {"mono": 1, "two": 2}


def log(text: str) -> None:
    print(f"bench_realwalks: {text}", file=sys.stderr, flush=True)


def suffix(hands_off: bool, carry: str) -> str:
    """What the names of a sequence and its runs add for ``--hands-off`` and ``--carry``."""
    return ("_handsoff" if hands_off else "") + (f"_{carry}" if carry != "none" else "")


def sequence(root: Path, walk: str, variant: str, cameras: int, size: tuple[int, int], rate: float,
             background: int, hands_off: bool = False, carry: str = "none") -> Path:
    """The bag of one sequence, synthesised on first use (kept in ``root``). ``hands_off``: no
    background-only frames and no start or body description; ``carry``: what the person carries."""
    from awalker_tools.synth import VARIANTS, SynthConfig, synthesise

    seq = root / f"{walk}_{variant}_{cameras}cam{suffix(hands_off, carry)}"
    bag = seq / "synth.bag"
    if not bag.exists():
        frames = int(np.ceil(max(3.0, VARIANTS[variant][2] + 0.2) * rate))
        synthesise(SynthConfig(out_dir=seq, cameras=cameras, rate=rate, frames=frames,
                               background_frames=0 if hands_off else background, descriptions=not hands_off, seed=1, mocap=(MOCAP_DIR / "07.asf", MOCAP_DIR / f"{walk}.amc"), width=size[0],
                               height=size[1], person="dressed", variant=variant, user_start=True,
                               tape_measure=True, carry=carry), progress=False)
    return bag


def score(result: dict, variant: str, rate: float) -> dict:
    """The reported figures of one run."""
    from awalker_tools.synth import VARIANTS

    walk = result["walk"]
    entry = {"absolute_median_mm": round(result["absolute_mm"]["median"], 1),
             "relative_median_mm": round(result["relative_mm"]["median"], 1),
             "heading_median_deg": round(walk["heading_error_deg"]["median"], 1),
             "swap_fraction": round(walk["swap_fraction"], 3), "fallen_frames": walk["fallen_frames"],
             "off_person_frames": walk["off_person_frames"],
             "ended_on_person": not (walk["end"]["fallen"] or walk["end"]["off_person"]),
             "recovery": result.get("recovery", {})}
    gait = result.get("gait", {}).get("comparison", {})    # heel strikes against the truth's (inference/gait.py)
    entry.update({"heel_strike_error_s": gait.get("timing_error_s_median"),
                  "heel_strike_bias_s": gait.get("timing_bias_s_median"),
                  "step_length_error_m": gait.get("step_length_error_m_median"),
                  "speed_error_m_s": gait.get("speed_error_m_s")})
    bias = result["bias"]        # constant offsets in the person's frame (evaluation.marker_bias)
    entry["absolute_without_offsets_mm"] = round(bias["absolute_median_without_offsets_mm"], 1)
    entry["offsets_mm"] = {group: {axis: round(v, 1) for axis, v in offset.items()}
                           for group, offset in group_offsets(bias).items()}
    turn = VARIANTS[variant][1]
    if turn is not None:
        after = int(round((turn[1] + turn[2] + 1.0) * rate))       # frames after the person appears
        headings = walk["per_frame_heading_error_deg"]
        entry["heading_1s_after_turn_deg"] = round(headings[min(after, len(headings) - 1)], 1)
    return entry


def hands_off_figures(runs: Path, run_dir: Path, job: str, seed: int, rate: float) -> dict:
    """Start delay (s after the first frame; None if it never started) of a hands-off run, and the
    absolute median error of the hand-started run of the same sequence and seed (None if not run)."""
    import yaml

    start = run_dir / "start.yaml"
    frame = (yaml.safe_load(start.read_text()) or {}).get("start", {}).get("frame") if start.is_file() else None
    hand = runs / f"{job}_tracker_s{seed}" / "eval.json"
    return {"start_delay_s": None if frame is None else round(frame / rate, 3),
            "hand_started_absolute_median_mm": round(json.loads(hand.read_text())["absolute_mm"]["median"], 1)
            if hand.is_file() else None}


def main(argv: list[str] | None = None) -> int:
    from awalker_tools.pipeline import TrackOptions, run_tracking

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True, help="sequences and runs are kept (and reused) here")
    parser.add_argument("--walks", nargs="+", choices=WALKS, default=list(WALKS))
    parser.add_argument("--variants", nargs="+", choices=VARIANT_NAMES, default=list(VARIANT_NAMES))
    parser.add_argument("--settings", nargs="+", choices=list(SETTINGS), default=list(SETTINGS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4], help="tracker seeds")
    parser.add_argument("--particles", type=int, default=TrackOptions.particles,
                        help="particles per run (default: awalker track's own default, what a user gets)")
    parser.add_argument("--size", nargs=2, type=int, default=(320, 240), metavar=("W", "H"))
    parser.add_argument("--rate", type=float, default=30.0, choices=(30.0, 60.0))
    parser.add_argument("--background-frames", type=int, default=15)
    parser.add_argument("--no-dead-reckoning", action="store_true", help="skip the no-image baseline")
    parser.add_argument("--hands-off", action="store_true",
                        help="no background-only frames, no start or body description: the automatic start")
    parser.add_argument("--leg-scale-spread", type=float, default=0.0,
                        help="awalker track --leg-scale-spread (the particles' leg lengths; runs named ..._legsS_sN)")
    parser.add_argument("--fit-body", action="store_true",
                        help="awalker track --fit-body: fit the leg length to the images, then track again (runs named ..._fit_sN)")
    parser.add_argument("--likelihood-scale", type=float, default=TrackOptions.likelihood_scale,
                        help="awalker track --likelihood-scale for the tracked runs (runs named ..._lsS_sN unless the default)")
    parser.add_argument("--lookahead", type=int, default=TrackOptions.lookahead,
                        help="awalker track --lookahead (tau) for the tracked runs (runs named ..._laT_sN unless the default)")
    parser.add_argument("--pelvis-ceiling", type=float, default=TrackOptions.pelvis_ceiling,
                        help="awalker track --pelvis-ceiling for the tracked runs, with any number of cameras (runs named "
                             "..._pcF_sN; default: the tracker's, 0.97 with two cameras and off with one)")
    parser.add_argument("--true-body", action="store_true",
                        help="track with the person's own sizes (ground_truth_body.yaml), not the tape's (runs named ..._truebody_sN)")
    parser.add_argument("--carry", choices=CARRIED, default="none",
                        help="the person carries a backpack or a shoulder bag (synth --carry): unmodelled foreground")
    args = parser.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
    args.out.mkdir(parents=True, exist_ok=True)
    report: dict = {"benchmark": "realwalks", "settings": {
        "particles": args.particles, "size": list(args.size), "rate": args.rate, "seeds": args.seeds,
        "background_frames": 0 if args.hands_off else args.background_frames, "hands_off": args.hands_off,
        "carry": args.carry, "leg_scale_spread": args.leg_scale_spread, "fit_body": args.fit_body, "true_body": args.true_body,
        "likelihood_scale": args.likelihood_scale, "lookahead": args.lookahead, "pelvis_ceiling": args.pelvis_ceiling, "cpus": os.cpu_count()}, "runs": {}, "summary": {}}
    if args.true_body and args.hands_off:
        parser.error("--true-body replaces the body description, which --hands-off runs do not have")
    jobs = [(w, v, s) for w in args.walks for v in args.variants for s in args.settings]
    for k, (walk, variant, setting) in enumerate(jobs):
        name = f"{walk} {variant} {setting}"
        started = time.monotonic()
        bag = sequence(args.out / "sequences", walk, variant, SETTINGS[setting], tuple(args.size), args.rate,
                       args.background_frames, args.hands_off, args.carry)
        own_body = bag.parent / "ground_truth_body.yaml"
        if args.true_body and not own_body.is_file():
            log(f"error: {own_body} missing (the sequence predates it): delete {bag.parent} to synthesise it again")
            return 2
        modes = [("tracker", seed, True) for seed in args.seeds]
        if not (args.no_dead_reckoning or args.hands_off):    # dead reckoning needs a start description
            modes += [("dead_reckoning", seed, False) for seed in args.seeds]
        for mode, seed, images in modes:
            legs = f"_legs{args.leg_scale_spread:g}" if images and args.leg_scale_spread > 0 else ""
            legs += "_fit" if images and args.fit_body else ""
            legs += "_truebody" if images and args.true_body else ""
            if images and args.likelihood_scale != TrackOptions.likelihood_scale:
                legs += f"_ls{args.likelihood_scale:g}"
            if images and args.lookahead != TrackOptions.lookahead:
                legs += f"_la{args.lookahead}"
            if images and args.pelvis_ceiling != TrackOptions.pelvis_ceiling:
                legs += f"_pc{args.pelvis_ceiling:g}"
            run_name = f"{walk}_{variant}_{setting}_{mode}{suffix(args.hands_off, args.carry)}{legs}_s{seed}"
            run_dir = args.out / "runs" / run_name
            if not (run_dir / "eval.json").exists():
                with contextlib.redirect_stdout(sys.stderr):
                    run_tracking(TrackOptions(bag=bag, out=run_dir, particles=args.particles, seed=seed,
                                              body=own_body if images and args.true_body else None,
                                              likelihood_scale=args.likelihood_scale if images else 0.0,
                                              recovery=images, lookahead=args.lookahead if images else TrackOptions.lookahead,
                                              leg_scale_spread=args.leg_scale_spread if images else 0.0,
                                              pelvis_ceiling=args.pelvis_ceiling if images else TrackOptions.pelvis_ceiling,
                                              auto_start=args.hands_off, overlays=False, quiet=True,
                                              fit_body=True if images and args.fit_body else None))
                evaluate_run(run_dir)
            result = json.loads((run_dir / "eval.json").read_text())
            if "bias" not in result:        # scored before eval reported the offsets
                result = evaluate_run(run_dir)
            entry = score(result, variant, args.rate)
            if args.hands_off:
                entry.update(hands_off_figures(args.out / "runs", run_dir, f"{walk}_{variant}_{setting}", seed, args.rate))
            report["runs"].setdefault(name, {}).setdefault(mode, {})[seed] = entry
        runs = report["runs"][name]
        tracked = list(runs["tracker"].values())
        summary = {key: {"median": float(np.median([r[key] for r in tracked])),
                         "worst": float(np.max([r[key] for r in tracked]))}
                   for key in ("absolute_median_mm", "relative_median_mm")}
        if "heading_1s_after_turn_deg" in tracked[0]:
            values = [r["heading_1s_after_turn_deg"] for r in tracked]
            summary["heading_1s_after_turn_deg"] = {"median": float(np.median(values)), "worst": float(np.max(values))}
        summary["absolute_without_offsets_mm"] = {"median": float(np.median([r["absolute_without_offsets_mm"] for r in tracked])),
                                                  "worst": float(np.max([r["absolute_without_offsets_mm"] for r in tracked]))}
        summary["offsets_mm_median"] = {group: {axis: float(np.median([r["offsets_mm"][group][axis] for r in tracked]))
                                                for axis in OFFSET_AXES} for group in OFFSET_GROUPS}
        summary["runs_ended_on_person"] = f"{sum(r['ended_on_person'] for r in tracked)}/{len(tracked)}"
        summary["reacquisitions"] = [r["recovery"].get("reacquisitions", 0) for r in tracked]
        summary["swap_fraction_median"] = float(np.median([r["swap_fraction"] for r in tracked]))
        for key in ("heel_strike_error_s", "heel_strike_bias_s", "step_length_error_m", "speed_error_m_s"):
            values = [r[key] for r in tracked if r.get(key) is not None]
            summary[f"{key}_median"] = float(np.median(values)) if values else None
        if args.hands_off:
            delays = [r["start_delay_s"] for r in tracked if r["start_delay_s"] is not None]
            summary["started"] = f"{len(delays)}/{len(tracked)}"
            summary["start_delay_s"] = {"median": float(np.median(delays)) if delays else None,
                                        "worst": float(np.max(delays)) if delays else None}
            hand = [r["hand_started_absolute_median_mm"] for r in tracked if r["hand_started_absolute_median_mm"]]
            if len(hand) == len(tracked):
                summary["hand_started_absolute_median_mm"] = {"median": float(np.median(hand)),
                                                              "worst": float(np.max(hand))}
        if "dead_reckoning" in runs:
            summary["dead_reckoning_absolute_median_mm"] = float(np.median(
                [r["absolute_median_mm"] for r in runs["dead_reckoning"].values()]))
        report["summary"][name] = summary
        log(f"[{k + 1}/{len(jobs)}] {name}: absolute {summary['absolute_median_mm']['median']:.0f} "
            f"(worst {summary['absolute_median_mm']['worst']:.0f}), relative "
            f"{summary['relative_median_mm']['median']:.0f} (worst {summary['relative_median_mm']['worst']:.0f}) mm"
            + f", without constant offsets {summary['absolute_without_offsets_mm']['median']:.0f}"
            + (f", heading 1 s after the turn {summary['heading_1s_after_turn_deg']['median']:.0f} deg"
               if "heading_1s_after_turn_deg" in summary else "")
            + f", on the person at the end {summary['runs_ended_on_person']}"
            + (f", started {summary['started']} after {summary['start_delay_s']['median']} s (median)"
               if args.hands_off else "")
            + (f", hand-started {summary['hand_started_absolute_median_mm']['median']:.0f} mm"
               if "hand_started_absolute_median_mm" in summary else "")
            + (f", dead reckoning {summary['dead_reckoning_absolute_median_mm']:.0f} mm (median of seeds)"
               if "dead_reckoning_absolute_median_mm" in summary else "")
            + f" ({time.monotonic() - started:.0f} s)")
    report["overall"] = overall(report["summary"])
    print(json.dumps(report, indent=1))
    return 0


def overall(summaries: dict[str, dict]) -> dict:
    """Per setting (the last part of a sequence's name): the median of the walk medians, absolute and without
    the constant offsets, and the median over walks of each marker group's median offset (mm)."""
    by_setting: dict[str, list[dict]] = {}
    for name, summary in summaries.items():
        by_setting.setdefault(name.rsplit(" ", 1)[-1], []).append(summary)
    return {setting: {
        "walks": len(items),
        "absolute_median_mm": float(np.median([s["absolute_median_mm"]["median"] for s in items])),
        "absolute_without_offsets_mm": float(np.median([s["absolute_without_offsets_mm"]["median"] for s in items])),
        "offsets_mm": {group: {axis: float(np.median([s["offsets_mm_median"][group][axis] for s in items]))
                               for axis in OFFSET_AXES} for group in OFFSET_GROUPS}}
        for setting, items in by_setting.items()}


if __name__ == "__main__":
    sys.exit(main())
