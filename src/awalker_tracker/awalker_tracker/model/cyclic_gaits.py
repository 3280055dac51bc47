"""Cyclic gaits of the Anthropomorphic Walker (paper eq. 3, Fig. 3-4) and the packaged gait table.

For a speed v (m/s) and step length s (m) the start pose is double support with the legs at
+a / -a, s = 2 (R a + (L - R) sin a), and one step lasts T = s / v. Newton's method with a
finite-difference Jacobian finds x = (phi1'_0, phi2'_0, kappa, iota) such that simulating from
(a, -a, phi1'_0, phi2'_0) strikes the ground at time T and the post-impact state equals the
start state (legs swapped). The residual (4,) is

    [t_strike - T (s), phi1+ - a (rad), phi1'+ - phi1'_0 (rad/s), phi2'+ - phi2'_0 (rad/s)]

(phi2+ = -phi1+ at a strike, so the pose residual is one number). :func:`solve_grid` sweeps a
speed x step-length grid with continuation from solved neighbours plus several fresh starting
guesses; :class:`GaitTable` holds the result (``data/cyclic_gaits.json``).

Eq. (3) has more than one solution family. The mirror-symmetric gaits (both legs vertical together
at mid-step, pre-collision rates equal to the start rates; see :func:`symmetric_residual`) exist
over the whole grid and give smooth kappa and iota maps (Fig. 3); the packaged table holds them.
Up to 4.5 km/h they are locally stable (step-map radius < 1) except for slow, very long steps. From
5 km/h they are unstable (radius 1.0-1.5: a perturbation grows step after step) and an asymmetric
family beside them is stable (radius 0.83-1.0; e.g. 5 km/h, 0.7 m: kappa 0.749, radius 0.925 instead
of kappa 0.737, radius 1.077; its swing leg retracts a little more before the strike). ``family=
"stable"`` keeps the most stable solution at each point instead. It was measured and not adopted:
the cyclic-gait toe-off already corrects the stance rate at every strike, and tracking real walks
was worse with it (docs/design.md, "Which cyclic gait").
"""
from __future__ import annotations

import dataclasses
import functools
import json
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path

import numba
import numpy as np

from ..errors import InputError
from .dynamics import heel_strike, integrate, simulate_to_strike
from .walker import LEFT, WalkerParams, WalkerState

TABLE_VERSION = 2
#: RK4 step (s) of the simulations inside the gait solver.
SOLVER_STEP = 1.0 / 480.0
#: Converged when max |residual| is below this (s, rad, rad/s).
RESIDUAL_TOLERANCE = 1e-9
KMH = 1.0 / 3.6  # m/s per km/h


def double_support_angle(params: WalkerParams, step_length: np.ndarray | float) -> np.ndarray:
    """Leg angle a (rad) with both feet down for a step length (m): inverse of WalkerParams.step_length."""
    s = np.asarray(step_length, float)
    r, al = params.foot_radius, params.leg_length - params.foot_radius
    a = s / (2.0 * params.leg_length)
    for _ in range(30):
        f = 2.0 * (r * a + al * np.sin(a)) - s
        a = a - f / (2.0 * (r + al * np.cos(a)))
    return a


#: Preferred human step length at 5 km/h for L = 0.9 m (m), and its growth with speed: step ~ speed^0.42
#: (people step about 0.65-0.75 m at 5 km/h; docs/design.md, *A person's usual step length*). Scaled to other leg lengths by Froude similarity.
PREFERRED_STEP_AT_5KMH = 0.7
PREFERRED_STEP_EXPONENT = 0.42


def preferred_step_length(params: WalkerParams, speed: np.ndarray | float) -> np.ndarray | float:
    """A person's usual step length (m) at ``speed`` (m/s): 0.7 m at 5 km/h for a 0.9 m leg, growing as
    speed^0.42, at equal Froude number v / sqrt(g L) for other legs (step length scales with L)."""
    reference = WalkerParams(leg_length=0.9, gravity=params.gravity)
    froude_ratio = np.asarray(speed, float) / (5.0 * KMH) * np.sqrt(reference.leg_length / params.leg_length)
    out = PREFERRED_STEP_AT_5KMH * params.leg_length / reference.leg_length * froude_ratio ** PREFERRED_STEP_EXPONENT
    return float(out) if np.ndim(out) == 0 else out


