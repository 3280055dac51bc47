"""Milliseconds to advance N walkers by one 1/30 s frame (RK4, default sub-steps, heel strikes happening).

Walkers start spread over the phase of the 5 km/h, 0.7 m cyclic gait so that about 1/15 of them
strike in every frame, as in tracking. Prints JSON: per N the median and min ms per frame, the
strikes per frame, and the share of time spent in strike handling.
Usage: .venv/bin/python benchmarks/bench_walker.py [--frames 30] [--sizes 1000 5000 20000] [--substeps 4]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from awalker_tracker.model import dynamics, cyclic_gaits
from awalker_tracker.model.walker import WalkerParams, WalkerState


def spread_walkers(params: WalkerParams, table: cyclic_gaits.GaitTable, n: int, rng: np.random.Generator
                   ) -> tuple[WalkerState, np.ndarray, np.ndarray]:
    w1, w2, kappa, iota = (float(np.ravel(x)[0]) for x in table.lookup(5 / 3.6, 0.7))
    a = float(cyclic_gaits.double_support_angle(params, 0.7))
    state = WalkerState.from_arrays(a, -a, w1, w2)
    # advance one walker through a stride and pick states at random phases
    states = []
    s = state
    for _ in range(60):
        s, _ = dynamics.advance(params, s, kappa, iota, 1 / 120)
        states.append(s)
    picks = rng.integers(0, len(states), n)
    fields = ("stance_angle", "swing_angle", "stance_rate", "swing_rate", "contact_origin", "stance_leg")
    walkers = WalkerState(*(np.concatenate([getattr(states[i], f) for i in picks]) for f in fields))
    return walkers, np.full(n, kappa) + 0.05 * rng.standard_normal(n), np.full(n, iota)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 5000, 20000])
    parser.add_argument("--substeps", type=int, default=None, help="RK4 sub-steps per frame (default: dynamics'")
    args = parser.parse_args()
    params = WalkerParams()
    table = cyclic_gaits.GaitTable.load()
    rng = np.random.default_rng(0)
    results = []
    for n in args.sizes:
        walkers, kappa, iota = spread_walkers(params, table, n, rng)
        tss = np.zeros(n)
        times, strikes = [], []
        for _ in range(args.frames):
            t0 = time.perf_counter()
            walkers, ev = dynamics.advance(params, walkers, kappa, iota, 1 / 30, substeps=args.substeps,
                                           time_since_strike=tss)
            times.append(time.perf_counter() - t0)
            tss = ev.time_since_strike
            strikes.append(int(ev.heel_strike.sum()))
        # the same frames without any strike handling, for the share of time strikes cost
        no_strike = []
        still = WalkerState.from_arrays(np.full(n, 0.3), np.full(n, -0.3), np.full(n, -1.0), np.full(n, 0.5))
        for _ in range(args.frames):
            t0 = time.perf_counter()
            dynamics.advance(params, still, kappa, iota, 1 / 30, substeps=args.substeps)
            no_strike.append(time.perf_counter() - t0)
        results.append({"walkers": n, "ms_per_frame_median": 1e3 * float(np.median(times)),
                        "ms_per_frame_min": 1e3 * float(np.min(times)),
                        "ms_per_frame_without_strikes_median": 1e3 * float(np.median(no_strike)),
                        "strikes_per_frame_mean": float(np.mean(strikes)),
                        "fallen_after": int(ev.fallen.sum()),
                        "substeps": args.substeps or dynamics.substeps_for(1 / 30)})
    print(json.dumps({"benchmark": "walker advance, 1/30 s frame", "results": results}, indent=1))


if __name__ == "__main__":
    main()
