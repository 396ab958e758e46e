"""emcee's ensemble sampler with a resumable HDF5 chain, a process pool and a seeded start.

`run_sampler(posterior, settings, chain_path)` is the one entry point:

- the chain lives in an ``emcee.backends.HDFBackend`` file (normally
  ``archive.chain_path(pass_id, name)``); every step is written as it is taken, so a run
  killed at any moment (even with SIGKILL) resumes from its last stored step when called
  again with the same settings. The random state is stored with each step, so the resumed
  chain is the one an uninterrupted run would have produced.
- every `checkpoint_every` steps the chain file is copied atomically beside itself
  (``.bak``); if a kill lands in the middle of an HDF5 write and leaves the file unreadable,
  the run restarts from that copy instead of from scratch.
- walkers start either from the prior (``init="prior"``) or from a short global search
  (``init="search"``: scipy's differential evolution on the log posterior, then a small ball
  around the best point), so that the ensemble starts in the dominant mode.
- a fixed `seed` reproduces a run exactly (initial positions, the search and emcee's moves).
- with ``processes > 1`` the log posterior runs in a ``multiprocessing`` pool whose workers
  receive the posterior once, at start-up, rather than with every batch of walkers.
- ``until_converged=True`` runs until the chain after its burn-in (`BURN_IN_TAUS`
  autocorrelation times) is `CONVERGED_TAUS` autocorrelation times long on every parameter, with
  the estimates steady, checked every ``check_every`` steps; ``n_steps`` then caps the length.
  ``time_limit_s`` stops any run when its time is up (the global search at half of it).
  `ChainRun.stopped` says why a run ended.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor
import contextlib
from dataclasses import asdict, dataclass, field
import itertools
import json
import math
import multiprocessing
import os
from pathlib import Path
import pickle
import shutil
import time
from typing import Any

import emcee
from emcee.autocorr import integrated_time
import h5py
import numpy as np
from scipy.optimize import differential_evolution, minimize
from tqdm.auto import tqdm

from rsodb.fit.parameters import FORMERLY_FIXED
from rsodb.pool import SINGLE_THREAD_ENV, environment

__all__ = [
    "SamplerSettings",
    "ChainRun",
    "run_sampler",
    "INITIALISERS",
    "read_chain",
    "convergence_check",
    "CONVERGED_TAUS",
    "BURN_IN_TAUS",
]

CHAIN_GROUP = "mcmc"
# Stand-in for -ln p where the posterior is zero, for the minimiser (it needs finite values).
_IMPOSSIBLE = 1e30
# emcee's guidance: trust the autocorrelation time, and the posterior, when the chain after
# burn-in is at least ~50 of them long; burn-in takes a few of them.
CONVERGED_TAUS = 50
BURN_IN_TAUS = 5
# How a run stopped by its convergence check says so (its verdict still weighs the acceptance).
STOPPED_LONG_ENOUGH = f"stopped at {CONVERGED_TAUS} autocorrelation times"
# Autocorrelation estimates counted as steady when they moved by less than this between checks.
_STEADY = 0.1
# Largest count a sampler setting takes (steps, walkers, ...): far above any real fit, and below
# what the chain's HDF5 dataset and numpy's integers hold, so a typo fails here, not mid-run.
MAX_COUNT = 10**9


def whole_number(value) -> bool:
    """An integer (true and false are not numbers here, although Python's bool is an int: a TOML
    boolean where a count belongs is a mistake, not 1). The fit configuration checks its counts
    with it too."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


