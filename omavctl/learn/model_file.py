"""The residual model file: writing, reading and validating ``.npz`` models.

:func:`save_model` writes a :class:`omavctl.learn.model.ResidualGP`;
:func:`load_model` reads one back, refusing anything but a valid model;
:func:`check_vehicle` refuses a model fitted for another vehicle.

File format (``.npz``, schema ``omavctl.model/2``; loadable with
``numpy.load(allow_pickle=False)``; strings are numpy unicode scalars, JSON for
structured data):

=================  ==========  ==================================================
key                shape       meaning
=================  ==========  ==================================================
schema             ()          ``"omavctl.model/2"``
features           ()          ``"wrench"`` or ``"wrench+rate"``
input_names        (d,)        GP input columns (``fx/m`` ... ``wz``)
train_inputs       (n, d)      training inputs z, physical units
train_targets      (n, 3)      residual minus effects at the inputs, rad/s^2
input_mean         (d,)        input normalisation: zn = (z - mean) / scale
input_scale        (d,)
target_mean        (3,)        constant prior mean per axis, rad/s^2
signal_variance    (3,)        s^2 per axis, (rad/s^2)^2
length_scales      (3, d)      l per axis and input, in normalised input units
noise_variance     (3,)        sigma^2 per axis, (rad/s^2)^2
band_noise         (3,)        optional: noise variance of the band inside the fit
                               flight's inputs (at most noise_variance, which it
                               reaches beyond them; absent: noise_variance)
band_scale,        (3,)        optional: the band inside the fit flight's inputs is
band_slope                     band_scale (1 + band_slope rho) times its latent
                               variance and noise, rho the latent variance's share
                               of the prior (omavctl.learn.band; absent: 1, 0)
torque_growth      (3,)        optional: growth of the band's std per rad/s^2 of
                               commanded angular acceleration beyond the fit
                               flight's (omavctl.learn.band; absent: 0)
range_growth       (3,)        optional: growth of the band's std, rad/s^2, per
                               training range beyond the training inputs' box
                               (omavctl.learn.band; absent: 0)
latent_scale       (3,)        optional: factor on the posterior (latent) variance
                               in predictions, fit's extrapolation calibration
                               (absent: 1). An axis whose GP ``fit`` switched off
                               has signal_variance 0 and target_mean 0.
beyond_scale       (3,)        optional: weight on the variance the residual may
                               gain beyond the training inputs' box, fit's
                               calibration on held-out input ends (absent: 0)
mean_shrink        (3,)        optional: weight kappa of the latent variance
                               against the squared GP mean, which is weighed by
                               m^2 / (m^2 + kappa v) (absent: 0, the mean as is)
rollout_gp         (3,)        optional: weight (0 or 1) of the GP mean in open-loop
                               rollouts, fit's verdict on held-out rollouts
                               (absent: 1, the mean as in one-step predictions)
effects            ()          JSON ``{"name": {"P": [..], "P_stderr": [..],
                               "P_ci95": [[low, high], ..], "P_pinned": [..],
                               "stderr_method": "hac"}}``: values, standard
                               errors, 95 % intervals (value -/+ 1.96 standard
                               errors; null where not finite), whether each
                               interval pins the parameter down; optional
                               ``theta_fitted``: the coefficients the model
                               predicts with where they differ from the
                               parameters' (a torque effect beside
                               ``inertia_error``, physical parameters);
                               optional ``P_systematic`` (the rotors' thrust
                               spread, in ``P_ci95``; ``P_ci95_statistical``
                               without it: omavctl.learn.spread)
vehicle            ()          JSON vehicle tree (``Vehicle.to_json()``)
provenance         ()          JSON: sources (name, sha256), filter, k-medoids,
                               GP fitting settings, seed, omavctl version
regressor_<name>   (n, 3, p)   optional, one per registered effect: its regressor
                               at the training points (held like the residual);
                               ``evaluate`` uses them to score effects the GP may
                               have partly absorbed
spread_train,      (n, 3, R),  optional: each rotor's residual per unit thrust error
spread_gain        (P, R)      at the training points, and the linear effects' share
                               of it (the band's thrust spread: learn.spread_band)
=================  ==========  ==================================================

Version history: docs/schemas.md. Version 1 files are still read: their standard errors
were white-residual least squares (``stderr_method`` ``"white"``, optimistic), their
intervals derived from them on reading.

Files are written deterministically (fixed zip timestamps, sorted JSON): same inputs, same bytes.
"""

