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
                          true_frames: np.ndarray | None = None, title: str = "") -> Path:
    """Posterior walking speed (mean +- std, m/s) and P(left leg is stance) per frame."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
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