@dataclass(frozen=True)
class SamplerSettings:
    """How to run the sampler.

    Parameters
    ----------
    n_walkers : int
        Ensemble size; at least twice the number of free parameters.
    n_steps : int
        Steps per walker in total (a resumed run stops at the same total).
    init : {"search", "multistart", "population", "prior"}
        Where walkers start: in a small ball around the best point of a differential-evolution
        search; in a small ball around the best point of a multi-start search (many prior
        points screened, the best refined locally: on light curves of a precessing body
        rendered by Blender Cycles it found the global mode where differential evolution of
        the same or a larger cost did not, docs/fitting.md); at the best distinct members of
        the differential-evolution search's final population (spread over the good modes of a
        multimodal posterior); or drawn from the prior.
    moves : {"de", "stretch"}
        emcee's proposal: a mixture of differential-evolution (80%; steps of 0.8 times emcee's
        default scale, ``DE_STEP_SHARE``) and snooker (20%) moves, which let walkers jump
        between separated modes (emcee's advice for multimodal posteriors) and mixed ~3x faster
        than the stretch move on the paper mesh's Cycles pass (docs/fitting.md, "Moves"); or
        the affine-invariant stretch move (emcee's default).
    search_strategy : str
        scipy's differential-evolution strategy (``randtobest1bin`` found the global mode of
        test light curves more often than ``best1bin`` for the same cost).
    search_maxiter, search_popsize : int
        Generations and population multiplier of the differential-evolution search (the
        population is ``search_popsize * ndim``; light-curve posteriors are multimodal and a
        6-parameter search needs a population of ~90 to find the global mode reliably).
    search_starts, search_polish, search_polish_evals : int
        ``init = "multistart"``: the coarse posterior is evaluated at ``search_starts`` points of
        a scrambled Sobol sequence over the priors, and the ``search_polish`` best of them are
        each refined by a Nelder-Mead search of at most ``search_polish_evals`` evaluations
        (8192 and 16 by default: on the two Cycles passes whose search had failed, 1024 and 8
        found neither true mode, 4096 and 16 one, 8192 and 16 both; docs/fitting.md).
    search_points : int
        The search runs on at most this many samples, evenly spread, without exposure
        sub-samples (a coarse posterior ~10x cheaper than the full one); the walkers then
        start around its best point on the full posterior.
    settle_evals : int
        ``init = "search"`` or ``"multistart"`` on a coarse search posterior: the search's best
        point is refined on the full posterior by a Nelder-Mead of at most this many
        evaluations (in this process) before the walkers start around it (0: not refined).
        The coarse posterior's best lies many posterior widths from the full one's (the paper
        mesh's Cycles pass: jitter 0.035 against 0.003 mag, P 7 sigma off), and walkers
        started there took ~700 of their steps to reach it.
    half_turns : bool
        ``init = "search"`` or ``"multistart"``: the search's best point is also turned half a
        revolution in its free spin and precession phases (each alone and both together, see
        `HALF_TURN_PHASES`), each turned point is refined on the full posterior like the best
        one, and the walkers start at whichever of them is best. A body that looks nearly the
        same turned half a revolution about its spin axis has a second mode there, which no
        local refinement reaches across the ridge between them, and a coarse search posterior
        can prefer the wrong one (a Cycles pass of the paper mesh, docs/fitting.md).
    ball_fraction : float
        Radius of the initial ball around the search's best point, as a fraction of each
        parameter's prior width.
    processes : int
        Worker processes for the log posterior (1: in this process; 0: one per core).
    seed : int
        Seed of every random choice of the run.
    checkpoint_every : int
        Steps between atomic backup copies of the chain file.
    until_converged : bool
        Stop as soon as the chain is converged (`convergence_check`), at most ``n_steps`` steps.
    check_every : int
        Steps between convergence checks.
    time_limit_s : float
        Stop sampling when this much time has passed since the run started (0: no limit); the
        chain so far is kept and a rerun continues it.
    """

    n_walkers: int = 20
    n_steps: int = 500
    init: str = "search"
    moves: str = "de"
    search_strategy: str = "randtobest1bin"
    search_maxiter: int = 100
    search_popsize: int = 15
    search_points: int = 60
    settle_evals: int = 300
    half_turns: bool = True
    search_starts: int = 8192
    search_polish: int = 16
    search_polish_evals: int = 400
    ball_fraction: float = 1e-3
    processes: int = 1
    seed: int = 0
    checkpoint_every: int = 50
    until_converged: bool = False
    check_every: int = 100
    time_limit_s: float = 0.0

    def __post_init__(self):
        for name in (
            "n_walkers",
            "n_steps",
            "search_maxiter",
            "search_popsize",
            "search_points",
            "search_starts",
            "search_polish",
            "search_polish_evals",
            "checkpoint_every",
            "check_every",
        ):
            value = getattr(self, name)
            if not whole_number(value) or not 1 <= value <= MAX_COUNT:
                raise ValueError(f"sampler setting {name}={value!r} must be a whole number from 1 to {MAX_COUNT:.0e}")
        if self.moves not in MOVES:
            raise ValueError(f"sampler setting moves={self.moves!r} is not one of {', '.join(MOVES)}")
        if self.init not in INITIALISERS:
            raise ValueError(f"sampler setting init={self.init!r} is not one of {', '.join(INITIALISERS)}")
        if not (whole_number(self.processes) and self.processes >= 0):
            raise ValueError(
                f"sampler setting processes={self.processes!r} must be 0 (all cores) or a positive integer"
            )
        if not (whole_number(self.seed) and self.seed >= 0):
            raise ValueError(f"sampler setting seed={self.seed!r} must be a non-negative integer")
        if not (whole_number(self.settle_evals) and 0 <= self.settle_evals <= MAX_COUNT):
            raise ValueError(
                f"sampler setting settle_evals={self.settle_evals!r} must be a whole number from 0 (no "
                f"refinement) to {MAX_COUNT:.0e}"
            )
        if not (0 < self.ball_fraction < 1):
            raise ValueError(f"sampler setting ball_fraction={self.ball_fraction!r} must be in (0, 1)")
        if not isinstance(self.half_turns, bool):
            raise ValueError(f"sampler setting half_turns={self.half_turns!r} must be true or false")
        if not isinstance(self.until_converged, bool):
            raise ValueError(f"sampler setting until_converged={self.until_converged!r} must be true or false")
        if not (
            isinstance(self.time_limit_s, (int, float))
            and not isinstance(self.time_limit_s, bool)
            and math.isfinite(self.time_limit_s)
            and self.time_limit_s >= 0
        ):
            raise ValueError(f"sampler setting time_limit_s={self.time_limit_s!r} must be seconds >= 0 (0: no limit)")

    @property
    def n_processes(self) -> int:
        return (os.cpu_count() or 1) if self.processes == 0 else int(self.processes)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, record: Mapping) -> SamplerSettings:
        unknown = sorted(set(record) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"unknown sampler settings {unknown}; known: {', '.join(cls.__dataclass_fields__)}")
        return cls(**record)

    def replace(self, **changes) -> SamplerSettings:
        return SamplerSettings(**{**asdict(self), **changes})


