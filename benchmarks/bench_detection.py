"""Where does one camera's detection put the person? The broad development set's recordings, frame by frame.

For each recording of the set (``awalker_tools/devset.py``, drawn and rendered as ``bench_realwalks`` does, into the
same ``--out``, so the two benchmarks share their sequences) and each one-camera variant (hand-started and hands off),
every frame's features are computed as `awalker track` computes them (the one-camera map; a hand-started recording's
frames before its start description's frame are the empty room, a hands-off one learns it from frames spread over the
walk, ``pipeline.recording_backgrounds``), the person's blob nearest the true pelvis is placed on the ground
(``vision.detection.locate_person``), and where the person is wholly in view its ground position is compared with the
true pelvis's. This is what the automatic start and the recovery of a lost track are given (``inference.autostart``,
``inference.recovery``), without the tracker.

Report, per recording and over all: frames scored, the median error (m) and the frames more than 0.3 m and
0.5 m off (a feet row a map row or more off; the trunk's own lowest row when a skirt cuts the legs off); how many
map rows the blob reaches below the true body's lowest heel or toe in the image (median per recording; shoes,
contact shadow and blur below the soles, or feet under the threshold where they look like the floor); the
median signed error along the camera's ray (m, > 0: placed too far), over all frames and by where the person
walks (``away`` from the camera, ``towards`` it, ``across``: the cosine of the walk's direction and the ray
above 0.5, below -0.5, between). For the hands-off recordings also the automatic start
(``inference.autostart.StartFinder`` fed each frame, as the tracker feeds it): its frame and its position's
error along the ray and across it (m) against the true pelvis at that frame (``evaluation.split_along_ray``,
as ``awalker eval``'s depth bias).
Prints ONE JSON document on stdout; progress on stderr.

    .venv/bin/python benchmarks/bench_detection.py --set tuning --seeds 0 1 --out bench_realwalks
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

VARIANTS = ("mono", "mono_handsoff")


def _walk_class(cosine: float) -> str:
    """Where the person walks relative to the camera's ray (``cosine`` of the two): away, towards or across."""
    return "away" if cosine > 0.5 else "towards" if cosine < -0.5 else "across"


