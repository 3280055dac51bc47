"""The one way a console script runs a node (ros2/demos Jazzy style): init, build, spin, clean up."""
from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from awalker_tracker.errors import InputError
from awalker_tracker.nodes.base import NodeParameter, parameter_help, wants_help


def run_node(program: str, make_node: Callable[[], Node], args: list[str] | None = None,
             spin: Callable[[Any], int | None] = rclpy.spin, parameters: Sequence[NodeParameter] = (),
             summary: str = "") -> int:
    """Run ``make_node()`` until shutdown with ``spin(node)``; the exit status for ``sys.exit``.

    ``-h``/``--help`` (before ``--ros-args``) prints ``summary`` and the node's ``parameters`` with their
    defaults and gives 0 without starting ROS. Bad parameters or inputs (``InputError``) print one line
    naming ``program`` and give 2; Ctrl-C and an external shutdown end normally; ``spin`` may return its own
    status."""
    if wants_help(sys.argv[1:] if args is None else args):
        try:
            print(parameter_help(program, summary, parameters))
        except BrokenPipeError:         # piped into e.g. `head`, which closed early
            sys.stderr.close()
        return 0
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
