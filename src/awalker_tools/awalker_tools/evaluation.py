"""Evaluation of tracked poses against ground truth (paper Sec. 6, HumanEva protocol).

Files (one row per frame and marker, metres, world frame z up):
    poses.csv / ground_truth.csv: ``frame,stamp_ns,marker,x,y,z``
    summary.csv: ``frame,stamp_ns,speed,speed_std,stance_left_probability,effective_sample_size,
                  resampled,heel_strike,stance_leg,reseeded_fallen,reacquired,person_still,strike_fraction,
                  track,in_view,cameras_in_view,particles``
                  (particles re-seeded at that frame after a fall / at the detected person, 1 where the
                  person stood still and the walkers were held, when in the period before the frame
                  the MAP walker struck, 0-1, NaN where it did not; which track of the run, from 1; 1 where
                  the person was in view of some camera, and the cameras that saw them, space-separated; the
                  particles the filter held, fewer than N where the adaptive count chose so)
Metrics:
- absolute error: per frame, mean 3D distance (mm) over pelvis, thorax, hips, knees, ankles;
- relative error: the same after translating the estimated pelvis onto the true one;
- median and mean +- std over frames (Table 2 format);
- foot skate: horizontal slip (mm) of a heel/toe marker that touches the ground in two
  consecutive frames; ground penetration (mm below z = 0) and float (mm of the lowest foot
  marker above the ground), computed for estimate and truth alike (the truth's values show
  the marker offset of the body model);
- constant offsets (``marker_bias``): each marker's mean error along the way the person faces, to their
  left and up, and the absolute error without them;
- the pelvis error seen from each camera (``view_bias``): along the camera's line of sight over the ground
  (depth, what one camera sees least) and across it;
- walk quality (``walk_quality``): facing-direction error, left/right leg swaps, frames fallen or
  off the person, and the state at the last frame (did the track end on the person, upright?).
"""
from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from awalker_tracker.errors import InputError
from awalker_tracker.inference.speed import walking_speed

EVAL_MARKERS = ("pelvis", "thorax", "left_hip", "right_hip", "left_knee", "right_knee",
                "left_ankle", "right_ankle")
FOOT_MARKERS = {"left": ("left_heel", "left_toe"), "right": ("right_heel", "right_toe")}
POSE_COLUMNS = ("frame", "stamp_ns", "marker", "x", "y", "z")
SUMMARY_COLUMNS = ("frame", "stamp_ns", "speed", "speed_std", "stance_left_probability",
                   "effective_sample_size", "resampled", "heel_strike", "stance_leg", "reseeded_fallen", "reacquired",
                   "person_still", "strike_fraction", "track", "in_view", "cameras_in_view", "particles")
# columns later versions added, read as 0 (strike_fraction: NaN, a strike at the frame; track 1, in view;
# particles 0: not recorded) from older files
OPTIONAL_SUMMARY_COLUMNS = {"reseeded_fallen": "0", "reacquired": "0", "person_still": "0", "strike_fraction": "nan",
                            "track": "1", "in_view": "1", "cameras_in_view": "", "particles": "0"}


@dataclass(frozen=True)
class PoseTrack:
    """Marker trajectories: ``markers[f, m]`` is marker ``marker_names[m]`` at frame ``frames[f]``."""

    frames: np.ndarray          # (F,) int
    stamps_ns: np.ndarray       # (F,) int
    marker_names: tuple[str, ...]
    markers: np.ndarray         # (F, M, 3) metres, NaN where a marker is missing

    def marker(self, name: str) -> np.ndarray:
        """(F, 3) trajectory of one marker."""
        return self.markers[:, self.marker_names.index(name)]


# ----------------------------------------------------------------------------- files

def write_poses_csv(path: Path, track: PoseTrack) -> None:
    """Write ``frame,stamp_ns,marker,x,y,z`` rows (metres)."""
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(POSE_COLUMNS)
        for f, (frame, stamp) in enumerate(zip(track.frames, track.stamps_ns)):
            for m, name in enumerate(track.marker_names):
                x, y, z = track.markers[f, m]
                writer.writerow([int(frame), int(stamp), name, f"{x:.6f}", f"{y:.6f}", f"{z:.6f}"])


def _read_csv_rows(path: Path, columns: Sequence[str], missing_file: str) -> list[dict[str, str]]:
    """The rows of a CSV file as dicts; InputError if the file or one of ``columns`` is missing."""
    if not path.is_file():
        raise InputError(f"{path}: {missing_file}")
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in columns if c not in (reader.fieldnames or [])]
        if missing:
            raise InputError(f"{path}: missing column(s) {', '.join(missing)} (expected header {','.join(columns)})")
        return list(reader)


