"""The one way a console script runs a node (ros2/demos Jazzy style): init, build, spin, clean up."""
from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from awalker_tracker.errors import InputError


def run_node(program: str, make_node: Callable[[], Node], args: list[str] | None = None,
             spin: Callable[[Any], int | None] = rclpy.spin) -> int:
    """Run ``make_node()`` until shutdown with ``spin(node)``; the exit status for ``sys.exit``.

    Bad parameters or inputs (``InputError``) print one line naming ``program`` and give 2;
    Ctrl-C and an external shutdown end normally; ``spin`` may return its own status."""
    rclpy.init(args=args)
    node = None
    try:
        node = make_node()
        return int(spin(node) or 0)
    except InputError as exc:
        print(f"{program}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
