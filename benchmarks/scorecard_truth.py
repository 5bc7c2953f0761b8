"""The scorecard's apparent truth: what the simulated vehicle really has on a fitted parameter.

The truth plant (omavctl/sim/plant.py) always has its documented default
imperfections: a per-rotor thrust spread ``1 + thrust_spread N(0, 1)`` drawn from
the truth file's ``seed``, the rotors' aerodynamic interference, 5 ms motor and
servo lags. A fit of ``com_offset`` on such a vehicle estimates the hidden offset
*plus* the part of the spread's torque that a centre-of-mass offset explains; a
fitted ``command_delay`` holds the wrench's 5 ms lag too. The scorecard scores a
fitted parameter against the hidden value and against this apparent truth
(docs/scorecard.md, "The apparent truth"), computed from the simulator's truth
and the record's flights alone, never from fitted values:

- **Thrust spread and interference** (``com_offset``, and ``rotor_interference``
  fitted with it): the spread's torque ``[A(alpha) (T (s - 1) eta)]_tau`` at the
  rotors' actual tilts ``alpha`` and thrusts ``T`` (and, when ``rotor_interference``
  is not fitted beside it, the interference's ``[A(alpha) (T (eta - 1))]_tau``),
  projected by least squares onto the fitted effects' torque regressors
  (``com_offset``: ``e_j x f``) over the flight's samples, in angular acceleration
  (``I^-1``). The flight is re-simulated from the record (:func:`flight_geometry`),
  or the hover closed form is used (:func:`hover_geometry`: one sample at hover,
  where ``r_x = -tau_y / (m g)``, ``r_y = tau_x / (m g)`` and ``r_z`` is not seen: 0).
  ``rotor_interference`` fitted without ``com_offset`` keeps the plant's
  coefficients (measured: its regressor, zero at hover, does not take the spread).
- **Timing** (``command_delay``, ``motor_lag``, ``servo_lag``): a first-order lag
  ``T`` of the wrench is, to first order in ``omega T``, a delay of ``T``: a fitted
  delay holds the default 5 ms motor time constant when ``motor_lag`` is not fitted
  beside it (a hidden slower lag is not a delay at these bandwidths and is not
  added). A controller faster than the log (1 kHz, logged at 100 Hz) applies
  commands that change within a log period the fit treats as held: on average the
  applied command leads the logged one by half a log period less half a controller
  step (4.5 ms), subtracted from a fitted delay or lag.

What needs no correction: ``rotational_drag``, ``inertia_error``, ``gyro_bias``
(nothing default imitates them); a hidden ``motor_lag``, ``servo_lag`` or
``rotor_interference`` replaces its default in the plant (the hidden value is the
plant's), up to the timing lead and the spread's projection above. Checked on the
simulator by benchmarks/scorecard_truth_check.py.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

#: the rotor thrust spread's generator stream (omavctl/sim/plant.py, _Flight)
SPREAD_STREAM = 0x5EED
#: the log's rate of the default vehicle (controller.rate_hz), Hz
LOG_RATE = 100.0
#: s, the plant's default motor and servo time constants (omavctl/sim/truth.py)
DEFAULT_LAG = 0.005
#: the linear effects whose fit the default spread and interference shift
LINEAR = ("com_offset", "rotor_interference")
#: the fitted sets a record's apparent truth is stored for
FITTED_SETS: tuple[tuple[str, ...], ...] = (
    ("com_offset",),
    ("rotor_interference",),
    ("com_offset", "rotor_interference"),
)


def plant_truth(tree: Mapping[str, Any]) -> Any:
    """The plant constants (omavctl.sim.truth.TruthParameters) of a record's truth tree
    on the default vehicle, and that vehicle."""
    from omavctl.sim.truth import truth_from_tree
    from omavctl.vehicle import load_vehicle

    vehicle = load_vehicle(None)
    return truth_from_tree(dict(tree), vehicle), vehicle


def spread_factors(seed: int, thrust_spread: float = 0.03) -> np.ndarray:
    """The per-rotor thrust factors (12,) the plant draws for a truth ``seed``: the
    first draw of ``default_rng([seed, 0x5EED])``, as omavctl/sim/plant.py does."""
    rng = np.random.default_rng([int(seed), SPREAD_STREAM])
    return 1.0 + thrust_spread * rng.standard_normal(12)


@dataclass(frozen=True)
class Geometry:
    """What the projection needs from a flight: actual tilts (N, 6) rad, rotor thrusts
    before the spread (N, 12) N, commanded body force (N, 3) N."""

    tilt: np.ndarray
    thrust: np.ndarray
    force: np.ndarray


def hover_geometry(vehicle: Any) -> Geometry:
    """One sample at hover: the allocation of ``m g e_z`` and no torque."""
    from omavctl.physics.allocation import Allocation

    wrench = np.array([0.0, 0.0, vehicle.mass * vehicle.gravity, 0.0, 0.0, 0.0])
    res = Allocation(vehicle).allocate(wrench[None, :])
    return Geometry(res.tilt, res.rotor_thrust, wrench[None, :3])


def _torque(alloc: Any, tilt: np.ndarray, rotor: np.ndarray) -> np.ndarray:
    return np.asarray(alloc.forward(tilt, rotor))[..., 3:]


def default_torques(
    geom: Geometry, spread: np.ndarray, rotor_rotor: float, rotor_arm: float, alloc: Any
) -> tuple[np.ndarray, np.ndarray]:
    """The spread's torque and the interference's torque (N, 3) N m at a flight's
    samples: ``[A(alpha) (T (s - 1) eta)]_tau`` and ``[A(alpha) (T (eta - 1))]_tau``."""
    wake, arm = alloc.interference(geom.tilt)
    eta = np.repeat(1.0 - rotor_rotor * wake - rotor_arm * arm, 2, axis=-1)
    spread_part = _torque(alloc, geom.tilt, geom.thrust * eta * (spread - 1.0))
    interference_part = _torque(alloc, geom.tilt, geom.thrust * (eta - 1.0))
    return spread_part, interference_part


def regressors(geom: Geometry, fitted: Iterable[str], alloc: Any) -> dict[str, np.ndarray]:
    """Torque regressors (N, 3, p) of the fitted linear effects: ``com_offset``'s
    ``e_j x f`` and ``rotor_interference``'s ``-[A(alpha) (T shape)]_tau``."""
    out: dict[str, np.ndarray] = {}
    if "com_offset" in fitted:
        eye = np.eye(3)
        out["com_offset"] = np.stack([np.cross(eye[j], geom.force) for j in range(3)], axis=-1)
    if "rotor_interference" in fitted:
        shapes = alloc.interference(geom.tilt)
        cols = [-_torque(alloc, geom.tilt, geom.thrust * np.repeat(s, 2, axis=-1)) for s in shapes]
        out["rotor_interference"] = np.stack(cols, axis=-1)
    return out