def read_poses_csv(path: Path) -> PoseTrack:
    """Read a poses/ground-truth CSV; extra columns are ignored, missing ones are an InputError."""
    path = Path(path)
    rows = _read_csv_rows(path, POSE_COLUMNS, f"no such pose file (expected CSV with columns {','.join(POSE_COLUMNS)})")
    if not rows:
        raise InputError(f"{path}: no pose rows (expected one row per frame and marker)")
    names: list[str] = []
    frame_stamp: dict[int, int] = {}
    values: dict[tuple[int, str], tuple[float, float, float]] = {}
    for line, row in enumerate(rows, start=2):
        try:
            frame, stamp = int(row["frame"]), int(row["stamp_ns"])
            xyz = (float(row["x"]), float(row["y"]), float(row["z"]))
        except (TypeError, ValueError):
            raise InputError(f"{path}:{line}: expected integer frame/stamp_ns and numeric x,y,z, got {row}") from None
        if not np.all(np.isfinite(xyz)):
            raise InputError(f"{path}:{line}: non-finite coordinate in {row}")
        if frame in frame_stamp and frame_stamp[frame] != stamp:
            raise InputError(f"{path}:{line}: frame {frame} has two stamps ({frame_stamp[frame]}, {stamp})")
        frame_stamp[frame] = stamp
        if row["marker"] not in names:
            names.append(row["marker"])
        values[(frame, row["marker"])] = xyz
    frames = np.array(sorted(frame_stamp), np.int64)
    markers = np.full((frames.size, len(names), 3), np.nan)
    index = {f: i for i, f in enumerate(frames)}
    for (frame, name), xyz in values.items():
        markers[index[frame], names.index(name)] = xyz
    stamps = np.array([frame_stamp[f] for f in frames], np.int64)
    return PoseTrack(frames, stamps, tuple(names), markers)


def write_summary_csv(path: Path, rows: Sequence[dict]) -> None:
    """Write per-frame tracker summaries (keys = SUMMARY_COLUMNS)."""
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=SUMMARY_COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: row[k] if k in row else OPTIONAL_SUMMARY_COLUMNS[k] for k in SUMMARY_COLUMNS})


def read_summary_csv(path: Path) -> dict[str, np.ndarray]:
    """Columns of summary.csv as arrays (heel_strike and stance_leg as strings)."""
    path = Path(path)
    required = [c for c in SUMMARY_COLUMNS if c not in OPTIONAL_SUMMARY_COLUMNS]
    rows = _read_csv_rows(path, required, "no such summary file (written by `awalker track`)")
    out: dict[str, np.ndarray] = {}
    try:
        for key in SUMMARY_COLUMNS:
            col = [r.get(key) or OPTIONAL_SUMMARY_COLUMNS.get(key, "") for r in rows]
            if key in ("heel_strike", "stance_leg", "cameras_in_view"):
                out[key] = np.array(col, dtype=object)
            elif key in ("frame", "stamp_ns", "reseeded_fallen", "reacquired", "person_still", "track", "in_view",
                         "particles"):
                out[key] = np.array(col, np.int64)
            elif key == "resampled":
                out[key] = np.array([c.strip().lower() in ("1", "true") for c in col])
            else:
                out[key] = np.array(col, float)
    except ValueError as exc:
        raise InputError(f"{path}: bad value in column {key!r}: {exc}") from None
    return out


# ----------------------------------------------------------------------------- metrics

def align_tracks(estimate: PoseTrack, truth: PoseTrack) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``estimate`` and ``truth`` with equal stamps (frames whose stamps match)."""
    common, est_rows, true_rows = np.intersect1d(estimate.stamps_ns, truth.stamps_ns, return_indices=True)
    if common.size == 0:
        hint = ""
        if estimate.stamps_ns.size and truth.stamps_ns.size:
            offset_s = (truth.stamps_ns[0] - estimate.stamps_ns[0]) * 1e-9
            hint = (f"; the truth starts {offset_s:+.3f} s from the estimate: a bag made by `awalker convert "
                    f"--fps` counts from --start-time (default 0), so convert it with the truth's first stamp "
                    f"as --start-time")
        raise InputError("estimate and ground truth share no frame stamps "
                         f"(estimate {estimate.stamps_ns[:3].tolist()}..., truth {truth.stamps_ns[:3].tolist()}...)"
                         + hint)
    return est_rows, true_rows


def _select(track: PoseTrack, names: Sequence[str], rows: np.ndarray, what: str) -> np.ndarray:
    missing = [n for n in names if n not in track.marker_names]
    if missing:
        raise InputError(f"{what}: missing marker(s) {', '.join(missing)} (needed: {', '.join(names)})")
    return track.markers[rows][:, [track.marker_names.index(n) for n in names]]


def marker_errors(estimate: PoseTrack, truth: PoseTrack,
                  markers: Sequence[str] = EVAL_MARKERS) -> dict[str, np.ndarray]:
    """Per-frame absolute and pelvis-aligned relative errors (mm) over ``markers``."""
    est_rows, true_rows = align_tracks(estimate, truth)
    est = _select(estimate, markers, est_rows, "estimate")
    tru = _select(truth, markers, true_rows, "ground truth")
    absolute = 1000.0 * np.nanmean(np.linalg.norm(est - tru, axis=2), axis=1)
    est_p = _select(estimate, ["pelvis"], est_rows, "estimate")
    tru_p = _select(truth, ["pelvis"], true_rows, "ground truth")
    shifted = est - est_p + tru_p
    relative = 1000.0 * np.nanmean(np.linalg.norm(shifted - tru, axis=2), axis=1)
    per_marker = 1000.0 * np.nanmean(np.linalg.norm(est - tru, axis=2), axis=0)
    return {"frames": estimate.frames[est_rows], "stamps_ns": estimate.stamps_ns[est_rows],
            "absolute_mm": absolute, "relative_mm": relative,
            "per_marker_mm": dict(zip(markers, per_marker.tolist()))}


#: The marker groups whose constant offsets are reported together (``group_offsets``), and the offsets' axes.
OFFSET_GROUPS = {"pelvis": ("pelvis",), "thorax": ("thorax",), "hips": ("left_hip", "right_hip"),
                 "knees": ("left_knee", "right_knee"), "ankles": ("left_ankle", "right_ankle")}
OFFSET_AXES = ("along", "left", "up")


def group_offsets(bias: dict[str, object]) -> dict[str, dict[str, float]]:
    """Per ``OFFSET_GROUPS`` group present in a ``marker_bias`` result: its markers' mean offset (mm) per axis."""
    per_marker = bias["per_marker_mm"]
    return {group: {axis: float(np.mean([per_marker[m][axis] for m in markers])) for axis in OFFSET_AXES}
            for group, markers in OFFSET_GROUPS.items() if all(m in per_marker for m in markers)}


