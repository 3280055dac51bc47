"""`awalker track BAG [--start START.yaml] [--body BODY.yaml] --out DIR`: track a walking person."""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from awalker_tracker.errors import InputError

from awalker_tools.commands import whole_number
from awalker_tools.outdir import output_path
from awalker_tracker.inference.profiles import DEFAULT_PROFILE, PROFILES, tracking_profile
from awalker_tracker.inference.smc import MAX_PARTICLES
from awalker_tracker.inference.sync import DEFAULT_TOLERANCE

DEFAULTS = PROFILES[DEFAULT_PROFILE]


def run(args: argparse.Namespace) -> int:
    from awalker_tools.pipeline import TrackOptions, run_tracking
    from awalker_tracker.inference.autostart import AutoStartConfig
    from awalker_tracker.inference.filter_model import TrackerConfig

    profile = tracking_profile(args.profile, "--profile")       # the defaults of what is not given

    def given(value: object, default: object) -> object:
        return default if value is None else value

    particles, lookahead = given(args.particles, profile.num_particles), given(args.lookahead, profile.lookahead)
    trust, seed = given(args.trust, profile.trust), given(args.seed, profile.seed)
    likelihood_scale = given(args.likelihood_scale, profile.likelihood_scale)
    leg_scale_spread = given(args.leg_scale_spread, profile.leg_scale_spread)
    if not 1 <= particles <= MAX_PARTICLES:
        raise InputError(f"--particles must lie in 1-{MAX_PARTICLES} (the most a filter takes), got {particles}")
    if args.min_particles is not None and not 0 <= args.min_particles <= particles:
        raise InputError(f"--min-particles must lie in 0-{particles} (--particles), got {args.min_particles}")
    if seed < 0:
        raise InputError(f"--seed must be an integer >= 0, got {seed}")
    if not 0 <= likelihood_scale < math.inf:
        raise InputError(f"--likelihood-scale must be finite and >= 0, got {likelihood_scale}")
    try:
        TrackerConfig(leg_scale_spread=leg_scale_spread)      # the tracker node's check, before anything starts
    except ValueError as exc:
        raise InputError(f"--leg-scale-spread: {exc}") from None
    if args.pelvis_ceiling is not None:
        try:
            TrackerConfig(pelvis_ceiling=args.pelvis_ceiling)
        except ValueError as exc:
            raise InputError(f"--pelvis-ceiling: {exc}") from None
    if args.depth_band is not None and not args.depth_band >= 0:
        raise InputError(f"--depth-band must be >= 0 m (0: off), got {args.depth_band}")
    if not 0.0 <= trust <= 1.0:
        raise InputError(f"--trust (gamma) must lie in [0, 1], got {trust}")
    if lookahead < 0:
        raise InputError(f"--lookahead must be >= 0, got {lookahead}")
    if not 0.0 <= args.sync_tolerance < 1.0:
        raise InputError(f"--sync-tolerance must lie in [0, 1) frame periods, got {args.sync_tolerance}")
    follow_near = tuple(args.follow_near) if args.follow_near is not None else None
    try:
        AutoStartConfig(follow_near=follow_near)      # the tracker node's check, before anything starts
    except ValueError as exc:
        raise InputError(f"--follow-near: {exc}") from None
    run_tracking(TrackOptions(
        bag=Path(args.bag), out=output_path(args.out, "--out"), start=Path(args.start) if args.start else None,
        body=Path(args.body) if args.body else None, profile=args.profile, particles=particles,
        min_particles=args.min_particles,
        lookahead=lookahead, trust=trust, seed=seed, likelihood_scale=likelihood_scale,
        leg_scale_spread=leg_scale_spread, pelvis_ceiling=args.pelvis_ceiling,
        recovery=profile.recovery and not args.no_recovery, depth_band_m=args.depth_band,
        auto_start=args.auto_start or args.follow_near is not None,
        follow_near=follow_near, overlays=not args.no_overlay, fit_body=args.fit_body,
        storage=args.storage, force=args.force, sync_tolerance=args.sync_tolerance,
        share_topics=args.share_topics))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "track", help="track the walking person of a bag (replay, features, tracker, pose publisher in one process)",
        description="Runs replay (lockstep), one features node per camera, the tracker and the pose publisher "
                    "in one process and writes DIR/result.bag, poses.csv (MAP trajectory), summary.csv, "
                    "overlay images and video. Start and body descriptions: --start/--body, else the bag's "
                    "/awalker/start_description and /awalker/body_description, else start.yaml/body.yaml "
                    "beside the bag; with no start description the tracker finds the walking person itself.")
    parser.add_argument("bag", help="input rosbag2 bag (directory, .mcap or .db3)")
    parser.add_argument("--out", required=True, help="output directory: new or empty (see --force)")
    parser.add_argument("--force", action="store_true",
                        help="--out may hold a previous run: the files its run.yaml lists are replaced, every "
                             "other file is kept (one in the way of this run's outputs stops it)")
    parser.add_argument("--start", help="start description YAML (start: frame, position, heading, speed, ...)")
    parser.add_argument("--auto-start", action="store_true",
                        help="ignore any start description and find the walking person in the images (also done "
                             "when there is none); the start found is written to DIR/start.yaml")
    parser.add_argument("--follow-near", nargs=2, type=float, metavar=("X", "Y"),
                        help="with several people in view, follow the one first seen within 1.5 m of this world "
                             "ground point (m); implies --auto-start (default: the first person seen walking)")
    parser.add_argument("--body", help="body description YAML (segment sizes in metres)")
    parser.add_argument("--profile", choices=tuple(PROFILES), default=DEFAULT_PROFILE,
                        help="defaults of the options below, as the tracker node's profile parameter "
                             "(inference/profiles.py): " + "; ".join(f"{name} {p.num_particles} particles"
                                                                     for name, p in PROFILES.items())
                             + f" (default {DEFAULT_PROFILE}; realtime runs about 3 times faster)")
    parser.add_argument("--particles", type=whole_number, default=None,
                        help=f"number of particles (default: the profile's, {DEFAULTS.num_particles})")
    parser.add_argument("--min-particles", type=int, default=None,
                        help="adaptive particle count (KLD-sampling, docs/tracking.md): the fewest a resampling may "
                             f"keep, --particles the most; 0: --particles throughout (default: the profile's, "
                             f"{DEFAULTS.min_particles})")
    parser.add_argument("--lookahead", type=int, default=None,
                        help=f"look-ahead tau in frames (default {DEFAULTS.lookahead})")
    parser.add_argument("--trust", type=float, default=None,
                        help=f"gamma: trust in the look-ahead weights when resampling (default {DEFAULTS.trust})")
    parser.add_argument("--seed", type=int, default=None, help=f"random seed (default {DEFAULTS.seed})")
    parser.add_argument("--likelihood-scale", type=float, default=None,
                        help=f"exponent on the image likelihood (tempering, default {DEFAULTS.likelihood_scale}; "
                             "0: images unused, dead reckoning from the start description)")
    parser.add_argument("--leg-scale-spread", type=float, default=None,
                        help="let the particles' leg lengths differ from the body description's: log-normal spread "
                             "(e.g. 0.04), wandering 0.1 %% per frame; default "
                             f"{DEFAULTS.leg_scale_spread:g}: the body's own (docs/design.md, "
                             "\"Leg length per particle\")")
    parser.add_argument("--pelvis-ceiling", type=float, default=None, metavar="F",
                        help="keep each particle's pelvis at most its own fraction of the walker's hip height, drawn "
                             "around F, over the stance, the stance knee bending as a person's does, with any number "
                             "of cameras (0.85-1; 1: off; default 0.97 with two or more cameras and off with one, "
                             "docs/design.md, Pelvis ceiling)")
    parser.add_argument("--depth-band", type=float, default=None, metavar="M",
                        help="one camera: walkers whose pelvis lies more than M metres from where the person's feet row "
                             "puts them lose weight, from half a second in (default: RecoveryConfig.depth_band_m, "
                             "0.15; 0: off; docs/tracking.md, Recovery)")
    parser.add_argument("--no-recovery", action="store_true",
                        help="never re-seed fallen walkers, re-acquire a lost track, hold the walkers while the person "
                             "stands still or hold one camera's depth by the feet row (the exact filter of the paper)")
    parser.add_argument("--sync-tolerance", type=float, default=DEFAULT_TOLERANCE, metavar="F",
                        help="cameras' images whose stamps differ by less than F frame periods make one frame (nearest "
                             "stamp; default 1/3; 0: equal stamps only); a frame missing a camera is tracked with the "
                             "others")
    parser.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap", help="result bag storage")
    parser.add_argument("--no-overlay", action="store_true", help="skip overlay images and video")
    parser.add_argument("--fit-body", action=argparse.BooleanOptionalAction, default=None,
                        help="track twice: fit the body's leg length to the images of the first pass (as "
                             "`awalker fitbody` does, DIR/first_pass/) and track again with it (default: only "
                             "when there is no body description, so that the body is scaled to the person's "
                             "height seen in the images)")
    parser.add_argument("--share-topics", action="store_true",
                        help="let other ROS 2 processes on this host (RViz, ros2 topic echo) see the pipeline's "
                             "topics on ROS_DOMAIN_ID; by default the in-process pipeline is isolated")
    parser.set_defaults(func=run)
