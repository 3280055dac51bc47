"""`awalker gaits solve|plot`: solve the cyclic-gait table (eq. 3) and plot it (paper Fig. 3-4)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from awalker_tracker.errors import InputError
from awalker_tracker.model import cyclic_gaits
from awalker_tracker.model.walker import WalkerParams

from awalker_tools.outdir import check_new_path

PACKAGED_TABLE = Path(cyclic_gaits.__file__).resolve().parents[1] / "data" / "cyclic_gaits.json"
#: The installed awalker_tracker package: its files (the packaged gait table among them) are never written.
PACKAGE_DIR = PACKAGED_TABLE.parents[1]
#: `gaits solve` writes here unless --out says otherwise (a new file in the current folder).
DEFAULT_OUT = "cyclic_gaits.json"
#: The most grid points `gaits solve` takes (the default grid has 11 x 19 = 209; each point takes up to a few
#: seconds, so 2:7:100000, with millions of points, would not finish).
MAX_GRID_POINTS = 2000


def _range(text: str, what: str) -> tuple[float, float, int]:
    try:
        lo, hi, n = text.split(":")
        value = (float(lo), float(hi), int(n))
    except ValueError:
        raise InputError(f"--{what} {text!r}: expected LOW:HIGH:COUNT, e.g. 2:7:11") from None
    if not (np.isfinite(value[0]) and np.isfinite(value[1]) and 0 < value[0] < value[1]) or value[2] < 2:
        raise InputError(f"--{what} {text!r}: need finite 0 < LOW < HIGH and COUNT >= 2")
    return value


def solve_output(text: str, force: bool) -> Path:
    """Where `gaits solve` may write: a new file (or, with ``force``, an existing one), never a file of the
    installed package (``PACKAGE_DIR``: its gait table is read-only)."""
    out = check_new_path(text, "--out", force=force)
    if out.resolve().is_relative_to(PACKAGE_DIR):
        raise InputError(f"--out {out}: inside the installed package ({PACKAGE_DIR}), whose gait table is "
                         "read-only; write the table elsewhere and pass it with --table")
    return out


def run_solve(args: argparse.Namespace) -> int:
    if not (np.isfinite(args.leg_length) and args.leg_length > 0):
        raise InputError(f"--leg-length {args.leg_length}: expected a positive length in metres")
    if not (np.isfinite(args.gravity) and args.gravity > 0):
        raise InputError(f"--gravity {args.gravity}: expected a positive finite acceleration in m/s^2")
    speeds_range, steps_range = _range(args.speeds, "speeds"), _range(args.step_lengths, "step-lengths")
    if speeds_range[2] * steps_range[2] > MAX_GRID_POINTS:
        raise InputError(f"--speeds {args.speeds} x --step-lengths {args.step_lengths}: "
                         f"{speeds_range[2] * steps_range[2]} grid points, at most {MAX_GRID_POINTS}")
    out = solve_output(args.out, args.force)
    params = WalkerParams(leg_length=args.leg_length, gravity=args.gravity)
    speeds, step_lengths = cyclic_gaits.grid_axes(speeds_range, steps_range)
    table = cyclic_gaits.solve_grid(params, speeds, step_lengths, progress=cyclic_gaits.stderr_progress, family=args.family)
    table.save(out)
    coef, rms = cyclic_gaits.fit_impulse_mean(table) if table.converged.sum() >= 4 else (np.full(4, np.nan), np.nan)
    radius = table.step_map_radius[table.converged]
    summary = {"out": str(out), "converged": int(table.converged.sum()), "points": int(table.converged.size),
               "max_residual_converged": float(np.max(table.residual[table.converged], initial=0.0)),
               "locally_stable_points": int(np.sum(radius < 1.0)),
               "impulse_fit": {"coefficients": np.asarray(coef).tolist(), "rms_m_per_s": rms},
               "not_converged": [{"speed_kmh": round(float(table.speeds[i]) / cyclic_gaits.KMH, 3),
                                  "step_length": float(table.step_lengths[j]), "reason": table.reason[i][j]}
                                 for i, j in zip(*np.nonzero(~table.converged))]}
    print(json.dumps(summary, indent=1))
    return 0


def run_plot(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = cyclic_gaits.GaitTable.load(args.table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    speeds_kmh = table.speeds / cyclic_gaits.KMH
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for ax, name, label in zip(axes, ("stiffness", "toe_off_impulse"),
                               ("stiffness kappa (N m/rad per kg)", "toe-off impulse iota (m/s)")):
        values = np.where(table.converged, getattr(table, name), np.nan)
        # kappa spans two orders of magnitude (and dips below 0): a symmetric-log colour scale
        norm = matplotlib.colors.SymLogNorm(linthresh=0.1) if name == "stiffness" else None
        mesh = ax.pcolormesh(speeds_kmh, table.step_lengths, values.T, shading="nearest", cmap="viridis", norm=norm)
        levels = np.array([-0.2, 0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0]) if name == "stiffness" else 8
        contours = ax.contour(speeds_kmh, table.step_lengths, values.T, levels=levels, colors="w", linewidths=0.6)
        ax.clabel(contours, fontsize=7, fmt="%.2g")
        fig.colorbar(mesh, ax=ax, label=label)
        ax.set_xlabel("speed (km/h)")
        ax.set_ylabel("step length (m)")
        ax.set_title(f"{label.split(' (')[0]} of cyclic gaits (blank: not converged)")
    fig.tight_layout()
    fig3 = out / "gait_parameters.png"
    fig.savefig(fig3, dpi=110)
    plt.close(fig)

    pts = table.converged_points()
    coef, rms = cyclic_gaits.fit_impulse_mean(table)
    fig = plt.figure(figsize=(6.5, 5))
    ax = fig.add_subplot(projection="3d")
    w1, w2 = pts["pre_stance_rate"], pts["pre_swing_rate"]
    ax.scatter(w1, w2, pts["toe_off_impulse"], c="k", s=8, label="cyclic gaits")
    g1, g2 = np.meshgrid(np.linspace(w1.min(), w1.max(), 20), np.linspace(w2.min(), w2.max(), 20))
    ax.plot_wireframe(g1, g2, coef[0] + coef[1] * g1 + coef[2] * g2 + coef[3] * g1 * g2, color="tab:red",
                      linewidth=0.5, label=f"bilinear fit (RMS {rms:.3f} m/s)")
    ax.set_xlabel("phi1'- (rad/s)")
    ax.set_ylabel("phi2'- (rad/s)")
    ax.set_zlabel("iota (m/s)")
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig4 = out / "impulse_fit.png"
    fig.savefig(fig4, dpi=110)
    plt.close(fig)
    print(json.dumps({"plots": [str(fig3), str(fig4)], "impulse_fit": {"coefficients": coef.tolist(),
                                                                     "rms_m_per_s": rms}}))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("gaits", help="solve or plot the cyclic-gait table of the walker (eq. 3)")
    sub = parser.add_subparsers(dest="gaits_command", required=True)
    solve = sub.add_parser("solve", help="solve eq. (3) over a speed x step-length grid (progress on stderr)")
    solve.add_argument("--out", default=DEFAULT_OUT,
                       help=f"output JSON, a new file (default {DEFAULT_OUT} in the current folder; never the "
                            "packaged table, which is read-only)")
    solve.add_argument("--force", action="store_true", help="replace --out if it exists")
    solve.add_argument("--speeds", default="2:7:11", help="km/h LOW:HIGH:COUNT (default 2:7:11)")
    solve.add_argument("--step-lengths", default="0.3:1.2:19", help="m LOW:HIGH:COUNT (default 0.3:1.2:19)")
    solve.add_argument("--leg-length", type=float, default=WalkerParams().leg_length, help="L in m")
    solve.add_argument("--gravity", type=float, default=WalkerParams().gravity, help="g in m/s^2")
    solve.add_argument("--family", choices=("symmetric", "stable"), default="symmetric",
                       help="which cyclic gait to keep where several solve eq. (3): the mirror-symmetric one "
                            "(the default, the packaged table) or the most stable (smallest step-map radius)")
    solve.set_defaults(func=run_solve)
    plot = sub.add_parser("plot", help="PNG plots of kappa/iota over the grid (Fig. 3) and the iota fit (Fig. 4)")
    plot.add_argument("--out", required=True, help="output directory")
    plot.add_argument("--table", default=None, help="gait table JSON (default: the packaged table)")
    plot.set_defaults(func=run_plot)