def linear_shift(
    geom: Geometry,
    fitted: Iterable[str],
    spread: np.ndarray,
    rotor_rotor: float,
    rotor_arm: float,
    vehicle: Any,
) -> dict[str, dict[str, list[float]]]:
    """What the default imperfections add to the fitted linear effects' parameters
    (``{effect: {parameter: [values]}}``): the least-squares projection, in angular
    acceleration, of the spread's torque (plus the interference's when
    ``rotor_interference`` is not fitted) onto the fitted effects' regressors; a
    regressor the samples do not excite (the interference's at hover) stays 0, and
    so does ``rotor_interference`` fitted without ``com_offset``."""
    from omavctl.physics.allocation import Allocation

    fitted = [n for n in LINEAR if n in set(fitted)]
    if not fitted:
        return {}
    if "com_offset" not in fitted:
        # measured (benchmarks/scorecard_truth_check.py, ri71/ri72): fitted alone, the
        # interference keeps the plant's coefficients; its regressor, zero at hover,
        # cannot take the spread's torque, which the fit's GP (a function of the
        # wrench) absorbs instead
        return {"rotor_interference": {"rotor_rotor": [0.0], "rotor_arm": [0.0]}}
    alloc = Allocation(vehicle)
    spread_tau, inter_tau = default_torques(geom, spread, rotor_rotor, rotor_arm, alloc)
    target = spread_tau if "rotor_interference" in fitted else spread_tau + inter_tau
    cols = regressors(geom, fitted, alloc)
    inv = np.linalg.inv(vehicle.inertia)
    x = np.concatenate([cols[n] for n in fitted], axis=-1)  # (N, 3, p)
    xw = np.einsum("ij,njp->nip", inv, x).reshape(-1, x.shape[-1])
    yw = (target @ inv.T).reshape(-1)
    # a column the samples do not excite (the interference's at hover, tilts 0) stays 0
    norms = np.linalg.norm(xw, axis=0)
    seen = norms > 1e-9 * max(float(norms.max()), 1e-300)
    theta = np.zeros(xw.shape[1])
    if seen.any():
        theta[seen] = np.linalg.lstsq(xw[:, seen] / norms[seen], yw, rcond=None)[0] / norms[seen]
    out: dict[str, dict[str, list[float]]] = {}
    if "com_offset" in fitted:
        out["com_offset"] = {"r": [float(v) for v in theta[:3]]}
        theta = theta[3:]
    if "rotor_interference" in fitted:
        out["rotor_interference"] = {
            "rotor_rotor": [float(theta[0])],
            "rotor_arm": [float(theta[1])],
        }
    return out


