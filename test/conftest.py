"""Shared fixtures: a private rclpy Context per test, one DDS domain per xdist worker."""
from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
MOCAP_DIR = REPO_ROOT / "test" / "data" / "mocap"  # copy of ../shared/data/mocap/cmu_subject07 (07.asf, 07_01.amc)


def _worker_domain() -> int:
    """Domain id unique to this pytest-xdist worker (gw0 -> 40, gw1 -> 41, ...)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return 40 + int(worker.removeprefix("gw") or 0)


@pytest.fixture
def ros_domain_id() -> int:
    return _worker_domain()


@pytest.fixture
def ros_context(ros_domain_id: int) -> Iterator[object]:
    """A private rclpy Context on this worker's domain, shut down after the test.

    In-process only: ROS_AUTOMATIC_DISCOVERY_RANGE=OFF keeps other processes out. Tests that
    span processes set LOCALHOST themselves (see test/tools/test_replay_multiprocess.py).
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF")
    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_domain_id, signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield ctx
    finally:
        ctx.try_shutdown()