from __future__ import annotations

import io
import json
import math
import re
import zipfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.atomic import atomic_path
from omavctl.base.errors import ModelError, library_reason
from omavctl.learn.estimate import systematic_from_json
from omavctl.learn.model import (
    SCHEMA_FITTED,
    SCHEMA_NAME,
    SCHEMA_VERSION,
    EffectEstimate,
    ResidualGP,
)
from omavctl.learn.spread_band import read_spread
from omavctl.physics.effects import EFFECTS, get_effect
from omavctl.vehicle import Vehicle

__all__ = ["MAX_MAGNITUDE", "check_model_paths", "check_vehicle", "load_model", "save_model"]

#: The GP inputs of each ``features`` value.
_FEATURE_INPUTS = {"wrench": 6, "wrench+rate": 9, "wrench+dtorque": 9, "wrench+rate+dtorque": 12}

#: Keys of the model file, in the order they are written.
_KEYS = (
    "schema",
    "features",
    "input_names",
    "train_inputs",
    "train_targets",
    "input_mean",
    "input_scale",
    "target_mean",
    "signal_variance",
    "length_scales",
    "noise_variance",
    "effects",
    "vehicle",
    "provenance",
)
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)


def _vehicle_from_json(text: str, source: str) -> Vehicle:
    """The vehicle stored in a model (its merged YAML tree as JSON)."""
    # vehicle.py has no public "vehicle from a tree" yet; _build validates the tree.
    from omavctl.vehicle import _build

    tree = json.loads(text)
    if not isinstance(tree, dict):
        raise ValueError("vehicle is not a mapping")
    return _build(tree, None, source)


def save_model(path: str | Path, model: ResidualGP) -> None:
    """Write ``model`` to ``path`` (.npz) atomically and deterministically."""
    arrays = model.to_arrays()
    keys = [*_KEYS, *sorted(k for k in arrays if k not in _KEYS)]
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as zf:
        for key in keys:
            arr = np.asarray(arrays[key])
            if arr.dtype.hasobject:  # pragma: no cover - guarded by construction
                raise ModelError(f"refusing to write object array '{key}'", path)
            if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
                raise ModelError(f"refusing to write non-finite values in '{key}'", path)
            buf = io.BytesIO()
            np.lib.format.write_array(buf, arr, allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=_ZIP_DATE)
            info.external_attr = 0o644 << 16
            info.compress_type = zipfile.ZIP_STORED
            zf.writestr(info, buf.getvalue())


def _check_schema(value: str, path: Path) -> int:
    reads = f"this omavctl reads {SCHEMA_NAME}/1 to /3"
    m = re.fullmatch(r"(.+)/(\d+)", value)
    if m is None or m.group(1) != SCHEMA_NAME:
        raise ModelError(f"unknown schema '{value}' ({reads})", path)
    version = int(m.group(2))
    if version > SCHEMA_VERSION + 1:  # 3: effects with theta_fitted (SCHEMA_FITTED)
        raise ModelError(
            f"schema '{value}' is newer than this omavctl supports ({SCHEMA_FITTED})", path
        )
    if version < 1:
        raise ModelError(f"unknown schema '{value}' ({reads})", path)
    return version


def check_model_paths(paths: Iterable[str | Path | None]) -> None:
    """Refuse, before any work, a model path that is a directory (``--model .``):
    outputs derived from its name and the output checks would otherwise misread it."""
    for p in paths:
        if p is not None and Path(p).is_dir():
            raise ModelError("is a directory, not a model file (.npz)", Path(p))


