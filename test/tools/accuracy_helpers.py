"""The per-frame speed error of a run, shared by test_accuracy.py and benchmarks/bench_accuracy.py."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from awalker_tools import evaluation
from awalker_tools.commands.eval import load_truth


def speed_error(run_dir: Path, truth_source: Path) -> float:
    """Mean |estimated - true| walking speed over the tracked frames (m/s); the true speed is the truth's
    pelvis by the tracker's own definition (``inference.speed``), as `awalker eval` plots it. Truth: CSV or bag."""
    truth = load_truth(Path(truth_source))
    summary = evaluation.read_summary_csv(Path(run_dir) / "summary.csv")
    true_speed = dict(zip(truth.stamps_ns.tolist(), evaluation.track_speed(truth).tolist()))
    errors = [abs(s - true_speed[t]) for t, s in zip(summary["stamp_ns"].tolist(), summary["speed"].tolist())
              if t in true_speed]
    return float(np.mean(errors)) if errors else float("nan")


def pelvis_offsets(estimate: evaluation.PoseTrack, truth: evaluation.PoseTrack) -> np.ndarray:
    """Estimated minus true pelvis position (F, 3) m over the frames both tracks have, in frame order."""
    rows, true_rows = evaluation.align_tracks(estimate, truth)
    return estimate.marker("pelvis")[rows] - truth.marker("pelvis")[true_rows]
