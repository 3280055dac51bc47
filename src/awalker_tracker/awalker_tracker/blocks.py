"""Per-particle kernels over blocks of particles on every core.

The compiled kernels (``numba.njit(nogil=True)``) are serial loops over particles that release the
GIL, and each particle's work is independent of the others', so a batch of N particles can be cut
into contiguous blocks that run at once on several threads: the calling thread and worker threads
each take the next block not yet taken (``BLOCKS_PER_THREAD`` blocks per thread). The result is the
same, bit for bit, as one call over all N (no particle's arithmetic depends on the blocks; random
numbers are drawn before the kernels run).

Batches smaller than ``MIN_BLOCK`` particles per thread run in the calling thread (a thread hand-off
costs ~20-50 us). The number of threads is the number of cores this process may use, or the
environment variable ``AWALKER_THREADS`` (1: everything in the calling thread).

BLAS libraries (numpy's, scipy's and OpenCV's OpenBLAS) run on one thread (``limit_blas_threads``, called when
``awalker_tracker`` is imported): the tracker's products are small (weights times 15000 particles' values), and
OpenBLAS, which splits a long one over the cores, keeps its threads spinning for a while after each call, so
that a product every frame held the second core the kernels' blocks need (docs/speed.md, *Threads*).
"""
from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

MIN_BLOCK = 1000     # particles: smaller batches are not cut
# blocks per thread: with one per thread, a thread kept off its core by the process's other work (the
# features beside the tracker) held the batch up by half of it (5000 particles, `awalker track` on a
# 300-frame walk, 3 alternate pairs: medians 30.1 -> 30.9 frames/s, every pair faster; 8 gained no more)
BLOCKS_PER_THREAD = 4

T = TypeVar("T")
_pool: ThreadPoolExecutor | None = None
_pool_workers = 0


def _forget_pool() -> None:
    """In a forked child the parent's worker threads do not exist: start a pool of its own when needed."""
    global _pool, _pool_workers
    _pool, _pool_workers = None, 0


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def thread_count() -> int:
    """Threads a batch may use: ``AWALKER_THREADS`` if set, else the cores this process may run on."""
    value = os.environ.get("AWALKER_THREADS", "").strip()
    if value:
        try:
            threads = int(value)
        except ValueError:
            raise ValueError(f"AWALKER_THREADS must be a whole number of threads, got {value!r}") from None
        if threads < 1:
            raise ValueError(f"AWALKER_THREADS must be >= 1, got {threads}")
        return threads
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:      # not on Linux
        return os.cpu_count() or 1


def limit_blas_threads() -> None:
    """Keep the BLAS libraries on one thread: those loaded later through ``OPENBLAS_NUM_THREADS`` (read when a
    library loads), those loaded already through threadpoolctl. Left alone if the environment names a BLAS
    thread count (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``): the user's choice."""
    if any(name in os.environ for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")):
        return
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")


def block_bounds(n: int, threads: int | None = None, per_thread: int = 1) -> list[tuple[int, int]]:
    """Contiguous [start, stop) blocks of near-equal size covering range(n): ``per_thread`` for each
    thread that gets at least ``MIN_BLOCK`` particles (one block when n is small)."""
    count = max(1, min(thread_count() if threads is None else threads, n // MIN_BLOCK))
    count = count * per_thread if count > 1 else 1
    edges = [round(k * n / count) for k in range(count + 1)]
    return [(edges[k], edges[k + 1]) for k in range(count)]


def over_blocks(n: int, work: Callable[[slice], T]) -> list[T]:
    """``work(rows)`` for the blocks ``rows`` (slices) of range(n), at once on several threads (the
    calling thread among them); their results in block order. ``work`` must only touch its rows of
    per-particle arrays (write outputs into row slices of arrays allocated beforehand).

    The blocks are ``BLOCKS_PER_THREAD`` times as many as the threads, and each thread takes the next
    block not yet taken until none is left: a thread that the other work of the process keeps off its
    core (the features' threads beside the tracker) holds up the batch by one block at most, not by
    half of it. The calling thread waits only for blocks another thread has taken."""
    global _pool, _pool_workers
    blocks = [slice(start, stop) for start, stop in block_bounds(n, per_thread=BLOCKS_PER_THREAD)]
    if len(blocks) == 1:
        return [work(blocks[0])]
    workers = len(blocks) // BLOCKS_PER_THREAD - 1
    if _pool is None or _pool_workers < workers:
        if _pool is not None:
            _pool.shutdown(wait=False)
        _pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="awalker-block")
        _pool_workers = workers
    batch = _Batch(blocks, work)
    for _ in range(workers):
        _pool.submit(batch.drain)
    batch.drain()
    return batch.results()


class _Batch:
    """The blocks of one ``over_blocks`` call, taken one at a time by whichever thread asks next."""

    def __init__(self, blocks: list[slice], work: Callable[[slice], T]) -> None:
        self._blocks, self._work = blocks, work
        self._results: list = [None] * len(blocks)
        self._next = itertools.count()      # next() on it is atomic under the interpreter lock
        self._done = 0
        self._error: BaseException | None = None
        self._finished = threading.Condition()

    def drain(self) -> None:
        """Do blocks until none is left to take (a worker that starts late finds none and returns)."""
        while (k := next(self._next)) < len(self._blocks):
            try:
                self._results[k] = self._work(self._blocks[k])
            except BaseException as exc:      # raised in the calling thread by results()
                self._error = self._error or exc
            finally:
                with self._finished:
                    self._done += 1
                    if self._done == len(self._blocks):
                        self._finished.notify_all()

    def results(self) -> list:
        """The blocks' results in order, once every block is done; a block's error raised here."""
        with self._finished:
            self._finished.wait_for(lambda: self._done == len(self._blocks))
        if self._error is not None:
            raise self._error
        return self._results