def cyclic_residual(params: WalkerParams, speed: float, step_length: float, unknowns: np.ndarray,
                    step: float = SOLVER_STEP) -> np.ndarray:
    """Residuals of eq. (3) for one or several unknown vectors x = (phi1'_0, phi2'_0, kappa, iota).

    ``unknowns`` has shape (4,) or (K, 4); returns (4,) or (K, 4); NaN where no strike happened.
    """
    x = np.atleast_2d(np.asarray(unknowns, float))
    a = float(double_support_angle(params, step_length))
    duration = step_length / speed
    start = WalkerState.from_arrays(a, -a, x[:, 0], x[:, 1])
    post, times, _ = simulate_to_strike(params, start, x[:, 2], x[:, 3], step=step, max_time=1.5 * duration + 0.2)
    res = np.stack([times - duration, post.stance_angle - a, post.stance_rate - x[:, 0],
                    post.swing_rate - x[:, 1]], axis=1)
    return res[0] if np.ndim(unknowns) == 1 else res


@dataclass(frozen=True)
class GaitSolution:
    """Result of solving eq. (3) at one (speed, step length)."""

    speed: float
    step_length: float
    unknowns: np.ndarray        # (phi1'_0, phi2'_0, kappa, iota)
    residual: float             # max |residual| (s, rad, rad/s mixed)
    converged: bool
    reason: str
    iterations: int
    pre_collision_rates: np.ndarray  # (phi1'-, phi2'-) just before the strike (rad/s)
    step_map_radius: float = np.nan  # largest |Floquet multiplier| of the step-to-step map (< 1: stable)


def _pre_collision_rates(params: WalkerParams, speed: float, step_length: float, x: np.ndarray) -> np.ndarray:
    """(phi1', phi2') just before the heel strike of the gait x (rad/s)."""
    a = float(double_support_angle(params, step_length))
    start = WalkerState.from_arrays(a, -a, x[0], x[1])
    _, _, pre = simulate_to_strike(params, start, x[2], x[3], step=SOLVER_STEP, max_time=1.5 * step_length / speed + 0.2)
    return pre[0]


def _newton(residual: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, max_iterations: int,
            tolerance: float) -> tuple[np.ndarray, float, str, int]:
    """Damped Newton with a forward-difference Jacobian; ``residual`` maps (K, 4) -> (K, 4) in one batch.

    Returns (x, max |residual|, reason, iterations).
    """
    x = np.asarray(x0, float).copy()
    res = residual(x[None])[0]
    if not np.all(np.isfinite(res)):
        return x, np.inf, "no heel strike from the starting guess", 0
    norm = float(np.max(np.abs(res)))
    for iteration in range(max_iterations + 1):
        if norm < tolerance:
            return x, norm, "converged", iteration
        if iteration == max_iterations:
            break
        eps = 1e-7 * np.maximum(1.0, np.abs(x))
        jac = (residual(x[None, :] + np.diag(eps)) - res[None, :]).T / eps[None, :]
        if not np.all(np.isfinite(jac)):
            return x, norm, "jacobian undefined (a probe missed the heel strike)", iteration
        try:
            delta = np.linalg.solve(jac, -res)
        except np.linalg.LinAlgError:
            return x, norm, "singular jacobian", iteration
        lam = 1.0                                   # backtracking on max |residual|
        while lam > 1e-3:
            trial = x + lam * delta
            trial_res = residual(trial[None])[0]
            if np.all(np.isfinite(trial_res)):
                trial_norm = float(np.max(np.abs(trial_res)))
                if trial_norm < norm * (1.0 - 1e-4 * lam) or trial_norm < tolerance:
                    break
            lam *= 0.5
        else:
            return x, norm, "line search failed (no descent)", iteration
        x, res, norm = trial, trial_res, trial_norm
    return x, norm, "max iterations", max_iterations


def solve_point(params: WalkerParams, speed: float, step_length: float, guess: np.ndarray,
                max_iterations: int = 30, tolerance: float = RESIDUAL_TOLERANCE) -> GaitSolution:
    """Solve eq. (3) at one point by damped Newton from ``guess`` (FD Jacobian columns simulated as one batch)."""
    x, norm, reason, iterations = _newton(lambda xs: cyclic_residual(params, speed, step_length, xs),
                                          guess, max_iterations, tolerance)
    converged = reason == "converged"
    if converged and x[3] < 0.0:
        converged, reason = False, "solved but non-physical (iota < 0: the toe-off would pull)"
    elif converged and x[2] < 0.0:
        reason = "converged (kappa < 0: a slightly repelling hip spring)"
    pre = _pre_collision_rates(params, speed, step_length, x) if np.isfinite(norm) else np.full(2, np.nan)
    return GaitSolution(speed, step_length, x, norm, converged, reason, iterations, pre)


