"""`awalker eval DIR [--truth CSV|BAG]`: marker errors, foot skate and plots of a tracking run."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import yaml

from awalker_tracker.errors import InputError
from awalker_tracker.vision.camera import load_calibration

from awalker_tools import evaluation, plots
from awalker_tools.outdir import RESULT_BAG, add_written, check_may_write, check_new_path, incomplete_reason

RUN_FILE = "run.yaml"   # written by `awalker track`: {input: bag path, ...}
#: What eval writes into the run's folder (besides --json's file, DIR/eval.json by default).
PLOTS = ("error_over_time.png", "speed_stance.png", "gait_vs_truth.png")
OUTPUTS = ("eval.json", *PLOTS)


def find_truth(run_dir: Path, truth: Path | None) -> Path:
    """The ground-truth source: --truth, else DIR/ground_truth.csv, else beside/in the input bag."""
    if truth is not None:
        if not truth.exists():
            raise InputError(f"--truth {truth}: no such file or bag")
        return truth
    candidates = [run_dir / "ground_truth.csv"]
    run_file = run_dir / RUN_FILE
    if run_file.is_file():
        info = yaml.safe_load(run_file.read_text()) or {}
        if info.get("input"):
            bag = Path(info["input"])
            candidates += [bag.parent / "ground_truth.csv", bag / "ground_truth.csv", bag]
    for c in candidates:
        if c.is_file() and c.suffix == ".csv":
            return c
        if c.exists() and c.suffix != ".csv":
            return c
    raise InputError(f"{run_dir}: no ground truth found (looked for {', '.join(map(str, candidates))}); "
                     "pass --truth ground_truth.csv or a bag with /awalker/ground_truth")


def load_truth(path: Path) -> evaluation.PoseTrack:
    if path.suffix == ".csv":
        return evaluation.read_poses_csv(path)
    return evaluation.truth_from_bag(path)


def run(args: argparse.Namespace) -> int:
    run_dir = Path(args.dir)
    if not run_dir.is_dir():
        raise InputError(f"{run_dir}: not a directory (expected the --out DIR of `awalker track`)")
    # the run's own files may be replaced (an earlier eval's, listed in run.yaml); anything else is refused
    check_may_write(run_dir, PLOTS)
    if args.json is not None:
        out = check_new_path(args.json, "--json", force=None)
    else:
        out = run_dir / "eval.json"
        check_may_write(run_dir, [out.name])
    if (reason := incomplete_reason(run_dir)) is not None:
        print(f"awalker eval: {run_dir} is incomplete ({reason}); evaluating the frames it holds", file=sys.stderr)
    estimate = evaluation.read_poses_csv(run_dir / "poses.csv")
    truth_path = find_truth(run_dir, Path(args.truth) if args.truth else None)
    truth = load_truth(truth_path)
    summary_path = run_dir / "summary.csv"
    summary = evaluation.read_summary_csv(summary_path) if summary_path.is_file() else None
    result_bag = run_dir / RESULT_BAG
    live = evaluation.live_track_from_bag(result_bag) if result_bag.exists() else None
    calibration = run_dir / "calibration.yaml"      # written by `awalker track`: the run's cameras
    cameras = load_calibration(calibration) if calibration.is_file() else []
    result = evaluation.evaluate(estimate, truth, summary, live, cameras)
    result["truth_source"] = str(truth_path)
    out.write_text(json.dumps(result, indent=1))
    per_frame = result["per_frame"]
    pngs = [plots.plot_errors(run_dir / "error_over_time.png", np.array(per_frame["frame"]),
                              np.array(per_frame["absolute_mm"]), np.array(per_frame["relative_mm"]),
                              title=f"3D marker error: {run_dir.name}")]
    if summary is not None:
        pngs.append(plots.plot_speed_and_stance(
            run_dir / "speed_stance.png", summary["frame"], summary["speed"], summary["speed_std"],
            summary["stance_left_probability"], true_speed=evaluation.track_speed(truth),
            true_frames=truth.frames, title=f"speed and stance leg: {run_dir.name}", in_view=summary["in_view"] > 0))
    stance = None
    if summary is not None and len(summary["stamp_ns"]) == len(estimate.stamps_ns):
        stance = np.array([0 if leg == "left" else 1 for leg in summary["stance_leg"]])
    pngs.append(plots.plot_gait(run_dir / "gait_vs_truth.png", evaluation.track_steps(estimate, stance),
                                estimate.marker("pelvis")[:, :2], evaluation.track_steps(truth),
                                truth.marker("pelvis")[:, :2], title=f"footprints: {run_dir.name} (squares: truth)"))
    inside = [p.name for p in (out, *pngs) if p.resolve().parent == run_dir.resolve()]
    add_written(run_dir, inside)
    print(evaluation.format_table(result, label=run_dir.name))
    print(f"wrote {out} and {', '.join(str(p) for p in pngs)}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "eval", help="3D marker error (absolute/relative), foot skate and plots of a tracking run",
        description="Compare DIR/poses.csv of `awalker track` with ground truth (paper Sec. 6): "
                    "median and mean +- std of absolute and pelvis-aligned errors over pelvis, thorax, "
                    "hips, knees and ankles; foot skate, penetration and float; writes DIR/eval.json "
                    "and PNG plots of error, speed and stance probability over time.")
    parser.add_argument("dir", help="output directory of `awalker track` (holds poses.csv, summary.csv)")
    parser.add_argument("--truth", help="ground truth: CSV (frame,stamp_ns,marker,x,y,z) or a bag with "
                                        "/awalker/ground_truth (default: found beside the run or input bag)")
    parser.add_argument("--json", help="where to write the metrics: a new file (default DIR/eval.json)")
    parser.set_defaults(func=run)
