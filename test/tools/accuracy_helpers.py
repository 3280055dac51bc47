"""Ground-truth stance leg from foot motion and the speed error of a run, shared by test_accuracy.py
and benchmarks/bench_accuracy.py.

`awalker eval` labels the true stance leg as the foot with the lower markers; with motion capture
that label is biased by per-foot marker heights (CMU 07_01: the flat left foot's markers rest
~38 mm above the floor, the right foot's ~15 mm) and it gives double-support frames to the
trailing foot. Here the stance foot is the PLANTED one: its heel and toe move slower than
``planted_m_s`` horizontally while the other foot swings faster than ``swinging_m_s``; frames where
neither or both feet are planted (double support) are not scored.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from awalker_tools import evaluation
from awalker_tools.commands.eval import load_truth


def foot_speed(track: evaluation.PoseTrack, side: str) -> np.ndarray:
    """(F,) horizontal speed (m/s) of a foot: the larger of its heel and toe speeds, central differences."""
    t = track.stamps_ns * 1e-9
    speeds = [np.linalg.norm(np.gradient(track.marker(f"{side}_{part}")[:, :2], t, axis=0), axis=1)
              for part in ("heel", "toe")]
    return np.maximum(*speeds)


def planted_stance_left(truth: evaluation.PoseTrack, planted_m_s: float = 0.25,
                        swinging_m_s: float = 0.5) -> np.ndarray:
    """(F,) object array: True = left foot planted and right swinging, False = the reverse, None = not clear."""
    left, right = foot_speed(truth, "left"), foot_speed(truth, "right")
    out = np.full(left.size, None, dtype=object)
    out[(left < planted_m_s) & (right > swinging_m_s)] = True
    out[(right < planted_m_s) & (left > swinging_m_s)] = False
    return out


def stance_agreement(run_dir: Path, truth_source: Path) -> tuple[float, int]:
    """Fraction of scored frames where the tracker's stance-left probability (summary.csv) is on the
    planted foot's side of 0.5, and the number of scored frames. Truth: CSV or bag."""
    truth = load_truth(Path(truth_source))
    summary = evaluation.read_summary_csv(Path(run_dir) / "summary.csv")
    labels = dict(zip(truth.stamps_ns.tolist(), planted_stance_left(truth).tolist()))
    scored = [(p > 0.5) == labels[s] for s, p in zip(summary["stamp_ns"].tolist(),
                                                     summary["stance_left_probability"].tolist())
              if labels.get(s) is not None]
    return (float(np.mean(scored)) if scored else float("nan")), len(scored)


def speed_error(run_dir: Path, truth_source: Path) -> float:
    """Mean |estimated - true| walking speed over the tracked frames (m/s); the true speed is the
    pelvis ground speed over about one stride, as `awalker eval` plots it. Truth: CSV or bag."""
    truth = load_truth(Path(truth_source))
    summary = evaluation.read_summary_csv(Path(run_dir) / "summary.csv")
    rate = 1e9 / float(np.median(np.diff(truth.stamps_ns)))
    true_speed = dict(zip(truth.stamps_ns.tolist(), evaluation.pelvis_speed(truth, rate).tolist()))
    errors = [abs(s - true_speed[t]) for t, s in zip(summary["stamp_ns"].tolist(), summary["speed"].tolist())
              if t in true_speed]
    return float(np.mean(errors)) if errors else float("nan")