def score_sequence(bag: Path, find_start: bool = False) -> dict:
    """Detection errors (m) against the true pelvis over the frames where the person is wholly in view and,
    with ``find_start``, the automatic start's error (module docstring)."""
    from awalker_tools import evaluation
    from awalker_tools.bagio import SequenceReader
    from awalker_tools.pipeline import recording_backgrounds
    from awalker_tracker.inference.autostart import StartFinder
    from awalker_tracker.inference.filter_model import StartDescription
    from awalker_tracker.vision.detection import locate_person, person_blobs, wholly_in_view
    from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor, map_downsample

    truth = evaluation.read_poses_csv(bag.parent / "ground_truth.csv")
    pelvis = truth.marker("pelvis")[:, :2]
    # (frames, 4, 3) m: the heels and toes, the lowest of which in the image is where the person's blob should end
    soles = np.stack([truth.marker(name) for foot in evaluation.FOOT_MARKERS.values() for name in foot], axis=1)
    dt = float(np.median(np.diff(truth.stamps_ns))) * 1e-9
    # the true walking direction: the pelvis's displacement over +-0.25 s (zero while standing)
    reach = max(1, int(round(0.25 / dt)))
    ahead = pelvis[np.minimum(np.arange(len(pelvis)) + reach, len(pelvis) - 1)]
    behind = pelvis[np.maximum(np.arange(len(pelvis)) - reach, 0)]
    walk = ahead - behind
    scored, offsets, row_depths = [], [], []      # truth rows of the frames scored, detection - truth (m), row depths
    below_soles = []        # map rows from the true lowest heel or toe down to the blob's lowest row
    start = None
    with SequenceReader(bag) as reader:
        cameras = reader.cameras
        by_name = {c.name: c for c in cameras}
        # a hand-started recording's frames before its start are the empty room, as `awalker track` learns them
        described = bag.parent / "start.yaml"
        empty = StartDescription.from_yaml(described).frame if described.exists() else 0
        downsample = {c.name: map_downsample(c.width, len(cameras)) for c in cameras}
        extractors = [FeatureExtractor(FeatureConfig(downsample=downsample[c.name], background_frames=empty))
                      for c in cameras]
        if not empty:       # hands off, as `awalker track`: the background from frames spread over the recording
            backgrounds = recording_backgrounds(reader, downsample)
            for extractor, camera in zip(extractors, cameras):
                extractor.use_background(backgrounds[camera.name])
        finder = StartFinder(cameras, dt) if find_start else None
        for frame, (stamp, images) in enumerate(reader.frames()):
            features = [e.process(images[c.name], stamp_ns=stamp) for e, c in zip(extractors, cameras)]
            if finder is not None and start is None:
                start = finder.push(frame, features)
            rows = np.flatnonzero(truth.frames == frame)
            if rows.size == 0:
                continue
            x, y = pelvis[rows[0]]
            seen = [person_blobs(f, c.name) for f, c in zip(features, cameras)]
            detection = locate_person(seen, cameras, near=np.array([x, y, 0.9]))
            if detection is not None and wholly_in_view(detection, cameras):
                scored.append(rows[0])
                offsets.append(detection.position - (x, y))
                row_depths.append(detection.row_depth_m)
                for blob in detection.blobs:
                    uv, _ = by_name[blob.camera].project(soles[rows[0]])
                    below_soles.append((blob.feet_uv[1] - float(uv[:, 1].max())) / blob.row_px)
        if finder is not None and start is None:
            start = finder.finish()
    eye = cameras[0].position
    scored, offsets = np.asarray(scored, int), np.reshape(offsets, (-1, 2))
    errors = np.linalg.norm(offsets, axis=1)
    along_ray = evaluation.split_along_ray(offsets, pelvis[scored], eye)[0]
    steps = walk[scored]
    lengths = np.linalg.norm(steps, axis=1)
    cosines = evaluation.split_along_ray(steps, pelvis[scored], eye)[0] / np.maximum(lengths, 1e-9)
    moving = lengths > 0.3 * 2 * reach * dt                                  # faster than 0.3 m/s
    classes = np.array([_walk_class(c) if m else "standing" for c, m in zip(cosines, moving)])
    result = {"frames": int(errors.size), "median_m": float(np.median(errors)) if errors.size else None,
              "over_0.3_m": int(np.sum(errors > 0.3)), "over_0.5_m": int(np.sum(errors > 0.5)),
              "along_ray_median_m": float(np.median(along_ray)) if errors.size else None,
              "row_depth_median_m": float(np.median(row_depths)) if errors.size else None,
              "feet_row_below_soles_rows_median": float(np.median(below_soles)) if below_soles else None,
              "along_ray_by_walk": {k: {"frames": int(np.sum(classes == k)),
                                        "median_m": float(np.median(along_ray[classes == k]))}
                                    for k in ("away", "towards", "across") if np.any(classes == k)}}
    if find_start:
        result["start"] = None
        rows = np.flatnonzero(truth.frames == start.frame) if start is not None else np.array([], int)
        if rows.size:
            true_xy, step = pelvis[rows[0]], walk[rows[0]]
            along, across = evaluation.split_along_ray(np.asarray(start.position) - true_xy, true_xy, eye)
            cosine = evaluation.split_along_ray(step, true_xy, eye)[0] / max(float(np.linalg.norm(step)), 1e-9)
            result["start"] = {"frame": int(start.frame), "along_ray_m": float(along), "across_ray_m": float(across),
                               "walk": _walk_class(float(cosine))}
    return result


