"""`awalker demo`: track the sample bag in bags/ and print the evaluation (the README's main command)."""
from __future__ import annotations

import argparse
from pathlib import Path

from awalker_tracker.errors import InputError
from awalker_tracker.inference.profiles import DEFAULT_PROFILE, PROFILES
from awalker_tracker.inference.smc import MAX_PARTICLES

from awalker_tools.commands import whole_number

REPO_ROOT = Path(__file__).resolve().parents[4]


def find_sample_bag(search: list[Path]) -> Path:
    """The first bag (directory with metadata.yaml, .mcap or .db3 file) in the given folders."""
    for folder in search:
        if not folder.is_dir():
            continue
        for candidate in sorted(folder.iterdir()):
            if candidate.is_dir() and (candidate / "metadata.yaml").is_file():
                return candidate
            if candidate.suffix in (".mcap", ".db3"):
                return candidate
    raise InputError(f"no sample bag found in {', '.join(str(f) for f in search)}; pass --bag BAG")


def run(args: argparse.Namespace) -> int:
    from awalker_tools.commands import eval as eval_command
    from awalker_tools.outdir import output_path, prepare_output_dir
    from awalker_tools.pipeline import TRACK_OUTPUTS, TrackOptions, run_tracking

    if not 1 <= args.particles <= MAX_PARTICLES:
        raise InputError(f"--particles must lie in 1-{MAX_PARTICLES} (the most a filter takes), got {args.particles}")
    if args.seed < 0:
        raise InputError(f"--seed must be an integer >= 0, got {args.seed}")
    bag = Path(args.bag) if args.bag else find_sample_bag([Path.cwd() / "bags", REPO_ROOT / "bags"])
    out = output_path(args.out, "--out")
    # an earlier demo's files (its run.yaml lists them) are replaced with --force, the user's never
    prepare_output_dir(out, force=args.force, outputs=TRACK_OUTPUTS + eval_command.OUTPUTS)
    run_tracking(TrackOptions(bag=bag, out=out, particles=args.particles, seed=args.seed, force=True))
    status = eval_command.run(argparse.Namespace(dir=str(out), truth=None, json=None))
    print(f"look at {out / 'overlay.mp4'}, {out / 'error_over_time.png'} and {out / 'speed_stance.png'}")
    return status


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demo", help="track the sample bag in bags/ and print the evaluation",
        description="Runs `awalker track` on the sample bag (bags/) into --out (new or empty; --force replaces "
                    "an earlier demo's outputs there, nothing else), then `awalker eval` against its ground truth.")
    parser.add_argument("--bag", help="bag to track (default: the sample bag in bags/)")
    parser.add_argument("--out", default="demo_out", help="output directory, new or empty (default demo_out)")
    parser.add_argument("--force", action="store_true",
                        help="replace an earlier run's outputs in --out (those its run.yaml lists); other files stay")
    defaults = PROFILES[DEFAULT_PROFILE]
    parser.add_argument("--particles", type=whole_number, default=defaults.num_particles,
                        help=f"number of particles (default {defaults.num_particles}, as awalker track)")
    parser.add_argument("--seed", type=int, default=defaults.seed, help=f"random seed (default {defaults.seed})")
    parser.set_defaults(func=run)
