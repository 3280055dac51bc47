"""`awalker fitbody DIR`: fit the leg length of a tracking run's body to its images, and the stance leg its
start left open (issue 12 §1, §3).

Reads the output directory of `awalker track` and writes DIR/body_fitted.yaml (``awalker_tools.fit_body``),
to track again with ``awalker track BAG --body DIR/body_fitted.yaml``, and, when the run's start named no
stance leg, DIR/start_fitted.yaml.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import yaml

from awalker_tracker.errors import InputError
from awalker_tracker.inference.smc import MAX_PARTICLES


def run(args: argparse.Namespace) -> int:
    from awalker_tools.fit_body import fit_run_dir

    for factor in args.factors or ():
        if not 0.5 < factor < 1.5:          # also NaN; the fit's own range (inference/bodyfit.py)
            raise InputError(f"--factors {factor}: each leg factor must lie in (0.5, 1.5)")
    if not 1 <= args.particles <= MAX_PARTICLES:
        raise InputError(f"--particles must lie in 1-{MAX_PARTICLES} (the most a filter takes), got {args.particles}")
    if args.frames < 1 or args.seed < 0:
        raise InputError(f"--frames must be >= 1 and --seed >= 0, got {args.frames} and {args.seed}")
    summary = fit_run_dir(Path(args.dir), args.factors, frames=args.frames, particles=args.particles, seed=args.seed)
    print(yaml.safe_dump({"fitbody": summary}, sort_keys=False), end="")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "fitbody", help="fit the leg length of a tracking run's body to its images (writes body_fitted.yaml)",
        description="Runs the filter on the image features a tracking run recorded, once per candidate leg "
                    "length (thigh and shank scaled), over the first frames from its start, and keeps the one "
                    "the images support best (the filter's evidence). Writes DIR/body_fitted.yaml; track again "
                    "with --body DIR/body_fitted.yaml. When the run's start named no stance leg (found "
                    "automatically, or 'unknown'), it weighs the two legs the same way and writes "
                    "DIR/start_fitted.yaml.")
    parser.add_argument("dir", help="output directory of `awalker track`")
    parser.add_argument("--factors", type=float, nargs="+",
                        help="candidate scales of thigh and shank (default 0.91 0.94 0.97 1.0 1.03 for a body "
                             "given to the run, 0.97 1.0 1.03 1.06 1.09 1.12 for one scaled to the seen height)")
    parser.add_argument("--frames", type=int, default=60, help="frames of evidence from the start (default 60)")
    parser.add_argument("--particles", type=int, default=5000, help="particles per candidate (default 5000)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.set_defaults(func=run)
