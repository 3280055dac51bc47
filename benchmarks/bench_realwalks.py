"""Tracking real people's walks as users record them: the broad development benchmark.

Each run is a trial of the development set (``awalker_tools/devset.py``: 15 stretches of CMU motion capture,
8 subjects, straight and slow walks, starts from standing, a curved U-turn, a turn on the spot, slow turns with
pauses) drawn from the run's seed as a user records it (person shape and clothes, cameras, rate and image
size, light and noise, the user's errors in the start and body descriptions, no stance leg), rendered by the
dressed renderer, and tracked with `awalker track`'s defaults and the run's seed as the tracker seed:
hand-started (background frames, start and body descriptions as the user wrote them) and hands off (no
empty frames, no descriptions: the automatic start), with one camera and with two. Scored with `awalker eval`
against the motion capture.

Report (per setting and mode; only ever quote the reporting set's): median of the walk medians (a walk's
median: over its runs of each run's median error over frames, pelvis, thorax, hips, knees, ankles), the 90th
percentile run and the worst run, runs with legs swapped on more than 5 % of frames, runs whose cadence
(steps per minute) is more than 15 % off the person's (a walker stepping twice as often as a slow walker
swaps its legs at every extra step), the pelvis's mean error along the first camera's line of sight (its
depth, ``awalker eval``'s ``view_bias``: what one camera sees least), the largest
frame-to-frame pelvis step of the MAP path (poses.csv) and of the live path (the published MAP pose), the
turning trials' median, runs that ended on the person, runs in which most of the walkers fell in one frame
(JSON only), per subject the heel-strike timing and step length
errors (medians over runs of each run's median); hands off: the ratio to the hand-started figure and, per
walk, the runs whose start named the wrong stance leg. The JSON also gives where each run's start lies along the
first camera's view (``start_depth_m``, + = farther; hands off, the automatic start's) and its median per setting
and mode.

    .venv/bin/python benchmarks/bench_realwalks.py                                   # quick subset, seeds 0-2
    .venv/bin/python benchmarks/bench_realwalks.py --set reporting --seeds 0 1 2 3 4 5 6 7 8 9 --markdown table.md
    .venv/bin/python benchmarks/bench_realwalks.py --set tuning --trials 91_10 --seeds 0 --settings mono

``--against REPORT`` compares each run with the same run of an earlier report (the JSON this benchmark
printed, other code on the same recordings): per setting and mode, the paired differences' mean with its
standard error, median, and the runs better and worse. A default chosen on these same runs starts ahead of
any change, and the slow walks move by +-25-33 mm a run whatever changes (docs/tracking.md, *Reading these
comparisons*): a standard error of 4-5 mm over 22 runs does not tell a 5 mm change from chance.

Sequences and runs are kept in --out and reused (a run with an eval.json is not tracked again; delete it to
re-run; a run folder without one, left by a run stopped before its evaluation, is tracked afresh). Several
benchmark processes may share one --out (e.g. one per core, with different --seeds or --settings): each
recording and each run is claimed by a lock file beside it (``claimed``), so a process waits for a recording or
run another live process is making, then reuses it. A run's
result bags (60-550 MB each; the reporting set over ten seeds would fill ~50 GB) are deleted once it is
evaluated; --keep-bags keeps them, for benchmarks/depth_profile.py and likelihood_gap.py, which read the features.
Prints ONE JSON document on stdout; progress on stderr.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_accuracy import evaluate_run  # noqa: E402  (one `awalker eval` wrapper for both benchmarks)

SETTINGS = {"mono": 1, "two": 2}
MODES = ("hand", "handsoff")
SWAPPED_FRACTION = 0.05       # a run with legs swapped on more of its frames counts as swapped
CADENCE_OFF = 0.15            # a run whose steps per minute are more than this fraction off the truth's
FAILED = "failed.txt"         # in a run's directory: why `awalker track` refused to track (the run counts as lost)


def log(text: str) -> None:
    print(f"bench_realwalks: {text}", file=sys.stderr, flush=True)


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (on this machine)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextlib.contextmanager
def claimed(path: Path, poll_s: float = 5.0):
    """Hold ``path`` (a recording's or a run's folder) for this process: the lock file ``<path>.lock`` holds its
    pid, made atomically with the pid already in it (written to a file of this process's own, then hard-linked to
    the lock's name), so no lock is ever seen empty. While another live process holds it, wait (saying so once) and
    re-try; a lock whose process has died (a benchmark stopped by a signal) is taken over. The lock is removed on
    leaving, also after an error. Without it, a second process found a run folder without its eval.json, took it
    for one left by a stopped run and deleted it under the process tracking it."""
    lock = path.with_name(path.name + ".lock")
    lock.parent.resolve().mkdir(parents=True, exist_ok=True)     # also where a folder is a link to one not made yet
    mine = lock.with_name(f"{lock.name}.{os.getpid()}")
    waited = False
    while True:
        mine.write_text(str(os.getpid()))
        try:
            os.link(mine, lock)      # fails if the lock exists: atomic, like O_EXCL
            break
        except FileExistsError:
            pass
        finally:
            mine.unlink()
        try:
            holder = int(lock.read_text().strip() or 0)
        except (OSError, ValueError):
            holder = 0               # gone since: look again
        if holder and not _alive(holder):
            log(f"{lock}: its process {holder} is gone; taking it over")
            with contextlib.suppress(FileNotFoundError):
                lock.unlink()
            continue
        if not waited:
            log(f"{path.name}: process {holder or '?'} is making it; waiting")
            waited = True
        time.sleep(poll_s)
    try:
        yield
    finally:
        with contextlib.suppress(FileNotFoundError):
            lock.unlink()


def variant_of(setting: str, mode: str) -> str:
    return setting if mode == "hand" else f"{setting}_handsoff"


def start_figures(run_dir: Path, truth_csv: Path) -> dict:
    """Where the run started (its start.yaml: the user's, or hands off the automatic start with the leg weighed in
    the first pass) against the truth at that frame, reading both once:

    - ``start_leg_right``: whether its stance leg is the person's (``evaluation.start_stance_left``: the planted
      foot, or for a person standing still the other foot than the first step's); None without a stance leg or
      where the truth has no clear one (a double support);
    - ``start_depth_m``: how far (m) its position lies beyond the true pelvis along the first camera's horizontal
      line of sight (+ = farther from the camera; what one camera places least well, and a run keeps:
      docs/tracking.md, *The automatic start placed 0.2 m farther*).

    Both None if the run has no start or the truth no row at its frame."""
    import yaml

    from awalker_tools import evaluation
    from awalker_tracker.vision.camera import load_calibration

    out: dict = {"start_leg_right": None, "start_depth_m": None}
    start_file = run_dir / "start.yaml"
    if not start_file.is_file():
        return out
    start = (yaml.safe_load(start_file.read_text()) or {}).get("start", {})
    truth = evaluation.read_poses_csv(truth_csv)
    rows = np.flatnonzero(truth.frames == int(start.get("frame", -1)))
    if not rows.size:
        return out
    row = int(rows[0])
    if start.get("stance_leg") in ("left", "right"):
        left = evaluation.start_stance_left(truth, row)
        out["start_leg_right"] = None if left is None else (start["stance_leg"] == "left") == left
    if "position" in start:
        camera = load_calibration(run_dir / "calibration.yaml")[0]
        pelvis = truth.marker("pelvis")[row, :2]
        depth, _ = evaluation.split_along_ray(np.asarray(start["position"], float) - pelvis, pelvis, camera.position)
        out["start_depth_m"] = round(float(depth), 3)
    return out


def score(result: dict, run_dir: Path, truth_csv: Path) -> dict:
    """The figures of one run."""
    walk, gait = result["walk"], result.get("gait", {}).get("comparison", {})
    estimate, truth = (result.get("gait", {}).get(k, {}).get("cadence_steps_min") for k in ("estimate", "truth"))
    first_camera = next(iter(result.get("view_bias", {}).values()), None)
    continuity = result.get("continuity", {})
    return {"absolute_median_mm": round(result["absolute_mm"]["median"], 1),
            "relative_median_mm": round(result["relative_mm"]["median"], 1),
            "frames": result["absolute_mm"]["frames"],
            "swap_fraction": round(walk["swap_fraction"], 3),
            "heading_median_deg": round(walk["heading_error_deg"]["median"], 1),
            "ended_on_person": not (walk["end"]["fallen"] or walk["end"]["off_person"]),
            "off_person_frames": walk["off_person_frames"],
            "map_max_step_m_s": round(continuity.get("map_max_step_m_s", float("nan")), 2),
            "live_max_step_m_s": round(continuity.get("live_max_step_m_s", float("nan")), 2),
            "heel_strike_error_s": gait.get("timing_error_s_median"),
            "heel_strike_bias_s": gait.get("timing_bias_s_median"),
            "step_length_error_m": gait.get("step_length_error_m_median"),
            "cadence_ratio": round(estimate / truth, 3) if estimate and truth else None,
            "depth_bias_mm": None if first_camera is None else first_camera["depth_mm"],
            **start_figures(run_dir, truth_csv),
            "reacquisitions": result.get("recovery", {}).get("reacquisitions", 0),
            "frames_most_walkers_fallen": result.get("recovery", {}).get("frames_most_walkers_fallen", 0),
            **filter_load(run_dir)}


def filter_load(run_dir: Path) -> dict:
    """A run's filter frames/s (its posteriors over the seconds spent filtering, run.yaml; several benchmark
    processes at once share the cores) and its mean particle count (summary.csv; None where not recorded)."""
    import yaml

    from awalker_tools import evaluation

    run = yaml.safe_load((run_dir / "run.yaml").read_text()) or {}
    seconds = float(run.get("seconds_in_filter") or 0.0)
    counts = evaluation.read_summary_csv(run_dir / "summary.csv")["particles"]
    return {"filter_frames_per_s": round(run.get("posteriors", 0) / seconds, 2) if seconds > 0 else None,
            "mean_particles": round(float(np.mean(counts))) if counts.size and np.all(counts > 0) else None}


def failed_run(why: str) -> dict:
    """The figures of a run `awalker track` refused (e.g. no walking person found): infinitely wrong, never on the
    person, so that it counts against every figure."""
    inf = float("inf")
    return {"failed": why, "absolute_median_mm": inf, "relative_median_mm": inf, "frames": 0, "swap_fraction": 1.0,
            "heading_median_deg": inf, "ended_on_person": False, "off_person_frames": None,
            "map_max_step_m_s": float("nan"), "live_max_step_m_s": float("nan"), "heel_strike_error_s": None,
            "heel_strike_bias_s": None, "step_length_error_m": None, "cadence_ratio": None,
            "depth_bias_mm": None, "start_leg_right": None, "start_depth_m": None, "reacquisitions": 0,
            "filter_frames_per_s": None, "mean_particles": None}


def summarise(runs: dict[tuple[str, int], dict], trials: dict) -> dict:
    """Figures over the runs of one setting and mode: {(trial, seed): score}."""
    by_walk: dict[str, list[float]] = {}
    for (trial, _), run in runs.items():
        by_walk.setdefault(trial, []).append(run["absolute_median_mm"])
    walk_medians = {trial: float(np.median(v)) for trial, v in by_walk.items()}
    errors = np.array([r["absolute_median_mm"] for r in runs.values()])
    turning = [m for trial, m in walk_medians.items() if trials[trial].turns]
    out = {"runs": len(runs), "walks": len(walk_medians),
           "median_of_walk_medians_mm": float(np.median(list(walk_medians.values()))),
           "p90_run_mm": float(np.percentile(errors, 90, method="higher")), "worst_run_mm": float(errors.max()),
           "relative_median_of_walk_medians_mm": float(np.median([np.median([r["relative_median_mm"] for (t, _), r in
                                                                            runs.items() if t == trial])
                                                                 for trial in walk_medians])),
           "turning_median_of_walk_medians_mm": float(np.median(turning)) if turning else None,
           "runs_legs_swapped": int(sum(r["swap_fraction"] > SWAPPED_FRACTION for r in runs.values())),
           "runs_cadence_off": int(sum(r["cadence_ratio"] is None or abs(r["cadence_ratio"] - 1) > CADENCE_OFF
                                       for r in runs.values())),
           "median_abs_depth_bias_mm": float(np.median([abs(r["depth_bias_mm"]) for r in runs.values()
                                                         if r["depth_bias_mm"] is not None] or [np.nan])),
           # where the starts lie along the first camera's view (signed: a median away from 0 is a bias a run keeps)
           "median_start_depth_m": _median_of(runs, "start_depth_m"),
           "largest_map_step_m_s": float(np.nanmax([r["map_max_step_m_s"] for r in runs.values()])),
           "largest_live_step_m_s": float(np.nanmax([r["live_max_step_m_s"] for r in runs.values()])),
           "runs_ended_on_person": int(sum(r["ended_on_person"] for r in runs.values())),
           # runs in which most of the particle cloud fell in one frame (slow walks: docs/tracking.md, Alternatives)
           "runs_most_walkers_fell": int(sum(r.get("frames_most_walkers_fallen", 0) > 0 for r in runs.values())),
           "runs_failed": int(sum("failed" in r for r in runs.values())),
           "median_filter_frames_per_s": _median_of(runs, "filter_frames_per_s"),
           "median_mean_particles": _median_of(runs, "mean_particles"),
           "walk_medians_mm": {t: round(m, 1) for t, m in sorted(walk_medians.items())}}
    legs: dict[str, list[bool]] = {}
    for (trial, _), run in runs.items():
        if run["start_leg_right"] is not None:
            legs.setdefault(trial, []).append(run["start_leg_right"])
    out["start_leg_wrong"] = {t: f"{v.count(False)}/{len(v)}" for t, v in sorted(legs.items())}
    subjects: dict[str, dict[str, list[float]]] = {}
    for (trial, _), run in runs.items():
        for key in ("heel_strike_error_s", "heel_strike_bias_s", "step_length_error_m"):
            if run[key] is not None:
                subjects.setdefault(trials[trial].subject, {}).setdefault(key, []).append(run[key])
    out["gait_by_subject"] = {s: {k: round(float(np.median(v)), 3) for k, v in figures.items()}
                              for s, figures in sorted(subjects.items())}
    return out


#: A run counts as better or worse than the baseline's by more than this (mm of its median error).
PAIRED_MARGIN_MM = 1.0


def paired(runs: dict[str, dict[str, dict]], baseline: dict[str, dict[str, dict]]) -> dict[str, dict]:
    """Each setting and mode's runs against the same runs (trial, seed, setting, mode) of a baseline report (both
    ``report["runs"]``: {"07_01 s0": {"two": figures}}): the paired difference of each run's median error (mm),
    its mean with the standard error of the mean, its median, the runs better and worse by more than
    PAIRED_MARGIN_MM and the largest changes. A run that failed on one side only is infinitely better or worse:
    counted, not averaged."""
    differences: dict[str, list[tuple[str, float, float]]] = {}
    for key, variants in sorted(runs.items()):
        for variant, entry in variants.items():
            base = baseline.get(key, {}).get(variant)
            if base is not None:
                differences.setdefault(variant, []).append(
                    (key, float(base["absolute_median_mm"]), float(entry["absolute_median_mm"])))
    out = {}
    for variant, rows in sorted(differences.items()):
        # a run that failed on both sides did not change
        change = np.array([0.0 if new == old else new - old for _, old, new in rows])
        finite = change[np.isfinite(change)]
        order = [row for row, d in sorted(zip(rows, change), key=lambda pair: abs(pair[1]), reverse=True) if d != 0.0]
        error = float(finite.std(ddof=1) / np.sqrt(finite.size)) if finite.size > 1 else None
        out[variant] = {
            "runs": len(rows), "mean_mm": round(float(finite.mean()), 1) if finite.size else None,
            "standard_error_mm": None if error is None else round(error, 1),
            "median_mm": round(float(np.median(change)), 1),
            "better": int(np.sum(change < -PAIRED_MARGIN_MM)), "worse": int(np.sum(change > PAIRED_MARGIN_MM)),
            "not_finite": int(change.size - finite.size),
            "largest": [f"{key} {old:.0f} -> {new:.0f}" for key, old, new in order[:4]]}
    return out


def _median_of(runs: dict[tuple[str, int], dict], key: str) -> float | None:
    """The median of a run figure over the runs that have it (None if none has)."""
    values = [r.get(key) for r in runs.values() if r.get(key) is not None]
    return float(np.median(values)) if values else None


def markdown(report: dict) -> str:
    """The report's table for the README: one row per figure, a column per setting and mode."""
    columns = [(s, m) for s in SETTINGS for m in MODES if f"{s} {m}" in report["summary"]]
    if not columns:
        return ""
    head = "| " + " | ".join(["figure"] + [f"{'one camera' if s == 'mono' else 'two cameras'}, "
                                             f"{'hand-started' if m == 'hand' else 'hands off'}" for s, m in columns]) + " |"
    rows = [head, "|" + "---|" * (len(columns) + 1)]

    def row(label: str, fmt) -> None:
        rows.append("| " + " | ".join([label] + [fmt(report["summary"][f"{s} {m}"], s, m) for s, m in columns]) + " |")

    row("median of walk medians (mm)", lambda x, s, m: f"{x['median_of_walk_medians_mm']:.0f}")
    row("relative (pelvis aligned), median of walk medians (mm)",
        lambda x, s, m: f"{x['relative_median_of_walk_medians_mm']:.0f}")
    row("90th percentile run / worst run (mm)", lambda x, s, m: f"{x['p90_run_mm']:.0f} / {x['worst_run_mm']:.0f}")
    row("turning trials, median of walk medians (mm)",
        lambda x, s, m: "-" if x["turning_median_of_walk_medians_mm"] is None else f"{x['turning_median_of_walk_medians_mm']:.0f}")
    row("hands off / hand-started", lambda x, s, m: (
        f"{x['median_of_walk_medians_mm'] / report['summary'][f'{s} hand']['median_of_walk_medians_mm']:.2f}"
        if m == "handsoff" and f"{s} hand" in report["summary"] else "-"))
    row(f"runs with legs swapped on > {SWAPPED_FRACTION:.0%} of frames",
        lambda x, s, m: f"{x['runs_legs_swapped']} of {x['runs']}")
    row(f"runs whose cadence is more than {CADENCE_OFF:.0%} off the person's (steps/min)",
        lambda x, s, m: f"{x['runs_cadence_off']} of {x['runs']}")
    row("pelvis depth bias along the first camera's view, median over runs of its size (mm)",
        lambda x, s, m: f"{x['median_abs_depth_bias_mm']:.0f}")
    row("largest pelvis step between frames, MAP path / live (m/s)",
        lambda x, s, m: f"{x['largest_map_step_m_s']:.1f} / {x['largest_live_step_m_s']:.1f}")
    row("starts naming the wrong stance leg, worst walk",
        lambda x, s, m: max(x["start_leg_wrong"].values(), key=lambda v: int(v.split("/")[0]) / max(int(v.split("/")[1]), 1))
        if x.get("start_leg_wrong") else "-")
    row("runs ending on the person (runs that never started)",
        lambda x, s, m: f"{x['runs_ended_on_person']} of {x['runs']} ({x['runs_failed']})")
    walks = sorted({w for s, m in columns for w in report["summary"][f"{s} {m}"]["walk_medians_mm"]})
    rows += ["", "| walk: median over its runs (mm) | " + " | ".join(head.split(" | ")[1:]),
             "|" + "---|" * (len(columns) + 1)]
    for walk in walks:
        rows.append(f"| {walk} | " + " | ".join(
            f"{report['summary'][f'{s} {m}']['walk_medians_mm'].get(walk, float('nan')):.0f}" for s, m in columns) + " |")
    subjects = sorted({k for s, m in columns for k in report["summary"][f"{s} {m}"]["gait_by_subject"]})
    rows += ["", "| subject: heel-strike timing / step length error, medians of runs | "
             + " | ".join(head.split(" | ")[1:]), "|" + "---|" * (len(columns) + 1)]
    for subject in subjects:
        cells = []
        for s, m in columns:
            g = report["summary"][f"{s} {m}"]["gait_by_subject"].get(subject, {})
            cells.append(f"{g['heel_strike_error_s']:.3f} s / {100 * g['step_length_error_m']:.1f} cm"
                         if "heel_strike_error_s" in g and "step_length_error_m" in g else "-")
        rows.append(f"| {subject} | " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


def drop_result_bags(run_dir: Path) -> list[Path]:
    """Delete the result bags of an evaluated run (its own and its first pass's); returns those deleted."""
    from awalker_tools.outdir import RESULT_BAG
    from awalker_tools.pipeline import FIRST_PASS_DIR

    bags = [bag for bag in (run_dir / RESULT_BAG, run_dir / FIRST_PASS_DIR / RESULT_BAG) if bag.exists()]
    for bag in bags:
        shutil.rmtree(bag)
    return bags


def track_and_evaluate(run_dir: Path, bag: Path, args: argparse.Namespace, seed: int, mode: str) -> None:
    """Track ``bag`` into ``run_dir`` and evaluate it, unless an earlier run left its eval.json or its
    ``FAILED`` note (a folder with neither was left by a run stopped before its evaluation: tracked afresh)."""
    from awalker_tools.pipeline import TrackOptions, run_tracking
    from awalker_tracker.errors import InputError

    if (run_dir / "eval.json").exists():
        if "view_bias" not in json.loads((run_dir / "eval.json").read_text()):
            evaluate_run(run_dir)           # evaluated before eval split the error by camera: again
        return
    if (run_dir / FAILED).exists():
        return
    if run_dir.exists():    # left by a run stopped before its evaluation (Ctrl-C, a full disk)
        shutil.rmtree(run_dir)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            run_tracking(TrackOptions(bag=bag, out=run_dir, particles=args.particles,
                                      min_particles=args.min_particles, seed=seed, auto_start=mode == "handsoff",
                                      overlays=False, quiet=True))
        evaluate_run(run_dir)
        if not args.keep_bags:
            drop_result_bags(run_dir)
    except InputError as exc:       # e.g. no walking person found: the run failed, say so
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / FAILED).write_text(str(exc))


