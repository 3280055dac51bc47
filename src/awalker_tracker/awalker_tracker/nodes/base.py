"""The base of awalker's nodes: rclpy's Node, whose QoS event handlers and services can be left out.

rclpy gives every publisher and subscription a handler that logs an incompatible QoS offer, and every node six
parameter services and a type description service. An executor scans all of them each time it waits, which
it does about once per message: `awalker track` runs its nodes in one process, on a private domain, each
reader matched to its writer there, and leaves them out (``private_node_options``): 62 frames/s end to end
against 58 at 500 particles (four alternate pairs; docs/speed.md, "Fewer returns to the interpreter lock").
"""
from __future__ import annotations

from typing import Any

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
