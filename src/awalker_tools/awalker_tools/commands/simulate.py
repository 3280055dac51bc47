"""`awalker simulate`: simulate one Anthropomorphic Walker for a number of steps, write CSV or JSON.

Start from a cyclic gait (``--speed``/``--step-length`` looked up in the gait table) or from an
explicit state and controls (``--angle --stance-rate --swing-rate --stiffness --impulse``);
``--stochastic`` samples the control prior of Sec. 4.2 instead of holding kappa/iota fixed (our default
prior; add ``--paper-prior`` for the paper's variances and bilinear toe-off, see model/control.py).
One row per output sample (``--rate`` Hz, the first row is the start state):

time (s), stance_leg (left|right), stance_angle, swing_angle (rad), stance_rate, swing_rate (rad/s),
stiffness (kappa used in the frame ending at this row, N m/rad per kg), toe_off_impulse (iota of the
last heel strike, or the fixed iota; m/s), contact_x (stance-foot ground contact, m), hip_x, hip_y (m),
total_energy (J/kg: kinetic + gravitational with ground at 0 + kappa/2 (phi2 - phi1)^2, using this row's
kappa), heel_strike (1 if a heel strike happened in the frame ending at this row), fallen (0/1).
"""
from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from awalker_tracker.errors import InputError
from awalker_tracker.model import control, dynamics, cyclic_gaits
from awalker_tracker.model.walker import LEFT, RIGHT, WalkerParams, WalkerState, hip_position, stance_contact_x

COLUMNS = ("time", "stance_leg", "stance_angle", "swing_angle", "stance_rate", "swing_rate", "stiffness",
           "toe_off_impulse", "contact_x", "hip_x", "hip_y", "total_energy", "heel_strike", "fallen")


def _start(args: argparse.Namespace, params: WalkerParams, table: cyclic_gaits.GaitTable | None
           ) -> tuple[WalkerState, float, float]:
    """Initial state, stiffness and toe-off impulse from the gait or the explicit options."""
    leg = LEFT if args.stance_leg == "left" else RIGHT
    explicit = [args.angle, args.stance_rate, args.swing_rate, args.stiffness, args.impulse]
    if any(v is not None for v in explicit):
        if any(v is None for v in explicit):
            raise InputError("explicit start needs all of --angle --stance-rate --swing-rate --stiffness --impulse")
        state = WalkerState.from_arrays(args.angle, -args.angle, args.stance_rate, args.swing_rate, 0.0, leg)
        return state, float(args.stiffness), float(args.impulse)
    if args.speed is None or args.step_length is None:
        raise InputError("give --speed and --step-length (a cyclic gait) or an explicit start state and controls")
    assert table is not None
    v, s = args.speed, args.step_length
    if not (table.speeds[0] <= v <= table.speeds[-1] and table.step_lengths[0] <= s <= table.step_lengths[-1]):
        raise InputError(f"--speed {v} m/s / --step-length {s} m outside the gait table "
                         f"({table.speeds[0]:.2f}-{table.speeds[-1]:.2f} m/s, "
                         f"{table.step_lengths[0]:.2f}-{table.step_lengths[-1]:.2f} m)")
    w1, w2, kappa, iota = (float(np.ravel(x)[0]) for x in table.lookup(v, s))
    a = float(cyclic_gaits.double_support_angle(params, s))
    return WalkerState.from_arrays(a, -a, w1, w2, 0.0, leg), kappa, iota


def simulate(params: WalkerParams, state: WalkerState, stiffness: float, impulse: float, steps: int, rate: float,
             prior: control.ControlPrior | None = None, seed: int = 0, max_time: float = 120.0) -> list[dict]:
    """Rows (see module docstring) until ``steps`` heel strikes, a fall, or ``max_time`` seconds."""
    dt = 1.0 / rate
    rng = np.random.default_rng(seed)
    ctrl = control.initial_control(prior, 1, rng, stiffness=stiffness, toe_off_impulse=impulse) if prior else None
    kappa, iota, tss = stiffness, impulse, np.zeros(1)
    rows = [_row(params, 0.0, state, kappa, iota, False, False)]
    strikes, frame = 0, 0
    while strikes < steps and frame * dt < max_time:
        frame += 1
        if prior is not None:
            state, ctrl, events = control.sample_transition(params, prior, state, ctrl, dt, rng)
            kappa = float(ctrl.stiffness[0])
            iota = float(ctrl.toe_off_impulse[0])
        else:
            state, events = dynamics.advance(params, state, kappa, iota, dt, time_since_strike=tss)
            tss = events.time_since_strike
        strikes += int(events.heel_strike[0])
        rows.append(_row(params, frame * dt, state, kappa, iota, bool(events.heel_strike[0]),
                         bool(events.fallen[0])))
        if events.fallen[0]:
            break
    return rows


