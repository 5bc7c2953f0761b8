"""Informative trajectory generation (the paper's "Generation of Informative Trajectories").

1. Fly the task M times in a batched closed-loop simulation: nominal rigid body,
   the model-based controller (PID + inversion of the model's mean), and as
   "truth" the nominal dynamics plus one consistent GP posterior function sample
   per simulation (:class:`~omavctl.planning.gp.PathwiseSamples`). epsilon defaults
   to the mean distance between commanded and achieved input (the paper's heuristic).
2. Propose K deviation coefficient sets (:mod:`~omavctl.planning.candidates`):
   all at once at random, or generation by generation with the cross-entropy
   method (:mod:`~omavctl.planning.search`).
3. Simulate every candidate M times, all K*M simulations in one batch per time
   step (:mod:`~omavctl.planning.batched`; the task flies in the same batch);
   reject those that break allocation limits, attitude limits or diverge. The
   attitude limit is ``max_tilt_deg`` or the task's largest tilt plus
   ``tilt_margin_deg`` (10 deg for the variance objective), the lower: a refit on a
   flight that tilts 20 deg or more beyond the task got worse on it (docs/informative.md).
   The S test points the variance is integrated over (``region``): ``"pool"``
   (default) S medoids of the GP inputs of the task's and the first generation's
   feasible candidates' simulations (:func:`pool_test_points`):
   the region the task and its deviations reach, which the model must know for
   the flights the user flies next; ``"task"`` (the paper) S points uniform in
   the epsilon-balls around the task's own inputs. With ``"task"`` the cost
   favours flights that hug the task: on the informative-flight benchmark it
   ranked the flown candidates against the error their refit removed on held-out
   flights of the region (docs/informative.md).
4. Score the feasible ones with the objective (:mod:`~omavctl.planning.scoring`):
   for each simulation the points ``fit`` would add, and the posterior variance
   at the test points given prior data + those points by a rank update.
5. Cost = mean over the M simulations; lowest wins.

Random streams: the posterior samples, the test points and the candidates
each draw from their own child of ``SeedSequence(seed)``, so the fast and the
reference path (``fast=False``) see the same samples, test points and candidates.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.errors import OmavctlError
from omavctl.planning.candidates import (
    deviated_references,
    sample_coefficients,
    yaw_deviation_deg,
)
from omavctl.planning.gp import GPAxes, PathwiseSamples
from omavctl.planning.rollout import REASONS, Progress
from omavctl.planning.scoring import Flights, Objective, VarianceObjective
from omavctl.planning.search import MIN_GENERATION, CrossEntropy, generation_sizes
from omavctl.planning.simulate import Batch, Simulator
from omavctl.planning.workers import available_cores, run_tasks
from omavctl.sim.trajectory import Trajectory

__all__ = ["OBJECTIVES", "TILT_MARGIN_DEG", "PlanResult", "PlanSettings", "plan", "tilt_limit"]


#: Default ``PlanSettings.tilt_margin_deg``: chosen on the informative-flight
#: benchmark's seeds 1-4 (docs/informative.md), where flights tilting 5-10 deg beyond
#: the task removed the most region error and those 20+ deg beyond raised the task's
TILT_MARGIN_DEG = 10.0


def task_tilt_deg(task: Trajectory) -> float:
    """The task reference's largest |roll| or |pitch|, deg."""
    return float(np.rad2deg(np.abs(task.euler[:, :2]).max()))


def tilt_limit(task: Trajectory, settings: PlanSettings) -> float:
    """The attitude limit the candidates' simulations are held to (deg): ``--max-tilt``,
    or the task's largest tilt plus ``--tilt-margin`` when that is lower (by default
    TILT_MARGIN_DEG for the variance objective; the effects objective's parameters are
    global, so it is held to ``--max-tilt`` alone)."""
    margin = settings.tilt_margin_deg
    if margin is None:
        margin = TILT_MARGIN_DEG if settings.objective == "variance" else 90.0
    return min(settings.max_tilt_deg, task_tilt_deg(task) + margin)


