"""`awalker convert`: videos or image folders + calibration YAML -> a sequence bag."""
from __future__ import annotations

import argparse
from pathlib import Path

from awalker_tools.bagio import IMAGE_FORMATS, STORAGES
from awalker_tools.outdir import check_new_path
from awalker_tools.video_to_bag import convert, parse_source

EPILOG = """\
Calibration YAML (one file, one entry per camera; world frame z up, ground z = 0):
  cameras:
    - name: cam0                                  # used in topics: /cam0/image_raw
      width: 640
      height: 480
      K: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
      distortion: [k1, k2, p1, p2, k3]            # OpenCV order; 0, 4, 5 or 8 values
      pose: {position: [x, y, z], orientation: [qx, qy, qz, qw]}   # optical frame in the world
Timestamps file: one stamp per frame in seconds, increasing ('#' starts a comment).
Several --video/--images options make a multi-camera bag, synchronised by frame index.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "convert",
        help="video(s) or image folder(s) + calibration YAML -> rosbag2 sequence bag",
        description="Build a sequence bag (images, camera_info, /tf_static camera poses, optional "
        "start/body descriptions) from videos or image folders and a calibration YAML.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--calibration", required=True, type=Path, help="calibration YAML (schema below)")
    parser.add_argument("--out", required=True, help="output bag directory (must not exist)")
    parser.add_argument("--storage", choices=sorted(STORAGES), default="mcap", help="bag storage (default mcap)")
    parser.add_argument("--compressed", action="store_true", help="store CompressedImage instead of raw Image")
    parser.add_argument("--image-format", choices=IMAGE_FORMATS, default="png",
                        help="compression with --compressed (png lossless, default; jpeg smaller)")
    parser.add_argument("--timestamps", type=Path, help="file with one stamp per frame (s)")
    parser.add_argument("--fps", type=float, help="frame rate when there is no timestamps file "
                        "(default: the video's)")
    parser.add_argument("--start-time", type=float, default=0.0, help="stamp of frame 0 with --fps (s, default 0)")
    parser.add_argument("--video", action="append", default=[], metavar="CAM=PATH", help="a camera's video file")
    parser.add_argument("--images", action="append", default=[], metavar="CAM=DIR",
                        help="a camera's image folder (files in natural order)")
    parser.add_argument("--start-description", type=Path, metavar="YAML", help="start description YAML")
    parser.add_argument("--body-description", type=Path, metavar="YAML", help="body description YAML")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = check_new_path(args.out, "--out", force=None, what="bag")
    sources = [parse_source(s, "video") for s in args.video] + [parse_source(s, "images") for s in args.images]
    convert(
        args.calibration, out, sources, storage=args.storage, compressed=args.compressed,
        image_format=args.image_format, timestamps=args.timestamps, fps=args.fps, start_time=args.start_time,
        start_description=args.start_description, body_description=args.body_description,
    )
    return 0
