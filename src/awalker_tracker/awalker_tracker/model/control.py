"""Stochastic control prior of the Anthropomorphic Walker (paper Sec. 4.2), vectorised over particles.

- Within a stride the stiffness of every frame is kappa_t ~ N(kappa_bar, sigma_kappa^2) (eq. 4).
- Per stride, kappa_bar(i+1) ~ N(beta mu_kappa + (1 - beta) kappa_bar(i), sigma_kappa_bar^2) (eq. 5).
  kappa_bar is never sampled (Rao-Blackwellised): each particle keeps the mean and variance of its
  Gaussian belief over kappa_bar; kappa_t is drawn from the predictive N(mean, variance + sigma_kappa^2),
  then the belief is conditioned on the drawn kappa_t (a scalar Kalman update); at a heel strike the
  belief is pushed through the AR(1) of eq. (5) and the new stride's first kappa_t is drawn there
  (the toe-off below is aimed with it).
- The toe-off impulse iota ~ Gamma(mean mu_iota, variance sigma_iota^2) is drawn AT the heel strike,
  inside :func:`dynamics.advance`, from the walker's pre-impact state: one draw per stride, used for
  the toe-off that starts the new stride (the paper's "at the beginning of each stride"). Two rules
  for its mean (``ControlPrior.toe_off_rule``):

  * ``"bilinear"`` (the paper, Fig. 4): mu_iota(q'-) bilinear in the pre-collision rates, fitted over
    the solved cyclic gaits.
  * ``"cyclic_gait"`` (default): the iota that puts the new stance leg's rate on the cyclic gait
    with the new stride's stiffness and the step length just taken (:meth:`GaitTable.gait_for_stiffness`,
    :func:`dynamics.impulse_for_stance_rate`): a one-step (deadbeat) correction towards the gait family.

*Step length.* From a cyclic gait's heel strike, no stride of one stiffness and one push steps longer than
the gait's own step: the toe-off rule keeps the step it is given, and any other push or stiffness shortens it.
So iota's noise only ever shortens steps (5 km/h, 0.7 m: a median 0.635 m after 15 steps, none longer than
0.7 m), and a walker whose step is too short for the person can only quicken its cadence. A stride whose spring
is stiffer before mid-stance and softer after steps longer, the reverse shorter; so each stride may draw a tilt
tau ~ N(0, sigma_tau^2) (``ControlPrior.stiffness_tilt_variance``, 0 by default; the tracker's with two cameras
or more: ``TrackerConfig``), and the walker feels kappa_t + tau while the stance leg is ahead of the vertical and
kappa_t - tau after. The belief over kappa_bar is conditioned on kappa_t, not on the tilt.

Units (checked against the solved cyclic gaits, see test_control.py): kappa in N m/rad per kg, so
mu_kappa = 0.7 sits inside the solved range (0.74 at 5 km/h, 0.7 m with L = 0.9 m); iota in m/s.

Why the defaults are not the paper's (measured with :func:`prior_walk_statistics`, 1000 walkers, 20
steps; figures in docs/design.md, "The control prior and where it departs from the paper"): the paper calls its walker "very stable" and says
other controllers may work as well. This walker, checked by its invariants, is not:

- Open loop (fixed kappa, iota) the step-to-step map of the cyclic gaits has largest Floquet
  multiplier 0.88 at 4 km/h / 0.6 m but 1.08 at 5 km/h / 0.7 m and 1.35 at 6 km/h / 0.75 m.
- The bilinear rule feeds speed back positively (a faster walker gets a bigger push): the multiplier
  becomes 3-4 at every gait, and with the paper's variances every walker falls within a few steps.
- The knee-less swing leg must overtake the mirror angle of the stance leg before the strike; a
  stiffness off by ~0.1-0.2 N m/rad per kg for part of a stride is enough to trip it (the stance
  leg falls forward before the swing leg arrives). sigma_kappa^2 = 1.0 per frame and
  sigma_kappa_bar^2 = 0.5 per stride (standard deviations larger than mu_kappa itself) trip it
  at once, whatever the toe-off rule.

The default keeps the paper's structure, beta, mu_kappa and sigma_iota^2, uses the cyclic-gait toe-off
and sigma_kappa^2 = 1e-4 per frame, sigma_kappa_bar^2 = 0.01 per stride. :meth:`ControlPrior.paper`
gives the paper's values for comparison.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from .cyclic_gaits import GaitTable, fit_impulse_mean, gait_initial_state, preferred_step_length
from .dynamics import StepEvents, advance, impulse_for_stance_rate
from .walker import WalkerParams, WalkerState

#: Smallest Gamma mean (m/s) used for iota where a rule would give <= 0.
MIN_IMPULSE_MEAN = 1e-3
#: Toe-off rules for the Gamma mean of iota (see the module docstring).
TOE_OFF_RULES = ("cyclic_gait", "bilinear")
STIFFNESS_TARGETS = ("constant", "usual_gait")


@dataclass(frozen=True)
class ControlPrior:
    """Parameters of the control prior; variances in the squared units of their variables."""

    beta: float = 0.85                        # pull of kappa_bar towards mu_kappa per stride
    mu_kappa: float = 0.7                     # N m/rad per kg
    kappa_bar_variance: float = 0.01          # sigma_kappa_bar^2, per stride (paper: 0.5)
    kappa_noise_variance: float = 1.0e-4      # sigma_kappa^2, per frame around kappa_bar (paper: 1.0)
    impulse_variance: float = 0.05**2         # sigma_iota^2 (m/s)^2
    # sigma_tau^2 per stride: each stride's stiffness is tilted by tau, +tau while the stance leg is ahead of the
    # vertical and -tau after (module docstring, *Step length*); 0: no tilt
    stiffness_tilt_variance: float = 0.0
    # mu_iota(q'-) = c0 + c1 phi1'- + c2 phi2'- + c3 phi1'- phi2'- (m/s, rates in rad/s); "bilinear" rule
    impulse_mean_coefficients: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    toe_off_rule: str = "cyclic_gait"
    gait_table: GaitTable | None = field(default=None, compare=False, repr=False)  # "cyclic_gait" rule
    # what eq. (5) pulls kappa_bar towards at each stride: "constant" mu_kappa (the paper), or "usual_gait": the
    # stiffness of the cyclic gait at sample_transition's target_speed (else the speed of the stride just taken)
    # and a person's usual step length there
    stiffness_target: str = "constant"

    def __post_init__(self) -> None:
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError("ControlPrior.beta must lie in [0, 1]")
        for name in ("kappa_bar_variance", "kappa_noise_variance", "impulse_variance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ControlPrior.{name} must be > 0")
        if not (np.isfinite(self.stiffness_tilt_variance) and self.stiffness_tilt_variance >= 0):
            raise ValueError("ControlPrior.stiffness_tilt_variance must be >= 0")
        if len(self.impulse_mean_coefficients) != 4:
            raise ValueError("ControlPrior.impulse_mean_coefficients needs 4 values (bilinear fit)")
        if self.toe_off_rule not in TOE_OFF_RULES:
            raise ValueError(f"ControlPrior.toe_off_rule must be one of {TOE_OFF_RULES}, got {self.toe_off_rule!r}")
        if self.toe_off_rule == "cyclic_gait" and self.gait_table is None:
            raise ValueError("ControlPrior: the 'cyclic_gait' toe-off rule needs gait_table")
        if self.stiffness_target not in STIFFNESS_TARGETS:
            raise ValueError(f"ControlPrior.stiffness_target must be one of {STIFFNESS_TARGETS}, got "
                             f"{self.stiffness_target!r}")
        if self.stiffness_target == "usual_gait" and self.gait_table is None:
            raise ValueError("ControlPrior: the 'usual_gait' stiffness target needs gait_table")

    @classmethod
    def from_gait_table(cls, table: GaitTable, **overrides) -> "ControlPrior":
        """The default prior on ``table``, with mu_iota's bilinear fit over its converged gaits (unless overridden)."""
        coef, _ = fit_impulse_mean(table)
        settings = dict(impulse_mean_coefficients=tuple(float(c) for c in coef), gait_table=table)
        return cls(**{**settings, **overrides})

    @classmethod
    def paper(cls, table: GaitTable, **overrides) -> "ControlPrior":
        """The paper's prior: bilinear toe-off, sigma_kappa^2 = 1.0, sigma_kappa_bar^2 = 0.5."""
        settings = dict(kappa_noise_variance=1.0, kappa_bar_variance=0.5, toe_off_rule="bilinear")
        return cls.from_gait_table(table, **{**settings, **overrides})

    def impulse_mean(self, params: WalkerParams, pre_state: WalkerState, stride_stiffness: np.ndarray) -> np.ndarray:
        """Gamma mean of iota (m/s) for walkers just before their heel strike, floored at MIN_IMPULSE_MEAN.

        ``stride_stiffness``: kappa (N m/rad per kg) of the stride the strike starts (used by "cyclic_gait").
        """
        if self.toe_off_rule == "bilinear":
            c0, c1, c2, c3 = self.impulse_mean_coefficients
            w1, w2 = pre_state.stance_rate, pre_state.swing_rate
            mean = c0 + c1 * w1 + c2 * w2 + c3 * w1 * w2
        else:
            step = params.step_length(-pre_state.stance_angle)
            _, stance_rate, _, _ = self.gait_table.gait_for_stiffness(stride_stiffness, step)
            mean = impulse_for_stance_rate(params, pre_state, stance_rate)
        return np.maximum(np.nan_to_num(mean, nan=MIN_IMPULSE_MEAN), MIN_IMPULSE_MEAN)

    def stiffness_mean_target(self, params: WalkerParams, pre_state: WalkerState, stride_time: np.ndarray,
                              speed: float | None = None) -> np.ndarray:
        """mu_kappa of eq. (5) for walkers just before their heel strike (N m/rad per kg): the constant, or
        ("usual_gait") the cyclic gait's kappa at ``speed`` (m/s; None: the speed of the stride ending, step
        length / ``stride_time`` s), clamped to the table's speeds, and the usual step length at that speed;
        mu_kappa where the table has no gait there."""
        if self.stiffness_target == "constant":
            return np.full(np.shape(stride_time), self.mu_kappa)
        table = self.gait_table
        if speed is None:
            speed = params.step_length(-pre_state.stance_angle) / np.maximum(stride_time, 1e-3)
        speed = np.clip(np.broadcast_to(np.asarray(speed, float), np.shape(stride_time)), table.speeds[0],
                        table.speeds[-1])
        usual = preferred_step_length(params, speed)
        covered = table.covers(speed, usual)
        target = np.full(np.shape(speed), self.mu_kappa)
        if covered.any():
            target[covered] = table.lookup(speed[covered], usual[covered])[2]
        return target

    def sample_impulse(self, rng: np.random.Generator, mean: np.ndarray) -> np.ndarray:
        """iota ~ Gamma with the given mean (m/s) and variance sigma_iota^2 (shape mean^2/var, scale var/mean)."""
        mean = np.asarray(mean, float)
        return rng.gamma(mean * mean / self.impulse_variance, self.impulse_variance / mean)