def _read_members(path: Path) -> dict[str, np.ndarray]:
    """Every array of the npz, refusing pickles and object arrays."""
    try:
        with path.open("rb") as f:
            head = f.read(4)
    except IsADirectoryError:
        raise ModelError("is a directory, not a model file (.npz)", path) from None
    except OSError as err:
        raise ModelError(f"cannot read: {err.strerror or err}", path) from None
    if head[:1] == b"\x80":
        raise ModelError("contains pickled data; refusing to load", path)
    if not zipfile.is_zipfile(path):
        cut = "truncated or damaged: it begins as an .npz (zip) file but its end is missing"
        if head == b"PK\x03\x04":  # a zip's first member, but no directory at its end
            raise ModelError(f"{cut} (an interrupted copy or download?)", path)
        raise ModelError("not an omavctl model: expected an .npz (zip) file", path)
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                if not info.filename.endswith(".npy"):
                    raise ModelError(
                        f"unexpected member '{info.filename}': not an omavctl model", path
                    )
                with zf.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    if version == (1, 0):
                        _, _, dtype = np.lib.format.read_array_header_1_0(f)
                    else:
                        _, _, dtype = np.lib.format.read_array_header_2_0(f)
                if dtype.hasobject:
                    raise ModelError("contains pickled data; refusing to load", path)
        out: dict[str, np.ndarray] = {}
        with np.load(path, allow_pickle=False) as npz:
            for key in npz.files:
                out[key] = np.asarray(npz[key])
        return out
    except ModelError:
        raise
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as err:
        text = str(err)
        if "pickle" in text:
            raise ModelError("contains pickled data; refusing to load", path) from None
        raise ModelError(f"corrupt model file: {library_reason(err)}", path) from None


def _text(arrays: Mapping[str, np.ndarray], key: str, path: Path) -> str:
    arr = arrays[key]
    if arr.shape != () or arr.dtype.kind != "U":
        raise ModelError(f"key '{key}' must be a string", path)
    return str(arr)


def _json(arrays: Mapping[str, np.ndarray], key: str, path: Path) -> Any:
    try:
        return json.loads(_text(arrays, key, path))
    except json.JSONDecodeError as err:
        raise ModelError(f"key '{key}' is not valid JSON: {err.msg}", path) from None


def _optional_nonnegative(arrays: Mapping[str, np.ndarray], key: str, p: Path) -> np.ndarray | None:
    """The optional per-axis (3,) ``key``, None when absent; refused when negative."""
    if key not in arrays:
        return None
    out = _float(arrays, key, (3,), p)
    if np.any(out < 0):
        raise ModelError(f"key '{key}' must not be negative", p)
    return out


def _float(
    arrays: Mapping[str, np.ndarray], key: str, shape: tuple[int, ...], path: Path
) -> np.ndarray:
    arr = arrays[key]
    if arr.dtype.kind not in "fi" or arr.shape != shape:
        raise ModelError(f"key '{key}' must be numbers of shape {shape}, got {arr.shape}", path)
    arr = arr.astype(float)
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"key '{key}' has non-finite values", path)
    if arr.size and np.max(np.abs(arr)) > MAX_MAGNITUDE:
        raise ModelError(
            f"key '{key}' holds implausible values (up to {np.max(np.abs(arr)):.3g})", path
        )
    return arr


#: Largest magnitude of any number in a model: normalised inputs, rad/s^2 targets,
#: variances and effect parameters are all far below it; beyond is a corrupt file.
MAX_MAGNITUDE = 1e12
#: The ways of obtaining a standard error a model file may name.
STDERR_METHODS = ("hac", "white")


def _effects_from_json(tree: Any, path: Path, version: int) -> dict[str, EffectEstimate]:
    """The effect estimates of a model file; version 1 files hold white-residual
    standard errors (``stderr_method`` "white"), later ones say which they hold."""
    if not isinstance(tree, dict):
        raise ModelError("key 'effects' must map effect names to parameters", path)
    out: dict[str, EffectEstimate] = {}
    for name, params in tree.items():
        try:
            effect = get_effect(name)
        except Exception:
            raise ModelError(f"unknown effect '{name}' in the model", path) from None
        values, stderr = {}, {}
        for p in effect.parameters:
            try:
                values[p.name] = np.asarray(params[p.name], dtype=float).reshape(p.size)
                stderr[p.name] = np.asarray(params[f"{p.name}_stderr"], dtype=float).reshape(p.size)
            except (KeyError, TypeError, ValueError):
                raise ModelError(
                    f"effect '{name}': parameter '{p.name}' missing or not {p.size} number(s)",
                    path,
                ) from None
            both = np.concatenate([values[p.name], stderr[p.name]])
            both = np.nan_to_num(both, nan=0.0, posinf=0.0, neginf=0.0)
            if not np.all(np.isfinite(values[p.name])) or np.any(np.abs(both) > MAX_MAGNITUDE):
                raise ModelError(
                    f"effect '{name}': parameter '{p.name}' is not finite or implausible", path
                )
        method = params.get("stderr_method", "hac") if version >= 2 else "white"
        if method not in STDERR_METHODS:
            raise ModelError(
                f"effect '{name}': unknown stderr_method '{method}' "
                f"(known: {', '.join(STDERR_METHODS)})",
                path,
            )
        fitted = _fitted(params, effect, path)
        systematic = systematic_from_json(params, effect)
        out[name] = EffectEstimate(name, values, stderr, method, fitted, systematic)
    return out


