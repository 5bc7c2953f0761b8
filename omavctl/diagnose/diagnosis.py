"""The ``diagnosis`` of an evaluation: what the model misses, in physical terms.

Every registered effect not in the model is scored against the model's
remaining error (:func:`omavctl.diagnose.scoring.score_effects`); the best
missing one is accepted, what it explains removed and the others rescored
(forward selection, up to 3). Structure left after that (correlation with
an input or state feature, a spectral peak) is reported as unexplained. The
same ranking on the nominal residual says what the GP (with the effects) has
learned, in physical terms; each learned effect's ``estimate`` is made as
``fit --effects`` would make it (:mod:`omavctl.diagnose.estimates`), so that the
two agree. :func:`fit_command` is the command that adds the top missing effect.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from omavctl.diagnose.actuators import actuator_fits, with_actuators
from omavctl.diagnose.claims import (
    LARGE_CUT_KEYS,
    Guarded,
    claimed_axes,
    excludes_null,
    learned_claim,
)
from omavctl.diagnose.estimates import ESTIMATE_METHOD, SecondStage, fit_estimates
from omavctl.diagnose.fit_flight_check import checked_on_fit_flight
from omavctl.diagnose.held_beside import held_timing_beside
from omavctl.diagnose.joint import JointStep, joint_selection
from omavctl.diagnose.learned_alikes import learned_look_alikes
from omavctl.diagnose.learned_beside import learned_beside_look_alikes
from omavctl.diagnose.learned_fit_pinned import learned_fit_pinned
from omavctl.diagnose.logread import FitFlight
from omavctl.diagnose.metrics import AXES
from omavctl.diagnose.scoring import (
    BLOCK_SECONDS,
    MIN_EXPLAINED,
    MIN_NOISE_RATIO,
    MIN_T,
    EffectScore,
    score_effects,
    time_blocks,
)
from omavctl.diagnose.selection import lag_checked, select_guarded
from omavctl.diagnose.timing_beside import timing_beside_look_alikes
from omavctl.learn.band import growth_variance
from omavctl.learn.model import ResidualGP
from omavctl.learn.signal import ResidualSamples, SavitzkyGolay
from omavctl.physics.effects import EFFECTS, get_effect

__all__ = [
    "BLOCK_SECONDS",
    "diagnose",
    "measurement_noise",
    "unexplained_structure",
    "weight_std",
]


#: How the diagnosis decides (the evaluation JSON's ``diagnosis.method``, with the
#: claim floor and the log's noise).
METHOD: dict[str, Any] = {
    "split": f"alternate {BLOCK_SECONDS:g} s blocks: fit on even, score on odd",
    "standard_errors": "delete-one-block jackknife",
    "min_explained_variance": MIN_EXPLAINED,
    "min_t_value": MIN_T,
    "refit": "parameters fitted to the model's own training points as fit --effects "
    "would (GP hyperparameters kept); a missing effect must lower the error with them",
    "parameter_bounds": "bounded least squares within THETA_RANGE (plausible values); the "
    "joint selection's first pass and a lag's partner in the held-out profile are held to "
    "the bounds that are the effect's null (a drag, a lag, an interference is not negative)",
    "selection": "forward: best missing effect removed, others rescored, up to 3; "
    "with the effects that, estimated jointly from the model's training points as fit "
    "--effects would, lower the physics-only error on the held-out flight (joint; the "
    "default imperfections' look-alikes take no slot of its cap, and what they leave is "
    "the yardstick of a further effect; a step's part is judged against the claim floor by "
    "the upper end of its 95 % interval; with no lag or delay taken, each is judged beside "
    "the look-alikes refitted on the held-out flight, and with only look-alikes taken, any "
    "other effect too)",
    "claim_guard": "a claim is kept only where the 95 % interval of its estimate as the fit "
    "command makes it excludes the effect's null on an axis it is claimed on, and, claimed by "
    "the joint selection alone, where its estimate on the fit flight (least squares at the "
    "model's training points, with the other claims) excludes it too (not_pinned); when "
    "two claims or more are held back together, only the last-ranked of them is, and the "
    "others are guarded again without it; a lag or delay held back gives way to the next "
    "lag or delay that passed its joint step",
    "timing_pair": "with no lag or delay claimed nor in the model, each lag or delay and "
    "each pair of them is profiled over its time constants with its exact form on the "
    "held-out physics-only error (the look-alikes refitted at each value); a pair is "
    "claimed when each member passes, beside the other, the bars of a single claim (15 % "
    "share, part at the claim floor, Newey-West t, at least one sample period), else the "
    "best single one on the same bars; a pair may also be a lag or delay with an effect "
    "linear in its parameters (least squares with the look-alikes at each value, in its "
    "plausible range: timing_claims); the claims guard then estimates them as the fit "
    "command does",
    "learned_claim": "with nothing missing, an effect the GP learned is claimed when its "
    "interval excludes its null and, estimated from the training points by least squares, "
    "it passes the joint test on the held-out physics-only error, or fails only its "
    "per-block t and removes at least half of that error by a consistent fraction in every "
    "block (large cut); the large cut is first judged on what the default imperfections' "
    "look-alikes leave at their least-squares fit on the held-out flight, for an effect "
    "that is not one of them (learned_claims)",
    "learned_estimate": ESTIMATE_METHOD,
}


def unexplained_structure(
    residual: np.ndarray, features: dict[str, np.ndarray], dt: float, min_corr: float = 0.3
) -> list[dict[str, Any]]:
    """Structure in a residual (n, 3) that remains: feature correlations and spectral peaks.

    features: name -> (n,) values. A correlation counts when |r| >= min_corr;
    a spectral peak when a Welch periodogram bin above 0.2 Hz holds more than
    10x the median power and more than 10% of the total.
    """
    from scipy.signal import welch

    out: list[dict[str, Any]] = []
    for i, axis in enumerate(AXES):
        r = residual[:, i]
        if r.std() == 0:
            continue
        for name, f in features.items():
            if f.std() == 0:
                continue
            c = float(np.corrcoef(r, f)[0, 1])
            if abs(c) >= min_corr:
                out.append(
                    {"kind": "feature correlation", "axis": axis, "feature": name, "correlation": c}
                )
        nper = min(r.size, 512)
        if nper >= 64:
            freq, power = welch(r - r.mean(), fs=1.0 / dt, nperseg=nper)
            keep = freq > 0.2
            if keep.any():
                j = int(np.argmax(np.where(keep, power, -np.inf)))
                ratio = float(power[j] / max(np.median(power[keep]), 1e-300))
                share = float(power[j] / max(power.sum(), 1e-300))
                if ratio > 10 and share > 0.1:
                    out.append(
                        {
                            "kind": "spectral peak",
                            "axis": axis,
                            "frequency_hz": float(freq[j]),
                            "power_ratio": ratio,
                            "power_share": share,
                        }
                    )
    out.sort(key=lambda d: -abs(d.get("correlation", 0.0)))
    return out


def measurement_noise(
    samples: Sequence[ResidualSamples], sg: SavitzkyGolay, model: ResidualGP
) -> float:
    """Noise std (rad/s^2) of the measured angular acceleration.

    The body-rate noise of the logs (:attr:`ResidualSamples.rate_noise`, from
    second differences, median over logs and axes) through the derivative
    filter's noise gain ``||h||``; the model's noise std (median over axes of
    the GP's) when the logs do not tell. The GP's noise also holds whatever
    fast structure it could not fit, and it can be near 0 when its training
    flight was smooth enough for it to interpolate: the log's is the
    measurement's own.
    """
    rates = np.array([s.rate_noise for s in samples], dtype=float)
    if np.isfinite(rates).any():
        return float(np.nanmedian(rates)) * sg.noise_gain
    return float(np.median(np.sqrt(model.noise_variance)))


def _regressors(samples: Sequence[ResidualSamples], model: ResidualGP) -> dict[str, np.ndarray]:
    """Regressor (n, 3, p) per effect the diagnosis considers (``Effect.diagnosed``, or in
    the model already) over the concatenated samples."""
    return {
        n: np.concatenate([s.regressors[n] for s in samples])
        for n, e in EFFECTS.items()
        if e.diagnosed or n in model.effects
    }


def weight_std(model: ResidualGP, z: np.ndarray, std: np.ndarray) -> np.ndarray:
    """The std (n, 3) the diagnosis weighs samples by (``1 / std^2``): the model's band
    std (n, 3) at GP inputs z (n, d) without its growth beyond the fit inputs
    (:func:`omavctl.learn.band.growth_variance`). That growth is room the band leaves
    for an error the fit flight could not show, such as an effect the model lacks; the
    diagnosis looks for exactly that error, and weighing it away there lost the first
    answer of a tune draw when the growth doubled (docs/scorecard.md, session 33)."""
    grown = growth_variance(model, z)
    if not np.any(grown > 0):
        return std
    return np.sqrt(np.maximum(std**2 - grown, 1e-12 * np.maximum(std**2, 1e-300)))


def diagnose(
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    model_mean: np.ndarray,
    model_std: np.ndarray,
    features: dict[str, np.ndarray],
    sg: SavitzkyGolay,
    contributions: dict[str, np.ndarray] | None = None,
    fit_flight: FitFlight | None = None,
) -> dict[str, Any]:
    """The ``diagnosis`` section (see module docstring).

    samples: the residual samples of every log built with every registry effect's
    regressor; model_mean (n, 3) the model's residual prediction on the concatenated
    samples, model_std (n, 3) its std. ``contributions`` receives each candidate's
    fitted part of the remaining error (n, 3) rad/s². ``fit_flight`` reads the model's
    fit logs, to check a claim made on their estimate as fit would make it
    (:mod:`omavctl.diagnose.fit_flight_check`)."""
    residual = np.concatenate([s.residual for s in samples])
    log_id = np.concatenate([np.full(s.n, i) for i, s in enumerate(samples)])
    blocks = time_blocks(np.concatenate([s.t for s in samples]), log_id, BLOCK_SECONDS)
    regs = _regressors(samples, model)
    z = np.concatenate([s.inputs(model.features) for s in samples])
    model_std = weight_std(model, z, model_std)
    candidates, refit = _candidates(regs, model, z)
    remaining = residual - model_mean
    noise = measurement_noise(samples, sg, model)
    floor = MIN_NOISE_RATIO * noise
    missing = score_effects(remaining, candidates, blocks, model_std, floor, refit)
    if contributions is not None:
        contributions.update({s.name: s.contribution for s in missing})
    # what the physics-free residual behaves like, with the same materiality: an
    # "effect" below the measurement's own noise is not claimed as learned
    learned = score_effects(residual, regs, blocks, noise_floor=floor)
    physics = residual - np.concatenate([model.effects_samples(s) for s in samples])
    raw = candidates_raw(regs, model)
    joint = joint_selection(model, physics, raw, blocks, floor)
    taken = [j.name for j in joint] + [s.name for s in missing if s.missing]
    joint[:0] = timing_beside_look_alikes(samples, model, physics, raw, taken, floor, blocks, sg.dt)
    # fit's second stage (a GP fitted to these samples) for every estimate quoted
    stage = SecondStage(samples, model, sg)
    accepted, after, guarded = select_guarded(
        samples,
        model,
        (missing, remaining, candidates, joint),
        lambda rem, pool: score_effects(rem, pool, blocks, model_std, floor, refit),
        (floor, stage),
    )
    guarded = lag_checked(samples, model, physics, guarded, (accepted, missing, floor), stage)
    fits = actuator_fits(samples, model)
    guarded, actuators = with_actuators(samples, model, guarded, fits, floor)
    unexplained = unexplained_structure(after, features, sg.dt)
    names = guarded.kept
    estimates = fit_estimates(samples, list(model.effects), [s.name for s in learned], stage)
    out: dict[str, Any] = {
        "method": {**METHOD, "min_contribution_rms": floor, "measurement_noise_std": noise},
        "missing_effects": [s.to_json() for s in missing],
        "missing": names,
        "below_noise": None if names else _below_noise(missing, noise),
        "refit_rejected": None if names else _refit_rejected(missing),
        "missing_steps": accepted,
        "joint_steps": [s.to_json() for s in joint],
        "unexplained": unexplained,
        "learned": [{**s.to_json(), "estimate": estimates[s.name]} for s in learned],
        # the claims' estimates as the printed fit command makes them, those held back
        # (their interval holds the null), the held-out profiles that found claims
        "claim_estimates": guarded.estimates,
        "not_pinned": guarded.held_back,
        "timing_claims": {n: p for n, p in guarded.profiles.items() if n in names},
        "actuators": actuators,
    }
    _mark_entries(out["missing_effects"], guarded, actuators)
    unpinned: dict[str, Any] = {}  # filled by the learned claim's fit-flight check
    held = (floor, sg.dt, guarded, (fit_flight, sg, unpinned))
    return {**out, **_learned_part(out, stage, samples, model, (physics, raw, blocks), held)}


def _learned_part(
    out: Mapping[str, Any],
    stage: SecondStage,
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    judged: tuple[np.ndarray, dict[str, np.ndarray], np.ndarray],
    held: tuple[float, float, Guarded, tuple[FitFlight | None, SavitzkyGolay, dict[str, Any]]],
) -> dict[str, Any]:
    """When nothing else is claimed, the learned effect the held-out flight confirms
    (:func:`_learned_claim`): the diagnosis's ``learned_claims``, ``learned_steps`` and,
    without one, ``learned_held``; ``fit_flight_unpinned`` the claims the fit flight,
    estimated as fit would, did not pin down. ``judged``: (the physics-only error (n, 3),
    the raw regressors, the 2 s blocks); ``held`` as :func:`_learned_claim`'s."""
    physics, raw, blocks = judged
    step, pool, unpinned = None, [], held[3][2]
    if not out["missing"]:
        pool = _learned_pool(out["learned"], stage, physics, raw, blocks, held[0])
        step = _learned_claim(pool, samples, model, physics, raw, blocks, held)
    named = out["missing"] or step
    return {
        "learned_claims": [step[0].name, *getattr(step[0], "also", [])] if step else [],
        "learned_steps": [_learned_json(*step)] if step else [],
        **({} if named else {"learned_held": _learned_held(pool, model, raw, unpinned)}),
        **({"fit_flight_unpinned": unpinned} if unpinned else {}),
    }


def _mark_entries(
    entries: Sequence[dict[str, Any]], guarded: Guarded, actuators: Mapping[str, Any] | None
) -> None:
    """The ranking's entries as the claims ended: held back (not pinned down), claimed
    from the actuators' feedback, and without what the actuators rule out in their
    ambiguous sets (the actuators tell what the torque could not)."""
    ruled = set(actuators["ruled_out"]) if actuators else set()
    claimed = set(actuators["claimed"]) if actuators else set()
    for entry in entries:
        if any(h["name"] == entry["name"] for h in guarded.held_back):
            entry["missing"] = False  # claimed by a test, but its interval holds its null
            entry["not_pinned"] = True
        if entry["name"] in claimed:
            entry["missing"] = True  # the actuators show it, above the claim floor
        entry["ambiguous_with"] = [a for a in entry.get("ambiguous_with") or [] if a not in ruled]


def _learned_held(
    pool: Sequence[Mapping[str, Any]],
    model: ResidualGP,
    raw: Mapping[str, np.ndarray],
    unpinned: Mapping[str, Any],
) -> dict[str, str]:
    """Why each effect of the learned ``pool`` was not claimed when none was (the
    verdict said "not pinned down away from its null, or adding it does not lower the
    held-out physics-only error" and left the user to guess which): ``not_shown`` (the
    physics-only residual does not claim it), ``look_alike`` (of an effect the model
    holds), ``not_pinned`` (no claimed axis's 95 % interval excludes its null) or
    ``no_fall`` (pinned down, but its fit-flight estimate fails the held-out test on
    the physics-only error, :func:`omavctl.diagnose.claims.learned_claim`), or
    ``fit_flight_not_pinned`` (claimed on the fit flight's training points, but
    ``unpinned``: estimated there as fit would, its interval holds 0,
    :mod:`omavctl.diagnose.fit_flight_check`)."""
    out: dict[str, str] = {}
    for entry in pool:
        name = str(entry.get("name"))
        if name in unpinned:
            out[name] = "fit_flight_not_pinned"
            continue
        if name in model.effects or name not in raw:
            continue
        axes = claimed_axes(entry.get("explained_variance_per_axis"))
        if entry.get("missing") is not True:
            out[name] = "not_shown"
        elif set(entry.get("ambiguous_with") or []) & set(model.effects):
            out[name] = "look_alike"
        elif not excludes_null(name, entry.get("estimate") or {}, axes):
            out[name] = "not_pinned"
        else:
            out[name] = "no_fall"
    return out


def _learned_claim(
    pool: list[dict[str, Any]],
    samples: Sequence[ResidualSamples],
    model: ResidualGP,
    physics: np.ndarray,
    raw: dict[str, np.ndarray],
    blocks: np.ndarray,
    held: tuple[float, float, Guarded, tuple[FitFlight | None, SavitzkyGolay, dict[str, Any]]],
) -> tuple[JointStep, Mapping[str, Any]] | None:
    """The learned claim: a lag or delay held back as not pinned down on the held-out
    flight, judged there at its fit-flight estimate beside the look-alikes
    (:mod:`omavctl.diagnose.held_beside`); else judged beside the default look-alikes
    refitted on the held-out flight (:mod:`omavctl.diagnose.learned_beside`), then on the
    whole physics-only error ``physics`` (n, 3) (:func:`omavctl.diagnose.claims.
    learned_claim`), or one the held-out flight does not pin down that the fit flight does,
    when it removes more (:mod:`omavctl.diagnose.learned_fit_pinned`; beside the
    look-alikes judged together, the larger share). ``held``: (the claim floor, the
    log's sample period, the claims guard, (the fit-flight reader, the filter, the
    claims it did not pin down: filled here)); a lag or delay claimed on its fit-flight
    estimate stands only where that flight, estimated as fit would, pins it down too
    (:mod:`omavctl.diagnose.fit_flight_check`)."""
    floor, dt, guarded, (fit_flight, sg, unpinned) = held
    args = (pool, samples, model, physics, raw, blocks, floor)
    timing = held_timing_beside(
        guarded.held_back, samples, model, physics, raw, blocks, (floor, dt)
    )
    if timing is not None:
        entry, stands = checked_on_fit_flight(timing[1], fit_flight, model, sg)
        if stands:
            return timing[0], entry
        unpinned[str(entry.get("name"))] = entry["fit_flight_fit"]
    beside = learned_beside_look_alikes(*args)
    if beside is not None:
        return beside
    claim = learned_claim(*args)
    there = learned_fit_pinned(pool, model, physics, raw, blocks, floor)
    if there is None or (claim is not None and claim[0].share >= there[0].share):
        return claim or learned_look_alikes(pool, model, physics, raw, blocks, floor)
    together = learned_look_alikes(pool, model, physics, raw, blocks, floor)
    return together if together is not None and together[0].share > there[0].share else there


def _learned_json(step: JointStep, entry: Mapping[str, Any]) -> dict[str, Any]:
    """A learned claim's JSON: its ranking entry (what the physics-only residual shows,
    the estimate, the look-alikes) with the held-out test's numbers (and, accepted on
    its large cut, :class:`omavctl.diagnose.claims.LargeCutStep`'s)."""
    test = step.to_json()
    keys = (
        "share",
        "share_of_total",
        "block_t",
        "beside_look_alikes",
        "jointly_with",
        *LARGE_CUT_KEYS,
    )
    return {**entry, **{k: test[k] for k in keys if k in test}}


def _learned_pool(
    learned: list[dict[str, Any]],
    stage: SecondStage,
    physics: np.ndarray,
    raw: dict[str, np.ndarray],
    blocks: np.ndarray,
    floor: float,
) -> list[dict[str, Any]]:
    """What the GP learned beyond the model's physics: the ranking on the nominal
    residual (``learned``) for a model without effects; for one with effects the same
    ranking on the physics-only residual (n, 3) over the effects it lacks, each claimed
    one with its estimate as fit --effects would make it."""
    model = stage.model
    if not model.effects:
        return learned
    scores = [s for s in score_effects(physics, raw, blocks, noise_floor=floor) if s.missing]
    ests = fit_estimates(stage.samples, list(model.effects), [s.name for s in scores], stage)
    return [{**s.to_json(), "estimate": ests[s.name]} for s in scores]


def _candidates(
    regs: dict[str, np.ndarray], model: ResidualGP, z: np.ndarray
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Each candidate's regressor (n, 3, p) against the model's remaining error, and
    its parameters theta (p,) estimated from the model's training points.

    The GP was trained on data that contained any missing effect: on this data
    it predicts k(z, Z) (K + s^2 I)^-1 X_train theta of it. The model's error is
    therefore linear in theta through X - smooth(X_train) (exact for the GP
    mean with fixed hyperparameters); z (n, d) the GP inputs of the samples.
    """
    candidates, refit = {}, {}
    for n, r in regs.items():
        if n in model.effects:
            continue
        if n in model.train_regressors:
            r = r - model.smooth(z, model.train_regressors[n])
            refit[n] = model.basis_estimate(
                model.train_regressors[n], np.full(r.shape[2], get_effect(n).prior_std)
            )[0]
        candidates[n] = r
    return candidates, refit


def candidates_raw(regs: dict[str, np.ndarray], model: ResidualGP) -> dict[str, np.ndarray]:
    """The registry regressors (n, 3, p) of the effects ``model`` lacks."""
    return {n: r for n, r in regs.items() if n not in model.effects}


def _below_noise(scores: Sequence[EffectScore], noise: float) -> str | None:
    """The best effect that passes every test of a missing one but the noise floor, with
    a part of the error above the log's noise itself (worth a test flight: claimed, it
    would break the rule that clean logs claim nothing), else None."""
    for s in scores:
        refit_ok = s.refit_explained_variance is None or s.refit_explained_variance > 0
        if (
            s.significant
            and s.plausible
            and not s.above_noise
            and s.explained_variance >= MIN_EXPLAINED
            and refit_ok
            and s.contribution_rms >= noise
        ):
            return s.name
    return None


def _refit_rejected(scores: Sequence[EffectScore]) -> str | None:
    """The best effect that passes every test of a missing one but the refit test
    (estimated as ``fit --effects`` would, from the model's training points, it does
    not lower the held-out error), else None: the verdict says so with the number."""
    for s in scores:
        if (
            s.significant
            and s.plausible
            and s.above_noise
            and s.explained_variance >= MIN_EXPLAINED
            and s.refit_explained_variance is not None
            and s.refit_explained_variance <= 0
        ):
            return s.name
    return None