def timing_lead(controller_rate_hz: float | None, log_rate: float = LOG_RATE) -> float:
    """s by which the applied command leads the logged one the fit treats as held: half
    a log period less half a controller step when the controller is faster than the
    log (0.0045 s at 1 kHz on a 100 Hz log), else 0."""
    if controller_rate_hz is None or controller_rate_hz <= log_rate:
        return 0.0
    return 0.5 * (1.0 / log_rate - 1.0 / controller_rate_hz)


def timing_truth(effect: str, truth: Any, fitted: Iterable[str]) -> dict[str, list[float]] | None:
    """The apparent value of a timing effect's parameter on the plant ``truth``
    (TruthParameters), fitted beside ``fitted``; None for other effects."""
    lead = timing_lead(truth.controller_rate_hz)
    if effect == "command_delay":
        # the default lag (not a hidden one: at 50-120 ms, omega T is not small) when
        # motor_lag is not fitted beside the delay to hold it
        default = truth.motor_time_constant <= DEFAULT_LAG
        lag = truth.motor_time_constant if default and "motor_lag" not in set(fitted) else 0.0
        return {"tau_d": [truth.command_delay + lag - lead]}
    if effect == "motor_lag":
        return {"T_m": [truth.motor_time_constant - lead]}
    if effect == "servo_lag":
        return {"T_s": [truth.servo_time_constant - lead]}
    return None


def fitted_sets(record: Mapping[str, Any]) -> list[tuple[str, frozenset[str]]]:
    """(effect, the effects fitted with it) of every fit in the record, last fit last."""
    out = []
    for fit in record.get("fits") or []:
        names = frozenset(fit.get("effects") or {})
        out += [(n, names) for n in names]
    return out


def apparent_truth(
    record: Mapping[str, Any], geometry: Mapping[str, Geometry] | None = None
) -> dict[str, Any]:
    """The apparent truth of a record (JSON-ready): per flight role (``fit``, ``held``)
    the linear shifts for each fitted set of :data:`FITTED_SETS` (key ``"a+b"``), and
    ``method`` (``flight`` when ``geometry`` holds that role's re-simulated samples,
    else ``hover``). Timing effects are closed form (:func:`timing_truth`)."""
    truth, vehicle = plant_truth(record["truth"])
    spread = spread_factors(truth.seed, truth.thrust_spread)
    out: dict[str, Any] = {"spread": [float(v) for v in spread]}
    for role in ("fit", "held"):
        geom = (geometry or {}).get(role)
        method = "flight" if geom is not None else "hover"
        geom = geom or hover_geometry(vehicle)
        shifts = {
            "+".join(s): linear_shift(geom, s, spread, truth.rotor_rotor, truth.rotor_arm, vehicle)
            for s in FITTED_SETS
        }
        out[role] = {"method": method, "shifts": shifts}
    return out


def _set_key(fitted: Iterable[str]) -> str:
    return "+".join(n for n in LINEAR if n in set(fitted)) or ""


def apparent_value(
    record: Mapping[str, Any],
    apparent: Mapping[str, Any] | None,
    effect: str,
    fitted: Iterable[str],
    role: str = "fit",
) -> dict[str, list[float]] | None:
    """The apparent truth of ``effect``'s parameters in a fit beside ``fitted``, on
    the ``role`` flight (``{parameter: [values]}``), or None when the defaults do
    not shift it (the hidden value is the truth)."""
    fitted = set(fitted) | {effect}
    if effect in ("command_delay", "motor_lag", "servo_lag"):
        truth, _ = plant_truth(record["truth"])
        return timing_truth(effect, truth, fitted)
    if effect not in LINEAR:
        return None
    if apparent is None:
        apparent = apparent_truth(record)
    shift = apparent[role]["shifts"][_set_key(fitted)][effect]
    base = _base_values(record, effect)
    return {k: [b + s for b, s in zip(base[k], shift[k], strict=True)] for k in shift}


