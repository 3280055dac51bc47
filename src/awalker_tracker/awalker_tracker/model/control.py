"""Stochastic control prior of the Anthropomorphic Walker (paper Sec. 4.2), vectorised over particles.

- Within a stride the stiffness of every frame is kappa_t ~ N(kappa_bar, sigma_kappa^2) (eq. 4).
- Per stride, kappa_bar(i+1) ~ N(beta mu_kappa + (1 - beta) kappa_bar(i), sigma_kappa_bar^2) (eq. 5).
  kappa_bar is never sampled (Rao-Blackwellised): each particle keeps the mean and variance of its
  Gaussian belief over kappa_bar; kappa_t is drawn from the predictive N(mean, variance + sigma_kappa^2),
  then the belief is conditioned on the drawn kappa_t (a scalar Kalman update); at a heel strike the
  belief is pushed through the AR(1) of eq. (5).
- The toe-off impulse iota ~ Gamma(mean mu_iota(q'-), variance sigma_iota^2), mu_iota bilinear in
  the pre-collision rates q'- = (phi1'-, phi2'-) (Fig. 4). Because its mean needs q'-, iota is drawn
  AT the heel strike, inside :func:`dynamics.advance`, from the rates located at the impact: one draw
  per stride, used for the toe-off that starts the new stride (the paper's "at the beginning of each
  stride"). ``ControlState.toe_off_impulse`` keeps the last value used.

Units (checked against the solved cyclic gaits, see test_control.py): kappa in N m/rad per kg, so
mu_kappa = 0.7 sits inside the solved range (0.74 at 5 km/h, 0.7 m with L = 0.9 m); iota in m/s.

Stability (measured with :func:`prior_walk_statistics`; defaults are the paper's values): the
walker is far less forgiving than the paper suggests. Open-loop (fixed kappa, iota) the step-to-step
map of the cyclic gaits has largest Floquet multiplier 0.88 at 4 km/h / 0.6 m but 1.08 at
5 km/h / 0.7 m and 1.35 at 6 km/h / 0.75 m; the bilinear feedback iota = mu_iota(q'-) raises it to
3-4, and the swing foot clears the ground by only ~0.16 rad of phi1 + phi2, so perturbed walkers
scuff (the swing foot never rises above the ground, no heel strike) and fall forward. With the
paper's noise nearly all sampled walkers fall within a few steps; in tracking, the likelihood and
resampling must carry the particles (give fallen particles zero weight).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .dynamics import StepEvents, advance
from .gaits import GaitTable, fit_impulse_mean, gait_initial_state
from .walker import WalkerParams, WalkerState

#: Smallest Gamma mean (m/s) used for iota where the bilinear fit would give <= 0.
MIN_IMPULSE_MEAN = 1e-3


@dataclass(frozen=True)
class ControlPrior:
    """Parameters of the control prior; variances in the squared units of their variables."""

    beta: float = 0.85                        # pull of kappa_bar towards mu_kappa per stride
    mu_kappa: float = 0.7                     # N m/rad per kg
    kappa_bar_variance: float = 0.5           # sigma_kappa_bar^2, per stride
    kappa_noise_variance: float = 1.0         # sigma_kappa^2, per frame around kappa_bar
    impulse_variance: float = 0.05**2         # sigma_iota^2 (m/s)^2
    # mu_iota(q'-) = c0 + c1 phi1'- + c2 phi2'- + c3 phi1'- phi2'- (m/s, rates in rad/s)
    impulse_mean_coefficients: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError("ControlPrior.beta must lie in [0, 1]")
        for name in ("kappa_bar_variance", "kappa_noise_variance", "impulse_variance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ControlPrior.{name} must be > 0")
        if len(self.impulse_mean_coefficients) != 4:
            raise ValueError("ControlPrior.impulse_mean_coefficients needs 4 values (bilinear fit)")

    @classmethod
    def from_gait_table(cls, table: GaitTable, **overrides) -> "ControlPrior":
        """Prior whose mu_iota is the least-squares bilinear fit over the table's converged gaits."""
        coef, _ = fit_impulse_mean(table)
        return cls(impulse_mean_coefficients=tuple(float(c) for c in coef), **overrides)

    def impulse_mean(self, pre_stance_rate: np.ndarray, pre_swing_rate: np.ndarray) -> np.ndarray:
        """mu_iota(q'-) in m/s, floored at MIN_IMPULSE_MEAN."""
        c0, c1, c2, c3 = self.impulse_mean_coefficients
        w1, w2 = np.asarray(pre_stance_rate, float), np.asarray(pre_swing_rate, float)
        return np.maximum(c0 + c1 * w1 + c2 * w2 + c3 * w1 * w2, MIN_IMPULSE_MEAN)

    def sample_impulse(self, rng: np.random.Generator, pre_stance_rate: np.ndarray,
                       pre_swing_rate: np.ndarray) -> np.ndarray:
        """iota ~ Gamma with mean mu_iota(q'-) and variance sigma_iota^2 (shape mean^2/var, scale var/mean)."""
        mean = self.impulse_mean(pre_stance_rate, pre_swing_rate)
        return rng.gamma(mean * mean / self.impulse_variance, self.impulse_variance / mean)


