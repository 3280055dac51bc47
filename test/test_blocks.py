"""Blocks of particles on several threads (awalker_tracker/blocks.py): the blocks, the threads, and the
same particles out of the compiled kernels whether a batch is cut or not."""
from __future__ import annotations

import os
import threading
import time
from dataclasses import fields, is_dataclass

import numpy as np
import pytest

from awalker_tracker import blocks
from awalker_tracker.inference.filter_model import StartDescription, TrackerConfig, TrackerModel, marker_likelihood
from awalker_tracker.model.body import BodyDescription
from awalker_tracker.model.walker import LEFT


@pytest.mark.parametrize("n, threads, per_thread",
                         [(0, 2, 1), (999, 4, 1), (1999, 2, 1), (2000, 2, 1), (5000, 2, 1), (5001, 3, 1), (9000, 1, 1),
                          (1999, 2, 4), (2000, 2, 4), (5000, 2, 4), (5001, 3, 4), (9000, 1, 4)])
def test_blocks_cover_the_batch_once_in_order(n: int, threads: int, per_thread: int):
    bounds = blocks.block_bounds(n, threads, per_thread)
    assert bounds[0][0] == 0 and bounds[-1][1] == n
    assert all(stop == start for (_, stop), (start, _) in zip(bounds, bounds[1:]))
    cut = max(1, min(threads, n // blocks.MIN_BLOCK))
    assert len(bounds) == (cut * per_thread if cut > 1 else 1)
    if len(bounds) > 1:
        sizes = [stop - start for start, stop in bounds]
        assert min(sizes) * per_thread >= blocks.MIN_BLOCK - per_thread and max(sizes) - min(sizes) <= 1


def test_blocks_run_on_several_threads_and_come_back_in_order(monkeypatch):
    monkeypatch.setenv("AWALKER_THREADS", "3")
    seen: list[tuple[int, str]] = []
    together = threading.Barrier(3, timeout=10)     # broken unless three blocks at a time run at once

    def work(rows: slice) -> int:
        seen.append((rows.start, threading.current_thread().name))
        if together is not None:
            together.wait()
        return rows.stop

    n = 3 * blocks.MIN_BLOCK + 7
    expected = blocks.block_bounds(n, 3, blocks.BLOCKS_PER_THREAD)
    assert len(expected) == 3 * blocks.BLOCKS_PER_THREAD
    assert blocks.over_blocks(n, work) == [stop for _, stop in expected]
    assert sorted(start for start, _ in seen) == [start for start, _ in expected]      # each block once
    names = {name for _, name in seen}
    assert threading.current_thread().name in names and len(names) == 3
    monkeypatch.setenv("AWALKER_THREADS", "1")
    together = None
    assert blocks.over_blocks(n, work) == [n]


def test_a_thread_held_off_its_core_holds_the_batch_up_by_one_block(monkeypatch):
    """A worker that is slow in its first block (as if the process's other threads kept it off its core):
    the calling thread takes every other block meanwhile."""
    monkeypatch.setenv("AWALKER_THREADS", "2")
    caller = threading.current_thread()
    by_thread: dict[str, int] = {}
    slow_once = threading.Event()

    def work(rows: slice) -> int:
        me = threading.current_thread()
        if me is not caller and not slow_once.is_set():
            slow_once.set()
            time.sleep(0.5)
        by_thread[me.name] = by_thread.get(me.name, 0) + 1
        return rows.stop

    n = 2 * blocks.MIN_BLOCK
    total = len(blocks.block_bounds(n, 2, blocks.BLOCKS_PER_THREAD))
    assert total == 2 * blocks.BLOCKS_PER_THREAD
    assert blocks.over_blocks(n, work)[-1] == n
    assert by_thread[caller.name] >= total - 1 and sum(by_thread.values()) == total


def test_an_error_in_a_worker_block_reaches_the_caller(monkeypatch):
    monkeypatch.setenv("AWALKER_THREADS", "2")
    n = 2 * blocks.MIN_BLOCK
    caller = threading.current_thread()
    met = threading.Barrier(2, timeout=10)      # both threads take a block before any raises
    started: set[threading.Thread] = set()
    entered: list[int] = []
    raised: list[int] = []

    def work(rows: slice) -> int:
        me = threading.current_thread()
        if me not in started:
            started.add(me)
            met.wait()
        entered.append(rows.start)
        if me is not caller:
            raised.append(rows.start)
            raise FloatingPointError(f"block at {rows.start}")
        return rows.stop

    with pytest.raises(FloatingPointError, match=r"block at \d+") as error:
        blocks.over_blocks(n, work)
    assert str(error.value) == f"block at {raised[0]}"           # the first error, from the worker's block
    starts = [start for start, _ in blocks.block_bounds(n, 2, blocks.BLOCKS_PER_THREAD)]
    assert sorted(entered) == starts and len(raised) < len(starts)   # every block done before it is raised


def _cut_in_child(n: int, result) -> None:
    result.put(blocks.over_blocks(n, lambda rows: rows.stop))


@pytest.mark.skipif(not hasattr(os, "register_at_fork"), reason="fork only")
def test_a_forked_child_cuts_its_batches_too(monkeypatch):
    """The parent's worker threads are not in a forked child: without a pool of its own it would wait forever."""
    import multiprocessing

    monkeypatch.setenv("AWALKER_THREADS", "2")
    n = 2 * blocks.MIN_BLOCK
    stops = [stop for _, stop in blocks.block_bounds(n, 2, blocks.BLOCKS_PER_THREAD)]
    assert blocks.over_blocks(n, lambda rows: rows.stop) == stops     # the parent's pool exists
    context = multiprocessing.get_context("fork")
    result = context.Queue()
    child = context.Process(target=_cut_in_child, args=(n, result))
    child.start()
    child.join(timeout=20)
    if child.is_alive():
        child.kill()
    assert child.exitcode == 0 and result.get(timeout=1) == stops


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


_BLAS_REPORT = """
import json, sys
{first}
import awalker_tracker
import cv2, scipy.linalg                      # BLAS libraries loaded after the package
from threadpoolctl import threadpool_info
print(json.dumps([(i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"]))
"""


def _blas_threads(first: str, **env: str) -> list:
    """(library, threads) of every BLAS library loaded in a fresh interpreter that runs ``first``, then imports
    awalker_tracker, then OpenCV and scipy.linalg."""
    import json
    import subprocess
    import sys

    clean = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                              "MKL_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", _BLAS_REPORT.format(first=first)], env={**clean, **env},
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: BLAS runs on one thread anyway")
@pytest.mark.parametrize("first", ["", "import numpy"])
def test_blas_libraries_run_on_one_thread(first: str):
    """Every BLAS library runs on one thread once awalker_tracker is imported, whether numpy was loaded before it
    (threadpoolctl) or the libraries load after it (the environment): spinning BLAS threads held the second core
    the particle blocks need (docs/speed.md)."""
    libraries = _blas_threads(first)
    assert len(libraries) >= 2, libraries                     # numpy's and at least one more (OpenCV's, scipy's)
    assert all(threads == 1 for _, threads in libraries), libraries


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: BLAS runs on one thread anyway")
def test_a_blas_thread_count_the_user_sets_is_kept():
    libraries = _blas_threads("import numpy", OPENBLAS_NUM_THREADS="2")
    assert libraries and all(threads == 2 for _, threads in libraries), libraries
