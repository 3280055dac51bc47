"""Where does one camera's detection put the person? The broad development set's recordings, frame by frame.

For each recording of the set (``awalker_tools/devset.py``, drawn and rendered as ``bench_realwalks`` does, into
the same ``--out``, so the two benchmarks share their sequences) and each one-camera variant (hand-started and
hands off), every frame's features are computed as with no known background frames (the background learned
from the walk itself, ``FeatureConfig``'s defaults, the one-camera map), the person's blob nearest the true
pelvis is placed on the ground (``vision.detection.locate_person``), and where the person is wholly in view
its ground position is compared with the true pelvis's. This is what the automatic start and the recovery of a
lost track are given (``inference.autostart``, ``inference.recovery``), without the tracker.

Report, per recording and over all: frames scored, the median error (m) and the frames more than 0.3 m and
0.5 m off (a feet row a map row or more off; the trunk's own lowest row when a skirt cuts the legs off).
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


def score_sequence(bag: Path) -> dict:
    """Detection errors (m) against the true pelvis over the frames where the person is wholly in view."""
    from awalker_tools import evaluation
    from awalker_tools.bagio import SequenceReader
    from awalker_tracker.vision.detection import locate_person, person_blobs, wholly_in_view
    from awalker_tracker.vision.features import FeatureConfig, FeatureExtractor, map_downsample

    truth = evaluation.read_poses_csv(bag.parent / "ground_truth.csv")
    pelvis = truth.marker("pelvis")
    errors = []
    with SequenceReader(bag) as reader:
        cameras = reader.cameras
        extractors = [FeatureExtractor(FeatureConfig(downsample=map_downsample(c.width, len(cameras))))
                      for c in cameras]
        for frame, (stamp, images) in enumerate(reader.frames()):
            features = [e.process(images[c.name], stamp_ns=stamp) for e, c in zip(extractors, cameras)]
            rows = np.flatnonzero(truth.frames == frame)
            if rows.size == 0:
                continue
            x, y = pelvis[rows[0], :2]
            seen = [person_blobs(f, c.name) for f, c in zip(features, cameras)]
            detection = locate_person(seen, cameras, near=np.array([x, y, 0.9]))
            if detection is not None and wholly_in_view(detection, cameras):
                errors.append(float(np.hypot(*(detection.position - (x, y)))))
    found = np.asarray(errors)
    return {"frames": int(found.size), "median_m": float(np.median(found)) if found.size else None,
            "over_0.3_m": int(np.sum(found > 0.3)), "over_0.5_m": int(np.sum(found > 0.5))}


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
            bags += [(f"{trial} s{seed} {variant}", made[variant]) for variant in VARIANTS]
    report: dict = {"benchmark": "detection", "set": args.set, "seeds": args.seeds, "recordings": {}}
    with ProcessPoolExecutor(max(1, args.jobs)) as pool:
        for k, (name, result) in enumerate(zip([n for n, _ in bags], pool.map(score_sequence, [b for _, b in bags]))):
            report["recordings"][name] = result
            print(f"[{k + 1}/{len(bags)}] {name}: {result['over_0.5_m']} of {result['frames']} frames more than "
                  f"0.5 m off ({(time.monotonic() - started) / 60:.1f} min)", file=sys.stderr, flush=True)
    results = list(report["recordings"].values())
    medians = [r["median_m"] for r in results if r["median_m"] is not None]
    report["summary"] = {"frames": sum(r["frames"] for r in results),
                         "over_0.3_m": sum(r["over_0.3_m"] for r in results),
                         "over_0.5_m": sum(r["over_0.5_m"] for r in results),
                         "median_of_recording_medians_m": float(np.median(medians)) if medians else None}
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
