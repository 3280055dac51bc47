"""Shared fixtures: a private rclpy Context per test, one DDS domain per xdist worker."""
from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
MOCAP_DIR = REPO_ROOT / "test" / "data" / "mocap"  # CMU motion capture (test/data/mocap/README.md)
MOCAP_07 = MOCAP_DIR / "cmu_subject07"          # subject 7: 07.asf, 07_01.amc, 07_02.amc, 07_04.amc


def _worker_domain() -> int:
    """Domain id unique to this pytest-xdist worker (gw0 -> 40, gw1 -> 41, ...)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    return 40 + int(worker.removeprefix("gw") or 0)


@pytest.fixture
def ros_domain_id() -> int:
    return _worker_domain()


def _private_context(domain: int, discovery_range: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[object]:
    """A private rclpy Context on ``domain`` with ROS_AUTOMATIC_DISCOVERY_RANGE=``discovery_range``.

    The environment is set too, so that subprocesses started by the test join the same domain."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", discovery_range)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    try:
        yield ctx
    finally:
        ctx.try_shutdown()


@pytest.fixture
def ros_context(ros_domain_id: int, monkeypatch: pytest.MonkeyPatch) -> Iterator[object]:
    """A private rclpy Context on this worker's domain, in-process only (discovery OFF keeps other
    processes out), shut down after the test."""
    yield from _private_context(ros_domain_id, "OFF", monkeypatch)


@pytest.fixture
def localhost_context(ros_domain_id: int, monkeypatch: pytest.MonkeyPatch) -> Iterator[object]:
    """A private rclpy Context on this worker's domain + 10 that discovers other processes on this
    host: for tests that start nodes in a subprocess (it inherits the domain through the environment)."""
    yield from _private_context(ros_domain_id + 10, "LOCALHOST", monkeypatch)
