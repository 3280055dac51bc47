"""`awalker synth --out DIR`: a synthetic walking sequence (bag + calibration/body/start YAML + CSV)."""
from __future__ import annotations

import argparse
from pathlib import Path

from awalker_tools.outdir import output_path, prepare_output_dir, record_written
from awalker_tools.person_render import CARRIED
from awalker_tools.synth import OCCLUDED_SHARE, VARIANTS, SynthConfig, synthesise


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "synth",
        help="synthesise a walking-person bag with exact ground truth",
        description="Render a person walking through a textured room, seen by 1-4 calibrated cameras, into "
        "DIR/<name>.bag with DIR/calibration.yaml, body.yaml, start.yaml and ground_truth.csv. Motion comes "
        "from the walker dynamics on the cyclic gaits and the conditional kinematics, or from a CMU mocap walk (--from-mocap).",
    )
    parser.add_argument("--out", required=True, help="output directory, new or empty (see --force)")
    parser.add_argument("--force", action="store_true",
                        help="--out may hold an earlier synth's files (listed in its run.yaml): they are replaced, "
                             "other files are kept (one in the way of this run's outputs stops it)")
    parser.add_argument("--name", default="synth", help="bag name inside DIR (default: synth)")
    parser.add_argument("--cameras", type=int, default=1, help="number of cameras, 1-4 (default 1)")
    parser.add_argument("--rate", type=float, default=30.0, choices=(30.0, 60.0), help="frame rate, Hz")
    parser.add_argument("--frames", type=int, default=90, help="frames with the person (default 90)")
    parser.add_argument("--background-frames", type=int, default=8,
                        help="empty-room frames before the person appears (default 8)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (same seed, same bag)")
    parser.add_argument("--speed", type=float, default=1.3, help="walking speed, m/s (default 1.3)")
    parser.add_argument("--step-length", type=float, default=0.7, help="step length, m (default 0.7)")
    parser.add_argument("--speed-change", action="store_true", help="slow down over the middle third")
    parser.add_argument("--turn", type=float, default=0.0, metavar="DEG",
                        help="turn by DEG degrees (left +, at most 90) over the middle third")
    parser.add_argument("--occluder", nargs="?", type=float, const=OCCLUDED_SHARE, default=0.0, metavar="SHARE",
                        help="a box hiding the lower body for a stretch: in front of SHARE of the walk's path "
                             f"(default {OCCLUDED_SHARE:g}: both feet hidden on about a fifth of a 40-frame walk; "
                             "over 1: hidden throughout)")
    parser.add_argument("--from-mocap", nargs=2, type=Path, metavar=("ASF", "AMC"),
                        help="drive the body with a CMU motion capture walk instead of the walker")
    parser.add_argument("--person", choices=("model", "dressed"), default="model",
                        help="model: the tracker's own body (a mirror); dressed: a person with arms, hair, striped "
                             "shirt, jeans and shoes drawn by another renderer (needs --from-mocap)")
    parser.add_argument("--variant", choices=tuple(VARIANTS),
                        default="straight", help="mocap walk variant: 20 %% slower/faster, veering 35 degrees over "
                                                 "2.5 s, a 180-degree turn within 2 s, or standing still for 1.5 s "
                                                 "after 1.5 s (stop) (the walk is repeated as long as --frames needs)")
    parser.add_argument("--user-start", action="store_true",
                        help="start.yaml as a user would write it: position within 5 cm, heading within 5 degrees, "
                             "speed within 10 %%, no step length")
    parser.add_argument("--tape-measure", action="store_true",
                        help="body.yaml lengths off by a few per cent, as measured with a tape (mocap walks)")
    parser.add_argument("--second-person", action="store_true",
                        help="--person dressed: a second person (other clothes) walks the same walk the other way "
                             "1.2 m further back, crossing behind the first; the truth and start are the first's (the second's "
                             "truth: DIR/second_person.csv)")
    parser.add_argument("--carry", choices=CARRIED, default="none",
                        help="--person dressed: carries a backpack or a shoulder bag (by the right hip, strap over "
                             "the left shoulder), something the tracker's body does not have (default none)")
    parser.add_argument("--no-descriptions", action="store_true",
                        help="a user's own video: no start.yaml, body.yaml or description topics (track it with the "
                             "automatic start; add --background-frames 0 for no empty frames either)")
    parser.add_argument("--size", nargs=2, type=int, default=(640, 480), metavar=("W", "H"),
                        help="image size in pixels (default 640 480)")
    parser.add_argument("--noise", type=float, default=3.0, help="sensor noise sigma, grey levels (default 3)")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap", help="bag storage (default mcap)")
    parser.add_argument("--image-format", choices=("jpeg", "png", "raw"), default="jpeg",
                        help="image encoding: jpeg/png CompressedImage or raw Image (default jpeg)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = output_path(args.out, "--out")
    config = SynthConfig(
        out_dir=out, name=args.name, cameras=args.cameras, rate=args.rate, frames=args.frames,
        background_frames=args.background_frames, seed=args.seed, speed=args.speed, step_length=args.step_length,
        speed_change=args.speed_change, turn_deg=args.turn, occluder=args.occluder,
        mocap=tuple(args.from_mocap) if args.from_mocap else None, width=args.size[0], height=args.size[1],
        noise_sigma=args.noise, storage=args.storage, compressed=args.image_format != "raw",
        image_format="png" if args.image_format == "raw" else args.image_format,
        person=args.person, variant=args.variant, user_start=args.user_start, tape_measure=args.tape_measure,
        descriptions=not args.no_descriptions, second_person=args.second_person, carry=args.carry,
    )
    outputs = (f"{args.name}.bag", "run.yaml", "calibration.yaml", "body.yaml", "start.yaml", "ground_truth.csv",
               "ground_truth_body.yaml", "second_person.csv", *(f"overlay_cam{k}.png" for k in range(config.cameras)))
    kept = prepare_output_dir(out, force=args.force, outputs=outputs)
    try:
        paths = synthesise(config)
    finally:
        record_written(out, kept, {"command": "synth"})      # what this run wrote, for a later --force
    for kind, path in paths.items():
        print(f"{kind}: {path}")
    return 0