@dataclass(frozen=True, eq=False)
class ChainRun:
    """What a sampler run leaves behind (read back from the chain file).

    Attributes
    ----------
    names : tuple of str
        Free parameter names (the chain's last axis).
    chain : (n_steps, n_walkers, ndim) float
        Every walker's position at every step (wrapped angles not reduced).
    log_prob : (n_steps, n_walkers) float
        Log posterior at those positions.
    acceptance_fraction : (n_walkers,) float
    autocorr_time : (ndim,) float
        Integrated autocorrelation time per parameter, in steps (:func:`autocorr_time`;
        unreliable when the chain is shorter than ~50 of them).
    resumed_from : int
        Steps already in the file when this call started (0 for a fresh run).
    steps_run : int
        Steps taken by this call.
    elapsed_s : float
        Wall time of this call, initialisation included.
    init : mapping
        How walkers were started (method, search best value, evaluations).
    chain_path : str
        The HDFBackend file.
    stopped : str
        Why sampling ended, in words ("" after the planned steps).
    burn_in : int or None
        Burn-in the convergence check settled on (``until_converged`` runs), else None.
    """

    names: tuple[str, ...]
    chain: np.ndarray
    log_prob: np.ndarray
    acceptance_fraction: np.ndarray
    autocorr_time: np.ndarray
    resumed_from: int
    steps_run: int
    elapsed_s: float
    init: Mapping[str, Any]
    chain_path: str
    stopped: str = ""
    burn_in: int | None = None

    @property
    def n_steps(self) -> int:
        return self.chain.shape[0]

    @property
    def n_walkers(self) -> int:
        return self.chain.shape[1]


# -- log posterior in this process or in pool workers ----------------------------------------
_WORKER_POSTERIORS: tuple = (None, None)


def _install_worker(payload: bytes) -> None:
    """Unpickle the posteriors `_open_pool` sent, from a copy of the bytes. Unpickled from the
    buffer the start-up pipe delivered (as the executor's initargs, or from those bytes), the
    shape cache's tables sit in memory that made an evaluation of the whole TOPEX pass 13-35%
    slower in one worker (92-111 against 76-83 ms, as from a file); from a fresh copy it
    is not."""
    global _WORKER_POSTERIORS
    _WORKER_POSTERIORS = pickle.loads(bytearray(payload))


def _worker_log_prob(theta: np.ndarray) -> float:
    return _WORKER_POSTERIORS[0](theta)


def _worker_cost(theta: np.ndarray) -> float:
    value = _WORKER_POSTERIORS[1](theta)
    return -value if math.isfinite(value) else _IMPOSSIBLE


def _worker_settle(start_and_evals: tuple[np.ndarray, int]) -> tuple[np.ndarray, float, float, int]:
    return _settle(_WORKER_POSTERIORS[0], *start_and_evals)


@dataclass(frozen=True, eq=False)
class _InProcessSettle:
    posterior: Any

    def __call__(self, start_and_evals: tuple[np.ndarray, int]) -> tuple[np.ndarray, float, float, int]:
        return _settle(self.posterior, *start_and_evals)


@dataclass(frozen=True, eq=False)
class _Cost:
    """-ln p for a minimiser, in this process; ``wrap``: phases wrapped into their turn first (a
    Nelder-Mead simplex steps over a phase's wrap; other bounds are the prior's)."""

    posterior: Any
    wrap: bool = False

    def __call__(self, theta):
        value = self.posterior(self.posterior.space.wrap(theta) if self.wrap else theta)
        return -value if math.isfinite(value) else _IMPOSSIBLE


@dataclass(eq=False)
class _Evaluator:
    """Where log posteriors run: `log_prob`/`cost` functions and the `map` that applies them."""

    posterior: Any
    search_posterior: Any
    pool: Any = None
    deadline: float | None = None  # perf_counter time at which a global search stops (None: never)
    progress: bool = False
    log_prob: Callable = field(init=False)
    cost: Callable = field(init=False)
    settle: Callable = field(init=False)  # (start, evaluations) -> `_settle` on the full posterior
    map: Callable = field(init=False)

    def __post_init__(self):
        if self.pool is None:
            self.log_prob, self.cost, self.map = self.posterior, _Cost(self.search_posterior), map
            self.settle = _InProcessSettle(self.posterior)
        else:
            self.log_prob, self.cost, self.map = _worker_log_prob, _worker_cost, self.pool.map
            self.settle = _worker_settle

    def past_deadline(self) -> bool:
        return self.deadline is not None and time.perf_counter() >= self.deadline


