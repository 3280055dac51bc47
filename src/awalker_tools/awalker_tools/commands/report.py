"""`awalker report DIR`: one HTML page of a tracking run for a clinician or an engineer.

The page (DIR/report.html, self-contained: pictures embedded) holds the gait table (per step and
the medians, left/right symmetry), the footprints picture, speed and stance-leg probability over
time, the tracking quality (effective sample size, re-sampling, recovery events), how the run started
(run.yaml: where the start and the body came from, what the first pass fitted) and, when `awalker eval`
was run, the errors against ground truth and the gait comparison.
"""
from __future__ import annotations

import argparse
import base64
import csv
import html
import json
import sys
from pathlib import Path

import numpy as np

from awalker_tracker.errors import InputError

from awalker_tools import evaluation, plots
from awalker_tools.outdir import add_written, check_may_write, incomplete_reason, read_run_file

REPORT_FILE = "report.html"


def _image(path: Path, caption: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(caption)}" style="max-width:100%">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def _table(rows: list[dict[str, object]], columns: list[str]) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(r.get(c, '')))}</td>" for c in columns) + "</tr>"
                   for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _fmt(value: object, digits: int = 2) -> str:
    return f"{value:.{digits}f}" if isinstance(value, (int, float)) and np.isfinite(value) else "-"


def _start_section(info: dict) -> list[str]:
    """How the run started (run.yaml's ``info``; none: no section): the start's and the body's sources and what the
    first pass fitted."""
    if not info:
        return []
    row = {"start": info.get("start_source", "-"), "body": info.get("body_source", "-")}
    columns = ["start", "body"]
    fit = info.get("body_fit") or {}
    if "log_evidence" in fit:
        row["leg length fitted (m)"] = (f"{fit['leg_length_m']} (x{fit['leg_factor']:.2f}"
                                        + (", the seen height kept" if fit.get("height_kept") else "") + ")")
        columns.append("leg length fitted (m)")
    if "stance_leg" in fit:
        evidence = fit["stance_log_evidence"]
        filters = fit.get("stance_filters_per_leg")
        row["stance leg at the start, weighed (log evidence, nats)"] = (
            f"{fit['stance_leg']} ({', '.join(f'{leg} {value:.1f}' for leg, value in evidence.items())}"
            + (f"; {filters} filters per leg" if filters else "") + ")")
        columns.append("stance leg at the start, weighed (log evidence, nats)")
    return ["<h2>How it started</h2>", _table([row], columns)]


def _tracks_section(info: dict) -> list[str]:
    """The run's tracks (run.yaml's ``info``, its ``tracks``): frames, frames in view, and where and why each
    ended."""
    tracks = info.get("tracks")
    if not isinstance(tracks, list) or not tracks:
        return []
    rows = [{"track": t["track"], "frames": f"{t['first_frame']}-{t['last_frame']}", "in view": t["frames_in_view"],
             "ended": ("tracked to the end" if not t["ended"] else
                       f"frame {t['ended']['frame']}: the person {t['ended']['reason']} (last in view at frame "
                       f"{t['ended']['last_in_view_frame']})")} for t in tracks]
    return ["<h2>Tracks</h2>", _table(rows, ["track", "frames", "in view", "ended"])]


