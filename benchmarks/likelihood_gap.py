"""Is it the likelihood or the search? The image likelihood of the truth against that of a run's MAP poses.

For a synthetic sequence SEQ (an `awalker synth` output directory: calibration.yaml, ground_truth.csv) and
runs of `awalker track` on its bag (RUN: result.bag with the features, poses.csv, body.yaml), at every other
frame of each run:
- gap: log p(images | truth) - log p(images | MAP), both posed as the run's body from their markers
  (``acclaim.segments_from_markers``; the previous frame's pose for the flow), summed over the cameras. Positive:
  the likelihood prefers the truth, so what keeps the tracker from it is the prior or the search (a pose the
  prior cannot reach, or particles that do not get there), not the likelihood;
- by group: the gain of putting the truth's markers of one group (the upper body, the knees, each foot, each
  leg below the hip) into the MAP pose, where the likelihood sees the difference.
The likelihood is untempered here (the tracker multiplies it by ``--likelihood-scale``, 0.1). Prints JSON: per
run and over all runs, the median gap (nats), the share of frames where the truth scores higher and the
median gain of each group.

    .venv/bin/python benchmarks/likelihood_gap.py SEQ RUN [RUN ...]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from depth_profile import recorded_features  # noqa: E402  (one reader of the recorded features)

GROUPS = {
    "upper_body": ("pelvis", "thorax", "head", "left_hip", "right_hip"),
    "knees": ("left_knee", "right_knee"),
    "left_foot": ("left_ankle", "left_heel", "left_toe"),
    "right_foot": ("right_ankle", "right_heel", "right_toe"),
    "left_leg": ("left_knee", "left_ankle", "left_heel", "left_toe"),
    "right_leg": ("right_knee", "right_ankle", "right_heel", "right_toe"),
}


def summary(gaps: list[float], gains: dict[str, list[float]]) -> dict:
    values = np.asarray(gaps, float)
    return {"frames": int(values.size),
            "gap_nats_median": round(float(np.median(values)), 1) if values.size else None,
            "truth_higher_share": round(float(np.mean(values > 0)), 3) if values.size else None,
            "group_gain_nats_median": {g: round(float(np.median(v)), 1) if v else None for g, v in gains.items()}}


def main(argv: list[str] | None = None) -> int:
    from awalker_tracker.errors import InputError
    from awalker_tracker.model.acclaim import MARKER_NAMES, segments_from_markers
    from awalker_tracker.model.body import BodyDescription
    from awalker_tracker.vision.camera import load_calibration
    from awalker_tracker.vision.likelihood import log_likelihood

    from awalker_tools import evaluation

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("seq", type=Path, help="awalker synth output directory (the truth)")
    parser.add_argument("runs", type=Path, nargs="+", help="awalker track output directories of runs on SEQ's bag")
    args = parser.parse_args(argv)
    report: dict = {"seq": str(args.seq), "runs": {}}
    all_gaps: list[float] = []
    all_gains: dict[str, list[float]] = {g: [] for g in GROUPS}
    try:
        cameras = load_calibration(args.seq / "calibration.yaml")
        truth = evaluation.read_poses_csv(args.seq / "ground_truth.csv")
        truth_columns = [truth.marker_names.index(m) for m in MARKER_NAMES]
        truth_row = {int(s): k for k, s in enumerate(truth.stamps_ns)}
        for run in args.runs:
            body = BodyDescription.from_yaml(run / "body.yaml")
            estimate = evaluation.read_poses_csv(run / "poses.csv")
            columns = [estimate.marker_names.index(m) for m in MARKER_NAMES]
            features = recorded_features(run)

            def score(now: np.ndarray, before: np.ndarray, stamp: int) -> float:
                pose, previous = segments_from_markers(body, now[None]), segments_from_markers(body, before[None])
                return sum(float(log_likelihood(body.parts, pose, previous, [c], [features[c.name][stamp]])[0])
                           for c in cameras)

            gaps: list[float] = []
            gains: dict[str, list[float]] = {g: [] for g in GROUPS}
            for k in range(1, len(estimate.frames), 2):
                stamp = int(estimate.stamps_ns[k])
                j = truth_row.get(stamp, 0)
                if j == 0 or any(stamp not in features.get(c.name, {}) for c in cameras):
                    continue
                mine = [estimate.markers[i][columns] for i in (k, k - 1)]
                true = [truth.markers[i][truth_columns] for i in (j, j - 1)]
                base = score(*mine, stamp)
                gaps.append(score(*true, stamp) - base)
                for group, names in GROUPS.items():
                    rows = [MARKER_NAMES.index(n) for n in names]
                    mixed = [m.copy() for m in mine]
                    for m, t in zip(mixed, true):
                        m[rows] = t[rows]
                    gains[group].append(score(*mixed, stamp) - base)
            report["runs"][run.name] = summary(gaps, gains)
            all_gaps += gaps
            for group in GROUPS:
                all_gains[group] += gains[group]
            print(f"likelihood_gap: {run.name}: {report['runs'][run.name]['gap_nats_median']} nats", file=sys.stderr,
                  flush=True)
    except InputError as exc:
        print(f"likelihood_gap: error: {exc}", file=sys.stderr)
        return 2
    report["all_runs"] = summary(all_gaps, all_gains)
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