@dataclass(frozen=True)
class PlanSettings:
    """Options of :func:`plan` (CLI flags of ``omavctl plan``)."""

    candidates: int = 20
    sims: int = 8
    frequencies: int = 2
    min_freq: float = 0.1  # Hz
    max_freq: float = 2.0  # Hz
    amplitude: float = 1.0  # rad/s^2
    epsilon: float | None = None  # normalised input units; None: paper's heuristic
    test_points: int = 500
    region: str = "pool"  # test points over the pool's states; "task": the paper's balls
    points: int = 40
    seed: int = 0
    rff_features: int = 128  # per axis; ranks candidates as 256 do (docs/planning-performance.md)
    max_tilt_deg: float = 80.0  # attitude limit on roll and pitch
    #: and at most this far beyond the task's largest reference tilt (deg;
    #: :func:`tilt_limit`; None: TILT_MARGIN_DEG for the variance objective, whose
    #: refit further tilts hurt on the task (docs/informative.md), none for effects)
    tilt_margin_deg: float | None = None
    #: candidates turn at most this far from the task's reference yaw (deg, known before
    #: simulating: :func:`~omavctl.planning.candidates.yaw_deviation_deg`; others are
    #: redrawn); None: no limit (docs/informative.md, session 15)
    yaw_margin_deg: float | None = None
    max_error_deg: float = 30.0  # attitude error beyond which a simulation diverged
    stride: int = 4  # points are picked among every stride-th simulated sample
    search: str = "random"  # or "cem"
    generations: int = 8  # cem: generations the candidates are spent in
    selection: str = "batched"  # or "kmedoids" (per simulation, as fit)
    objective: str = "variance"  # or "effects" (omavctl.planning.effects_objective)
    effects: tuple[str, ...] = ()  # effects objective: () = the model's fitted effects
    fast: bool = True  # False: the straightforward reference path
    jobs: int = 0  # worker processes; 0: one per usable core (results do not depend on it)


def _variance_objective(model, gp: GPAxes, test: np.ndarray, settings: PlanSettings) -> Objective:
    return VarianceObjective(gp, test, settings.points, settings.selection, settings.seed)


def _effects_objective(model, gp: GPAxes, test: np.ndarray, settings: PlanSettings) -> Objective:
    from omavctl.planning.effects_objective import EffectsObjective, resolve_effects

    names = resolve_effects(model, settings.effects)
    return EffectsObjective(model, gp, names, settings.points, settings.stride)


#: Objectives by name: (model, model GPs, test points, settings) -> objective. Every
#: objective that can be built for the model is computed; ``settings.objective`` ranks.
OBJECTIVES = {"variance": _variance_objective, "effects": _effects_objective}


#: Pool states the medoids of :func:`pool_test_points` are picked among (a seeded
#: subsample): many per test point (40 for 500), cheap beside the simulations
POOL_STATES = 20000

#: Where the variance objective's test points come from (``PlanSettings.region``)
REGIONS = ("pool", "task")