def symmetric_residual(params: WalkerParams, speed: float, step_length: float, unknowns: np.ndarray,
                       step: float = SOLVER_STEP) -> np.ndarray:
    """Residual (K, 4) of the mirror-symmetric cyclic gait: both legs vertical at T/2, impact maps q'- to q'+.

    The walker is symmetric under x -> -x with time reversal, so a gait whose legs are both
    vertical at mid-step retraces its first half mirrored: its pre-collision rates equal its start
    rates, and it is cyclic iff the impact (with iota) leaves the rates unchanged. These are the
    human-like gaits (mid-swing at mid-stance); they form one smooth family over the grid.
    """
    x = np.atleast_2d(np.asarray(unknowns, float))
    a = float(double_support_angle(params, step_length))
    half = 0.5 * step_length / speed
    n = max(1, int(np.ceil(half / step)))
    mid = integrate(params, WalkerState.from_arrays(np.full(len(x), a), -a, x[:, 0], x[:, 1]), x[:, 2], half / n, n)
    p1, p2 = mid.stance_angle, mid.swing_angle
    pre = WalkerState.from_arrays(-a, a, x[:, 0], x[:, 1])
    post = heel_strike(params, pre, x[:, 3])
    return np.stack([p1, p2, post.stance_rate - x[:, 0], post.swing_rate - x[:, 1]], axis=1)


def solve_symmetric_point(params: WalkerParams, speed: float, step_length: float, guess: np.ndarray,
                          max_iterations: int = 30, tolerance: float = RESIDUAL_TOLERANCE) -> GaitSolution:
    """Find a mirror-symmetric gait (see :func:`symmetric_residual`), then polish it on eq. (3) itself."""
    x, norm, reason, _ = _newton(lambda xs: symmetric_residual(params, speed, step_length, xs), guess,
                                 max_iterations, tolerance)
    if reason != "converged":
        return GaitSolution(speed, step_length, x, np.inf, False, f"symmetric gait: {reason}", 0, np.full(2, np.nan))
    return solve_point(params, speed, step_length, x, max_iterations, tolerance)


def is_symmetric(solution: GaitSolution, tolerance: float = 1e-5) -> bool:
    """Pre-collision rates equal the start rates (legs vertical together at mid-step)."""
    return bool(np.all(np.abs(solution.pre_collision_rates - solution.unknowns[:2]) < tolerance))


def default_guesses(params: WalkerParams, speed: float, step_length: float) -> list[np.ndarray]:
    """Fresh starting guesses for a point with no solved neighbour (dimensionless kappa 0.05-1)."""
    a = float(double_support_angle(params, step_length))
    duration = step_length / speed
    mean_rate = 2.0 * a / duration
    gl = params.gravity * params.leg_length
    guesses = []
    for kappa_dimless in (0.1, 0.02, 0.4):
        for swing_factor in (-0.5, 0.5):
            iota = 0.1 * params.speed_unit * (speed / params.speed_unit)
            guesses.append(np.array([-mean_rate, swing_factor * mean_rate, kappa_dimless * gl, iota]))
    return guesses


def grid_axes(speeds_kmh: tuple[float, float, int] = (2.0, 7.0, 11),
              step_lengths: tuple[float, float, int] = (0.3, 1.2, 19)) -> tuple[np.ndarray, np.ndarray]:
    """Speeds (m/s) and step lengths (m) of the default grid: 2-7 km/h x 0.3-1.2 m."""
    return np.linspace(*speeds_kmh[:2], speeds_kmh[2]) * KMH, np.linspace(*step_lengths[:2], step_lengths[2])