@dataclass(eq=False)
class _ProcessPool:
    """A process pool with the ``map(fn, iterable)`` emcee and scipy call.

    Built on `concurrent.futures.ProcessPoolExecutor` rather than `multiprocessing.Pool`: when
    a worker dies (e.g. the kernel's out-of-memory killer), the executor raises
    ``BrokenProcessPool`` instead of waiting forever for the lost result.
    """

    executor: Any
    processes: int
    environment: contextlib.ExitStack

    def map(self, fn: Callable, iterable) -> list:
        items = list(iterable)
        # About four chunks a worker: evaluations differ in cost (more or fewer shadow rays), and
        # with one chunk each the faster worker waited for the slower (20 walkers on the whole
        # TOPEX pass: 0.96 s a step, 0.88 s in chunks of one); a round trip costs ~0.2 ms.
        chunk = max(1, len(items) // (4 * self.processes))
        return list(self.executor.map(fn, items, chunksize=chunk))

    def close(self) -> None:
        self.executor.shutdown(wait=True, cancel_futures=True)
        self.environment.close()


def _open_pool(posterior, search_posterior, processes: int) -> _ProcessPool | None:
    if processes <= 1:
        return None

    # Each worker is one of `processes` on a small machine: one BLAS/OpenMP thread each, or
    # they fight over the cores. The executor spawns its workers lazily, so the variables stay
    # set until the pool is closed.
    single_threaded = contextlib.ExitStack()
    single_threaded.enter_context(environment(SINGLE_THREAD_ENV))
    # spawn, not fork: the parent may hold threads (tqdm, Dask, Open3D) that fork would copy
    # in a locked state.
    try:
        executor = ProcessPoolExecutor(
            processes,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_install_worker,
            initargs=(pickle.dumps((posterior, search_posterior), protocol=pickle.HIGHEST_PROTOCOL),),
        )
    except BaseException:
        single_threaded.close()
        raise
    return _ProcessPool(executor, processes, single_threaded)


# -- initialisation -----------------------------------------------------------------------
def _reflect_into(theta: np.ndarray, bounds: np.ndarray, periods: np.ndarray) -> np.ndarray:
    low, high = bounds[:, 0], bounds[:, 1]
    span = high - low
    folded = np.mod(theta - low, 2 * span)
    reflected = low + np.where(folded > span, 2 * span - folded, folded)
    return np.where(np.isnan(periods), reflected, theta)


def _finite_or_redraw(
    evaluator: _Evaluator, draw: Callable[[int], np.ndarray], n: int, what: str, attempts: int = 50
) -> tuple[np.ndarray, int]:
    """n positions with a finite log posterior, redrawing the others; (positions, evaluations)."""
    positions = draw(n)
    values = np.array(list(evaluator.map(evaluator.log_prob, positions)))
    evaluations = n
    for _ in range(attempts):
        bad = ~np.isfinite(values)
        if not bad.any():
            return positions, evaluations
        positions[bad] = draw(int(bad.sum()))
        values[bad] = list(evaluator.map(evaluator.log_prob, positions[bad]))
        evaluations += int(bad.sum())
    raise RuntimeError(
        f"could not find {n} starting points {what} where the posterior is non-zero after "
        f"{evaluations} tries; check that the priors allow the object to be visible"
    )


def init_from_prior(
    posterior, settings: SamplerSettings, rng: np.random.Generator, evaluator: _Evaluator
) -> tuple[np.ndarray, dict]:
    """Walkers drawn independently from the prior."""
    positions, evaluations = _finite_or_redraw(
        evaluator, lambda k: posterior.space.sample_prior(rng, k), settings.n_walkers, "in the prior"
    )
    return positions, {"method": "prior", "evaluations": evaluations}


def _search(posterior, settings: SamplerSettings, rng: np.random.Generator, evaluator: _Evaluator):
    """Differential evolution on the search posterior, then an L-BFGS-B polish of its best point.

    Returns (result, best, best_cost, polish evaluations).
    """
    space = posterior.space
    bounds = space.bounds
    with tqdm(
        total=settings.search_maxiter,
        desc="global search",
        unit="generation",
        disable=not evaluator.progress,
        leave=False,
    ) as bar:

        def generation_done(intermediate_result) -> bool:
            # True stops the search: half of a run's time limit is its share (the sampler needs the rest).
            bar.update(1)
            return evaluator.past_deadline()

        result = differential_evolution(
            evaluator.cost,
            bounds,
            maxiter=settings.search_maxiter,
            popsize=settings.search_popsize,
            strategy=settings.search_strategy,
            seed=int(rng.integers(2**31)),
            polish=False,
            init="sobol",
            tol=1e-8,
            # "deferred" updating evaluates whole generations through `map`: the same search
            # whether it runs here or in the pool.
            workers=evaluator.map,
            updating="deferred",
            callback=generation_done,
        )
    if result.fun >= _IMPOSSIBLE:
        raise RuntimeError("the global search found no point where the posterior is non-zero; widen the priors")
    # Polish here, in this process (scipy's own polish would call the pool-only cost function).
    polished = minimize(
        _Cost(evaluator.search_posterior),
        result.x,
        method="L-BFGS-B",
        bounds=bounds,
        options={"maxfun": 30 * space.ndim},
    )
    best, best_cost = (polished.x, polished.fun) if polished.fun < result.fun else (result.x, result.fun)
    return result, best, best_cost, int(polished.nfev)


def _search_multistart(posterior, settings: SamplerSettings, rng: np.random.Generator, evaluator: _Evaluator):
    """Screen ``search_starts`` Sobol points of the priors on the coarse posterior (through the
    evaluator's map), then refine the ``search_polish`` best by Nelder-Mead in this process.

    Light-curve posteriors have many narrow modes (spin and precession phases): an evolving
    population contracts onto the best region it has seen early, and one started from
    thousands of independent points with local refinement keeps the separate candidates apart.

    Returns (best, best cost, evaluations, starts that reached within 1 of the best cost).
    """
    from scipy.stats import qmc  # scipy.stats costs ~0.3 s to import; only this start needs it

    space = posterior.space
    bounds = space.bounds
    low, width = bounds[:, 0], bounds[:, 1] - bounds[:, 0]
    points = low + width * qmc.Sobol(space.ndim, seed=int(rng.integers(2**31))).random(settings.search_starts)
    costs = np.array(list(evaluator.map(evaluator.cost, points)))
    if not np.any(costs < _IMPOSSIBLE):
        raise RuntimeError("the global search found no point where the posterior is non-zero; widen the priors")
    cost, wrapped_cost = _Cost(evaluator.search_posterior), _Cost(evaluator.search_posterior, wrap=True)
    evaluations = len(points)
    best, best_cost, reached = None, math.inf, []
    for start in points[np.argsort(costs)[: settings.search_polish]]:
        found = minimize(
            wrapped_cost,
            start,
            method="Nelder-Mead",
            options={"maxfev": settings.search_polish_evals, "xatol": 1e-4, "fatol": 1e-2, "adaptive": True},
        )
        evaluations += int(found.nfev)
        reached.append(float(found.fun))
        if found.fun < best_cost:
            best, best_cost = space.wrap(found.x), float(found.fun)
    polished = minimize(cost, best, method="L-BFGS-B", bounds=bounds, options={"maxfun": 30 * space.ndim})
    evaluations += int(polished.nfev)
    if polished.fun < best_cost:
        best, best_cost = polished.x, float(polished.fun)
    return best, best_cost, evaluations, sum(value <= best_cost + 1.0 for value in reached)


def init_from_multistart(
    posterior, settings: SamplerSettings, rng: np.random.Generator, evaluator: _Evaluator
) -> tuple[np.ndarray, dict]:
    """Walkers in a small ball around the best point of a multi-start search (`_search_multistart`)."""
    best, best_cost, search_evaluations, agreeing = _search_multistart(posterior, settings, rng, evaluator)
    positions, evaluations, settling = _walkers_around_settled(best, posterior, settings, rng, evaluator)
    return positions, {
        "method": "multistart",
        "evaluations": search_evaluations + evaluations,
        "search_best_log_prob": float(-best_cost),
        "search_best": best.tolist(),
        "search_starts_agreeing": int(agreeing),
        **settling,
    }


def _search_info(method, result, best, best_cost, evaluations) -> dict:
    return {
        "method": method,
        "evaluations": evaluations,
        "search_best_log_prob": float(-best_cost),
        "search_best": best.tolist(),
        "search_generations": int(result.nit),
        "search_stopped": "at half the time limit" if "callback" in str(getattr(result, "message", "")) else "",
    }


# The settling Nelder-Mead's first simplex: this fraction of each prior's width from the start
# (ten times the walkers' ball), and it stops when its points' log posteriors agree this well.
_SETTLE_STEP_FRACTION = 1e-2
_SETTLE_LOG_PROB_SPREAD = 0.1


def _settle(posterior, start: np.ndarray, evaluations: int) -> tuple[np.ndarray, float, float, int]:
    """`start` refined on `posterior` by a Nelder-Mead of at most `evaluations` evaluations (0:
    not refined); (the better point, its cost, the start's cost, evaluations made)."""
    space = posterior.space
    cost = _Cost(posterior, wrap=True)
    start_cost = cost(start)
    if evaluations == 0:
        return start, start_cost, start_cost, 1
    step = (space.bounds[:, 1] - space.bounds[:, 0]) * _SETTLE_STEP_FRACTION
    simplex = np.vstack([start, start + np.diag(step)])
    found = minimize(
        cost,
        start,
        method="Nelder-Mead",
        options={
            "maxfev": evaluations,
            "initial_simplex": _reflect_into(simplex, space.bounds, space.periods),
            "xatol": math.inf,
            "fatol": _SETTLE_LOG_PROB_SPREAD,
            "adaptive": True,
        },
    )
    if found.fun < start_cost:
        return space.wrap(found.x), float(found.fun), start_cost, int(found.nfev) + 1
    return start, start_cost, start_cost, int(found.nfev) + 1


# The free phases `_half_turns` turns by half a revolution (see ``SamplerSettings.half_turns``).
HALF_TURN_PHASES = ("spin_phase_deg", "precession_phase_deg")


def _half_turns(best: np.ndarray, space) -> list[tuple[tuple[str, ...], np.ndarray]]:
    """`best` turned half a revolution in each non-empty combination of its free phases named in
    `HALF_TURN_PHASES`; (the phases turned, the point) for each."""
    index = {name: i for i, name in enumerate(space.names)}
    phases = [name for name in HALF_TURN_PHASES if name in index]
    turned = []
    for count in range(1, len(phases) + 1):
        for combination in itertools.combinations(phases, count):
            theta = np.array(best, dtype=float)
            for name in combination:
                theta[index[name]] += 0.5 * space.periods[index[name]]
            turned.append((combination, space.wrap(theta)))
    return turned


def _settled(
    best: np.ndarray, posterior, settings: SamplerSettings, evaluator: _Evaluator
) -> tuple[np.ndarray, dict, int]:
    """The walkers' centre: the search's `best` refined on the full posterior when the search ran
    on a coarse one (``SamplerSettings.settle_evals``), or one of its half turns refined the same
    way if that is better (``SamplerSettings.half_turns``); the refinements run through the
    evaluator's map (in parallel in a pool). (centre, facts for the run's init record,
    evaluations of the full posterior)."""
    turned = _half_turns(best, posterior.space) if settings.half_turns else []
    settle_best = settings.settle_evals > 0 and evaluator.search_posterior is not posterior
    if not turned and not settle_best:
        return best, {}, 0
    jobs = [(best, settings.settle_evals if settle_best else 0)]
    jobs += [(theta, settings.settle_evals) for _, theta in turned]
    settled = list(evaluator.map(evaluator.settle, jobs))
    chosen = int(np.argmin([cost for _, cost, _, _ in settled]))
    centre, cost = settled[chosen][:2]
    evaluations = sum(count for *_, count in settled)
    info: dict = {}
    if settings.settle_evals > 0:
        start_cost = settled[0][2]
        info["settle_evaluations"] = evaluations
        # (None where the coarse best had no full posterior at all: any finite point is a gain.)
        info["settle_log_prob_gain"] = max(start_cost - cost, 0.0) if start_cost < _IMPOSSIBLE else None
    if turned:
        phases_turned = [(), *(phases for phases, _ in turned)]
        info["half_turns"] = [
            {"phases": list(phases), "log_prob": -found[1] if found[1] < _IMPOSSIBLE else None}
            for phases, found in zip(phases_turned, settled)
        ]
        info["half_turn_chosen"] = list(phases_turned[chosen])
    return centre, info, evaluations


def _walkers_around(
    best: np.ndarray, posterior, settings: SamplerSettings, rng: np.random.Generator, evaluator: _Evaluator
) -> tuple[np.ndarray, int]:
    """``n_walkers`` points in a ball of ``ball_fraction`` of each prior's width around `best`,
    each with a finite full posterior; (positions, evaluations)."""
    space = posterior.space
    bounds = space.bounds
    width = (bounds[:, 1] - bounds[:, 0]) * settings.ball_fraction

    def ball(k: int) -> np.ndarray:
        theta = best + width * rng.standard_normal((k, space.ndim))
        return _reflect_into(theta, bounds, space.periods)

    return _finite_or_redraw(evaluator, ball, settings.n_walkers, "around the search's best point")


def _walkers_around_settled(
    best: np.ndarray, posterior, settings: SamplerSettings, rng: np.random.Generator, evaluator: _Evaluator
) -> tuple[np.ndarray, int, dict]:
    """`_walkers_around` the search's best point once `_settled` on the full posterior;
    (positions, evaluations of both, the settling's facts for the init record)."""
    start, settling, settle_evaluations = _settled(best, posterior, settings, evaluator)
    positions, evaluations = _walkers_around(start, posterior, settings, rng, evaluator)
    return positions, evaluations + settle_evaluations, settling


def init_from_search(
    posterior, settings: SamplerSettings, rng: np.random.Generator, evaluator: _Evaluator
) -> tuple[np.ndarray, dict]:
    """Walkers in a small ball around the best point of a differential-evolution search.

    The search minimises ``evaluator.cost`` (minus the coarse search posterior) and polishes
    its best point with L-BFGS-B; that point is refined on the full posterior (`_settled`),
    and the ball is checked there.
    """
    result, best, best_cost, polish_evaluations = _search(posterior, settings, rng, evaluator)
    positions, evaluations, settling = _walkers_around_settled(best, posterior, settings, rng, evaluator)
    info = _search_info("search", result, best, best_cost, int(result.nfev) + polish_evaluations + evaluations)
    return positions, {**info, **settling}


def init_from_population(
    posterior, settings: SamplerSettings, rng: np.random.Generator, evaluator: _Evaluator
) -> tuple[np.ndarray, dict]:
    """Walkers at the polished best point and the best other members of the search's last population.

    Members whose posterior is zero are replaced by points in a small ball around the best.
    """
    space = posterior.space
    result, best, best_cost, polish_evaluations = _search(posterior, settings, rng, evaluator)
    order = np.argsort(result.population_energies)
    members = np.unique(result.population[order], axis=0, return_index=True)[1]
    chosen = result.population[order][np.sort(members)]
    # The polished best point may be a member itself (when polishing did not move it): two
    # walkers at one point make emcee's snooker move divide by their zero distance.
    chosen = chosen[~np.all(chosen == best[None, :], axis=1)][: settings.n_walkers - 1]
    positions = np.vstack([best[None, :], chosen])
    bounds = space.bounds
    width = (bounds[:, 1] - bounds[:, 0]) * settings.ball_fraction
    while positions.shape[0] < settings.n_walkers:
        positions = np.vstack(
            [positions, _reflect_into(best + width * rng.standard_normal(space.ndim), bounds, space.periods)[None, :]]
        )
    values = np.array(list(evaluator.map(evaluator.log_prob, positions)))
    bad = ~np.isfinite(values)
    evaluations = settings.n_walkers
    if bad.any():

        def ball(k: int) -> np.ndarray:
            return _reflect_into(best + width * rng.standard_normal((k, space.ndim)), bounds, space.periods)

        positions[bad], extra = _finite_or_redraw(evaluator, ball, int(bad.sum()), "around the search's best point")
        evaluations += extra
    return positions, _search_info(
        "population", result, best, best_cost, int(result.nfev) + polish_evaluations + evaluations
    )


INITIALISERS = {
    "prior": init_from_prior,
    "search": init_from_search,
    "multistart": init_from_multistart,
    "population": init_from_population,
}


# The differential-evolution step as a share of emcee's default 2.38 / sqrt(2 ndim), the optimum
# for a Gaussian posterior. The whole TOPEX pass's posterior is not one: 400 steps of 20 walkers
# from one settled start (6 parameters) gave acceptance 0.16, 0.23 and 0.33 at 1, 0.8 and 0.6,
# and the most movement per step at 0.8 (mean squared jump 0.51, 0.55, 0.47 posterior sigmas^2;
# autocorrelation times 23, 20, 21 steps, median of the parameters) (docs/fitting.md, "Moves").
DE_STEP_SHARE = 0.8


def _moves(name: str, ndim: int):
    if name == "de":
        step = DE_STEP_SHARE * 2.38 / np.sqrt(2.0 * ndim)
        return [(emcee.moves.DEMove(gamma0=step), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    return None  # emcee's default stretch move


MOVES = ("stretch", "de")


# -- chain file -------------------------------------------------------------------------
def _backup_path(chain_path: Path) -> Path:
    return chain_path.with_name(chain_path.name + ".bak")


def _atomic_copy(source: Path, target: Path) -> None:
    partial = target.with_name(target.name + ".partial")
    shutil.copyfile(source, partial)
    with open(partial, "rb") as handle:
        os.fsync(handle.fileno())
    os.replace(partial, target)


def _stored_iteration(chain_path: Path) -> int | None:
    """Steps stored in the chain file, or None when the file is unreadable."""
    try:
        with h5py.File(chain_path, "r") as handle:
            return int(handle[CHAIN_GROUP].attrs["iteration"])
    except (OSError, KeyError):
        return None


def _run_identity(posterior, settings: SamplerSettings) -> dict:
    """What must match for a stored chain to be continued by this run."""
    return {
        "names": list(posterior.space.names),
        "n_walkers": settings.n_walkers,
        "seed": settings.seed,
        "init": settings.init,
        "moves": settings.moves,
        "space": posterior.space.to_dict(),
    }


def _same_model(stored: Mapping, space: Mapping) -> bool:
    """Whether the parameter space ``space`` (``ParameterSpace.to_dict``) is the stored chain's
    ``stored`` with at most some parameters added since, each held fixed at the value the model
    had before it was a parameter (`rsodb.fit.parameters.FORMERLY_FIXED`): the same posterior."""
    if stored.get("free") != space.get("free"):
        return False
    before, now = stored.get("fixed", {}), space.get("fixed", {})
    if any(name not in now or now[name] != value for name, value in before.items()):
        return False
    return all(name in FORMERLY_FIXED and now[name] == FORMERLY_FIXED[name] for name in set(now) - set(before))


def _prepare_chain_file(chain_path: Path, identity: dict, restart: bool) -> int:
    """Make `chain_path` usable; return the number of steps it already holds."""
    backup = _backup_path(chain_path)
    if restart:
        for path in (chain_path, backup):
            path.unlink(missing_ok=True)
        return 0
    if not chain_path.exists():
        return 0
    stored = _stored_iteration(chain_path)
    if stored is None:
        if backup.exists() and _stored_iteration(backup) is not None:
            # A kill during an HDF5 write can leave the file unreadable: go back to the last copy.
            os.replace(backup, chain_path)
            _atomic_copy(chain_path, backup)
            stored = _stored_iteration(chain_path)
        else:
            chain_path.unlink()
            backup.unlink(missing_ok=True)
            return 0
    with h5py.File(chain_path, "r") as handle:
        previous = json.loads(handle.attrs.get("rsodb_run", "null"))
    if stored == 0 or previous is None:
        chain_path.unlink()
        return 0
    changed = sorted(k for k in identity if previous.get(k) != identity[k])
    if changed == ["space"] and _same_model(previous["space"], identity["space"]):
        changed = []
    if changed:
        raise ValueError(
            f"the chain in {chain_path} was started with different {', '.join(changed)}; "
            "run again with restart=True (--restart) to discard it, or restore the original settings"
        )
    return stored


def read_chain(chain_path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(chain (steps, walkers, ndim), log_prob (steps, walkers), acceptance (walkers,)) from a file."""
    backend = emcee.backends.HDFBackend(str(chain_path), name=CHAIN_GROUP, read_only=True)
    iteration = backend.iteration
    return backend.get_chain(), backend.get_log_prob(), backend.accepted / max(iteration, 1)


def convergence_check(chain: np.ndarray, previous_tau: np.ndarray | None = None) -> tuple[bool, int, np.ndarray]:
    """(converged, burn-in steps, tau per parameter) of a (steps, walkers, ndim) chain.

    The burn-in is `BURN_IN_TAUS` times the longest autocorrelation time (measured on the
    second half, never more than half the chain); tau is then measured after the burn-in.
    Converged when the kept chain is `CONVERGED_TAUS` times the longest tau on every parameter
    and, given `previous_tau`, no tau moved by more than 10% since.
    """
    steps = chain.shape[0]
    first = autocorr_time(chain[steps // 2 :])
    longest = float(np.nanmax(first)) if np.any(np.isfinite(first)) else math.inf
    burn = int(min(steps // 2, math.ceil(BURN_IN_TAUS * longest))) if math.isfinite(longest) else steps // 2
    tau = autocorr_time(chain[burn:])
    if not np.all(np.isfinite(tau)):
        return False, burn, tau
    converged = steps - burn >= CONVERGED_TAUS * float(np.max(tau))
    if previous_tau is not None and np.all(np.isfinite(previous_tau)):
        converged &= bool(np.all(np.abs(tau - previous_tau) <= _STEADY * tau))
    return bool(converged), burn, tau


# -- the entry point ------------------------------------------------------------------------
def run_sampler(
    posterior,
    settings: SamplerSettings,
    chain_path: str | Path,
    *,
    restart: bool = False,
    progress: bool = True,
    description: str = "sampling",
    search_posterior=None,
) -> ChainRun:
    """Run (or resume) emcee on `posterior`, storing the chain in `chain_path`.

    Parameters
    ----------
    posterior : Posterior
        Picklable callable ``theta (ndim,) -> float`` with a ``space``.
    settings : SamplerSettings
        Walkers, steps, initialisation, processes and seed.
    chain_path : str or Path
        The HDFBackend file. When it already holds steps of a run with the same parameters,
        walkers and seed, sampling continues from its last step up to ``settings.n_steps``.
    restart : bool
        Discard any stored chain and start again.
    progress : bool
        Show a progress bar.
    description : str
        Label of the progress bar.
    search_posterior : Posterior, optional
        A cheaper posterior over the same parameters for the global search (default:
        `posterior` itself).

    Returns
    -------
    ChainRun
    """
    space = posterior.space
    if settings.n_walkers < 2 * space.ndim:
        raise ValueError(
            f"n_walkers={settings.n_walkers} is fewer than twice the {space.ndim} free parameters; "
            f"use at least {2 * space.ndim} walkers"
        )
    chain_path = Path(chain_path)
    chain_path.parent.mkdir(parents=True, exist_ok=True)
    identity = _run_identity(posterior, settings)
    started = time.perf_counter()
    stored = _prepare_chain_file(chain_path, identity, restart)
    remaining = max(settings.n_steps - stored, 0)
    init_info: dict = {"method": "resumed" if stored else settings.init}
    stopped, burn_in = "", None

    backend = emcee.backends.HDFBackend(str(chain_path), name=CHAIN_GROUP)
    search_posterior = posterior if search_posterior is None else search_posterior
    if search_posterior.space.names != space.names:
        raise ValueError("the search posterior must have the same free parameters as the posterior")
    pool = _open_pool(posterior, search_posterior, settings.n_processes) if remaining else None
    try:
        # The global search may take half of the time limit; sampling stops at the whole of it.
        deadline = started + 0.5 * settings.time_limit_s if settings.time_limit_s else None
        evaluator = _Evaluator(posterior, search_posterior, pool, deadline, progress)
        if stored == 0:
            rng = np.random.default_rng(settings.seed)
            positions, init_info = INITIALISERS[settings.init](posterior, settings, rng, evaluator)
            backend.reset(settings.n_walkers, space.ndim)
            with h5py.File(chain_path, "a") as handle:
                handle.attrs["rsodb_run"] = json.dumps(identity)
                handle.attrs["rsodb_init"] = json.dumps(init_info)
            start = emcee.State(positions, random_state=np.random.RandomState(settings.seed).get_state())
        else:
            with h5py.File(chain_path, "r") as handle:
                init_info = dict(json.loads(handle.attrs.get("rsodb_init", "{}")), resumed_at=stored)
            start = None  # continue from the backend's last step and random state
        if remaining:
            sampler = emcee.EnsembleSampler(
                settings.n_walkers,
                space.ndim,
                evaluator.log_prob,
                pool=pool,
                backend=backend,
                moves=_moves(settings.moves, space.ndim),
            )
            start = start if start is not None else backend.get_last_sample()
            stopped, burn_in, steps_done = _sample(
                sampler, start, remaining, stored, settings, chain_path, started, description, progress
            )
            remaining = steps_done
        elif settings.until_converged:
            converged, burn_in, _ = convergence_check(backend.get_chain())
            stopped = "" if converged else f"the step limit ({settings.n_steps}) was already reached"
    finally:
        if pool is not None:
            pool.close()
    elapsed = time.perf_counter() - started

    chain, log_prob, acceptance = read_chain(chain_path)
    return ChainRun(
        space.names,
        chain,
        log_prob,
        acceptance,
        autocorr_time(chain),
        stored,
        remaining,
        elapsed,
        init_info,
        str(chain_path),
        stopped,
        burn_in,
    )


def _sample(sampler, start, remaining, stored, settings, chain_path, started, description, progress):
    """Take up to `remaining` steps; (why it stopped, burn-in or None, steps taken)."""
    stopped, burn_in, previous_tau, taken = "", None, None, 0
    with tqdm(
        total=settings.n_steps, initial=stored, desc=description, unit="step", disable=not progress, leave=False
    ) as bar:
        for i, _ in enumerate(sampler.sample(start, iterations=remaining), start=stored + 1):
            bar.update(1)
            taken += 1
            if i % settings.checkpoint_every == 0 or i == settings.n_steps:
                _atomic_copy(chain_path, _backup_path(chain_path))
            if settings.until_converged and i % settings.check_every == 0:
                converged, burn_in, tau = convergence_check(sampler.get_chain(), previous_tau)
                previous_tau = tau
                if converged:
                    _atomic_copy(chain_path, _backup_path(chain_path))
                    stopped = (
                        f"{STOPPED_LONG_ENOUGH} after {i} steps: {i - burn_in} steps after a burn-in of {burn_in} are "
                        f"{(i - burn_in) / np.max(tau):.0f} autocorrelation times (tau up to {np.max(tau):.0f} steps)"
                    )
                    break
            if settings.time_limit_s and time.perf_counter() - started >= settings.time_limit_s:
                _atomic_copy(chain_path, _backup_path(chain_path))
                stopped = f"stopped at the time limit of {settings.time_limit_s:.0f} s after {i} steps"
                break
    if settings.until_converged and not stopped.startswith(STOPPED_LONG_ENOUGH):
        _, burn_in, _ = convergence_check(sampler.get_chain())
        stopped = stopped or f"stopped at the step limit of {settings.n_steps} steps before converging"
    return stopped, burn_in, taken


def autocorr_time(chain):
    """(ndim,) integrated autocorrelation time per parameter of a (steps, walkers, ndim) chain.

    emcee's estimate (``tol=0``) over the walkers that moved in that parameter: a walker that
    never accepted a step has no autocorrelation (emcee would divide by its zero variance and
    return NaN for the whole parameter). NaN where no walker moved or the chain has one step.
    """
    steps, _, ndim = chain.shape
    tau = np.full(ndim, np.nan)
    if steps < 2:
        return tau
    for d in range(ndim):
        moved = np.ptp(chain[:, :, d], axis=0) > 0.0
        if moved.any():
            tau[d] = integrated_time(chain[:, moved, d : d + 1], tol=0)[0]
    return tau
