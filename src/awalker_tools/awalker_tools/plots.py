"""PNG plots of a tracking run: marker error over time (paper Fig. 15), speed and stance-leg
probability over time (Fig. 8). Matplotlib with the Agg backend (no display needed)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_errors(path: Path, frames: np.ndarray, absolute_mm: np.ndarray, relative_mm: np.ndarray,
                title: str = "") -> Path:
    """Absolute and pelvis-aligned relative 3D marker error (mm) per frame."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.plot(frames, absolute_mm, label="absolute", color="tab:red")
    ax.plot(frames, relative_mm, label="relative (pelvis aligned)", color="tab:blue")
    ax.set_xlabel("frame")
    ax.set_ylabel("mean marker error (mm)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title or "3D marker error over time")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def plot_speed_and_stance(path: Path, frames: np.ndarray, speed: np.ndarray, speed_std: np.ndarray,
                          stance_left_probability: np.ndarray, true_speed: np.ndarray | None = None,
                          true_frames: np.ndarray | None = None, title: str = "",
                          in_view: np.ndarray | None = None) -> Path:
    """Posterior walking speed (mean +- std, m/s; ``true_speed``: the truth's by the same definition,
    ``inference.speed``) and P(left leg is stance) per frame; ``in_view`` (per frame, bool): the frames with the
    person out of every camera's view are shaded, and the lines break where frames are missing (between tracks)."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    frames = np.asarray(frames, float)
    if frames.size > 1 and np.any(np.diff(frames) > 1):      # a gap between tracks: NaN rows break the lines
        cut = np.nonzero(np.diff(frames) > 1)[0] + 1
        frames, speed, speed_std, stance_left_probability = (
            np.insert(np.asarray(a, float), cut, np.nan) for a in (frames, speed, speed_std, stance_left_probability))
        if in_view is not None:
            in_view = np.insert(np.asarray(in_view, bool), cut, True)
    if in_view is not None and not np.all(in_view):
        for axis in (top, bottom):
            axis.fill_between(frames, 0, 1, where=~np.asarray(in_view, bool), step="mid", color="0.8",
                              transform=axis.get_xaxis_transform(), label="out of view")
    top.plot(frames, speed, color="tab:green", label="estimated")
    top.fill_between(frames, speed - speed_std, speed + speed_std, color="tab:green", alpha=0.25)
    if true_speed is not None:
        top.plot(true_frames if true_frames is not None else frames, true_speed, "k--", label="true (pelvis)")
    top.set_ylabel("speed (m/s)")
    top.grid(alpha=0.3)
    top.legend()
    top.set_title(title or "walking speed and stance leg")
    bottom.plot(frames, stance_left_probability, color="tab:purple")
    bottom.set_ylim(-0.05, 1.05)
    bottom.set_ylabel("P(left stance)")
    bottom.set_xlabel("frame")
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def plot_gait(path: Path, steps: list, pelvis_xy: np.ndarray, true_steps: list | None = None,
              true_pelvis_xy: np.ndarray | None = None, title: str = "") -> Path:
    """Footprints seen from above over the ground plane with the pelvis path (left), and step length,
    step time and speed per step (right). ``steps``: inference.gait_events.Step lists."""
    plt = _pyplot()
    fig = plt.figure(figsize=(11, 4.5))
    top_view = fig.add_subplot(1, 2, 1)
    colours = {"left": "tab:blue", "right": "tab:red"}
    if true_steps is not None:
        top_view.plot(true_pelvis_xy[:, 0], true_pelvis_xy[:, 1], color="0.6", lw=1, label="true path")
        for s in true_steps:
            top_view.plot(s.x, s.y, marker="s", ms=9, mfc="none", mec=colours[s.foot], alpha=0.6)
    top_view.plot(pelvis_xy[:, 0], pelvis_xy[:, 1], color="k", lw=1.5, label="estimated path")
    for s in steps:
        top_view.plot(s.x, s.y, marker="o", ms=6, color=colours[s.foot])
        top_view.annotate(str(s.index), (s.x, s.y), fontsize=7, xytext=(3, 3), textcoords="offset points")
    top_view.plot([], [], "o", color=colours["left"], label="left heel strike")
    top_view.plot([], [], "o", color=colours["right"], label="right heel strike")
    if true_steps is not None:
        top_view.plot([], [], "s", mfc="none", mec="0.4", label="true strikes")
    top_view.set_aspect("equal", adjustable="datalim")
    top_view.set_xlabel("x (m)")
    top_view.set_ylabel("y (m)")
    top_view.grid(alpha=0.3)
    top_view.legend(fontsize=7)
    top_view.set_title(title or "footprints from above")
    per_step = fig.add_subplot(1, 2, 2)
    t = [s.time_s for s in steps]
    per_step.plot(t, [s.step_length_m for s in steps], "o-", label="step length (m)")
    per_step.plot(t, [s.step_time_s for s in steps], "s-", label="step time (s)")
    per_step.plot(t, [s.speed_m_s for s in steps], "^-", label="speed (m/s)")
    if true_steps is not None:
        per_step.plot([s.time_s for s in true_steps], [s.step_length_m for s in true_steps], "o--", color="0.5",
                      label="true step length")
    per_step.set_xlabel("time of heel strike (s)")
    per_step.grid(alpha=0.3)
    per_step.legend(fontsize=7)
    per_step.set_title("gait parameters per step")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)