@dataclass(frozen=True)
class GaitTable:
    """Solved cyclic gaits on a speed x step-length grid (arrays indexed [speed, step_length])."""

    params: WalkerParams
    speeds: np.ndarray            # (S,) m/s
    step_lengths: np.ndarray      # (P,) m
    stance_rate: np.ndarray       # (S, P) phi1'_0 rad/s, just after heel strike
    swing_rate: np.ndarray        # (S, P) phi2'_0 rad/s
    stiffness: np.ndarray         # (S, P) kappa, N m/rad per kg
    toe_off_impulse: np.ndarray   # (S, P) iota, m/s
    pre_stance_rate: np.ndarray   # (S, P) phi1' just before heel strike
    pre_swing_rate: np.ndarray    # (S, P) phi2' just before heel strike
    residual: np.ndarray          # (S, P) max |residual| of eq. (3)
    converged: np.ndarray         # (S, P) bool
    step_map_radius: np.ndarray | None = None  # (S, P) largest |Floquet multiplier| (< 1: stable)
    reason: tuple[tuple[str, ...], ...] = field(default=())
    solver_step: float = SOLVER_STEP
    version: int = TABLE_VERSION

    # ---- persistence -------------------------------------------------------------------
    def to_json(self) -> dict:
        return {
            "version": self.version,
            "description": "Cyclic gaits of the Anthropomorphic Walker (eq. 3); arrays indexed [speed][step_length]; "
                           "rates rad/s, stiffness N m/rad per kg, toe_off_impulse m/s, residual max |.| of "
                           "(t_strike - T [s], phi1+ - a [rad], rate errors [rad/s]).",
            "params": asdict(self.params),
            "solver_step": self.solver_step,
            "speeds": self.speeds.tolist(),
            "step_lengths": self.step_lengths.tolist(),
            **{name: _nan_to_none(getattr(self, name)) for name in (
                "stance_rate", "swing_rate", "stiffness", "toe_off_impulse", "pre_stance_rate",
                "pre_swing_rate", "residual")},
            "step_map_radius": _nan_to_none(self.step_map_radius if self.step_map_radius is not None
                                            else np.full(self.stiffness.shape, np.nan)),
            "converged": self.converged.tolist(),
            "reason": [list(r) for r in self.reason],
        }

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=1) + "\n")

    @classmethod
    def from_json(cls, data: dict, source: str = "<gait table>") -> "GaitTable":
        try:
            params = WalkerParams(**data["params"])
            arrays = {name: np.array(data[name], dtype=float) for name in (
                "stance_rate", "swing_rate", "stiffness", "toe_off_impulse", "pre_stance_rate",
                "pre_swing_rate", "residual")}
            table = cls(params=params, speeds=np.array(data["speeds"], float),
                        step_lengths=np.array(data["step_lengths"], float), **arrays,
                        converged=np.array(data["converged"], bool),
                        step_map_radius=np.array(data["step_map_radius"], float) if "step_map_radius" in data
                        else None,
                        reason=tuple(tuple(r) for r in data.get("reason", ())),
                        solver_step=float(data.get("solver_step", SOLVER_STEP)),
                        version=int(data.get("version", 0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{source}: not a gait table ({exc!r}); regenerate with `awalker gaits solve`") from exc
        shape = (table.speeds.size, table.step_lengths.size)
        for name in ("stiffness", "toe_off_impulse", "stance_rate", "swing_rate", "converged"):
            if getattr(table, name).shape != shape:
                raise InputError(f"{source}: {name} has shape {getattr(table, name).shape}, expected {shape}")
        return table

    @classmethod
    def load(cls, path: str | Path | None = None) -> "GaitTable":
        """The packaged table (awalker_tracker/data/cyclic_gaits.json) or the JSON file at ``path``."""
        if path is None:
            return _packaged_table()
        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: gait table not found")
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise InputError(f"{path}: not JSON ({exc})") from exc
        return cls.from_json(data, str(path))

    def scaled_to(self, params: WalkerParams) -> "GaitTable":
        """The same gaits for a walker of another leg length and gravity (exact: dimensional analysis).

        The equations of motion are the same in Kuo's dimensionless units, so a table solved for
        (L, g) holds for (L', g') with lengths x L'/L, times x sqrt(L'/L g/g'), speeds and iota x
        sqrt(L' g' / L g), rates x sqrt(L g' / L' g), kappa (per kg) x L' g' / L g. The other
        parameters (ratios and mass fractions) must match; raises ValueError if they do not.
        """
        ours = dataclasses.replace(self.params, leg_length=params.leg_length, gravity=params.gravity)
        if ours != params:
            raise ValueError(f"gait table solved for {self.params}; only leg_length and gravity can be rescaled, "
                             f"not to {params}")
        if params == self.params:
            return self
        length = params.leg_length / self.params.leg_length
        gravity = params.gravity / self.params.gravity
        speed, rate, time_ = np.sqrt(length * gravity), np.sqrt(gravity / length), np.sqrt(length / gravity)
        return dataclasses.replace(
            self, params=params, speeds=self.speeds * speed, step_lengths=self.step_lengths * length,
            stance_rate=self.stance_rate * rate, swing_rate=self.swing_rate * rate,
            pre_stance_rate=self.pre_stance_rate * rate, pre_swing_rate=self.pre_swing_rate * rate,
            stiffness=self.stiffness * length * gravity, toe_off_impulse=self.toe_off_impulse * speed,
            solver_step=self.solver_step * time_)

    # ---- queries -----------------------------------------------------------------------
    @functools.cached_property
    def _grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What the compiled look-ups take: speeds (S,), step lengths (L,), the values (4, S, L) stance rate,
        swing rate, kappa, iota with 0 where not converged (their weights are 0 there), converged (S, L)."""
        values = np.nan_to_num(np.stack([self.stance_rate, self.swing_rate, self.stiffness, self.toe_off_impulse]))
        return (np.ascontiguousarray(self.speeds, float), np.ascontiguousarray(self.step_lengths, float),
                np.ascontiguousarray(values, float), np.ascontiguousarray(self.converged, np.bool_))

    def _interpolated(self, speed: np.ndarray | float, step_length: np.ndarray | float
                      ) -> tuple[tuple[int, ...], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The broadcast shape, the flat queries (speed, step length) and the bilinear interpolation at them:
        values (4, M) and the converged corners' weight sums (M,)."""
        shape = np.broadcast_shapes(np.shape(speed), np.shape(step_length))
        v = np.broadcast_to(np.asarray(speed, float), shape).ravel()
        s = np.broadcast_to(np.asarray(step_length, float), shape).ravel()
        out, weight = np.empty((4, v.size)), np.empty(v.size)
        _lookup_kernel(*self._grid, v, s, out, weight)
        return shape, v, s, out, weight

    def covers(self, speed: np.ndarray | float, step_length: np.ndarray | float,
               min_weight: float = 1e-12) -> np.ndarray:
        """True where :meth:`lookup` has converged corners carrying more than ``min_weight`` (broadcast shape)."""
        shape, _, _, _, weight = self._interpolated(speed, step_length)
        return (weight > min_weight).reshape(shape)

    def lookup(self, speed: np.ndarray | float, step_length: np.ndarray | float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(stance_rate, swing_rate, stiffness, toe_off_impulse) bilinearly interpolated.

        Speed and step length broadcast against each other. Only converged grid cells are used;
        queries are clamped to the grid. Raises InputError when the enclosing cell has no converged
        corner. (Compiled: ``_lookup_kernel``.)
        """
        shape, v, s, out, weight = self._interpolated(speed, step_length)
        missing = np.flatnonzero(weight <= _MIN_CORNER_WEIGHT)
        if missing.size:
            raise _no_gait_error(self, v[missing[0]], s[missing[0]])
        if shape == ():
            return out[0, 0], out[1, 0], out[2, 0], out[3, 0]
        return out[0].reshape(shape), out[1].reshape(shape), out[2].reshape(shape), out[3].reshape(shape)

    def gait_for_stiffness(self, stiffness: np.ndarray | float, step_length: np.ndarray | float
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The cyclic gait with a given stiffness kappa (N m/rad per kg) and step length (m).

        Returns (speed m/s, stance_rate, swing_rate, toe_off_impulse) of that gait: at each step
        length the table's kappa rises with speed (checked in test_cyclic_gaits.py), so the speed is found
        by inverting kappa along the speed axis; queries are clamped to the grid. (Compiled:
        ``_stiffness_kernel``, called at every heel strike of every particle.)
        """
        kappa = np.asarray(stiffness, float)
        step = np.broadcast_to(np.asarray(step_length, float), kappa.shape).ravel()
        out = np.empty((4, kappa.size))
        failed = _stiffness_kernel(*self._grid, kappa.ravel(), step, out)
        if failed >= 0:
            raise _no_gait_error(self, out[0, failed], step[failed])
        return (out[0].reshape(kappa.shape), out[1].reshape(kappa.shape), out[2].reshape(kappa.shape),
                out[3].reshape(kappa.shape))

    def converged_points(self) -> dict[str, np.ndarray]:
        """Flattened arrays of the converged grid points (for fits and plots)."""
        mask = self.converged
        vv, ss = np.meshgrid(self.speeds, self.step_lengths, indexing="ij")
        return {"speed": vv[mask], "step_length": ss[mask], "stiffness": self.stiffness[mask],
                "toe_off_impulse": self.toe_off_impulse[mask], "pre_stance_rate": self.pre_stance_rate[mask],
                "pre_swing_rate": self.pre_swing_rate[mask], "stance_rate": self.stance_rate[mask],
                "swing_rate": self.swing_rate[mask], "residual": self.residual[mask]}


@functools.lru_cache(maxsize=1)
def _packaged_table() -> GaitTable:
    """The packaged table, parsed once per process (shared: do not modify its arrays)."""
    text = resources.files("awalker_tracker").joinpath("data/cyclic_gaits.json").read_text()
    return GaitTable.from_json(json.loads(text), "awalker_tracker/data/cyclic_gaits.json")


def _nan_to_none(array: np.ndarray) -> list:
    return [[None if not np.isfinite(x) else float(x) for x in row] for row in np.asarray(array, float)]


def fit_impulse_mean(table: GaitTable) -> tuple[np.ndarray, float]:
    """Least-squares bilinear fit iota ~ c0 + c1 w1 + c2 w2 + c3 w1 w2 over pre-collision rates (Fig. 4).

    Returns (coefficients (4,), RMS error in m/s).
    """
    pts = table.converged_points()
    w1, w2, iota = pts["pre_stance_rate"], pts["pre_swing_rate"], pts["toe_off_impulse"]
    design = np.stack([np.ones_like(w1), w1, w2, w1 * w2], axis=1)
    coef, *_ = np.linalg.lstsq(design, iota, rcond=None)
    rms = float(np.sqrt(np.mean((design @ coef - iota) ** 2)))
    return coef, rms


def step_map_radius(params: WalkerParams, speed: float, step_length: float, unknowns: np.ndarray) -> float:
    """Spectral radius of the step-to-step map (post-strike a, phi1', phi2') at fixed kappa, iota.

    Below 1 the cyclic gait is locally stable without any control; FD Jacobian, one batch.
    """
    x = np.asarray(unknowns, float)
    a = float(double_support_angle(params, step_length))
    base = np.array([a, x[0], x[1]])
    probes = np.vstack([base, base + 1e-6 * np.eye(3)])
    start = WalkerState.from_arrays(probes[:, 0], -probes[:, 0], probes[:, 1], probes[:, 2])
    post, _, _ = simulate_to_strike(params, start, x[2], x[3], step=SOLVER_STEP,
                                    max_time=1.5 * step_length / speed + 0.2)
    image = np.stack([post.stance_angle, post.stance_rate, post.swing_rate], axis=1)
    jac = (image[1:] - image[0]).T / 1e-6
    return float(np.max(np.abs(np.linalg.eigvals(jac)))) if np.all(np.isfinite(jac)) else np.inf


def _rated(params: WalkerParams, sol: GaitSolution) -> GaitSolution:
    """``sol`` with its step-map radius, and "(asymmetric gait)" added to its reason when it is one."""
    sol = dataclasses.replace(sol, step_map_radius=step_map_radius(params, sol.speed, sol.step_length, sol.unknowns))
    return sol if is_symmetric(sol) else dataclasses.replace(sol, reason=sol.reason + " (asymmetric gait)")


def _best_solution(params: WalkerParams, v: float, s: float, continued: list[np.ndarray],
                   fresh: list[np.ndarray], family: str) -> GaitSolution:
    """Collect the distinct gaits reachable from the guesses and pick one per ``family``.

    The symmetric solver runs from the guesses until it converges once; the general solver runs
    from every continuation guess (neighbours may lie on different families); the fresh guesses
    are tried only when nothing converged.
    """
    found: list[GaitSolution] = []
    failures: list[GaitSolution] = []

    def add(sol: GaitSolution) -> bool:
        if not sol.converged:
            failures.append(sol)
            return False
        if not any(np.allclose(sol.unknowns, f.unknowns, atol=1e-6) for f in found):
            found.append(sol)
        return True

    for guess in continued + fresh:
        sol = solve_symmetric_point(params, v, s, guess)
        if sol.converged and is_symmetric(sol) and add(sol):
            break
    if family == "stable" or not found:
        for guess in continued:
            add(solve_point(params, v, s, guess))
    if not found:
        for guess in fresh:
            if add(solve_point(params, v, s, guess)):
                break
    if not found:
        return min(failures, key=lambda f: f.residual)
    found = [_rated(params, f) for f in found]
    if family == "symmetric" and any(is_symmetric(f) for f in found):
        return next(f for f in found if is_symmetric(f))
    return min(found, key=lambda f: f.step_map_radius)


def _spread_stable_gaits(params: WalkerParams, speeds: np.ndarray, step_lengths: np.ndarray,
                         solutions: dict[tuple[int, int], GaitSolution],
                         progress: Callable[[str], None] | None, max_sweeps: int = 20) -> None:
    """Carry more stable gaits into neighbouring points until no point improves (in place).

    The first pass reaches each point from the side the continuation came from, so a locally
    stable family that branches off elsewhere (the asymmetric gaits from ~5 km/h) is missed next
    to where it starts. Each sweep re-solves every point from each neighbour whose step-map radius
    is smaller, starting from the neighbour's gait and from this point's gait shifted by the
    neighbour's offset from its own mirror-symmetric gait (near the branch point the two families
    are close and plain continuation falls back onto the symmetric one), and keeps a result whose
    radius is smaller.
    """
    offsets: dict[tuple[int, int], np.ndarray] = {}

    def offset_from_symmetric(key: tuple[int, int]) -> np.ndarray:
        if key not in offsets:
            sol = solutions[key]
            partner = solve_symmetric_point(params, float(speeds[key[0]]), float(step_lengths[key[1]]), sol.unknowns)
            offsets[key] = sol.unknowns - partner.unknowns if partner.converged else np.zeros(4)
        return offsets[key]

    for sweep in range(1, max_sweeps + 1):
        improved = 0
        for (i, j), current in sorted(solutions.items()):
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                key = (i + di, j + dj)
                other = solutions.get(key)
                if other is None or not other.converged or not other.step_map_radius < current.step_map_radius:
                    continue
                for guess in (other.unknowns, current.unknowns + offset_from_symmetric(key)):
                    sol = solve_point(params, float(speeds[i]), float(step_lengths[j]), guess)
                    if not sol.converged:
                        continue
                    sol = _rated(params, sol)
                    if sol.step_map_radius < current.step_map_radius - 1e-6:
                        solutions[(i, j)] = current = sol
                        offsets.pop((i, j), None)
                        improved += 1
        if progress is not None:
            progress(f"stable sweep {sweep}: {improved} points moved to a more stable gait")
        if not improved:
            return


def solve_grid(
    params: WalkerParams,
    speeds: np.ndarray,
    step_lengths: np.ndarray,
    progress: Callable[[str], None] | None = None,
    seed_point: tuple[float, float] = (5.0 * KMH, 0.7),
    family: str = "symmetric",
) -> GaitTable:
    """Solve eq. (3) over a grid by continuation from the grid point nearest ``seed_point``.

    Points are visited in order of distance from the seed; each tries the solutions of its
    already solved neighbours first, then :func:`default_guesses`. ``family`` picks among the
    solutions found at a point: "stable" (smallest step-map radius) or "symmetric" (the
    mirror-symmetric gait when found). ``progress`` receives one line per point.
    """
    if family not in ("stable", "symmetric"):
        raise ValueError(f"family must be 'stable' or 'symmetric', got {family!r}")
    speeds, step_lengths = np.asarray(speeds, float), np.asarray(step_lengths, float)
    shape = (speeds.size, step_lengths.size)
    solutions: dict[tuple[int, int], GaitSolution] = {}
    vi = (speeds - seed_point[0]) / max(np.ptp(speeds), 1e-9)
    sj = (step_lengths - seed_point[1]) / max(np.ptp(step_lengths), 1e-9)
    order = sorted(np.ndindex(*shape), key=lambda ij: vi[ij[0]] ** 2 + sj[ij[1]] ** 2)
    started = time.monotonic()
    for count, (i, j) in enumerate(order, 1):
        v, s = float(speeds[i]), float(step_lengths[j])
        guesses = []
        # linear extrapolation along a grid line from two solved points, then plain neighbours
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            near, far = solutions.get((i + di, j + dj)), solutions.get((i + 2 * di, j + 2 * dj))
            if near is not None and far is not None and near.converged and far.converged:
                guesses.append(2.0 * near.unknowns - far.unknowns)
        neighbours = sorted(((i + di, j + dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj),
                            key=lambda ij: abs(ij[0] - i) + abs(ij[1] - j))
        for key in neighbours:
            sol = solutions.get(key)
            if sol is not None and sol.converged:
                guesses.append(sol.unknowns)
        best = _best_solution(params, v, s, guesses, default_guesses(params, v, s), family)
        solutions[(i, j)] = best
        if progress is not None:
            progress(f"[{count}/{len(order)}] {v / KMH:.2f} km/h, {s:.3f} m: {best.reason}, "
                     f"residual {best.residual:.1e}, kappa {best.unknowns[2]:.3f}, iota {best.unknowns[3]:.3f}, "
                     f"step-map radius {best.step_map_radius:.3f} ({time.monotonic() - started:.0f} s)")

    if family == "stable":
        _spread_stable_gaits(params, speeds, step_lengths, solutions, progress)

    def grid(fn) -> np.ndarray:
        return np.array([[fn(solutions[(i, j)]) for j in range(shape[1])] for i in range(shape[0])], float)

    return GaitTable(
        params=params, speeds=speeds, step_lengths=step_lengths,
        stance_rate=grid(lambda s: s.unknowns[0]), swing_rate=grid(lambda s: s.unknowns[1]),
        stiffness=grid(lambda s: s.unknowns[2]), toe_off_impulse=grid(lambda s: s.unknowns[3]),
        pre_stance_rate=grid(lambda s: s.pre_collision_rates[0]),
        pre_swing_rate=grid(lambda s: s.pre_collision_rates[1]),
        residual=grid(lambda s: s.residual),
        step_map_radius=grid(lambda s: s.step_map_radius),
        converged=grid(lambda s: s.converged).astype(bool),
        reason=tuple(tuple(solutions[(i, j)].reason for j in range(shape[1])) for i in range(shape[0])),
    )


# ---- compiled table look-ups (numba, serial) ----------------------------------------------
# weight (sum of the converged corners' bilinear weights) at or below which a query has no gait
_MIN_CORNER_WEIGHT = 1e-12


def _no_gait_error(table: GaitTable, speed: float, step_length: float) -> InputError:
    speed = min(max(float(speed), table.speeds[0]), table.speeds[-1])
    step_length = min(max(float(step_length), table.step_lengths[0]), table.step_lengths[-1])
    return InputError(f"gait table: no converged gait near speed {speed:.3f} m/s, step length {step_length:.3f} m")


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cell(grid: np.ndarray, x: float) -> tuple[int, float]:
    """The interval [grid[i], grid[i + 1]] of ``grid`` (ascending, >= 2 points) that holds x clamped to the
    grid (the last one for its top end) and x's fraction along it (NaN for a NaN x)."""
    if not x == x:
        return 0, np.nan
    last = grid.size - 1
    x = min(max(x, grid[0]), grid[last])
    i = 0
    while i < last - 1 and grid[i + 1] <= x:
        i += 1
    return i, (x - grid[i]) / (grid[i + 1] - grid[i])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _bilinear(speeds: np.ndarray, step_lengths: np.ndarray, values: np.ndarray, converged: np.ndarray,
              speed: float, step_length: float, out: np.ndarray, q: int) -> float:
    """Bilinear interpolation of ``values`` (4, S, L) at (speed m/s, step length m) over the converged corners
    of the enclosing cell into out[:, q]; returns the sum of those corners' weights (<= 1e-12: no gait)."""
    i, tv = _cell(speeds, speed)
    j, ts = _cell(step_lengths, step_length)
    w00, w10, w01, w11 = (1 - tv) * (1 - ts), tv * (1 - ts), (1 - tv) * ts, tv * ts
    w00 = w00 if converged[i, j] else 0.0
    w10 = w10 if converged[i + 1, j] else 0.0
    w01 = w01 if converged[i, j + 1] else 0.0
    w11 = w11 if converged[i + 1, j + 1] else 0.0
    # summed corner by corner from 0, in this order: the same rounding as the numpy code this replaced
    total = 0.0 + w00 + w10 + w01 + w11
    for k in range(4):
        out[k, q] = (((0.0 + w00 * values[k, i, j]) + w10 * values[k, i + 1, j]) + w01 * values[k, i, j + 1]
                     + w11 * values[k, i + 1, j + 1]) / total
    return total


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _lookup_kernel(speeds: np.ndarray, step_lengths: np.ndarray, values: np.ndarray, converged: np.ndarray,
                   speed: np.ndarray, step_length: np.ndarray, out: np.ndarray, weight: np.ndarray) -> None:
    """``GaitTable.lookup`` of M queries (speed, step_length (M,)): values (4, M), corner weight sums (M,)."""
    for q in range(speed.size):
        weight[q] = _bilinear(speeds, step_lengths, values, converged, speed[q], step_length[q], out, q)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _stiffness_kernel(speeds: np.ndarray, step_lengths: np.ndarray, values: np.ndarray, converged: np.ndarray,
                      stiffness: np.ndarray, step_length: np.ndarray, out: np.ndarray) -> int:
    """``GaitTable.gait_for_stiffness`` of M queries (kappa, step length (M,)) into out (4, M): speed,
    stance rate, swing rate, iota. Per query, kappa at every grid speed (linear in speed between grid
    points at this step length), the grid interval where it crosses the asked kappa (the end intervals
    beyond the grid's kappa), the speed there, and the table at that speed. Returns the first query
    whose look-up has no converged gait (its clamped speed in out[0]), or -1."""
    n_speeds = speeds.size
    along = np.empty(n_speeds)              # kappa at each grid speed
    scratch = np.empty((4, 1))
    for q in range(stiffness.size):
        kappa, step = stiffness[q], step_length[q]
        below = -1
        for k in range(n_speeds):
            if _bilinear(speeds, step_lengths, values, converged, speeds[k], step, scratch, 0) <= _MIN_CORNER_WEIGHT:
                out[0, q] = speeds[k]
                return q
            along[k] = scratch[2, 0]
            if along[k] < kappa:
                below += 1
        below = min(max(below, 0), n_speeds - 2)
        low, high = along[below], along[below + 1]
        fraction = (kappa - low) / (high - low)
        if fraction == fraction:            # NaN stays NaN (the caller floors the toe-off)
            fraction = min(max(fraction, 0.0), 1.0)
        speed = speeds[below] + fraction * (speeds[below + 1] - speeds[below])
        if _bilinear(speeds, step_lengths, values, converged, speed, step, scratch, 0) <= _MIN_CORNER_WEIGHT:
            out[0, q] = speed
            return q
        out[0, q], out[1, q], out[2, q], out[3, q] = speed, scratch[0, 0], scratch[1, 0], scratch[3, 0]
    return -1


def gait_initial_state(
    params: WalkerParams,
    speed: np.ndarray | float,
    step_length: np.ndarray | float,
    contact_origin: np.ndarray | float = 0.0,
    stance_leg: np.ndarray | int = LEFT,
    table: GaitTable | None = None,
) -> WalkerState:
    """Double-support start state (just after heel strike) of the cyclic gait, broadcast to N."""
    table = GaitTable.load() if table is None else table
    w1, w2, _, _ = table.lookup(speed, step_length)
    a = double_support_angle(params, step_length)
    return WalkerState.from_arrays(a, -a, w1, w2, contact_origin, stance_leg)


def stderr_progress(line: str) -> None:
    """Progress printer for long solves (tqdm is not available)."""
    print(line, file=sys.stderr, flush=True)