@dataclass
class ControlState:
    """Per-particle control variables, arrays of shape (N,)."""

    stiffness: np.ndarray                # kappa_t of the last frame (N m/rad per kg)
    stiffness_mean_mean: np.ndarray      # mean of the Gaussian belief over kappa_bar
    stiffness_mean_variance: np.ndarray  # its variance
    toe_off_impulse: np.ndarray          # iota of the last heel strike (m/s)
    time_since_strike: np.ndarray        # s since the last heel strike

    def __len__(self) -> int:
        return int(self.stiffness.shape[0])

    def copy(self) -> "ControlState":
        return ControlState(*(getattr(self, f.name).copy() for f in fields(self)))

    def take(self, indices: np.ndarray) -> "ControlState":
        return ControlState(*(getattr(self, f.name)[indices] for f in fields(self)))


def initial_control(prior: ControlPrior, n: int, rng: np.random.Generator,
                    stiffness: np.ndarray | float | None = None,
                    toe_off_impulse: np.ndarray | float | None = None) -> ControlState:
    """Control state for n particles.

    With ``stiffness`` (e.g. of the starting cyclic gait) the belief over kappa_bar is centred
    there with variance sigma_kappa_bar^2; otherwise it is the stationary law of eq. (5):
    mean mu_kappa, variance sigma_kappa_bar^2 / (1 - (1 - beta)^2). ``rng`` draws nothing yet
    (kept for signature symmetry with sampling); the first kappa_t is drawn by the first transition.
    """
    del rng
    if stiffness is None:
        mean = np.full(n, prior.mu_kappa)
        variance = np.full(n, prior.kappa_bar_variance / (1.0 - (1.0 - prior.beta) ** 2))
    else:
        mean = np.broadcast_to(np.asarray(stiffness, float), (n,)).copy()
        variance = np.full(n, prior.kappa_bar_variance)
    iota = np.full(n, np.nan) if toe_off_impulse is None else np.broadcast_to(
        np.asarray(toe_off_impulse, float), (n,)).copy()
    return ControlState(stiffness=mean.copy(), stiffness_mean_mean=mean, stiffness_mean_variance=variance,
                        toe_off_impulse=iota, time_since_strike=np.zeros(n))


