"""Per-particle kernels over blocks of particles, one block per core.

The compiled kernels (``numba.njit(nogil=True)``) are serial loops over particles that release the
GIL, and each particle's work is independent of the others', so a batch of N particles can be cut
into contiguous blocks that run at once on several threads: the calling thread takes the first
block, worker threads the rest. The result is the same, bit for bit, as one call over all N (no
particle's arithmetic depends on the blocks; random numbers are drawn before the kernels run).

Batches smaller than ``MIN_BLOCK`` particles per block run in the calling thread (a thread hand-off
costs ~20-50 us). The number of threads is the number of cores this process may use, or the
environment variable ``AWALKER_THREADS`` (1: everything in the calling thread).
"""
from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

MIN_BLOCK = 1000     # particles: smaller batches are not cut

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


def block_bounds(n: int, threads: int | None = None) -> list[tuple[int, int]]:
    """Contiguous [start, stop) blocks covering range(n): one per thread, each at least ``MIN_BLOCK``
    particles (one block when n is small)."""
    count = max(1, min(thread_count() if threads is None else threads, n // MIN_BLOCK))
    edges = [round(k * n / count) for k in range(count + 1)]
    return [(edges[k], edges[k + 1]) for k in range(count)]


def over_blocks(n: int, work: Callable[[slice], T]) -> list[T]:
    """``work(rows)`` for the blocks ``rows`` (slices) of range(n), at once on several threads (the
    first in the calling thread); their results in block order. ``work`` must only touch its rows of
    per-particle arrays (write outputs into row slices of arrays allocated beforehand)."""
    global _pool, _pool_workers
    blocks = [slice(start, stop) for start, stop in block_bounds(n)]
    if len(blocks) == 1:
        return [work(blocks[0])]
    if _pool is None or _pool_workers < len(blocks) - 1:
        if _pool is not None:
            _pool.shutdown(wait=False)
        _pool = ThreadPoolExecutor(max_workers=len(blocks) - 1, thread_name_prefix="awalker-block")
        _pool_workers = len(blocks) - 1
    futures = [_pool.submit(work, rows) for rows in blocks[1:]]
    first = work(blocks[0])
    return [first] + [future.result() for future in futures]
