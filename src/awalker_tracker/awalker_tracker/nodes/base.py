"""The base of awalker's nodes: rclpy's Node, whose QoS event handlers and services can be left out.

rclpy gives every publisher and subscription a handler that logs an incompatible QoS offer, and every node six
parameter services and a type description service. An executor scans all of them each time it waits, which
it does about once per message: `awalker track` runs its nodes in one process, on a private domain, each
reader matched to its writer there, and leaves them out (``private_node_options``): 62 frames/s end to end
against 58 at 500 particles (four alternate pairs; docs/speed.md, "Fewer returns to the interpreter lock").
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM


class AwalkerNode(Node):
    """An rclpy Node; with ``qos_events=False`` its publishers and subscriptions get no QoS event handlers
    (an event callback passed explicitly is kept)."""

    def __init__(self, node_name: str, *, qos_events: bool = True, **kwargs: Any) -> None:
        self._qos_events = qos_events        # before Node's constructor, which creates publishers
        super().__init__(node_name, **kwargs)

    def create_publisher(self, *args: Any, **kwargs: Any) -> Any:
        if not self._qos_events:
            kwargs.setdefault("event_callbacks", PublisherEventCallbacks(use_default_callbacks=False))
        return super().create_publisher(*args, **kwargs)

    def create_subscription(self, *args: Any, **kwargs: Any) -> Any:
        if not self._qos_events:
            kwargs.setdefault("event_callbacks", SubscriptionEventCallbacks(use_default_callbacks=False))
        return super().create_subscription(*args, **kwargs)


def private_node_options(overrides: list[Parameter] | None = None) -> dict[str, Any]:
    """Keyword arguments of an ``AwalkerNode`` that only its own process reaches (module docstring): the
    parameter ``overrides`` and no QoS event handlers, parameter services or type description service."""
    return {"parameter_overrides": [*(overrides or []), Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)],
            "start_parameter_services": False, "qos_events": False}


@dataclass(frozen=True)
class NodeParameter:
    """A ROS parameter of a node, declared from this one description (``declare_parameters``) and listed by its
    console script's ``--help`` (``parameter_help``) without starting ROS.

    ``default``: the value, a ``Parameter.Type`` for a parameter with no default (unset unless given), or a
    ``Default`` that depends on another parameter declared before it (the tracker's profile)."""

    name: str
    default: Any
    description: str


@dataclass(frozen=True)
class Default:
    """A default computed from the value of an earlier parameter: ``compute(value)``; ``text`` shows it in
    ``--help`` (e.g. "the profile's: accurate 15000, realtime 5000")."""

    compute: Callable[[Any], Any]
    text: str
    after: str          # the parameter whose value it depends on


def declare_parameters(node: Node, parameters: Sequence[NodeParameter]) -> dict[str, Any]:
    """Declare ``parameters`` on ``node`` in order (with their descriptions); their values by name."""
    values: dict[str, Any] = {}
    for p in parameters:
        default = p.default.compute(values[p.default.after]) if isinstance(p.default, Default) else p.default
        values[p.name] = node.declare_parameter(p.name, default, ParameterDescriptor(description=p.description)).value
    return values


def _shown(default: Any) -> str:
    if isinstance(default, Default):
        return default.text
    if isinstance(default, Parameter.Type):
        return "unset"
    if isinstance(default, bool):
        return str(default).lower()
    return '""' if default == "" else str(default)


def parameter_help(program: str, summary: str, parameters: Sequence[NodeParameter]) -> str:
    """The usage text of a node's console script: how to run it and each parameter with its default."""
    width = max(len(p.name) for p in parameters)
    lines = [f"usage: {program} [--ros-args -p NAME:=VALUE ...]", "", summary, "", "ROS parameters (default):"]
    lines += [f"  {p.name:<{width}}  {p.description} ({_shown(p.default)})" for p in parameters]
    return "\n".join(lines)


def wants_help(args: Sequence[str]) -> bool:
    """Whether the command line asks for ``-h``/``--help`` before any ``--ros-args`` (which ROS reads)."""
    own = list(args)[: list(args).index("--ros-args")] if "--ros-args" in args else list(args)
    return "-h" in own or "--help" in own