def sample_transition(
    params: WalkerParams,
    prior: ControlPrior,
    walker: WalkerState,
    control: ControlState,
    dt: float,
    rng: np.random.Generator,
    substeps: int | None = None,
) -> tuple[WalkerState, ControlState, StepEvents]:
    """Sample one frame of the prior for N particles: kappa_t, dynamics, iota at strikes, kappa_bar stats."""
    m, v = control.stiffness_mean_mean, control.stiffness_mean_variance
    noise = prior.kappa_noise_variance
    kappa = m + np.sqrt(v + noise) * rng.standard_normal(m.shape)
    # condition the belief over kappa_bar on the drawn kappa_t (kappa_t = kappa_bar + N(0, noise))
    gain = v / (v + noise)
    m_post = m + gain * (kappa - m)
    v_post = v * noise / (v + noise)

    def impulse_at_strike(indices: np.ndarray, pre_stance_rate: np.ndarray, pre_swing_rate: np.ndarray):
        return prior.sample_impulse(rng, pre_stance_rate, pre_swing_rate)

    new_walker, events = advance(params, walker, kappa, impulse_at_strike, dt, substeps=substeps,
                                 time_since_strike=control.time_since_strike)
    strike = events.heel_strike
    # a new stride starts: kappa_bar(i+1) ~ N(beta mu + (1 - beta) kappa_bar(i), sigma_bar^2)
    keep = 1.0 - prior.beta
    m_new = np.where(strike, prior.beta * prior.mu_kappa + keep * m_post, m_post)
    v_new = np.where(strike, keep * keep * v_post + prior.kappa_bar_variance, v_post)
    iota = np.where(strike, events.toe_off_impulse, control.toe_off_impulse)
    fallen = events.fallen
    new_control = ControlState(
        stiffness=np.where(fallen, control.stiffness, kappa),
        stiffness_mean_mean=np.where(fallen, m, m_new),
        stiffness_mean_variance=np.where(fallen, v, v_new),
        toe_off_impulse=iota,
        time_since_strike=events.time_since_strike,
    )
    return new_walker, new_control, events


def prior_walk_statistics(params: WalkerParams, prior: ControlPrior, table: GaitTable, speed: float, step_length: float,
                          n: int = 1000, steps: int = 20, dt: float = 1.0 / 30.0, seed: int = 0,
                          max_time: float = 60.0) -> dict:
    """Sanity statistics of the prior: N walkers started on a cyclic gait, sampled until each took
    ``steps`` heel strikes or fell.

    Returns the fraction fallen before ``steps`` strikes, the median number of strikes before a fall,
    and percentiles of the step lengths (m) and step speeds (m/s) taken, with the least-squares slope
    of log(step length) against log(speed) (humans: about 0.42).
    """
    rng = np.random.default_rng(seed)
    walkers = gait_initial_state(params, np.full(n, speed), np.full(n, step_length), table=table)
    _, _, kappa0, iota0 = table.lookup(speed, step_length)
    ctrl = initial_control(prior, n, rng, stiffness=kappa0, toe_off_impulse=iota0)
    strikes = np.zeros(n, int)
    fallen = np.zeros(n, bool)
    last_x = np.full(n, np.nan)
    last_t = np.zeros(n)
    lengths, speeds = [], []
    frame = 0
    while ((strikes < steps) & ~fallen).any() and frame * dt < max_time:
        walkers, ctrl, ev = sample_transition(params, prior, walkers, ctrl, dt, rng)
        frame += 1
        active = (strikes < steps) & ~fallen
        fallen |= ev.fallen & active
        hit = np.flatnonzero(ev.heel_strike & active)
        t = (frame - 1 + ev.strike_fraction[hit]) * dt
        seen = np.isfinite(last_x[hit])
        lengths.append((ev.strike_position[hit] - last_x[hit])[seen])
        speeds.append(((ev.strike_position[hit] - last_x[hit]) / (t - last_t[hit]))[seen])
        last_x[hit], last_t[hit] = ev.strike_position[hit], t
        strikes[hit] += 1
    length, pace = np.concatenate(lengths), np.concatenate(speeds)
    usable = (length > 0.05) & (pace > 0.05)
    slope = float(np.polyfit(np.log(pace[usable]), np.log(length[usable]), 1)[0]) if usable.sum() > 2 else np.nan
    pct = (5, 25, 50, 75, 95)
    return {
        "walkers": n, "steps": steps, "fraction_fallen": float(fallen.mean()),
        "median_strikes_before_fall": float(np.median(strikes[fallen])) if fallen.any() else None,
        "step_length_percentiles_m": dict(zip(map(str, pct), np.percentile(length, pct).round(3).tolist())),
        "speed_percentiles_kmh": dict(zip(map(str, pct), (3.6 * np.percentile(pace, pct)).round(2).tolist())),
        "log_step_length_vs_log_speed_slope": slope,
    }
