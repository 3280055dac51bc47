"""`awalker replay BAG`: publish a bag into ROS 2 (rate or lockstep mode)."""
from __future__ import annotations

import argparse

from awalker_tools.replay import DEFAULT_ACK_TOPIC, ReplayConfig, replay_main


def register(subparsers: argparse._SubParsersAction) -> None:
    defaults = ReplayConfig()
    parser = subparsers.add_parser(
        "replay",
        help="publish a bag's topics into ROS 2 (rate or lockstep)",
        description="Publish every topic of a bag with its stored type, reliable; latched topics "
        "(/tf_static, descriptions) transient-local; each camera's pose also as /<cam>/camera_pose "
        "(geometry_msgs/PoseStamped). Waits for subscribers before the first message. Same as the "
        "console script `awalker_replay --ros-args -p bag:=BAG ...`.",
    )
    parser.add_argument("bag", help="bag directory (or .mcap / .db3 file)")
    parser.add_argument("--rate", type=float, default=defaults.rate,
                        help="real-time factor (default 1; ignored with --lockstep)")
    parser.add_argument("--lockstep", action="store_true",
                        help="publish one frame, then wait for its ack (std_msgs/Header with the frame stamp)")
    parser.add_argument("--ack-topic", default=DEFAULT_ACK_TOPIC, help=f"ack topic (default {DEFAULT_ACK_TOPIC})")
    parser.add_argument("--ack-timeout", type=float, default=defaults.ack_timeout,
                        help=f"give up after this many seconds without an ack (default {defaults.ack_timeout:g})")
    parser.add_argument("--frames-ahead", type=int, default=defaults.frames_ahead, metavar="N",
                        help="with --lockstep: publish up to N frames beyond the oldest unacknowledged one, so "
                        f"feature extraction overlaps tracking (default {defaults.frames_ahead})")
    parser.add_argument("--sync-tolerance", type=float, default=defaults.sync_tolerance, metavar="F",
                        help="cameras' images whose stamps differ by less than F frame periods make one frame "
                        "(default 1/3; 0: equal stamps only)")
    parser.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="replay only these topics")
    parser.add_argument("--wait-for-subscribers", type=float, default=defaults.wait_for_subscribers, metavar="SEC",
                        help="wait this long for subscribers before the first message (0: no wait; "
                        f"default {defaults.wait_for_subscribers:g})")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    config = ReplayConfig(
        rate=args.rate, lockstep=args.lockstep, ack_topic=args.ack_topic, topics=tuple(args.topics),
        wait_for_subscribers=args.wait_for_subscribers, ack_timeout=args.ack_timeout, frames_ahead=args.frames_ahead,
        sync_tolerance=args.sync_tolerance,
    ).validated("awalker replay")
    return replay_main(args.bag, config)