def build_report(run_dir: Path) -> Path:
    """Write run_dir/report.html from the files `awalker track` (and `awalker eval`) wrote; returns its path."""
    run_dir = Path(run_dir)
    needed = ["summary.csv", "gait.csv", "gait.json"]
    missing = [n for n in needed if not (run_dir / n).is_file()]
    if missing:
        raise InputError(f"{run_dir}: no {', '.join(missing)} (the output directory of `awalker track` holds them)")
    summary = evaluation.read_summary_csv(run_dir / "summary.csv")
    gait_summary = json.loads((run_dir / "gait.json").read_text())
    with open(run_dir / "gait.csv", newline="") as fh:
        steps = list(csv.DictReader(fh))
    written = [REPORT_FILE]
    if not (run_dir / "speed_stance.png").is_file():
        plots.plot_speed_and_stance(run_dir / "speed_stance.png", summary["frame"], summary["speed"],
                                    summary["speed_std"], summary["stance_left_probability"],
                                    in_view=summary["in_view"] > 0)
        written.append("speed_stance.png")
    parts = [f"<h1>awalker: {html.escape(run_dir.name)}</h1>"]
    if (reason := incomplete_reason(run_dir)) is not None:
        parts.append(f"<p><strong>Incomplete run:</strong> {html.escape(reason)}; this page shows the frames it "
                     "holds.</p>")
    frames = len(summary["frame"])
    sym = gait_summary.get("symmetry_left_over_right", {})
    parts.append("<h2>Gait</h2>")
    parts.append(_table([{
        "steps": gait_summary["steps"], "step length (m)": _fmt(gait_summary["step_length_m"]),
        "step width (m)": _fmt(gait_summary["step_width_m"]), "step time (s)": _fmt(gait_summary["step_time_s"]),
        "cadence (steps/min)": _fmt(gait_summary["cadence_steps_min"], 0),
        "speed (m/s)": _fmt(gait_summary["speed_m_s"]),
        "symmetry L/R length": _fmt(sym.get("step_length_m")), "symmetry L/R time": _fmt(sym.get("step_time_s")),
    }], ["steps", "step length (m)", "step width (m)", "step time (s)", "cadence (steps/min)", "speed (m/s)",
         "symmetry L/R length", "symmetry L/R time"]))
    if gait_summary.get("steps_out_of_view"):
        parts.append(f"<p>{gait_summary['steps_out_of_view']} step(s) predicted while the person was out of view "
                     "are left out of the steps and the medians.</p>")
    if "tracks" in gait_summary:
        parts.append(f"<p>The medians above are track {gait_summary['track']}'s (the most steps seen); per track:</p>")
        parts.append(_table([{"track": t["track"], "steps": t["steps"], "step length (m)": _fmt(t["step_length_m"]),
                              "cadence (steps/min)": _fmt(t["cadence_steps_min"], 0), "speed (m/s)": _fmt(t["speed_m_s"])}
                             for t in gait_summary["tracks"]],
                            ["track", "steps", "step length (m)", "cadence (steps/min)", "speed (m/s)"]))
    if "sides_note" in gait_summary:
        parts.append(f"<p><strong>Left and right:</strong> {html.escape(gait_summary['sides_note'])}.</p>")
    parts.append(f"<p>{html.escape(gait_summary['stance_note'])}.</p>")
    step_rows = [{k: (_fmt(float(v), 3) if k not in ("track", "index", "frame", "foot", "stamp_ns") else v)
                  for k, v in s.items()} for s in steps]
    parts.append(_table(step_rows, ["track", "index", "time_s", "foot", "x", "y", "step_length_m", "step_width_m",
                                    "step_time_s", "cadence_steps_min", "speed_m_s"]))
    for name, caption in (("gait_vs_truth.png", "footprints from above (circles: tracked, squares: truth)"),
                          ("gait.png", "footprints from above and gait parameters per step"),
                          ("speed_stance.png", "walking speed and probability that the left foot is on the ground "
                                               "(shaded: the person out of every camera's view)")):
        if (run_dir / name).is_file():
            parts.append(_image(run_dir / name, caption))
    parts.append("<h2>Tracking quality</h2>")
    ess = summary["effective_sample_size"]
    parts.append(_table([{
        "frames": frames, "N_eff median": _fmt(float(np.median(ess)), 0), "N_eff min": _fmt(float(np.min(ess)), 0),
        "resampled frames": int(np.sum(summary["resampled"])),
        "re-acquisitions": int(np.sum(summary["reacquired"] > 0)),
        "fallen walkers re-seeded": int(np.sum(summary["reseeded_fallen"])),
        "frames standing still (walkers held)": int(np.sum(summary["person_still"] > 0)),
        "frames with an uncertain stance leg (0.2-0.8)":
            int(np.sum((summary["stance_left_probability"] > 0.2) & (summary["stance_left_probability"] < 0.8))),
    }], ["frames", "N_eff median", "N_eff min", "resampled frames", "re-acquisitions", "fallen walkers re-seeded",
         "frames standing still (walkers held)", "frames with an uncertain stance leg (0.2-0.8)"]))
    info = read_run_file(run_dir)
    parts += _tracks_section(info)
    parts += _start_section(info)
    if (run_dir / "eval.json").is_file():
        result = json.loads((run_dir / "eval.json").read_text())
        parts.append("<h2>Against ground truth</h2>")
        parts.append(f"<pre>{html.escape(evaluation.format_table(result, label=run_dir.name))}</pre>")
        if (run_dir / "error_over_time.png").is_file():
            parts.append(_image(run_dir / "error_over_time.png", "3D marker error over time"))
    style = ("body{font-family:sans-serif;max-width:1000px;margin:auto}table{border-collapse:collapse;margin:8px 0}"
             "td,th{border:1px solid #ccc;padding:3px 6px;font-size:13px}figure{margin:10px 0}")
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>awalker report: {html.escape(run_dir.name)}"
            f"</title><style>{style}</style></head><body>{''.join(parts)}</body></html>")
    out = run_dir / REPORT_FILE
    out.write_text(page)
    add_written(run_dir, written)
    return out


def run(args: argparse.Namespace) -> int:
    run_dir = Path(args.dir)
    if not run_dir.is_dir():
        raise InputError(f"{run_dir}: not a directory (expected the --out DIR of `awalker track`)")
    check_may_write(run_dir, [REPORT_FILE])      # an earlier report (listed in run.yaml) only
    if (reason := incomplete_reason(run_dir)) is not None:
        print(f"awalker report: {run_dir} is incomplete ({reason}); reporting the frames it holds", file=sys.stderr)
    print(f"wrote {build_report(run_dir)}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "report", help="one HTML page of a tracking run: gait table, footprints, speed, tracking quality",
        description="Writes DIR/report.html (pictures embedded) from the outputs of `awalker track` and, if run, "
                    "`awalker eval`: the gait per step and its medians and symmetry, footprints seen from above, "
                    "speed and stance-leg probability over time, N_eff and recovery events, errors against truth.")
    parser.add_argument("dir", help="output directory of `awalker track`")
    parser.set_defaults(func=run)