def _row(params: WalkerParams, t: float, s: WalkerState, kappa: float, iota: float, strike: bool, fallen: bool
         ) -> dict:
    hx, hy = hip_position(params, s)
    return {"time": round(t, 9), "stance_leg": "left" if s.stance_leg[0] == LEFT else "right",
            "stance_angle": float(s.stance_angle[0]), "swing_angle": float(s.swing_angle[0]),
            "stance_rate": float(s.stance_rate[0]), "swing_rate": float(s.swing_rate[0]),
            "stiffness": kappa, "toe_off_impulse": iota, "contact_x": float(stance_contact_x(params, s)[0]),
            "hip_x": float(hx[0]), "hip_y": float(hy[0]),
            "total_energy": float(dynamics.total_energy(params, s, kappa)[0]),
            "heel_strike": int(strike), "fallen": int(fallen)}


def run(args: argparse.Namespace) -> int:
    if args.steps < 1:
        raise InputError(f"--steps {args.steps}: expected at least 1")
    if args.rate <= 0:
        raise InputError(f"--rate {args.rate}: expected a positive frame rate in Hz")
    if args.leg_length <= 0:
        raise InputError(f"--leg-length {args.leg_length}: expected a positive length in metres")
    params = WalkerParams(leg_length=args.leg_length)
    needs_table = args.stochastic or args.speed is not None or args.step_length is not None
    table = None
    if needs_table:
        try:
            table = cyclic_gaits.GaitTable.load(args.table).scaled_to(params)  # solved for L = 0.9 m: rescaled exactly
        except ValueError as exc:
            raise InputError(f"{args.table or 'packaged gait table'}: {exc}") from None
    state, kappa, iota = _start(args, params, table)
    if args.paper_prior and not args.stochastic:
        raise InputError("--paper-prior: only with --stochastic")
    prior = None
    if args.stochastic:
        prior = control.ControlPrior.paper(table) if args.paper_prior else control.ControlPrior.from_gait_table(table)
    rows = simulate(params, state, kappa, iota, args.steps, args.rate, prior, args.seed)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix == ".json":
        out.write_text(json.dumps({"params": {k: getattr(params, k) for k in params.__dataclass_fields__},
                                   "columns": list(COLUMNS), "rows": rows}, indent=1))
    else:
        with out.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=COLUMNS)
            writer.writeheader()
            writer.writerows(rows)
    strikes = sum(r["heel_strike"] for r in rows)
    distance = rows[-1]["hip_x"] - rows[0]["hip_x"]
    print(json.dumps({"out": str(out), "rows": len(rows), "heel_strikes": strikes, "fallen": bool(rows[-1]["fallen"]),
                      "duration_s": rows[-1]["time"], "mean_speed_m_s": distance / max(rows[-1]["time"], 1e-9)}))
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("simulate", help="simulate one walker from a cyclic gait or a state; CSV/JSON")
    parser.add_argument("--out", required=True, help="output file (.csv, or .json)")
    parser.add_argument("--speed", type=float, help="gait speed (m/s), with --step-length")
    parser.add_argument("--step-length", type=float, help="gait step length (m)")
    parser.add_argument("--angle", type=float, help="explicit start: double-support leg angle a (rad)")
    parser.add_argument("--stance-rate", type=float, help="explicit start: phi1' (rad/s)")
    parser.add_argument("--swing-rate", type=float, help="explicit start: phi2' (rad/s)")
    parser.add_argument("--stiffness", type=float, help="explicit: kappa (N m/rad per kg)")
    parser.add_argument("--impulse", type=float, help="explicit: toe-off iota (m/s)")
    parser.add_argument("--stance-leg", choices=("left", "right"), default="left")
    parser.add_argument("--steps", type=int, default=10, help="number of heel strikes to simulate")
    parser.add_argument("--rate", type=float, default=30.0, help="output samples per second (frame rate)")
    parser.add_argument("--stochastic", action="store_true", help="sample kappa/iota from the control prior")
    parser.add_argument("--paper-prior", action="store_true",
                        help="with --stochastic: the paper's variances and bilinear toe-off (walkers soon fall)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--leg-length", type=float, default=WalkerParams().leg_length, help="L in m")
    parser.add_argument("--table", default=None, help="gait table JSON (default: the packaged table)")
    parser.set_defaults(func=run)