def pool_test_points(states: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """count test points (count, d) among states (n, d) (fewer if n is smaller): medoids
    of a seeded subsample of POOL_STATES states after two alternating k-medoids steps
    from a random start (:func:`~omavctl.planning.scoring.batched_picks`). They follow
    the states' distribution, as a random sample would, but each stands for its
    neighbourhood: states lie closer to their nearest test point (by about 5-10 % on
    a two-cluster example, ``tests/test_plan_region.py``)."""
    return _medoids(states[rng.permutation(states.shape[0])[:POOL_STATES]], count)


def _medoids(sub: np.ndarray, count: int) -> np.ndarray:
    from omavctl.planning.scoring import batched_picks

    return batched_picks(np.asarray(sub, float)[None], min(count, sub.shape[0]))[0]


def pool_subsample(
    task_states: np.ndarray, pool: np.ndarray, rows: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """The states :func:`pool_test_points` would draw from ``concatenate([task_states,
    pool[rows].reshape(-1, d)])`` with the same rng, without building that array (1000
    candidates x 8 simulations hold about 5 million states): task_states (n, d), pool
    (K, M, Ts, d), rows (k,) candidate indices -> (min(n_all, POOL_STATES), d) float."""
    n_task, (_, m, ts, d) = task_states.shape[0], pool.shape
    pick = rng.permutation(n_task + rows.size * m * ts)[:POOL_STATES]
    out = np.empty((pick.size, d))
    first = pick < n_task
    out[first] = task_states[pick[first]]
    k, sim, t = np.unravel_index(pick[~first] - n_task, (rows.size, m, ts))
    out[~first] = pool[rows[k], sim, t]
    return out


def _test_points(
    visited: np.ndarray, epsilon: float, count: int, rng: np.random.Generator
) -> np.ndarray:
    """count points uniform in epsilon-balls around rows of visited (n, d)."""
    n, d = visited.shape
    centre = visited[rng.integers(0, n, size=count)]
    direction = rng.standard_normal((count, d))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = epsilon * rng.uniform(size=(count, 1)) ** (1.0 / d)
    return centre + radius * direction


@dataclass
class PlanResult:
    """Outcome of :func:`plan`.

    coefficients (K, 3, P, 2); cost (K,) mean posterior variance ((rad/s^2)^2),
    inf when infeasible; feasible (K,); reason (K,); tracking (K,) mean absolute
    tracking error in the simulations (rad/s^2); generation (K,) in which the
    candidate was proposed (0 for random search); best index (-1 if none is
    feasible); task_cost the cost of flying the task itself; epsilon used;
    prior_variance the mean variance of the model's band at the test points before
    any flight (:meth:`GPAxes.band_variance`); task the task; region where the test
    points are (``PlanSettings.region``).
    """

    coefficients: np.ndarray
    cost: np.ndarray
    feasible: np.ndarray
    reason: list[str]
    tracking: np.ndarray
    generation: np.ndarray
    best: int
    task_cost: float
    epsilon: float
    prior_variance: float
    test_points: np.ndarray
    task: Trajectory
    notes: list[str] = field(default_factory=list)
    #: every computed objective's numbers per candidate, (K, ...) means over the M
    #: simulations (inf/nan where infeasible): "variance", "effects", "effects_rel_se",
    #: "effects_correlation", "effects_se" (K, p); and the task's own, (...)
    metrics: dict[str, np.ndarray] = field(default_factory=dict)
    task_metrics: dict[str, np.ndarray] = field(default_factory=dict)
    objective: str = "variance"
    region: str = "pool"
    #: the effects objective's prior (names, values, scale, information), when computed
    effects: Any = None
    #: the attitude limit the candidates were held to (deg, :func:`tilt_limit`)
    max_tilt_deg: float = 80.0
    #: whether that limit is the task's tilt plus the margin (not ``--max-tilt``)
    tilt_by_margin: bool = False

    def versus_task(self, cost: float) -> float:
        """A cost against the task's, percent: for ``variance`` the ratio of posterior
        variances; for ``effects`` the ratio of the geometric-mean standard errors
        (``exp((cost - task) / 2p)``, p parameters), minus one."""
        if self.objective == "effects" and self.effects is not None:
            p = self.effects.values.size
            return 100.0 * (math.exp((cost - self.task_cost) / (2 * p)) - 1.0)
        return 100.0 * (cost / self.task_cost - 1.0) if self.task_cost else 0.0

    def best_trajectory(self, task: str | Path | None = None) -> Trajectory:
        """The chosen reference; ``task`` (the task file) is named when none is feasible."""
        if self.best < 0:
            raise OmavctlError(
                "no feasible candidate for this task: lower --amplitude or --max-freq", task
            )
        return Trajectory(
            deviated_references(self.task, self.coefficients[self.best : self.best + 1])[0]
        )


def _metrics(objectives: dict[str, Objective], flights: Flights) -> dict[str, np.ndarray]:
    """Every objective's numbers (K, ...) for flights, means over the M simulations."""
    out: dict[str, np.ndarray] = {}
    for name, objective in objectives.items():
        more = getattr(objective, "metrics", None)
        values = more(flights) if more is not None else {name: objective(flights)}
        out.update({key: v.mean(axis=1) for key, v in values.items()})
    return out


#: Candidates per scoring task: the same pieces for every ``--jobs``, so that the
#: scores do not depend on it (an objective's arithmetic may depend on its batch)
SCORE_CHUNK = 32


def _score(
    objectives: dict[str, Objective],
    batch: Batch,
    jobs: int = 1,
    progress: Progress | None = None,
    label: str = "scoring",
) -> tuple[dict[str, np.ndarray], np.ndarray, list[str]]:
    """Metrics (K, ...) (cost inf, others nan unless every simulation is feasible),
    feasible (K,), reasons (K,); pieces of SCORE_CHUNK candidates over ``jobs``
    processes."""
    feasible = (batch.code == 0).all(axis=1)
    pieces = [slice(lo, lo + SCORE_CHUNK) for lo in range(0, feasible.size, SCORE_CHUNK)]

    def piece(i: int, report: Callable[[float], None]) -> dict[str, np.ndarray]:
        return _score_piece(objectives, batch, feasible, pieces[i])

    metrics = _concat(run_tasks(piece, len(pieces), jobs, progress, label))
    reasons = [", ".join(sorted({REASONS[c] for c in row if c})) for row in batch.code]
    return metrics, feasible, reasons


def _score_piece(
    objectives: dict[str, Objective], batch: Batch, feasible: np.ndarray, part: slice
) -> dict[str, np.ndarray]:
    """Metrics of the candidates ``part`` (see :func:`_score`)."""
    ok = feasible[part]
    if not ok.any():
        return {key: np.full(ok.size, np.inf) for key in objectives}
    flights = Flights(batch.inputs[part][ok], batch.tracking[part][ok], batch.code[part][ok] == 0)
    metrics: dict[str, np.ndarray] = {}
    for key, v in _metrics(objectives, flights).items():
        metrics[key] = np.full((ok.size, *v.shape[1:]), np.inf if key in OBJECTIVES else np.nan)
        metrics[key][ok] = v
    return metrics


def _objectives(model, gp: GPAxes, test: np.ndarray, settings: PlanSettings) -> dict:
    """The chosen objective first, then every other one that can be built for the model
    (an effects objective without effects to plan for is left out)."""
    out = {settings.objective: OBJECTIVES[settings.objective](model, gp, test, settings)}
    for name, factory in OBJECTIVES.items():
        if name not in out:
            try:
                out[name] = factory(model, gp, test, settings)
            except OmavctlError:
                continue
    return out


def _concat(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Metrics of the generations joined; a generation with none feasible lacks extras."""
    keys = max(parts, key=len).keys()
    out = {}
    for key in keys:
        have = [p[key] for p in parts if key in p]
        width = have[0].shape[1:]
        out[key] = np.concatenate(
            [p[key] if key in p else np.full((len(next(iter(p.values()))), *width), np.nan)
             for p in parts]
        )  # fmt: skip
    return out


def _task_region(
    model_gp: GPAxes, batch: Batch, settings: PlanSettings, rng: np.random.Generator
) -> tuple[np.ndarray, float]:
    """Test points (S, d) and epsilon from the task's (and, for the ``pool`` region, the
    feasible candidates') simulations."""
    assert batch.task_inputs is not None and batch.task_gap is not None
    visited = batch.task_inputs.reshape(-1, model_gp.d)
    epsilon = batch.task_gap if settings.epsilon is None else settings.epsilon
    if not epsilon > 0:
        raise OmavctlError("--epsilon must be > 0 (the model predicts no residual at all)")
    if settings.region == "task":
        return _test_points(visited, epsilon, settings.test_points, rng), float(epsilon)
    rows = np.flatnonzero((batch.code == 0).all(axis=1))
    sub = pool_subsample(visited[:: settings.stride], batch.inputs, rows, rng)
    return _medoids(sub, settings.test_points), float(epsilon)


def _check(model, settings: PlanSettings) -> None:
    if settings.search not in ("random", "cem"):
        raise OmavctlError(f"unknown --search '{settings.search}' (random or cem)")
    if settings.region not in REGIONS:
        raise OmavctlError(f"unknown --region '{settings.region}' (pool or task)")
    if settings.objective not in OBJECTIVES:
        known = ", ".join(OBJECTIVES)
        raise OmavctlError(f"unknown --objective '{settings.objective}' (known: {known})")
    if settings.objective == "effects":  # before the simulations: bad effects fail fast
        from omavctl.planning.effects_objective import resolve_effects

        resolve_effects(model, settings.effects)


#: Draws of --yaw-margin's redrawing before it gives up (each of the missing count)
YAW_DRAWS = 200


def _within_yaw(task: Trajectory, margin: float | None, draw: Callable[[int], np.ndarray]):
    """``draw`` with the candidates that turn beyond ``margin`` from the task's yaw
    redrawn (``draw(n)`` -> (n, 3, P, 2)); ``draw`` itself when there is no margin."""
    if margin is None:
        return draw

    def redrawn(n: int) -> np.ndarray:
        kept: list[np.ndarray] = []
        for _ in range(YAW_DRAWS):
            c = draw(n)
            kept.append(c[yaw_deviation_deg(task, c) <= margin])
            if sum(len(k) for k in kept) >= n:
                return np.concatenate(kept)[:n]
        raise OmavctlError(
            f"--yaw-margin {margin:g}: too few candidates turn less than that from the "
            "task's yaw: raise it or lower --amplitude"
        )

    return redrawn


def _proposer(settings: PlanSettings, rng: np.random.Generator, task: Trajectory):
    """Generation sizes and ``propose(n, coeffs so far, costs so far)`` -> (n, 3, P, 2)."""
    s = settings
    bounds = (s.frequencies, s.min_freq, s.max_freq, s.amplitude)
    sizes = [s.candidates]
    if s.search == "cem":
        sizes = generation_sizes(s.candidates, s.generations)
    cem = CrossEntropy.for_bounds(*bounds)

    def propose(n: int, coeffs: list[np.ndarray], costs: list[np.ndarray]) -> np.ndarray:
        if coeffs:
            cem.update(np.concatenate(coeffs), np.concatenate(costs))
        return _within_yaw(task, s.yaw_margin_deg, draw)(n)

    def draw(n: int) -> np.ndarray:
        if cem.centres is None:  # first generation, or nothing feasible yet: uniform
            return sample_coefficients(rng, n, *bounds)
        return cem.sample(rng, n, (3, s.frequencies, 2))

    return sizes, propose


def plan(
    model,
    task: Trajectory,
    settings: PlanSettings,
    progress: Progress | None = None,
) -> PlanResult:
    """Propose, simulate and score candidate references (see module docstring)."""
    _check(model, settings)
    seeds = np.random.SeedSequence(settings.seed).spawn(3)
    rng_gp, rng_test, rng_cand = (np.random.default_rng(s) for s in seeds)
    gp = GPAxes.from_model(model)
    samples = PathwiseSamples(gp, settings.sims, rng_gp, settings.rff_features)
    limits = (tilt_limit(task, settings), settings.max_error_deg)
    jobs = settings.jobs or available_cores()
    sim = Simulator(model, samples, task, settings.stride, limits, settings.fast, jobs, progress)
    sizes, propose = _proposer(settings, rng_cand, task)
    coeffs: list[np.ndarray] = []
    parts: list[tuple[dict[str, np.ndarray], np.ndarray, list[str], np.ndarray]] = []
    objectives: dict[str, Objective] = {}
    for g, size in enumerate(sizes):
        coeffs.append(propose(size, coeffs, [p[0][settings.objective] for p in parts]))
        label = "simulating" if g == 0 else f"generation {g + 1}/{len(sizes)}"
        batch = sim(coeffs[-1], with_task=g == 0, label=label)
        if not objectives:
            test, epsilon = _task_region(gp, batch, settings, rng_test)
            objectives = _objectives(model, gp, test, settings)
            task_metrics, notes = _task_cost(objectives, batch, settings)
        scoring = "scoring" if len(sizes) == 1 else f"scoring {g + 1}/{len(sizes)}"
        scored = _score(objectives, batch, jobs, progress, scoring)
        parts.append((*scored, batch.tracking.mean(axis=1)))
    metrics = _concat([p[0] for p in parts])
    cost = metrics[settings.objective]
    feasible = np.concatenate([p[1] for p in parts])
    return PlanResult(
        coefficients=np.concatenate(coeffs),
        cost=cost,
        feasible=feasible,
        reason=[r for p in parts for r in p[2]],
        tracking=np.concatenate([p[3] for p in parts]),
        generation=np.repeat(np.arange(len(sizes)), sizes),
        best=int(np.argmin(cost)) if feasible.any() else -1,
        task_cost=float(task_metrics[settings.objective]),
        epsilon=epsilon,
        prior_variance=float(gp.band_variance(test).mean()),
        test_points=test,
        task=task,
        notes=notes + _search_notes(settings, sizes),
        metrics=metrics,
        task_metrics=task_metrics,
        objective=settings.objective,
        region=settings.region,
        effects=getattr(objectives.get("effects"), "prior", None),
        max_tilt_deg=limits[0],
        tilt_by_margin=limits[0] < settings.max_tilt_deg,
    )


def _search_notes(settings: PlanSettings, sizes: list[int]) -> list[str]:
    """A note when --search cem had too few candidates for a second generation."""
    if settings.search != "cem" or len(sizes) > 1:
        return []
    return [
        f"--search cem needs at least {2 * MIN_GENERATION} candidates for two generations "
        f"of {MIN_GENERATION}: these {settings.candidates} were sampled at random"
    ]


def _task_cost(
    objectives: dict[str, Objective], batch: Batch, settings: PlanSettings
) -> tuple[dict[str, np.ndarray], list[str]]:
    """The task's own metrics (its M simulations scored like a candidate) and notes."""
    assert batch.task_inputs is not None and batch.task_code is not None
    m = settings.sims
    flights = Flights(
        batch.task_inputs[None, :, :: settings.stride], np.zeros((1, m)), batch.task_code[None] == 0
    )
    notes = []
    if batch.task_code.any():
        why = sorted({REASONS[c] for c in batch.task_code if c})
        notes.append("the task itself breaks limits in simulation: " + ", ".join(why))
    return {k: v[0] for k, v in _metrics(objectives, flights).items()}, notes