def _fitted(params: Any, effect: Any, path: Path) -> np.ndarray | None:
    """An effect's optional ``theta_fitted`` (the coefficients the model predicts with,
    :class:`EffectEstimate`): None when absent (files before it), refused unless
    ``n_theta`` finite numbers."""
    if "theta_fitted" not in params:
        return None
    try:
        out = np.asarray(params["theta_fitted"], dtype=float).reshape(effect.n_theta)
    except (TypeError, ValueError):
        out = np.full(1, np.nan)
    if out.size != effect.n_theta or not np.all(np.abs(out) <= MAX_MAGNITUDE):
        raise ModelError(
            f"effect '{effect.name}': theta_fitted is not {effect.n_theta} finite number(s)", path
        )
    return out


def load_model(path: str | Path) -> ResidualGP:
    """Read a model file; :class:`ModelError` for anything but a valid ``omavctl.model/1``
    or ``/2``.

    Refuses: a missing file, a file that is not an npz, pickled data or object
    arrays, a missing or unknown schema, a newer schema, missing keys, wrong
    shapes, non-finite values.
    """
    p = Path(path)
    if not p.exists():
        raise ModelError("file not found", p)
    arrays = _read_members(p)
    version = _check_keys(arrays, p)
    features = _text(arrays, "features", p)
    names = _input_names(arrays, features, p)
    d = len(names)
    gp = _gp_arrays(arrays, d, p)
    n = gp["inputs"].shape[0]
    vehicle = _vehicle(arrays, p)
    provenance = _json(arrays, "provenance", p)
    if not isinstance(provenance, dict):
        raise ModelError("key 'provenance' must be a JSON object", p)
    regressors = _regressors(arrays, n, p)
    effects = _effects_from_json(_json(arrays, "effects", p), p, version)
    spread = read_spread(arrays, n, list(effects), _float, p)
    try:
        model = ResidualGP(
            vehicle=vehicle,
            features=features,
            input_names=names,
            input_mean=_float(arrays, "input_mean", (d,), p),
            target_mean=_float(arrays, "target_mean", (3,), p),
            effects=effects,
            provenance=provenance,
            train_regressors=regressors,
            **gp,
        )
    except (np.linalg.LinAlgError, ValueError) as err:
        reason = library_reason(err, "its arrays do not fit together")
        raise ModelError(f"inconsistent model: {reason}", p) from None
    model.spread = spread
    return model


def _check_keys(arrays: Mapping[str, np.ndarray], p: Path) -> int:
    """The schema version; ModelError unless the file has a schema this omavctl reads
    and every required key."""
    if "schema" not in arrays:
        raise ModelError("no 'schema' key: not an omavctl model", p)
    version = _check_schema(_text(arrays, "schema", p), p)
    missing = [k for k in _KEYS if k not in arrays]
    if missing:
        raise ModelError(f"missing keys: {', '.join(missing)}", p)
    return version


def _input_names(arrays: Mapping[str, np.ndarray], features: str, p: Path) -> tuple[str, ...]:
    """The GP input names (d,), as many as ``features`` has inputs."""
    names_arr = arrays["input_names"]
    if names_arr.ndim != 1 or names_arr.dtype.kind != "U":
        raise ModelError("key 'input_names' must be a list of strings", p)
    names = tuple(str(x) for x in names_arr)
    d = len(names)
    if _FEATURE_INPUTS.get(features) != d:
        raise ModelError(f"features '{features}' do not match {d} input names", p)
    return names


