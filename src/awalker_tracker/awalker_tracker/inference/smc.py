"""Sequential Monte Carlo with look-ahead (paper Sec. 5.2), generic over a vectorised model.

A model provides, for N particles held as arrays (a "states" object with ``take(indices)``):

- ``initial(n, rng) -> states``: samples of the state at the first frame;
- ``transition(states, rng) -> (states, info)``: one frame of the dynamics, s_t ~ p(s_t | s_{t-1});
  ``info`` is anything the model wants reported with the new states (e.g. heel strikes);
- ``log_likelihood(prev_states, states, obs) -> (N,)``: log p(z_t | s_t) (``prev_states`` is
  None at the first frame; models with optical flow use it);
- optionally ``bin_keys(states) -> (N, D) int``: the histogram bin of each particle's state, for the adaptive
  particle count (``SMCConfig.min_particles``; below);
- optionally ``rejuvenate(frame, log_weights, parent, states, obs, rng) -> states``: a data-driven
  move made after the transition (``parent`` -> ``states``; ``parent`` None at the first frame) and
  before the likelihood of frame ``frame`` (e.g. re-seeding particles at a person detected in
  ``obs``); ``log_weights`` are the particles' weights before this frame.
  Its proposals are not weight-corrected: a robustness device outside the exact filter. States it
  returns may carry ``continues`` (N,): for each particle, the row of the ``states`` it was given whose
  walk it continues (a particle copied from another continues that one's lineage); the frame's ancestry
  then follows it.

The filter keeps S_{t-1} = {s_{t-1}, w_{t-1}} and a window of simulated futures
s_t .. s_{t+tau} (one per particle) with their likelihoods. Before moving to frame t it forms
the look-ahead weights (eq. 13)  w_{t:t+tau} = c w_{t-1} prod_l p(z_l | s_l)  and, when their
effective sample size (eq. 14) falls below ``resample_fraction * N``, resamples S_{t-1} with
w_hat = (1 - gamma) w_{t-1} + gamma w_{t:t+tau} and re-weights the copies by w_{t-1} / w_hat
(steps 1-2 of Sec. 5.2); the futures are then simulated afresh from the resampled set.
Frame t's weights are w_t = c w_{t-1} p(z_t | s_t). All weights are kept as logarithms.

With ``SMCConfig.min_particles`` set, each resampling also chooses how many particles to keep, KLD-sampling
style (Fox 2003): enough that the histogram of the predicted particles s_t, over the k bins they occupy
(``bin_keys``), lies within ``kld_error`` of the true one's in Kullback-Leibler divergence with probability
``kld_quantile``: n = (k - 1) / (2 eps) (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3, clipped to
[``min_particles``, ``num_particles``]. The resampling draws ``num_particles``, the first frame of the new
window moves them all (the bins of the prediction, as Fox counts them: a posterior narrower than the motion's
spread is not mistaken for a small one), and a uniformly random n of them are kept, with their weights, before
that frame's ``rejuvenate`` and likelihood; the window's later frames and the frames up to the next resampling
run with n. A concentrated posterior is then followed with fewer particles. ``transition``'s ``info`` should
have ``take(indices)`` to be cut with them (else it is reported whole).

Because frame t needs the observations of frames t..t+tau, results lag the input by tau
frames; ``finish()`` flushes the last frames with a shortened window. Ancestry (which particle
of frame t-1 each particle of frame t descends from) is reported per frame; ``AncestryHistory``
turns it into the MAP trajectory without copying whole histories.
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

States = TypeVar("States")


class SMCModel(Protocol[States]):
    """What the particle filter needs from a model (all methods vectorised over particles)."""

    def initial(self, n: int, rng: np.random.Generator) -> States: ...

    def transition(self, states: States, rng: np.random.Generator) -> tuple[States, Any]: ...

    def log_likelihood(self, prev_states: States | None, states: States, obs: Any) -> np.ndarray: ...


RESAMPLING_SCHEMES = ("systematic", "stratified", "multinomial")


#: The most particles a filter takes: 200000 already hold about 2 GB of states and look-ahead copies and run
#: at under a frame per second; more is a typing slip (1e8 would exhaust the memory), refused at once.
MAX_PARTICLES = 200_000


@dataclass(frozen=True)
class SMCConfig:
    """Particle filter settings (paper values: N = 5000, tau = 3, gamma = 0.9, N_eff < N/10)."""

    num_particles: int = 5000
    lookahead: int = 3                # tau: future frames used to decide resampling (0 = plain filter)
    trust: float = 0.9                # gamma: trust in the look-ahead weights when resampling
    resample_fraction: float = 0.1    # resample when N_eff < resample_fraction * N
    resampling: str = "systematic"    # systematic | stratified | multinomial
    seed: int | None = 0
    # adaptive particle count (module doc): 0 keeps num_particles throughout; else the fewest a resampling
    # may draw, num_particles being the most
    min_particles: int = 0
    kld_error: float = 0.05           # epsilon: the histogram's allowed KL divergence (nats)
    kld_quantile: float = 0.99        # 1 - delta: the probability of staying within it

    def __post_init__(self) -> None:
        if not 1 <= self.num_particles <= MAX_PARTICLES:
            raise ValueError(f"SMCConfig.num_particles must lie in 1-{MAX_PARTICLES} (MAX_PARTICLES), "
                             f"got {self.num_particles}")
        if self.seed is not None and self.seed < 0:
            raise ValueError(f"SMCConfig.seed must be >= 0, got {self.seed}")
        if self.lookahead < 0:
            raise ValueError(f"SMCConfig.lookahead (tau) must be >= 0, got {self.lookahead}")
        if not 0.0 <= self.trust <= 1.0:
            raise ValueError(f"SMCConfig.trust (gamma) must lie in [0, 1], got {self.trust}")
        if not 0.0 <= self.resample_fraction <= 1.0:
            raise ValueError(f"SMCConfig.resample_fraction must lie in [0, 1], got {self.resample_fraction}")
        if self.resampling not in RESAMPLING_SCHEMES:
            raise ValueError(f"SMCConfig.resampling must be one of {RESAMPLING_SCHEMES}, got {self.resampling!r}")
        if not 0 <= self.min_particles <= self.num_particles:
            raise ValueError(f"SMCConfig.min_particles must lie in 0-num_particles ({self.num_particles}), "
                             f"got {self.min_particles}")
        if not self.kld_error > 0.0:
            raise ValueError(f"SMCConfig.kld_error (epsilon) must be > 0, got {self.kld_error}")
        if not 0.5 <= self.kld_quantile < 1.0:
            raise ValueError(f"SMCConfig.kld_quantile (1 - delta) must lie in [0.5, 1), got {self.kld_quantile}")


# ----------------------------------------------------------------------------- weights

def normalize_log_weights(log_weights: np.ndarray) -> np.ndarray:
    """Shift log weights so that sum(exp) = 1; all -inf (every particle impossible) -> uniform."""
    return _normalized_and_log_sum(log_weights)[0]


def _normalized_and_log_sum(log_weights: np.ndarray) -> tuple[np.ndarray, float]:
    """``normalize_log_weights`` and the log of the sum it divided by (-inf when all are -inf)."""
    log_weights = np.asarray(log_weights, float)
    top = np.max(log_weights)
    if not np.isfinite(top):
        if np.any(np.isnan(log_weights)) or top == np.inf:
            raise ValueError("log weights contain NaN or +inf")
        return np.full(log_weights.shape, -np.log(log_weights.size)), -np.inf
    log_sum = top + np.log(np.sum(np.exp(log_weights - top)))
    return log_weights - log_sum, float(log_sum)


def effective_sample_size(log_weights: np.ndarray) -> float:
    """N_eff = 1 / sum_j w_j^2 of normalised weights (eq. 14)."""
    w = np.exp(normalize_log_weights(log_weights))
    return float(1.0 / np.sum(w * w))


def resample(weights: np.ndarray, rng: np.random.Generator, scheme: str = "systematic",
             n: int | None = None) -> np.ndarray:
    """Indices of ``n`` draws (default len(weights)) from normalised ``weights``, sorted.

    Every scheme is unbiased: E[count of j] = n w_j. Systematic uses one uniform offset,
    stratified one uniform per stratum, multinomial independent draws.
    """
    weights = np.asarray(weights, float)
    n = weights.size if n is None else int(n)
    cumulative = np.cumsum(weights)
    cumulative /= cumulative[-1]
    if scheme == "systematic":
        positions = (rng.random() + np.arange(n)) / n
    elif scheme == "stratified":
        positions = (rng.random(n) + np.arange(n)) / n
    elif scheme == "multinomial":
        positions = np.sort(rng.random(n))
    else:
        raise ValueError(f"unknown resampling scheme {scheme!r}; expected one of {RESAMPLING_SCHEMES}")
    indices = np.searchsorted(cumulative, positions, side="right")
    return np.minimum(indices, weights.size - 1)


def kld_particle_count(bins: int, error: float, quantile: float) -> int:
    """Particles needed so that a sample's histogram over ``bins`` occupied bins lies within ``error`` (nats) of
    the true distribution's in KL divergence with probability ``quantile`` (Fox 2003, KLD-sampling; the
    Wilson-Hilferty approximation of the chi-square quantile). One bin: 1."""
    if bins <= 1:
        return 1
    z = float(NormalDist().inv_cdf(quantile))
    a = 2.0 / (9.0 * (bins - 1))
    return int(math.ceil((bins - 1) / (2.0 * error) * (1.0 - a + math.sqrt(a) * z) ** 3))


# ----------------------------------------------------------------------------- filter

@dataclass
class FilterStep(Generic[States]):
    """The weighted particle set of one frame, as the filter reports it."""

    frame: int                    # index of the observation (0-based, in push order)
    states: States
    info: Any                     # what the model's transition reported (None at frame 0)
    log_weights: np.ndarray       # (N,) normalised log w_t
    log_likelihood: np.ndarray    # (N,) log p(z_t | s_t)
    ancestors: np.ndarray         # (N,) index of each particle's parent among frame t-1's particles
    resampled: bool               # whether S_{t-1} was resampled before this frame
    effective_sample_size: float  # N_eff of w_t
    lookahead_ess: float          # N_eff of the look-ahead weights w_{t:t+tau} that decided resampling
    observation: Any = field(repr=False, default=None)
    log_evidence: float = float("nan")   # log p(z_t | z_1:t-1) ~ log sum_j w_{t-1,j} p(z_t | s_t^j)

    @property
    def weights(self) -> np.ndarray:
        return np.exp(self.log_weights)

    @property
    def best_index(self) -> int:
        """Index of the highest-weight particle (filtering MAP)."""
        return int(np.argmax(self.log_weights))


@dataclass
class _Future:
    """One frame of simulated futures: states, transition info, observation and log-likelihoods."""

    states: Any
    info: Any
    obs: Any
    log_likelihood: np.ndarray
    continues: np.ndarray | None = None   # rejuvenate's row map (module doc), None: each row its own


class ParticleFilter(Generic[States]):
    """SMC with look-ahead over an ``SMCModel``; push one observation per frame.

    ``push(obs)`` returns the FilterSteps completed by this observation (none during the first
    tau frames, then one per frame); ``finish()`` returns the remaining ones.
    """

    def __init__(self, model: SMCModel[States], config: SMCConfig = SMCConfig(),
                 rng: np.random.Generator | None = None) -> None:
        if config.min_particles > 0 and not callable(getattr(model, "bin_keys", None)):
            raise ValueError(f"SMCConfig.min_particles ({config.min_particles}) needs a model with bin_keys(states) "
                             f"(the adaptive count's histogram bins); {type(model).__name__} has none")
        self.model = model
        self.config = config
        self.rng = rng if rng is not None else np.random.default_rng(config.seed)
        self._prev_states: States | None = None      # S_{t-1} (None before frame 0)
        self._prev_log_weights = np.full(config.num_particles, -np.log(config.num_particles))
        self._window: deque[_Future] = deque()      # futures for frames t .. t+k
        self._next_frame = 0                         # frame index of window[0]
        self._initial: States | None = None          # frame-0 samples when S_{-1} does not exist
        self._count_due = False                      # the next simulated frame decides the adaptive count
        self._kept_rows: np.ndarray | None = None    # the rows of the resampled set that count kept
        self.num_resamples = 0

    @property
    def num_particles(self) -> int:
        """The particles held now: ``SMCConfig.num_particles``, or fewer after an adaptive resampling."""
        return self._prev_log_weights.size

    def _simulate_next(self, obs: Any) -> None:
        """Append the futures of the next frame, from the window's last entry or S_{t-1}."""
        if self._window:
            parent = self._window[-1].states
        else:
            parent = self._prev_states
        if parent is None:  # frame 0: samples from the initial distribution, no transition
            if self._initial is None:
                self._initial = self.model.initial(self.num_particles, self.rng)
            states, info = self._initial, None
        else:
            states, info = self.model.transition(parent, self.rng)
        if self._count_due:             # the first frame after a resampling: the adaptive count (module doc)
            self._count_due = False
            rows = self._counted_rows(states)
            if rows is not None:
                self._kept_rows = rows
                states = states.take(rows)
                info = info.take(rows) if callable(getattr(info, "take", None)) else info
                if parent is None:
                    self._initial = states
                else:
                    parent = self._prev_states = parent.take(rows)
                self._prev_log_weights = normalize_log_weights(self._prev_log_weights[rows])
        rejuvenate = getattr(self.model, "rejuvenate", None)
        continues = None
        if rejuvenate is not None:
            # the particles' weights as they stand before this frame: w_{t-1} times the window's likelihoods
            log_weights = self._prev_log_weights + sum((f.log_likelihood for f in self._window),
                                                       np.zeros(self.num_particles))
            states = rejuvenate(self._next_frame + len(self._window), log_weights, parent, states, obs, self.rng)
            continues = getattr(states, "continues", None)
        loglik = self._checked_loglik(parent, states, obs)
        self._window.append(_Future(states, info, obs, loglik, continues))

    def _checked_loglik(self, parent: States | None, states: States, obs: Any) -> np.ndarray:
        loglik = np.asarray(self.model.log_likelihood(parent, states, obs), float)
        if loglik.shape != (self.num_particles,):
            raise ValueError(f"log_likelihood returned shape {loglik.shape}, expected ({self.num_particles},)")
        if np.any(np.isnan(loglik)) or np.any(loglik == np.inf):
            raise ValueError("log_likelihood returned NaN or +inf")
        return loglik

    def push(self, obs: Any) -> list[FilterStep[States]]:
        """Add the observation of the next frame; returns the frames it completes."""
        self._simulate_next(obs)
        if len(self._window) > self.config.lookahead:
            return [self._advance()]
        return []

    def finish(self) -> list[FilterStep[States]]:
        """Complete the frames still waiting for look-ahead data (shortened windows)."""
        steps = []
        while self._window:
            steps.append(self._advance())
        return steps

    def _advance(self) -> FilterStep[States]:
        """Decide on resampling S_{t-1} with the window's look-ahead, then move to frame t."""
        cfg = self.config
        n = self.num_particles
        window_loglik = np.sum([f.log_likelihood for f in self._window], axis=0)
        lookahead_log_w = normalize_log_weights(self._prev_log_weights + window_loglik)   # eq. (13)
        lookahead_ess = float(1.0 / np.sum(np.exp(2.0 * lookahead_log_w)))                  # eq. (14)
        ancestors = np.arange(n)
        resampled = False
        if lookahead_ess < cfg.resample_fraction * n:
            # w_hat = (1 - gamma) w_{t-1} + gamma w_{t:t+tau}, in the log domain.
            with np.errstate(divide="ignore"):
                log_hat = np.logaddexp(np.log1p(-cfg.trust) + self._prev_log_weights,
                                       np.log(cfg.trust) + lookahead_log_w)
            log_hat = normalize_log_weights(log_hat)
            ancestors = resample(np.exp(log_hat), self.rng, cfg.resampling, n=cfg.num_particles)
            self._prev_log_weights = normalize_log_weights(
                self._prev_log_weights[ancestors] - log_hat[ancestors])
            observations = [f.obs for f in self._window]
            if self._prev_states is None:   # frame 0: resample the initial samples themselves
                self._initial = self._initial.take(ancestors)
            else:
                self._prev_states = self._prev_states.take(ancestors)
            self._window.clear()
            self._count_due = cfg.min_particles > 0
            for obs in observations:
                self._simulate_next(obs)
            if self._kept_rows is not None:            # the adaptive count kept these of the resampled rows
                ancestors, self._kept_rows = ancestors[self._kept_rows], None
            resampled = True
            self.num_resamples += 1
        current = self._window.popleft()
        if current.continues is not None:
            ancestors = ancestors[current.continues]
        # log p(z_t | z_1:t-1) is the log of the sum that normalises w_{t-1} p(z_t | s_t)
        log_w, log_evidence = _normalized_and_log_sum(self._prev_log_weights + current.log_likelihood)
        step = FilterStep(
            frame=self._next_frame, states=current.states, info=current.info, log_weights=log_w,
            log_likelihood=current.log_likelihood, ancestors=ancestors, resampled=resampled,
            effective_sample_size=float(1.0 / np.sum(np.exp(2.0 * log_w))),
            lookahead_ess=lookahead_ess, observation=current.obs, log_evidence=log_evidence)
        self._prev_states, self._prev_log_weights = current.states, log_w
        self._initial = None
        self._next_frame += 1
        return step

    def _counted_rows(self, predicted: States) -> np.ndarray | None:
        """The rows of the ``predicted`` particles the adaptive count keeps (sorted, a uniformly random n of
        them; module doc), or None to keep them all."""
        cfg = self.config
        size = self.num_particles
        keys = np.asarray(self.model.bin_keys(predicted)).reshape(size, -1)
        bins = np.unique(keys, axis=0).shape[0]
        n = min(max(kld_particle_count(bins, cfg.kld_error, cfg.kld_quantile), cfg.min_particles), cfg.num_particles)
        if n >= size:
            return None
        return np.sort(self.rng.choice(size, n, replace=False))

    def run(self, observations) -> list[FilterStep[States]]:
        """Filter a whole sequence (convenience for offline use and tests)."""
        steps: list[FilterStep[States]] = []
        for obs in observations:
            steps.extend(self.push(obs))
        steps.extend(self.finish())
        return steps


