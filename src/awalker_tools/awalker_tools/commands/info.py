"""`awalker info BAG`: topics, types, counts, duration, cameras, and what is missing for tracking."""
from __future__ import annotations

import argparse
import json

from awalker_tools.baginfo import bag_info, format_info


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "info",
        help="show a bag's topics, cameras and what it lacks for tracking",
        description="Print topics (type, count), duration, cameras (size, pose) and one MISSING line per "
        "item the tracker needs but the bag lacks (exit status 0 either way).",
    )
    parser.add_argument("bag", help="bag directory (or .mcap / .db3 file)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    info = bag_info(args.bag)
    print(json.dumps(info, indent=2) if args.json else format_info(info))
    return 0