def marker_bias(estimate: PoseTrack, truth: PoseTrack, markers: Sequence[str] = EVAL_MARKERS) -> dict[str, object]:
    """Where the error is a constant offset: per marker the mean error (mm) in the person's frame, ``along``
    the way the truth faces (``facing``), to its ``left`` and ``up``, and the absolute error (median over
    frames, mm, as ``marker_errors``) with each marker's mean offset taken out in that frame at every frame.
    The difference between that and the absolute error is what the constant offsets (a body riding high, a
    pelvis lagging behind) cost; the rest varies from frame to frame."""
    est_rows, true_rows = align_tracks(estimate, truth)
    error = _select(estimate, markers, est_rows, "estimate") - _select(truth, markers, true_rows, "ground truth")
    heading = facing(truth, true_rows)
    forward = np.stack([np.cos(heading), np.sin(heading)], axis=1)                # (F, 2)
    left = np.stack([-forward[:, 1], forward[:, 0]], axis=1)
    # (F, M, 3): along, left, up
    local = np.stack([np.einsum("fmk,fk->fm", error[..., :2], forward),
                      np.einsum("fmk,fk->fm", error[..., :2], left), error[..., 2]], axis=2)
    bias = np.nanmean(local, axis=0)                                               # (M, 3)
    rest = local - bias[None]
    without = 1000.0 * np.median(np.nanmean(np.linalg.norm(rest, axis=2), axis=1))
    return {"per_marker_mm": {name: {axis: round(1000.0 * float(v), 1) for axis, v in zip(OFFSET_AXES, b)}
                              for name, b in zip(markers, bias)},
            "absolute_median_without_offsets_mm": float(without)}