def main(argv: list[str] | None = None) -> int:
    from awalker_tools import devset
    from awalker_tools.pipeline import TrackOptions

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--set", choices=("quick", "tuning", "reporting", "all"), default="quick",
                        help="which trials (awalker_tools/devset.py; default quick: a small tuning subset)")
    parser.add_argument("--trials", nargs="+", help="only these trials of the set")
    parser.add_argument("--seeds", nargs="+", type=int, help="run seeds (recording and tracker; default 0-2 for "
                                                               "quick, else 0-9)")
    parser.add_argument("--settings", nargs="+", choices=list(SETTINGS), default=list(SETTINGS))
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument("--particles", type=int, default=TrackOptions.particles,
                        help="particles per run (default: awalker track's own default, what a user gets)")
    parser.add_argument("--min-particles", type=int, default=None,
                        help="the adaptive count's fewest particles (awalker track --min-particles; default: the "
                             "profile's, what a user gets)")
    parser.add_argument("--out", type=Path, default=Path("bench_realwalks"),
                        help="sequences and runs are kept (and reused) here (default ./bench_realwalks)")
    parser.add_argument("--markdown", type=Path, help="also write the summary table (markdown) here")
    parser.add_argument("--keep-bags", action="store_true",
                        help="keep each run's result bags (by default deleted once the run is evaluated)")
    parser.add_argument("--against", type=Path, metavar="REPORT",
                        help="a JSON report of an earlier run of this benchmark (other code, the same recordings): "
                             "each run's error against the same run there (paired differences)")
    args = parser.parse_args(argv)
    baseline = None
    if args.against is not None:
        try:
            baseline = json.loads(args.against.read_text())["runs"]
            if not isinstance(baseline, dict):
                raise TypeError(f"its 'runs' is a {type(baseline).__name__}, not a mapping of runs")
            for key, variants in baseline.items():
                for variant, entry in variants.items():
                    if not isinstance(entry.get("absolute_median_mm"), (int, float)):
                        raise TypeError(f"run {key!r} {variant} has no absolute_median_mm")
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            parser.error(f"--against {args.against}: not a report of this benchmark (a JSON document with its "
                         f"'runs'): {exc}")
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
    trials = devset.trials_of(args.set)
    if args.trials:
        unknown = sorted(set(args.trials) - set(trials))
        if unknown:
            parser.error(f"not in the {args.set} set: {', '.join(unknown)} (it has {', '.join(trials)})")
        trials = [t for t in trials if t in args.trials]
    seeds = args.seeds if args.seeds is not None else (list(range(3)) if args.set == "quick" else list(range(10)))
    suffix = ("" if args.particles == TrackOptions.particles else f"_p{args.particles}") + (
        "" if args.min_particles is None else f"_m{args.min_particles}")
    report: dict = {"benchmark": "realwalks", "set": args.set, "trials": trials, "seeds": seeds,
                    "settings": {"particles": args.particles, "min_particles": args.min_particles,
                                 "cpus": os.cpu_count(),
                                 "tuning_subjects": list(devset.TUNING_SUBJECTS),
                                 "reporting_subjects": list(devset.REPORTING_SUBJECTS)},
                    "runs": {}, "summary": {}}
    jobs = [(t, s) for s in seeds for t in trials]     # seed by seed: every walk is seen early
    started = time.monotonic()
    scores: dict[str, dict[tuple[str, int], dict]] = {}
    for k, (trial, seed) in enumerate(jobs):
        recording = devset.Recording.draw(trial, seed)
        sequence = args.out / "sequences" / f"{trial}_s{seed}"
        with claimed(sequence):
            bags = devset.make_recording(recording, sequence, progress=False)
        for setting in args.settings:
            for mode in args.modes:
                variant = variant_of(setting, mode)
                run_dir = args.out / "runs" / f"{trial}_s{seed}_{variant}{suffix}"
                with claimed(run_dir):
                    track_and_evaluate(run_dir, bags[variant], args, seed, mode)
                if (run_dir / FAILED).exists():
                    entry = failed_run((run_dir / FAILED).read_text())
                else:
                    entry = score(json.loads((run_dir / "eval.json").read_text()), run_dir,
                                  bags[variant].parent / "ground_truth.csv")
                report["runs"].setdefault(f"{trial} s{seed}", {})[variant] = entry
                scores.setdefault(f"{setting} {mode}", {})[(trial, seed)] = entry
                log(f"[{k + 1}/{len(jobs)}] {trial} seed {seed} {variant}: {entry['absolute_median_mm']:.0f} mm, "
                    + (f"FAILED ({entry['failed']}), " if "failed" in entry else "")
                    + f"swapped {entry['swap_fraction']:.0%}, steps {entry['map_max_step_m_s']:.1f} / "
                    f"{entry['live_max_step_m_s']:.1f} m/s ({(time.monotonic() - started) / 60:.1f} min)")
    report["summary"] = {key: summarise(runs, devset.TRIALS) for key, runs in scores.items()}
    if baseline is not None:
        report["against"] = {"report": str(args.against), "by_setting": paired(report["runs"], baseline)}
        for variant, figures in report["against"]["by_setting"].items():
            log(f"against {args.against}, {variant}: {figures['runs']} runs, mean {figures['mean_mm']} mm "
                f"(standard error {figures['standard_error_mm']}), median {figures['median_mm']}, "
                f"{figures['better']} better and {figures['worse']} worse by more than {PAIRED_MARGIN_MM:.0f} mm; "
                + "; ".join(figures["largest"]))
    table = markdown(report)
    report["markdown"] = table
    if args.markdown:
        args.markdown.write_text(table)
    log("\n" + table)
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