@dataclass
class ControlState:
    """Per-particle control variables, arrays of shape (N,)."""

    stiffness: np.ndarray                # kappa_t of the last frame (N m/rad per kg)
    stiffness_mean_mean: np.ndarray      # mean of the Gaussian belief over kappa_bar
    stiffness_mean_variance: np.ndarray  # its variance
    toe_off_impulse: np.ndarray          # iota of the last heel strike (m/s)
    time_since_strike: np.ndarray        # s since the last heel strike
    stiffness_tilt: np.ndarray           # tau of the current stride (N m/rad per kg; stiffness_tilt_variance)

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
                        toe_off_impulse=iota, time_since_strike=np.zeros(n), stiffness_tilt=np.zeros(n))


def sample_transition(
    params: WalkerParams,
    prior: ControlPrior,
    walker: WalkerState,
    control: ControlState,
    dt: float,
    rng: np.random.Generator,
    substeps: int | None = None,
    target_speed: float | None = None,
) -> tuple[WalkerState, ControlState, StepEvents]:
    """Sample one frame of the prior for N particles: kappa_t, dynamics, iota at strikes, kappa_bar stats.
    ``target_speed`` (m/s): the speed whose usual gait eq. (5) pulls towards with the "usual_gait" target
    (a tracker's posterior speed); None: each walker's stride just taken."""
    m, v = control.stiffness_mean_mean, control.stiffness_mean_variance
    noise = prior.kappa_noise_variance
    kappa = m + np.sqrt(v + noise) * rng.standard_normal(m.shape)
    # condition the belief over kappa_bar on the drawn kappa_t (kappa_t = kappa_bar + N(0, noise))
    gain = v / (v + noise)
    m_post = m + gain * (kappa - m)
    v_post = v * noise / (v + noise)

    keep = 1.0 - prior.beta
    # where a stride starts: kappa_bar(i+1) ~ N(beta mu + (1 - beta) kappa_bar(i), sigma_bar^2) (eq. 5)
    m_next = prior.beta * prior.mu_kappa + keep * m_post
    v_next = keep * keep * v_post + prior.kappa_bar_variance
    stride_kappa = np.full(m.shape, np.nan)
    tilt = control.stiffness_tilt.copy()

    def impulse_at_strike(indices: np.ndarray, pre_state: WalkerState) -> np.ndarray:
        if prior.stiffness_target != "constant":
            stride_time = control.time_since_strike[indices] + 0.5 * dt
            m_next[indices] = (prior.beta * prior.stiffness_mean_target(params, pre_state, stride_time, target_speed)
                               + keep * m_post[indices])
        # the new stride's first kappa_t, from the predictive law of its kappa_bar; the toe-off aims at it
        drawn = m_next[indices] + np.sqrt(v_next[indices] + noise) * rng.standard_normal(indices.size)
        stride_kappa[indices] = drawn
        if prior.stiffness_tilt_variance > 0:
            tilt[indices] = np.sqrt(prior.stiffness_tilt_variance) * rng.standard_normal(indices.size)
        return prior.sample_impulse(rng, prior.impulse_mean(params, pre_state, drawn))

    # the spring the walker feels: kappa_t tilted by the stride's tau, stiffer before mid-stance, softer after
    felt = kappa + control.stiffness_tilt * np.sign(walker.stance_angle) if prior.stiffness_tilt_variance > 0 else kappa
    new_walker, events = advance(params, walker, felt, impulse_at_strike, dt, substeps=substeps,
                                 time_since_strike=control.time_since_strike)
    strike = events.heel_strike
    with np.errstate(invalid="ignore"):
        gain_next = v_next / (v_next + noise)
        m_strike = m_next + gain_next * (stride_kappa - m_next)
        v_strike = v_next * noise / (v_next + noise)
    m_new = np.where(strike, m_strike, m_post)
    v_new = np.where(strike, v_strike, v_post)
    iota = np.where(strike, events.toe_off_impulse, control.toe_off_impulse)
    fallen = events.fallen
    new_control = ControlState(
        stiffness=np.where(fallen, control.stiffness, np.where(strike, stride_kappa, kappa)),
        stiffness_mean_mean=np.where(fallen, m, m_new),
        stiffness_mean_variance=np.where(fallen, v, v_new),
        toe_off_impulse=iota,
        time_since_strike=events.time_since_strike,
        stiffness_tilt=np.where(fallen, control.stiffness_tilt, tilt),
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
