"""AwalkerNode: the QoS event handlers and services a private pipeline leaves out, and what stays."""
from __future__ import annotations

import time


def _entities(node) -> tuple[int, set[str]]:
    """(the node's QoS event handlers, the names of its services)."""
    from rclpy.event_handler import EventHandler

    return sum(isinstance(w, EventHandler) for w in node.waitables), {s.srv_name for s in node.services}


def test_private_options_leave_out_event_handlers_and_services_but_not_messages(ros_context):
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from awalker_tracker.nodes.base import AwalkerNode, private_node_options

    usual = AwalkerNode("usual", context=ros_context)
    private = AwalkerNode("private", context=ros_context,
                          **private_node_options([Parameter("answer", value=42)]))
    received: list[str] = []
    deadlines: list[object] = []
    try:
        for node in (usual, private):
            publisher = node.create_publisher(String, f"/{node.get_name()}/out", 10)
            node.create_subscription(String, f"/{node.get_name()}/out", lambda m: received.append(m.data), 10)
        handlers, services = _entities(usual)
        assert handlers >= 2 and {"usual/get_parameters", "usual/get_type_description"} <= services
        handlers, services = _entities(private)
        assert handlers == 0 and services == set()
        # overrides still reach the node, and a callback asked for explicitly is kept
        assert private.declare_parameter("answer", 0).value == 42
        private.create_subscription(String, "/private/other", lambda m: None, 10,
                                    event_callbacks=SubscriptionEventCallbacks(deadline=deadlines.append))
        assert _entities(private)[0] >= 1       # the deadline handler (and those its callbacks object asks for)
        # messages still flow (publisher: the private node's)
        executor = SingleThreadedExecutor(context=ros_context)
        executor.add_node(private)
        deadline = time.monotonic() + 10
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        publisher.publish(String(data="hello"))
        while not received and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert received == ["hello"]
        executor.shutdown()
    finally:
        usual.destroy_node()
        private.destroy_node()