def _base_values(record: Mapping[str, Any], effect: str) -> dict[str, list[float]]:
    """The plant's own value of a linear effect's parameters: the hidden one, the
    default interference, or no offset."""
    hidden = record["hidden"].get(effect)
    if effect == "com_offset":
        r = (hidden or {}).get("r", [0.0, 0.0, 0.0])
        return {"r": [float(v) for v in r]}
    truth, _ = plant_truth(record["truth"])
    return {"rotor_rotor": [truth.rotor_rotor], "rotor_arm": [truth.rotor_arm]}


# ----------------------------------------------------------------- re-simulation
def flight_geometry(record: Mapping[str, Any], role: str, workdir: Path) -> Geometry | None:
    """Re-fly a record's ``role`` flight (``omavctl task`` for the reference, the plant
    in process with the record's truth and flight seed) and return its samples at the
    log rate; None for a planned flight (its reference needs the loop's model)."""
    flight = next(f for f in record["flights"] if f["role"] == role)
    if flight["family"] == "planned":
        return None
    ref = workdir / f"{role}-ref.csv"
    argv = [sys.executable, "-m", "omavctl", "task", flight["family"], *flight["options"]]
    argv += ["--duration", "20", "--out", str(ref)]
    subprocess.run(argv, check=True, capture_output=True)
    return simulated_geometry(ref, record["truth"], int(flight["seed"]))


def simulated_geometry(reference: Path, tree: Mapping[str, Any], seed: int) -> Geometry:
    """Fly ``reference`` (a task CSV) through the plant of the truth ``tree`` with the
    flight's noise ``seed`` (in process, as ``omavctl simulate`` does) and return
    its samples at the log rate."""
    from omavctl.sim.plant import simulate
    from omavctl.sim.trajectory import read_trajectory

    truth, vehicle = plant_truth(tree)
    result = simulate(read_trajectory(reference), vehicle, truth, seed=seed)
    series = result.log.series
    omega = np.asarray(series["rotor"].values)
    return Geometry(
        np.asarray(series["tilt"].values),
        vehicle.thrust_coefficient * omega**2,
        np.asarray(series["force_command"].values),
    )


def _needs_flight(record: Mapping[str, Any]) -> list[str]:
    """Roles whose flight the record's linear checks read: the fit flight when a
    hidden linear effect was fitted, the held-out one for a none draw's claims."""
    if record.get("error"):
        return []
    if not record["hidden"]:
        return ["held"]
    fitted = {n for n, _ in fitted_sets(record)}
    return ["fit"] if fitted & set(record["hidden"]) & set(LINEAR) else []


def build(records: Iterable[Mapping[str, Any]], simulate_flights: bool = True) -> dict[str, Any]:
    """The apparent truth of every record, keyed ``"split:index"``."""
    out: dict[str, Any] = {}
    for r in records:
        geometry: dict[str, Geometry] = {}
        if simulate_flights:
            with tempfile.TemporaryDirectory() as tmp:
                for role in _needs_flight(r):
                    geom = flight_geometry(r, role, Path(tmp))
                    if geom is not None:
                        geometry[role] = geom
        out[f"{r['split']}:{r['index']}"] = apparent_truth(r, geometry)
        print(f"{r['split']} {r['index']}: {sorted(geometry) or 'hover'}", file=sys.stderr)
    return out


def main(argv: list[str] | None = None) -> None:
    """``python benchmarks/scorecard_truth.py RECORDS.jsonl... --out APPARENT.json``."""
    import argparse
    import json

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("records", type=Path, nargs="+")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument(
        "--hover", action="store_true", help="the hover closed form only (no re-simulation)"
    )
    args = ap.parse_args(argv)
    from benchmarks.scorecard import read_records

    out = build(read_records(args.records), simulate_flights=not args.hover)
    args.out.write_text(json.dumps(out, sort_keys=True, allow_nan=False) + "\n")


if __name__ == "__main__":
    if __package__ in (None, ""):
        sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main()