def _gp_arrays(arrays: Mapping[str, np.ndarray], d: int, p: Path) -> dict[str, Any]:
    """The training data and hyperparameters, checked: :class:`ResidualGP` keyword
    arguments ``inputs`` (n, d), ``targets`` (n, 3), ``input_scale`` (d,),
    ``signal_variance``, ``noise_variance``, ``latent_scale`` and ``beyond_scale``
    (3,) (None when absent), ``length_scales`` (3, d)."""
    n = arrays["train_inputs"].shape[0] if arrays["train_inputs"].ndim == 2 else -1
    if n < 1:
        raise ModelError("key 'train_inputs' must be a non-empty (n, d) array", p)
    inputs = _float(arrays, "train_inputs", (n, d), p)
    targets = _float(arrays, "train_targets", (n, 3), p)
    scale = _float(arrays, "input_scale", (d,), p)
    sv = _float(arrays, "signal_variance", (3,), p)
    ls = _float(arrays, "length_scales", (3, d), p)
    nv = _float(arrays, "noise_variance", (3,), p)
    if np.any(scale <= 0) or np.any(sv < 0) or np.any(ls <= 0) or np.any(nv < 0):
        raise ModelError("scales, variances and length scales must be positive", p)
    if np.any((sv == 0) & (nv <= 0)):
        raise ModelError("an axis with its GP off (signal variance 0) needs a noise variance", p)
    optional = {
        key: _optional_nonnegative(arrays, key, p)
        for key in (
            "band_noise", "band_slope", "torque_growth", "range_growth", "beyond_scale",
            "mean_shrink",
        )
    }  # fmt: skip
    for key in ("latent_scale", "band_scale"):
        optional[key] = value = _float(arrays, key, (3,), p) if key in arrays else None
        if value is not None and np.any(value <= 0):
            raise ModelError(f"key '{key}' must be positive", p)
    rollout = _float(arrays, "rollout_gp", (3,), p) if "rollout_gp" in arrays else None
    if rollout is not None and np.any((rollout < 0) | (rollout > 1)):
        raise ModelError("key 'rollout_gp' must be between 0 and 1", p)
    return {
        "inputs": inputs,
        "targets": targets,
        "input_scale": scale,
        "signal_variance": sv,
        "length_scales": ls,
        "noise_variance": nv,
        "rollout_gp": rollout,
        **optional,
    }


def _vehicle(arrays: Mapping[str, np.ndarray], p: Path) -> Vehicle:
    """The vehicle the model was fitted for; ModelError when it is not a valid vehicle."""
    try:
        return _vehicle_from_json(_text(arrays, "vehicle", p), f"model {p.name}")
    except ModelError:
        raise
    except (ValueError, KeyError, TypeError) as err:  # includes ConfigError, JSON errors
        raise ModelError(f"key 'vehicle' is not a valid vehicle: {err}", p) from None


def _regressors(arrays: Mapping[str, np.ndarray], n: int, p: Path) -> dict[str, np.ndarray]:
    """Effect name -> regressor (n, 3, p) at the training points, for the effects this
    omavctl knows (the optional ``regressor_<name>`` keys)."""
    regressors = {}
    for key in sorted(arrays):
        if not key.startswith("regressor_"):
            continue
        name = key[len("regressor_") :]
        if name not in EFFECTS:
            continue  # an effect this omavctl does not know: its regressor is unused
        size = get_effect(name).n_theta
        regressors[name] = _float(arrays, key, (n, 3, size), p)
    return regressors


def check_vehicle(model: ResidualGP, vehicle: Vehicle, path: str | Path | None = None) -> None:
    """ModelError unless ``vehicle`` has the mass, inertia and command units the model
    was fitted for (the inputs u = [f/m, I^-1 tau] depend on them)."""
    mv = model.vehicle
    if not (
        math.isclose(mv.mass, vehicle.mass, rel_tol=1e-9)
        and np.allclose(mv.inertia, vehicle.inertia, rtol=1e-9, atol=0)
    ):
        raise ModelError(
            f"model was fitted for a vehicle of mass {mv.mass:g} kg and inertia diagonal "
            f"{np.round(np.diag(mv.inertia), 6).tolist()} kg m^2; this vehicle has "
            f"{vehicle.mass:g} kg and {np.round(np.diag(vehicle.inertia), 6).tolist()} kg m^2",
            path,
        )
    if mv.command_units != vehicle.command_units:
        raise ModelError(
            f"model was fitted for commands in {_units(mv.command_units)}; this vehicle's "
            f"commands are in {_units(vehicle.command_units)} (command_units)",
            path,
        )


def _units(units: Mapping[str, str]) -> str:
    """``"torque N m, force N"``: command units for messages."""
    return ", ".join(f"{k} {units.get(k, '?')}" for k in ("torque", "force"))
