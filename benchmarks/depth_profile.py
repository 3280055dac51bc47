"""Where one camera's depth information comes from: the image likelihood along a camera's horizontal
viewing direction (and across it), at the true pose of a synthetic sequence and around a run's MAP poses.

For each camera of SEQ (an `awalker synth` output directory: calibration.yaml, body.yaml,
ground_truth.csv) and the features RUN recorded (an `awalker track` output directory: result.bag,
poses.csv, body.yaml):
- truth: the true markers posed as our body (``acclaim.segments_from_markers`` with SEQ's body), moved by
  -0.4..+0.4 m along the view (+ = away from the camera) and across it, log-likelihood summed over every
  other frame: where it peaks (the mean offset within 2 nats of the top) and what 0.1 and 0.2 m cost;
- map: each MAP pose of RUN (RUN's body) moved along the view: the best shift per frame, what it gains,
  and the MAP's own depth error against the truth's pelvis.
The likelihood is untempered here (the tracker multiplies it by ``--likelihood-scale``, 0.1). Prints JSON.

    .venv/bin/python benchmarks/depth_profile.py SEQ RUN
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

OFFSETS = np.round(np.arange(-0.4, 0.401, 0.02), 3)   # m


def recorded_features(run: Path) -> dict[str, dict[int, object]]:
    """Per camera, stamp (ns) -> FrameFeatures from RUN's result.bag."""
    from awalker_msgs.msg import ImageFeatures
    from rclpy.serialization import deserialize_message
    from rosbags.rosbag2 import Reader

    from awalker_tools.outdir import RESULT_BAG
    from awalker_tracker.errors import InputError
    from awalker_tracker.nodes.features_node import features_from_msg
    from awalker_tracker.nodes.messages import stamp_to_ns

    bag = run / RESULT_BAG
    if not bag.exists():
        raise InputError(f"{bag}: no such bag (RUN must be an `awalker track` output directory)")
    out: dict[str, dict[int, object]] = {}
    with Reader(bag) as reader:
        connections = [c for c in reader.connections if c.topic.endswith("/features")]
        if not connections:
            raise InputError(f"{bag}: no /<camera>/features topic recorded")
        for connection, _, raw in reader.messages(connections=connections):
            msg = deserialize_message(raw, ImageFeatures)
            out.setdefault(msg.camera_name, {})[stamp_to_ns(msg.header.stamp)] = features_from_msg(msg)
    return out


def moved(segments, direction: np.ndarray):
    """One body's segments moved by each of OFFSETS along ``direction``: len(OFFSETS) bodies."""
    from awalker_tracker.model.body import BodySegments

    origin = segments.origin[0][None] + OFFSETS[:, None, None] * direction[None, None, :]
    return BodySegments(origin, np.repeat(segments.rotation[0][None], len(OFFSETS), axis=0))


def main(argv: list[str] | None = None) -> int:
    from awalker_tracker.errors import InputError
    from awalker_tracker.model.acclaim import segments_from_markers
    from awalker_tracker.model.body import BodyDescription
    from awalker_tracker.vision.camera import load_calibration
    from awalker_tracker.vision.likelihood import log_likelihood

    from awalker_tools import evaluation

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("seq", type=Path, help="awalker synth output directory (the truth)")
    parser.add_argument("run", type=Path, help="awalker track output directory of a run on SEQ's bag")
    args = parser.parse_args(argv)
    try:
        true_body = BodyDescription.from_yaml(args.seq / "body.yaml")
        run_body = BodyDescription.from_yaml(args.run / "body.yaml")
        cameras = load_calibration(args.seq / "calibration.yaml")
        truth = evaluation.read_poses_csv(args.seq / "ground_truth.csv")
        estimate = evaluation.read_poses_csv(args.run / "poses.csv")
        features = recorded_features(args.run)
    except InputError as exc:
        print(f"depth_profile: error: {exc}", file=sys.stderr)
        return 2
    truth_row = {int(s): k for k, s in enumerate(truth.stamps_ns)}
    pelvis = truth.marker_names.index("pelvis")
    report: dict = {"seq": str(args.seq), "run": str(args.run), "cameras": {}}
    for camera in cameras:
        seen = features.get(camera.name, {})
        view = camera.rotation[:, 2] * np.array([1.0, 1.0, 0.0])
        view /= np.linalg.norm(view)
        entry: dict = {}
        for name, direction in (("along_view", view), ("across_view", np.array([-view[1], view[0], 0.0]))):
            total, used = np.zeros(len(OFFSETS)), 0
            for k in range(1, len(truth.frames), 2):
                stamp = int(truth.stamps_ns[k])
                if stamp not in seen:
                    continue
                now = segments_from_markers(true_body, truth.markers[k][None])
                prev = segments_from_markers(true_body, truth.markers[k - 1][None])
                total += log_likelihood(true_body.parts, moved(now, direction), moved(prev, direction),
                                        [camera], [seen[stamp]])
                used += 1
            at = dict(zip(OFFSETS.tolist(), (total - total.max()).tolist()))
            entry[f"truth_{name}"] = {
                "frames": used, "peak_m": round(float(OFFSETS[total >= total.max() - 2.0].mean()), 3),
                "nats_at": {f"{d:+.1f} m": round(at[d], 1) for d in (-0.2, -0.1, 0.0, 0.1, 0.2)}}
        shifts, gains, errors = [], [], []
        for k in range(1, len(estimate.frames)):
            stamp = int(estimate.stamps_ns[k])
            if stamp not in seen or stamp not in truth_row:
                continue
            now = segments_from_markers(run_body, estimate.markers[k][None])
            prev = segments_from_markers(run_body, estimate.markers[k - 1][None])
            values = log_likelihood(run_body.parts, moved(now, view), moved(prev, view), [camera], [seen[stamp]])
            shifts.append(float(OFFSETS[np.argmax(values)]))
            gains.append(float(values.max() - values[np.flatnonzero(OFFSETS == 0.0)[0]]))
            errors.append(float((estimate.markers[k, pelvis, :2] - truth.markers[truth_row[stamp], pelvis, :2]) @ view[:2]))
        if shifts:
            entry["map_along_view"] = {
                "frames": len(shifts), "best_shift_m": {"median": float(np.median(shifts)),
                                                        "p10": float(np.percentile(shifts, 10)),
                                                        "p90": float(np.percentile(shifts, 90))},
                "gain_nats_median": round(float(np.median(gains)), 1),
                "map_depth_error_m": {"median": round(float(np.median(errors)), 3),
                                      "last": round(errors[-1], 3)}}
        report["cameras"][camera.name] = entry
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