# ----------------------------------------------------------------------------- ancestry

class AncestryHistory:
    """Per-frame particle payloads (e.g. markers) plus ancestry, for MAP lineages.

    Each frame stores its payload arrays (leading axis = particles) and the parent index of each
    particle. ``prune()`` (run every ``prune_every`` frames) drops the particles of past frames
    that have no living descendant, so memory follows the (quickly coalescing) ancestry tree,
    not N x T.
    """

    def __init__(self, prune_every: int = 25) -> None:
        self.prune_every = int(prune_every)
        self._payloads: list[dict[str, np.ndarray]] = []
        self._ancestors: list[np.ndarray | None] = []

    def __len__(self) -> int:
        return len(self._payloads)

    def append(self, ancestors: np.ndarray | None, payload: Mapping[str, np.ndarray]) -> None:
        """Add a frame; ``ancestors`` index the previous frame's particles (None for the first)."""
        if self._payloads and ancestors is None:
            raise ValueError("ancestors are required for every frame after the first")
        self._ancestors.append(None if ancestors is None else np.asarray(ancestors, np.int64))
        self._payloads.append({k: np.asarray(v) for k, v in payload.items()})
        if self.prune_every > 0 and len(self) % self.prune_every == 0:
            self.prune()

    def stored_particles(self) -> int:
        """Number of particle rows held over all frames (memory check)."""
        return int(sum(next(iter(p.values())).shape[0] if p else 0 for p in self._payloads))

    def prune(self) -> None:
        """Keep, in every past frame, only ancestors of the last frame's particles."""
        if len(self) < 2:
            return
        alive: np.ndarray | None = None  # rows kept in frame f (None: the last frame keeps all)
        for f in range(len(self) - 1, 0, -1):
            anc = self._ancestors[f] if alive is None else self._ancestors[f][alive]
            parents = np.unique(anc)                       # rows of frame f-1 still needed
            self._ancestors[f] = np.searchsorted(parents, anc)  # re-index into compacted frame f-1
            if alive is not None:
                self._payloads[f] = {k: v[alive] for k, v in self._payloads[f].items()}
            alive = parents
        self._payloads[0] = {k: v[alive] for k, v in self._payloads[0].items()}

    def lineage(self, index: int, first: int = 0) -> np.ndarray:
        """Row of each frame's payload from frame ``first`` on, on the path ending at particle ``index`` of the last
        frame."""
        rows = np.empty(len(self) - first, np.int64)
        for f in range(len(self) - 1, first - 1, -1):
            rows[f - first] = index
            if f > 0:
                index = int(self._ancestors[f][index])
        return rows

    def trajectory(self, index: int, first: int = 0) -> dict[str, np.ndarray]:
        """Payload arrays stacked over frames ``first``.. (default all) along the lineage of particle ``index``."""
        rows = self.lineage(index, first)
        keys = self._payloads[0].keys()
        return {k: np.stack([self._payloads[first + i][k][row] for i, row in enumerate(rows)]) for k in keys}


def map_trajectory(history: AncestryHistory, final_log_weights: np.ndarray) -> dict[str, np.ndarray]:
    """The MAP trajectory: lineage of the highest-weight particle of the last frame."""
    return history.trajectory(int(np.argmax(final_log_weights)))

