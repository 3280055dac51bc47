"""The rosbags type store: ROS 2 Jazzy types plus awalker_msgs, from the package's own .msg files.

One source of truth for message definitions: the .msg files of the installed ``awalker_msgs``
(the same files rclpy's generated code was built from), so the RIHS01 hashes written into bags
match what rclpy nodes advertise.
"""
from __future__ import annotations

import os
import sys
from functools import lru_cache
from pathlib import Path

from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosbags.typesys.store import Typestore

from awalker_tracker.errors import InputError

PACKAGE = "awalker_msgs"
_REPO_MSG_DIR = Path(__file__).resolve().parents[2] / PACKAGE / "msg"


def awalker_msg_dir() -> Path:
    """Directory holding awalker_msgs' .msg files.

    Order: the ament index (``AMENT_PREFIX_PATH``, a sourced ROS install), this interpreter's
    prefix (the project venv, where the set-up script installs the package), the source tree.
    """
    candidates: list[Path] = []
    if os.environ.get("AMENT_PREFIX_PATH"):
        try:
            from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

            try:
                candidates.append(Path(get_package_share_directory(PACKAGE)) / "msg")
            except PackageNotFoundError:
                pass
        except ImportError:
            pass
    candidates += [Path(sys.prefix) / "share" / PACKAGE / "msg", _REPO_MSG_DIR]
    for directory in candidates:
        if any(directory.glob("*.msg")):
            return directory
    raise InputError(f"{PACKAGE}: no .msg files found in any of {[str(c) for c in candidates]}")


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    """rosbags Typestore for ROS 2 Jazzy with every ``awalker_msgs/msg/*`` type registered (cached)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict = {}
    for path in sorted(awalker_msg_dir().glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"{PACKAGE}/msg/{path.stem}"))
    store.register(types)
    return store