def split_along_ray(offset_xy: np.ndarray, true_xy: np.ndarray, eye_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ground vectors ``offset_xy`` (..., 2) (m) split along the horizontal line of sight from ``eye_xy`` (2,) (a
    camera's position) to ``true_xy`` (..., 2) (+ = away from the camera) and across it (+ = to the left seen from
    the camera)."""
    ray = np.asarray(true_xy, float) - np.asarray(eye_xy, float)[:2]
    ray = ray / np.linalg.norm(ray, axis=-1, keepdims=True)
    offset = np.asarray(offset_xy, float)
    return (np.einsum("...k,...k->...", offset, ray),
            offset[..., 0] * -ray[..., 1] + offset[..., 1] * ray[..., 0])


def view_bias(estimate: PoseTrack, truth: PoseTrack, cameras: Sequence[object]) -> dict[str, dict[str, float]]:
    """Per camera (``vision.camera.Camera``, by name) the pelvis error (mm) over the ground split along the camera's
    horizontal line of sight to the true pelvis (``depth``, + = the estimate farther from the camera) and across
    it (``across``, + = to the left seen from the camera): the mean over frames, and the median of each frame's
    size (``depth_median_abs``, ``across_median_abs``). With one camera the error is mostly depth."""
    est_rows, true_rows = align_tracks(estimate, truth)
    true_pelvis = _select(truth, ["pelvis"], true_rows, "ground truth")[:, 0]
    error = _select(estimate, ["pelvis"], est_rows, "estimate")[:, 0] - true_pelvis
    out = {}
    for camera in cameras:
        depth, across = split_along_ray(error[:, :2], true_pelvis[:, :2], camera.position)
        out[camera.name] = {"depth_mm": round(1000.0 * float(np.nanmean(depth)), 1),
                            "across_mm": round(1000.0 * float(np.nanmean(across)), 1),
                            "depth_median_abs_mm": round(1000.0 * float(np.nanmedian(np.abs(depth))), 1),
                            "across_median_abs_mm": round(1000.0 * float(np.nanmedian(np.abs(across))), 1)}
    return out


def statistics(values: np.ndarray) -> dict[str, float]:
    """Median, mean and standard deviation over frames."""
    values = np.asarray(values, float)
    return {"median": float(np.median(values)), "mean": float(np.mean(values)), "std": float(np.std(values)),
            "max": float(np.max(values)), "frames": int(values.size)}


def ground_contact(track: PoseTrack, tolerance_m: float = 0.02) -> dict[str, np.ndarray]:
    """Per foot marker: (F,) bool, marker within ``tolerance_m`` of its lowest height in the sequence."""
    contact = {}
    for markers in FOOT_MARKERS.values():
        for name in markers:
            z = track.marker(name)[:, 2]
            contact[name] = z < np.nanmin(z) + tolerance_m
    return contact


def foot_plausibility(track: PoseTrack, tolerance_m: float = 0.02, stance_left: np.ndarray | None = None,
                      replaced: np.ndarray | None = None) -> dict[str, object]:
    """Foot skate, penetration and float of a pose track (mm).

    Skate: horizontal displacement between consecutive frames of each heel/toe marker that is
    in ground contact in both frames; with ``stance_left`` (per frame, e.g. the tracker's MAP
    stance leg) only the stance foot's markers count, and only while it stays the stance foot
    (a low swing foot gliding over the floor is not skating). ``replaced`` (per frame, bool): frames
    where the tracker put the body somewhere new (a re-acquisition); the step into such a frame is
    not a slide and is not counted (``skate_mm.replaced`` says how many frames were left out).
    Penetration: depth of the lowest foot marker below z = 0. Float: height of the lowest foot
    marker above z = 0.
    """
    for names in FOOT_MARKERS.values():
        for n in names:
            if n not in track.marker_names:
                raise InputError(f"pose track has no {n!r} marker (needed for foot skate)")
    contact = ground_contact(track, tolerance_m)
    consecutive = np.diff(track.frames) == 1
    if replaced is not None:
        consecutive &= ~np.asarray(replaced, bool)[1:]
    slips = []
    for name, touching in contact.items():
        xy = track.marker(name)[:, :2]
        step = 1000.0 * np.linalg.norm(np.diff(xy, axis=0), axis=1)
        both = touching[1:] & touching[:-1] & consecutive
        if stance_left is not None:
            on_foot = np.asarray(stance_left, bool) == name.startswith("left")
            both &= on_foot[1:] & on_foot[:-1]
        slips.append(step[both])
    slips_all = np.concatenate(slips) if slips else np.zeros(0)
    foot_z = np.stack([track.marker(n)[:, 2] for names in FOOT_MARKERS.values() for n in names], axis=1)
    lowest = 1000.0 * np.nanmin(foot_z, axis=1)
    penetration = np.maximum(0.0, -lowest) + 0.0   # + 0.0: no "-0.0" in reports
    floating = np.maximum(0.0, lowest)
    return {
        "skate_mm": {"mean": float(slips_all.mean()) if slips_all.size else 0.0,
                     "max": float(slips_all.max()) if slips_all.size else 0.0,
                     "contact_pairs": int(slips_all.size),
                     "replaced": int(np.sum(replaced)) if replaced is not None else 0},
        "penetration_mm": {"mean": float(penetration.mean()), "max": float(penetration.max())},
        "float_mm": {"mean": float(floating.mean()), "max": float(floating.max())},
    }


def track_speed(track: PoseTrack) -> np.ndarray:
    """Walking speed (F,) m/s of a pose track's pelvis, as the tracker defines and reports it
    (``inference.speed.walking_speed``: horizontal displacement per frame averaged over about one step)."""
    return walking_speed(track.marker("pelvis")[:, :2], track.stamps_ns)


def largest_step_speed(track: PoseTrack, marker: str = "pelvis") -> float:
    """The fastest horizontal move of ``marker`` from one frame of ``track`` to the next (m/s; 0 for fewer
    than two frames): a person's pelvis stays under ~3 m/s, so a faster step is a jump of the path."""
    if len(track.stamps_ns) < 2:
        return 0.0
    moved = np.linalg.norm(np.diff(track.marker(marker)[:, :2], axis=0), axis=1)
    seconds = np.diff(track.stamps_ns) * 1e-9
    return float(np.max(moved / np.maximum(seconds, 1e-9)))


def live_track_from_bag(path: Path) -> PoseTrack | None:
    """The pose the tracker published frame by frame (``/awalker/posterior``'s ``map_pose``: the joint states and
    markers a live user sees) from a run's result bag; None if the bag has no posteriors."""
    from awalker_tools.bagio import SequenceReader, stamp_ns_of

    with SequenceReader(path) as reader:
        if "/awalker/posterior" not in reader.topics:
            return None
        stamps, frames, markers, names = [], [], [], None
        for _, _, _, msg in reader.messages(["/awalker/posterior"]):
            pose = msg.map_pose
            names = tuple(pose.marker_names)
            stamps.append(stamp_ns_of(msg.header))
            frames.append(int(msg.frame_index))
            markers.append([[p.x, p.y, p.z] for p in pose.markers])
    if not stamps:
        return None
    order = np.argsort(stamps, kind="stable")
    return PoseTrack(np.array(frames)[order], np.array(stamps, np.int64)[order], names,
                     np.array(markers, float)[order])


def evaluate(estimate: PoseTrack, truth: PoseTrack, summary: dict[str, np.ndarray] | None = None,
             live: PoseTrack | None = None, cameras: Sequence[object] = ()) -> dict[str, object]:
    """All metrics as a JSON-ready dict (per-frame series included); ``live``: the pose published frame by
    frame (``live_track_from_bag``), whose continuity is scored beside the MAP trajectory's; ``cameras``: the
    run's calibrated cameras, for the error seen from each (``view_bias``). Only the frames
    summary.csv has in view are scored (``frames_out_of_view_left_out`` says how many were not)."""
    left_out = 0
    if summary is not None:
        seen = set(summary["stamp_ns"][summary["in_view"] > 0].tolist())
        keep = np.array([int(s) in seen for s in estimate.stamps_ns], bool)
        left_out = int(np.sum(~keep))
        if left_out == len(keep):
            raise InputError(f"none of the {len(keep)} estimated frames had the person in view (summary.csv "
                             "in_view): nothing to score")
        if left_out:
            estimate = PoseTrack(estimate.frames[keep], estimate.stamps_ns[keep], estimate.marker_names,
                                 estimate.markers[keep])
    errors = marker_errors(estimate, truth)
    stance_left = replaced = None
    if summary is not None:
        lookup = dict(zip(summary["stamp_ns"].tolist(), summary["stance_leg"].tolist()))
        if all(int(s) in lookup for s in estimate.stamps_ns):
            stance_left = np.array([lookup[int(s)] == "left" for s in estimate.stamps_ns])
        moved = dict(zip(summary["stamp_ns"].tolist(), (summary["reacquired"] > 0).tolist()))
        replaced = np.array([moved.get(int(s), False) for s in estimate.stamps_ns])
    result: dict[str, object] = {
        "absolute_mm": statistics(errors["absolute_mm"]),
        "relative_mm": statistics(errors["relative_mm"]),
        "per_marker_absolute_mm": errors["per_marker_mm"],
        "bias": marker_bias(estimate, truth),
        "view_bias": view_bias(estimate, truth, cameras),
        "estimate_feet": foot_plausibility(estimate, stance_left=stance_left, replaced=replaced),
        "truth_feet": foot_plausibility(truth),
        "walk": walk_quality(estimate, truth),
        "gait": gait_comparison(estimate, truth, summary),
        "continuity": {"map_max_step_m_s": largest_step_speed(estimate), "truth_max_step_m_s": largest_step_speed(truth),
                       **({"live_max_step_m_s": largest_step_speed(live)} if live is not None else {})},
        "per_frame": {"frame": errors["frames"].tolist(), "stamp_ns": errors["stamps_ns"].tolist(),
                      "absolute_mm": errors["absolute_mm"].round(3).tolist(),
                      "relative_mm": errors["relative_mm"].round(3).tolist()},
    }
    result["frames_out_of_view_left_out"] = left_out
    if len(truth.stamps_ns) > 1:
        result["truth_speed_m_s"] = float(np.nanmedian(track_speed(truth)))
    if summary is not None:
        particles = np.asarray(summary["particles"], float)
        result["recovery"] = {"reseeded_fallen_particles": int(np.sum(summary["reseeded_fallen"])),
                              "frames_with_fallen_reseeds": int(np.sum(summary["reseeded_fallen"] > 0)),
                              # frames where most of the particle cloud fell at once (a summary without the
                              # particle count: none counted)
                              "frames_most_walkers_fallen": int(np.sum((particles > 0) & (
                                  summary["reseeded_fallen"] > 0.5 * particles))),
                              "reacquisitions": int(np.sum(summary["reacquired"] > 0)),
                              "still_frames": int(np.sum(summary["person_still"] > 0))}
        result["estimated_speed_m_s"] = float(np.median(summary["speed"]))
        left = planted_stance_left(truth)
        if left is not None:
            stamps = truth.stamps_ns
            lookup = dict(zip(summary["stamp_ns"].tolist(), summary["stance_left_probability"].tolist()))
            known = [(lookup[s], l) for s, l in zip(stamps.tolist(), left.tolist()) if s in lookup and l is not None]
            if known:
                p, l = np.array([k[0] for k in known]), np.array([k[1] for k in known], bool)
                result["stance_correct_fraction"] = float(np.mean((p > 0.5) == l))
                result["stance_scored_frames"] = len(known)
    return result


GAIT_COLUMNS = ("index", "frame", "stamp_ns", "time_s", "foot", "x", "y", "step_length_m", "step_width_m",
                "step_time_s", "stride_time_s", "cadence_steps_min", "speed_m_s")


def track_steps(track: PoseTrack, stance_leg: np.ndarray | None = None,
                strike_fraction: np.ndarray | None = None) -> list:
    """The steps of a pose track (``inference.gait_events``): from its stance legs (0 left / 1 right per frame)
    when given (the tracker's own strikes, timed within the frame by ``strike_fraction``, the heel strike half a
    person's double support before: ``gait_events.walker_strike_delay_s``), else from its heel markers
    (``gait_events.heel_strikes``; each step where its heel comes to rest: ``gait_events.heel_at_rest``)."""
    from awalker_tracker.inference import gait_events

    from awalker_tracker.model.body import MARKER_NAMES

    markers = _select(track, list(MARKER_NAMES), np.arange(len(track.frames)), "pose track")   # inference.gait_events's order
    if stance_leg is None:
        stance, fraction = gait_events.stance_from_heels(markers, (track.stamps_ns - track.stamps_ns[0]) * 1e-9)
        return gait_events.steps(track.frames, track.stamps_ns, markers, stance, fraction, at_rest=True)
    return gait_events.steps(track.frames, track.stamps_ns, markers, np.asarray(stance_leg), strike_fraction,
                             walker_strikes=True)


@dataclass(frozen=True)
class TrackedWalk:
    """One track of a run for the gait outputs: its MAP poses, stance leg (0/1) and strike fraction per frame,
    and whether the person was in view (``inference.visibility``)."""

    track_id: int
    poses: PoseTrack
    stance_leg: np.ndarray
    strike_fraction: np.ndarray | None = None
    in_view: np.ndarray | None = None


def write_gait(out: Path, walks: Sequence[TrackedWalk], sides_known: bool = True) -> list:
    """gait.csv (one row per step seen, ``GAIT_COLUMNS`` and its track) and gait.json (``inference.gait_events.summary``
    of the track with the most steps seen, and with several tracks each one's under ``tracks``; ``sides_known``
    False: with its note that left and right may be swapped). A step whose heel strike fell on a frame with the
    person out of every camera's view was predicted, not seen: it is left out of both, and counted
    (``steps_out_of_view``). Returns the steps seen (``plot_gait_file`` draws them)."""
    import json

    from awalker_tracker.inference import gait_events

    seen_by_track: list[tuple[int, list]] = []
    left_out = 0
    for w in walks:
        steps = track_steps(w.poses, w.stance_leg, w.strike_fraction)
        if w.in_view is not None:
            in_view = dict(zip(w.poses.frames.tolist(), np.asarray(w.in_view, bool).tolist()))
            kept = [st for st in steps if in_view.get(st.frame, True)]
            left_out += len(steps) - len(kept)
            steps = kept
        seen_by_track.append((w.track_id, steps))
    with open(out / "gait.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=("track",) + GAIT_COLUMNS)
        writer.writeheader()
        for track_id, steps in seen_by_track:
            for row in gait_events.as_rows(steps):
                writer.writerow({"track": track_id,
                                 **{k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in row.items()}})
    main_id, main = max(seen_by_track, key=lambda t: len(t[1]), default=(1, []))
    summary: dict[str, object] = {"track": main_id, **gait_events.summary(main, sides_known), "steps_out_of_view": left_out}
    if len(seen_by_track) > 1:
        summary["tracks"] = [{"track": track_id, **gait_events.summary(steps, sides_known)}
                             for track_id, steps in seen_by_track]
    (out / "gait.json").write_text(json.dumps(summary, indent=1))
    return [st for _, steps in seen_by_track for st in steps]


def plot_gait_file(out: Path, track: PoseTrack, walk: list) -> Path:
    """gait.png: the footprints of ``walk`` seen from above with the pelvis path of ``track``."""
    from awalker_tools import plots

    return plots.plot_gait(out / "gait.png", walk, track.marker("pelvis")[:, :2], title=f"footprints: {out.name}")


def gait_comparison(estimate: PoseTrack, truth: PoseTrack, summary: dict[str, np.ndarray] | None) -> dict:
    """Gait summaries of the estimate (its stance legs from summary.csv when there, else its heels) and of
    the truth (its heels) over the frames the estimate covers, and their comparison
    (``inference.gait_events.compare``; step times count from the first tracked frame in both)."""
    from awalker_tracker.inference import gait_events

    covered = (truth.stamps_ns >= estimate.stamps_ns[0]) & (truth.stamps_ns <= estimate.stamps_ns[-1])
    truth = PoseTrack(truth.frames[covered], truth.stamps_ns[covered], truth.marker_names, truth.markers[covered])

    stance = fraction = None
    if summary is not None:
        lookup = dict(zip(summary["stamp_ns"].tolist(), summary["stance_leg"].tolist()))
        if all(int(s) in lookup for s in estimate.stamps_ns):
            stance = np.array([0 if lookup[int(s)] == "left" else 1 for s in estimate.stamps_ns])
            when = dict(zip(summary["stamp_ns"].tolist(), summary["strike_fraction"].tolist()))
            fraction = np.array([when[int(s)] for s in estimate.stamps_ns], float)
    est, true = track_steps(estimate, stance, fraction), track_steps(truth)
    return {"estimate": gait_events.summary(est), "truth": gait_events.summary(true), "comparison": gait_events.compare(est, true)}


def facing(track: PoseTrack, rows: np.ndarray) -> np.ndarray:
    """(F,) heading (rad) the body faces: the hip line (left hip to right hip, pointing to the body's right)
    turned by +90 degrees about the vertical."""
    hips = _select(track, ["left_hip", "right_hip"], rows, "pose track")
    across = hips[:, 1, :2] - hips[:, 0, :2]
    return np.arctan2(across[:, 0], -across[:, 1])


def legs_swapped(estimate: PoseTrack, truth: PoseTrack) -> np.ndarray:
    """(F,) bool over the frames the two tracks share (``align_tracks``): the estimate's knees and ankles lie
    nearer the truth's with left and right swapped."""
    est_rows, true_rows = align_tracks(estimate, truth)
    legs = [f"{side}_{joint}" for side in ("left", "right") for joint in ("knee", "ankle")]
    mirrored = [f"{'right' if n.startswith('left') else 'left'}_{n.split('_', 1)[1]}" for n in legs]
    est = _select(estimate, legs, est_rows, "estimate")
    same = np.linalg.norm(est - _select(truth, legs, true_rows, "ground truth"), axis=2).sum(axis=1)
    swapped = np.linalg.norm(est - _select(truth, mirrored, true_rows, "ground truth"), axis=2).sum(axis=1)
    return swapped < same


def walk_quality(estimate: PoseTrack, truth: PoseTrack, fallen_fraction: float = 0.6,
                 off_person_m: float = 0.5) -> dict[str, object]:
    """How the estimate follows a walk, beyond marker errors:

    - ``heading_error_deg``: |facing direction of the estimate - the truth's| per frame (``facing``);
    - ``swap_fraction``: frames whose knees and ankles lie nearer the truth with left and right swapped;
    - ``fallen_frames``: frames where the estimated pelvis is below ``fallen_fraction`` of the true pelvis height;
    - ``off_person_frames``: frames where the estimated pelvis is more than ``off_person_m`` from the true one
      over the ground;
    - ``end``: the last frame's pelvis ground error (m), heading error (deg), fallen and off-person flags."""
    est_rows, true_rows = align_tracks(estimate, truth)
    heading = np.degrees(np.abs(np.angle(np.exp(1j * (facing(estimate, est_rows) - facing(truth, true_rows))))))
    est_p = _select(estimate, ["pelvis"], est_rows, "estimate")[:, 0]
    tru_p = _select(truth, ["pelvis"], true_rows, "ground truth")[:, 0]
    fallen = est_p[:, 2] < fallen_fraction * tru_p[:, 2]
    ground_error = np.linalg.norm(est_p[:, :2] - tru_p[:, :2], axis=1)
    off = ground_error > off_person_m
    return {
        "heading_error_deg": statistics(heading),
        "swap_fraction": float(np.mean(legs_swapped(estimate, truth))),
        "fallen_frames": int(fallen.sum()),
        "off_person_frames": int(off.sum()),
        "end": {"pelvis_ground_error_m": float(ground_error[-1]), "heading_error_deg": float(heading[-1]),
                "fallen": bool(fallen[-1]), "off_person": bool(off[-1])},
        "per_frame_heading_error_deg": heading.round(2).tolist(),
    }


def foot_speed(track: PoseTrack, side: str) -> np.ndarray:
    """(F,) horizontal speed (m/s) of a foot: the larger of its heel and toe speeds (central differences)."""
    t = track.stamps_ns * 1e-9
    speeds = [np.linalg.norm(np.gradient(track.marker(f"{side}_{part}")[:, :2], t, axis=0), axis=1)
              for part in ("heel", "toe")]
    return np.maximum(*speeds)


def planted_stance_left(truth: PoseTrack, planted_m_s: float = 0.25, swinging_m_s: float = 0.5) -> np.ndarray | None:
    """(F,) object array of the true stance leg: True = left foot planted (heel and toe slower than
    ``planted_m_s``) while the right swings (faster than ``swinging_m_s``), False = the reverse, None =
    not clear (double support). Foot motion, not foot height: mocap marker heights differ per foot
    (CMU 07_01: the flat left foot's markers rest ~38 mm up, the right's ~15 mm). None without foot markers."""
    if len(truth.stamps_ns) < 2:
        return None
    try:
        left, right = foot_speed(truth, "left"), foot_speed(truth, "right")
    except ValueError:
        return None
    out = np.full(left.size, None, dtype=object)
    out[(left < planted_m_s) & (right > swinging_m_s)] = True
    out[(right < planted_m_s) & (left > swinging_m_s)] = False
    return out


def start_stance_left(truth: PoseTrack, row: int, still_m_s: float = 0.25) -> bool | None:
    """The person's stance leg at row ``row`` of ``truth`` (True = left), as a start there should name it: the
    planted foot (``planted_stance_left``); for a person standing still before the walk's first heel strike (both
    feet slower than ``still_m_s``), the other foot than that strike's (``gait_events.heel_strikes``): the walker
    stands on it while the first step swings. None where it is not clear (a double support, where the start
    description's convention names the trailing foot), with no strike to come, or without foot markers. Foot
    motion, not marker height: mocap feet rest a few centimetres apart in height, which would pick the lower
    foot of a person standing still."""
    from awalker_tracker.inference import gait_events
    from awalker_tracker.model.body import MARKER_NAMES
    from awalker_tracker.model.walker import RIGHT

    planted = planted_stance_left(truth)
    if planted is None or not 0 <= row < len(truth.frames):
        return None
    if planted[row] is not None:
        return bool(planted[row])
    if max(foot_speed(truth, "left")[row], foot_speed(truth, "right")[row]) >= still_m_s:
        return None
    markers = _select(truth, list(MARKER_NAMES), np.arange(len(truth.frames)), "ground truth")
    strikes = gait_events.heel_strikes(markers, (truth.stamps_ns - truth.stamps_ns[0]) * 1e-9)
    if not strikes or strikes[0][1] <= row:
        return None
    return strikes[0][2] == RIGHT


def format_table(result: dict[str, object], label: str = "") -> str:
    """Paper Table 2 style: median and mean +- std of absolute and relative errors (mm)."""
    a, r = result["absolute_mm"], result["relative_mm"]
    feet = result["estimate_feet"]
    lines = [
        f"{label or 'sequence':<24} {'median':>8} {'mean +- std':>16}   (mm, {a['frames']} frames)",
        f"{'absolute':<24} {a['median']:8.1f} {a['mean']:8.1f} +- {a['std']:5.1f}",
        f"{'relative (pelvis)':<24} {r['median']:8.1f} {r['mean']:8.1f} +- {r['std']:5.1f}",
        *([f"{result['frames_out_of_view_left_out']} frames with the person out of view left out"]
          if result.get("frames_out_of_view_left_out") else []),
        f"foot skate {feet['skate_mm']['mean']:.1f} mm mean ({feet['skate_mm']['max']:.1f} max), "
        f"penetration {feet['penetration_mm']['max']:.1f} mm max, float {feet['float_mm']['mean']:.1f} mm mean",
    ]
    if "bias" in result:
        parts = [f"{group} {'/'.join(format(offset[axis], '+.0f') for axis in OFFSET_AXES)}"
                 for group, offset in group_offsets(result["bias"]).items()]
        lines.append(f"mean offsets (mm, along/left/up): {', '.join(parts)}; absolute median without them "
                     f"{result['bias']['absolute_median_without_offsets_mm']:.1f} mm")
    for camera, seen in result.get("view_bias", {}).items():
        lines.append(f"pelvis seen from {camera}: depth {seen['depth_mm']:+.0f} mm mean (+ farther), "
                     f"{seen['depth_median_abs_mm']:.0f} median size; across {seen['across_mm']:+.0f} mm mean, "
                     f"{seen['across_median_abs_mm']:.0f} median size")
    if "walk" in result:
        walk, frames = result["walk"], a["frames"]
        end = walk["end"]
        lines.append(f"heading error {walk['heading_error_deg']['median']:.1f} deg median "
                     f"({walk['heading_error_deg']['max']:.1f} max); legs swapped on "
                     f"{100 * walk['swap_fraction']:.0f}% of frames; fallen on {walk['fallen_frames']}, off the "
                     f"person on {walk['off_person_frames']} of {frames} frames")
        lines.append(f"last frame: pelvis {1000 * end['pelvis_ground_error_m']:.0f} mm off over the ground, heading "
                     f"{end['heading_error_deg']:.1f} deg off" + (", FALLEN" if end["fallen"] else "")
                     + (", OFF THE PERSON" if end["off_person"] else ""))
    if "gait" in result:
        g, c = result["gait"], result["gait"]["comparison"]
        e, t = g["estimate"], g["truth"]

        def fmt(v: object, f: str) -> str:
            return format(v, f) if isinstance(v, (int, float)) else "-"
        lines.append(f"gait: step length {fmt(e['step_length_m'], '.2f')} m (true {fmt(t['step_length_m'], '.2f')}), "
                     f"cadence {fmt(e['cadence_steps_min'], '.0f')} steps/min (true {fmt(t['cadence_steps_min'], '.0f')}); "
                     f"heel strikes matched {c['matched_strikes']}/{c['true_strikes']}, timing error "
                     f"{fmt(c['timing_error_s_median'], '.3f')} s (signed {fmt(c['timing_bias_s_median'], '+.3f')}), "
                     f"step length error "
                     f"{fmt(c['step_length_error_m_median'], '.3f')} m median")
    if "stance_correct_fraction" in result:
        lines.append(f"stance leg right on {100 * result['stance_correct_fraction']:.1f}% of "
                     f"{result['stance_scored_frames']} frames with one foot planted")
    if "recovery" in result:
        rec = result["recovery"]
        lines.append(f"recovery: {rec['reacquisitions']} re-acquisitions of a lost track, "
                     f"{rec['reseeded_fallen_particles']} fallen particles re-seeded over "
                     f"{rec['frames_with_fallen_reseeds']} frames"
                     + (f" (most of the walkers at once on {rec['frames_most_walkers_fallen']})"
                        if rec.get("frames_most_walkers_fallen") else "")
                     + (f"; the person stood still (walkers held) on {rec['still_frames']} frames"
                        if rec.get("still_frames") else ""))
    if "estimated_speed_m_s" in result and "truth_speed_m_s" in result:
        lines.append(f"speed: estimated {result['estimated_speed_m_s']:.2f} m/s, true {result['truth_speed_m_s']:.2f} m/s")
    return "\n".join(lines)


def truth_from_bag(path: Path) -> PoseTrack:
    """Ground-truth markers (/awalker/ground_truth, awalker_msgs/BodyPose) of a bag; frame = message order."""
    from awalker_tracker.model.body import MARKER_NAMES

    from awalker_tools.bagio import GROUND_TRUTH_TOPIC, SequenceReader

    with SequenceReader(path) as reader:
        truth = reader.ground_truth()
    if truth is None:
        raise InputError(f"{path}: no {GROUND_TRUTH_TOPIC} messages (expected awalker_msgs/BodyPose ground truth)")
    stamps, markers = truth
    return PoseTrack(np.arange(len(stamps)), stamps, MARKER_NAMES, markers)