def main(argv: list[str] | None = None) -> int:
    from awalker_tools import devset

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--set", choices=("quick", "tuning", "reporting", "all"), default="quick",
                        help="which trials (default quick: bench_realwalks' default subset)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2],
                        help="recording seeds (default 0-2, as bench_realwalks' quick run)")
    parser.add_argument("--out", type=Path, default=Path("bench_realwalks"),
                        help="sequences are kept (and reused) in OUT/sequences, as bench_realwalks keeps them")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="recordings scored at once")
    args = parser.parse_args(argv)
    started = time.monotonic()
    bags = []
    for seed in args.seeds:
        for trial in devset.trials_of(args.set):
            made = devset.make_recording(devset.Recording.draw(trial, seed),
                                         args.out / "sequences" / f"{trial}_s{seed}", progress=False)
            bags += [(f"{trial} s{seed} {variant}", made[variant], variant.endswith("handsoff"))
                     for variant in VARIANTS]
    report: dict = {"benchmark": "detection", "set": args.set, "seeds": args.seeds, "recordings": {}}
    with ProcessPoolExecutor(max(1, args.jobs)) as pool:
        scored = pool.map(score_sequence, [b for _, b, _ in bags], [hands_off for _, _, hands_off in bags])
        for k, (name, result) in enumerate(zip([n for n, _, _ in bags], scored)):
            report["recordings"][name] = result
            start = result.get("start")
            said = "" if "start" not in result else (", no start" if start is None else
                                                     f", start {start['along_ray_m']:+.2f} m along the ray")
            print(f"[{k + 1}/{len(bags)}] {name}: {result['over_0.5_m']} of {result['frames']} frames more than "
                  f"0.5 m off{said} ({(time.monotonic() - started) / 60:.1f} min)", file=sys.stderr, flush=True)
    results = list(report["recordings"].values())

    def median_of(values: list) -> float | None:
        values = [v for v in values if v is not None]
        return float(np.median(values)) if values else None

    def along_ray(recordings: list[dict]) -> dict:
        """Medians over recordings of their median signed error along the ray: all frames and by walk."""
        return {"all_m": median_of([r["along_ray_median_m"] for r in recordings]),
                **{f"{k}_m": median_of([r["along_ray_by_walk"].get(k, {}).get("median_m") for r in recordings])
                   for k in ("away", "towards", "across")}}

    def below_soles(recordings: list[dict]) -> dict:
        """Median and range over recordings of how many map rows their blobs reach below the soles."""
        values = [r["feet_row_below_soles_rows_median"] for r in recordings
                  if r["feet_row_below_soles_rows_median"] is not None]
        return {"median": median_of(values), "min": min(values, default=None), "max": max(values, default=None)}

    of_variant = {variant: [r for name, r in report["recordings"].items() if name.endswith(f" {variant}")]
                  for variant in VARIANTS}
    starts = [r["start"] for r in results if "start" in r]
    found = [s for s in starts if s is not None]
    report["summary"] = {
        "frames": sum(r["frames"] for r in results),
        "over_0.3_m": sum(r["over_0.3_m"] for r in results),
        "over_0.5_m": sum(r["over_0.5_m"] for r in results),
        "median_of_recording_medians_m": median_of([r["median_m"] for r in results]),
        # how far the blob reaches below the person's soles (map rows; per recording: shoes, floor and light)
        "feet_row_below_soles_rows": {variant: below_soles(of_variant[variant]) for variant in VARIANTS},
        # hand-started recordings learn the background from the empty room, hands-off ones from the walk (a ghost)
        "along_ray_median_of_recordings": {variant: along_ray(of_variant[variant]) for variant in VARIANTS},
        "starts": {"recordings": len(starts), "found": len(found),
                   "along_ray_median_m": median_of([s["along_ray_m"] for s in found]),
                   "more_than_0.1_m_too_near": sum(s["along_ray_m"] < -0.1 for s in found),
                   "abs_along_ray_median_m": median_of([abs(s["along_ray_m"]) for s in found]),
                   "abs_across_ray_median_m": median_of([abs(s["across_ray_m"]) for s in found]),
                   "along_ray_by_walk_median_m": {
                       k: median_of([s["along_ray_m"] for s in found if s["walk"] == k])
                       for k in ("away", "towards", "across")}}}
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
