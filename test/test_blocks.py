"""Blocks of particles on several threads (awalker_tracker/blocks.py): the blocks, the threads, and the
same particles out of the compiled kernels whether a batch is cut or not."""
from __future__ import annotations

import os
import threading
from dataclasses import fields, is_dataclass

import numpy as np
import pytest

from awalker_tracker import blocks
from awalker_tracker.inference.tracker import StartDescription, TrackerConfig, TrackerModel, marker_likelihood
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.model.walker import LEFT


@pytest.mark.parametrize("n, threads", [(0, 2), (999, 4), (1999, 2), (2000, 2), (5000, 2), (5001, 3), (9000, 1)])
def test_blocks_cover_the_batch_once_in_order(n: int, threads: int):
    bounds = blocks.block_bounds(n, threads)
    assert bounds[0][0] == 0 and bounds[-1][1] == n
    assert all(stop == start for (_, stop), (start, _) in zip(bounds, bounds[1:]))
    assert len(bounds) == max(1, min(threads, n // blocks.MIN_BLOCK))
    if len(bounds) > 1:
        assert min(stop - start for start, stop in bounds) >= blocks.MIN_BLOCK


def test_blocks_run_on_several_threads_and_come_back_in_order(monkeypatch):
    monkeypatch.setenv("AWALKER_THREADS", "3")
    seen: list[tuple[int, str]] = []
    together = threading.Barrier(3, timeout=10)     # broken unless the three blocks run at once

    def work(rows: slice) -> int:
        seen.append((rows.start, threading.current_thread().name))
        if together is not None:
            together.wait()
        return rows.stop

    n = 3 * blocks.MIN_BLOCK + 7
    assert blocks.over_blocks(n, work) == [stop for _, stop in blocks.block_bounds(n, 3)]
    names = dict(seen)
    assert names[0] == threading.current_thread().name          # the first block in the calling thread
    assert len(set(names.values())) == 3
    monkeypatch.setenv("AWALKER_THREADS", "1")
    together = None
    assert blocks.over_blocks(n, work) == [n]


def test_an_error_in_a_worker_block_reaches_the_caller(monkeypatch):
    monkeypatch.setenv("AWALKER_THREADS", "2")
    n = 2 * blocks.MIN_BLOCK

    def work(rows: slice) -> int:
        if rows.start > 0:
            raise FloatingPointError(f"block at {rows.start}")
        return rows.stop

    with pytest.raises(FloatingPointError, match=f"block at {blocks.MIN_BLOCK}"):
        blocks.over_blocks(n, work)


def _cut_in_child(n: int, result) -> None:
    result.put(blocks.over_blocks(n, lambda rows: rows.stop))


@pytest.mark.skipif(not hasattr(os, "register_at_fork"), reason="fork only")
def test_a_forked_child_cuts_its_batches_too(monkeypatch):
    """The parent's worker threads are not in a forked child: without a pool of its own it would wait forever."""
    import multiprocessing

    monkeypatch.setenv("AWALKER_THREADS", "2")
    n = 2 * blocks.MIN_BLOCK
    assert blocks.over_blocks(n, lambda rows: rows.stop) == [blocks.MIN_BLOCK, n]     # the parent's pool exists
    context = multiprocessing.get_context("fork")
    result = context.Queue()
    child = context.Process(target=_cut_in_child, args=(n, result))
    child.start()
    child.join(timeout=20)
    if child.is_alive():
        child.kill()
    assert child.exitcode == 0 and result.get(timeout=1) == [blocks.MIN_BLOCK, n]


@pytest.mark.parametrize("value", ["0", "two", "-1"])
def test_a_bad_thread_count_is_named(monkeypatch, value: str):
    monkeypatch.setenv("AWALKER_THREADS", value)
    with pytest.raises(ValueError, match="AWALKER_THREADS"):
        blocks.thread_count()


def _arrays(value) -> list[np.ndarray]:
    """Every array of a (nested) dataclass of per-particle arrays, or a tuple of them."""
    if is_dataclass(value):
        return [a for f in fields(value) for a in _arrays(getattr(value, f.name))]
    if isinstance(value, tuple):
        return [a for item in value for a in _arrays(item)]
    return [np.asarray(value)]


def test_cut_batches_give_the_same_particles_bit_for_bit(monkeypatch):
    """Dynamics with heel strikes, eq. (6) with the swing clearance, and the posed bodies of 2500
    particles over 12 frames: cut into two blocks on two threads, the same numbers as in one block."""
    n = 2500
    assert len(blocks.block_bounds(n, 2)) == 2
    results = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("AWALKER_THREADS", threads)
        model = TrackerModel(BodyDescription.default(), StartDescription(0, (0.5, -0.3), 0.3, 1.3, 0.7, LEFT),
                             marker_likelihood(0.03), TrackerConfig(dt=1 / 30))
        rng = np.random.default_rng(7)
        states = model.initial(n, rng)
        strikes = 0
        for _ in range(12):
            states, events = model.transition(states, rng)
            strikes += int(np.sum(events.heel_strike))
        assert strikes > n // 4                     # the frames cover heel strikes (the impact path)
        results[threads] = _arrays(states)
    assert len(results["1"]) == len(results["2"])
    for one, two in zip(results["1"], results["2"]):
        np.testing.assert_array_equal(one, two)
