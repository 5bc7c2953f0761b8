"""Reading and writing evaluation files: the JSON and its sibling time series.

The JSON (schema ``omavctl.eval/1``) names its series file and records, under
``series``, the series' content hash (``sha256`` over every array's name,
dtype, shape and bytes, in key order) and a ``run_id`` that the ``.npz`` holds
too (key ``run_id``). Both files are written under temporary names and renamed
together (:func:`omavctl.base.atomic.atomic_paths`: JSON first, then the series),
so a JSON is never beside the series of another run unless the process was
killed between the two renames, and :func:`load_evaluation` refuses such a
pair. Nothing non-finite is written: a NaN or infinity in the series or in an
RMSE of ``metrics`` is an error, elsewhere it is written as null and listed in
``notes``.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from omavctl.base.atomic import atomic_paths
from omavctl.base.errors import OmavctlError
from omavctl.base.replace import head_has, is_npz_with

if TYPE_CHECKING:
    from omavctl.diagnose.evaluate import EvalResult

__all__ = [
    "is_evaluation_file",
    "is_series_file",
    "load_evaluation",
    "series_digest",
    "series_path",
    "write_evaluation",
]

SCHEMA = "omavctl.eval/1"
RUN_ID_KEY = "run_id"


def series_path(out: str | Path) -> Path:
    """Where the time series of ``out`` (eval JSON) are stored: ``<stem>.series.npz``."""
    out = Path(out)
    return out.with_name(out.stem + ".series.npz")


def is_evaluation_file(path: Path) -> bool:
    """Whether ``path`` is an evaluation JSON :func:`write_evaluation` wrote (its first
    key the schema): what ``evaluate --out`` may replace."""
    return head_has(path, f'"schema": "{SCHEMA.split("/")[0]}/')


def is_series_file(path: Path) -> bool:
    """Whether ``path`` is the series ``.npz`` :func:`write_evaluation` wrote."""
    return is_npz_with(path, {"t", RUN_ID_KEY})


def series_digest(series: Mapping[str, np.ndarray]) -> str:
    """sha256 of the arrays (names, dtypes, shapes, bytes; ``run_id`` excluded)."""
    h = hashlib.sha256()
    for key in sorted(k for k in series if k != RUN_ID_KEY):
        arr = np.ascontiguousarray(series[key])
        h.update(f"{key}\0{arr.dtype.str}\0{arr.shape}\0".encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def _non_finite(tree: Any, where: str = "") -> list[str]:
    """Dotted paths of every NaN/infinity in a JSON-like tree."""
    if isinstance(tree, float | np.floating):
        return [] if math.isfinite(tree) else [where or "(top)"]
    if isinstance(tree, np.ndarray):
        ok = not np.issubdtype(tree.dtype, np.number) or bool(np.all(np.isfinite(tree)))
        return [] if ok else [where]
    items: Any = ()
    if isinstance(tree, Mapping):
        items = ((f"{where}.{k}" if where else str(k), v) for k, v in tree.items())
    elif isinstance(tree, list | tuple):
        items = ((f"{where}[{i}]", v) for i, v in enumerate(tree))
    return [p for key, value in items for p in _non_finite(value, key)]


def _nulled(tree: Any) -> Any:
    """``tree`` with every NaN/infinity replaced by None (JSON null)."""
    if isinstance(tree, float | np.floating):
        return float(tree) if math.isfinite(tree) else None
    if isinstance(tree, np.ndarray):
        return _nulled(tree.tolist())
    if isinstance(tree, Mapping):
        return {k: _nulled(v) for k, v in tree.items()}
    if isinstance(tree, list | tuple):
        return [_nulled(v) for v in tree]
    return tree


def _finite_tree(tree: Mapping[str, Any]) -> dict[str, Any]:
    """The tree to write: a non-finite RMSE in ``metrics`` (what every reader of an
    evaluation needs) is an error; any other non-finite number (a standard error at
    a bound, an R² of a constant signal, ...) is written as null and listed in
    ``notes``."""
    bad = _non_finite(tree)
    core = [p for p in bad if re.fullmatch(r"metrics\.\w+\.rmse\.\w+", p)]
    if core:
        raise OmavctlError(
            f"the evaluation is not finite at '{core[0]}': the log holds values far outside "
            "what the model and the vehicle allow",
            _subject(tree),
        )
    out = dict(tree)
    if bad:
        out = _nulled(out)
        shown = ", ".join(bad[:5]) + (f" and {len(bad) - 5} more" if len(bad) > 5 else "")
        out["notes"] = [*out.get("notes", []), f"not finite, written as null: {shown}"]
    return out


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _subject(tree: Mapping[str, Any]) -> str | None:
    """The evaluated log, for messages (one log: its path; several: None)."""
    logs = tree.get("logs") or []
    return str(logs[0]["path"]) if len(logs) == 1 else None


def _run_id(tree: Mapping[str, Any], digest: str) -> str:
    """Run id: a hash of the JSON's content (without ``series``) and the series hash,
    so that a changed JSON or a series of another run is recognised."""
    body = {k: v for k, v in tree.items() if k != "series"}
    text = json.dumps(body, sort_keys=True, default=_json_default).encode()
    return hashlib.sha256(text + digest.encode()).hexdigest()[:16]


def write_evaluation(out: str | Path, result: EvalResult) -> None:
    """Write the JSON and its series ``.npz`` together (see the module docstring)."""
    out = Path(out)
    spath = series_path(out)
    bad = [k for k, v in result.series.items() if _non_finite(np.asarray(v))]
    if bad:
        raise OmavctlError(
            f"the evaluation's time series '{bad[0]}' is not finite: the log holds values far "
            "outside what the model and the vehicle allow",
            _subject(result.tree),
        )
    digest = series_digest(result.series)
    tree = _finite_tree(result.tree)
    tree.pop("series", None)
    run_id = _run_id(tree, digest)
    tree["series"] = {
        "file": spath.name,
        "keys": sorted(result.series),
        "sha256": digest,
        RUN_ID_KEY: run_id,
    }
    text = json.dumps(tree, indent=1, sort_keys=False, allow_nan=False, default=_json_default)
    with atomic_paths(out, spath) as (tmp_json, tmp_series):
        tmp_json.write_text(text + "\n")
        with tmp_series.open("wb") as fh:
            # typed Any: NumPy 2's stubs read **kwargs as its allow_pickle flag
            arrays: dict[str, Any] = {**result.series, RUN_ID_KEY: np.array(run_id)}
            np.savez(fh, **arrays)


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def _read_tree(p: Path) -> dict[str, Any]:
    try:
        raw = p.read_bytes()
        if raw.startswith(b"PK"):  # a zip: a model file (.npz), or a series file
            raise OmavctlError(
                "not an evaluation JSON: a NumPy .npz archive (a model or a series file); "
                "report reads the JSON that `omavctl evaluate --out FILE.json` writes",
                p,
            )
        text = raw.decode("utf-8")
    except FileNotFoundError:
        raise OmavctlError("file not found", p) from None
    except IsADirectoryError:
        raise OmavctlError("is a directory, not an evaluation JSON", p) from None
    except OSError as err:
        raise OmavctlError(f"cannot read: {err.strerror or err}", p) from None
    except UnicodeDecodeError:
        raise OmavctlError("not an evaluation JSON: it is not UTF-8 text", p) from None
    try:
        tree = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as err:
        raise OmavctlError(
            f"not an evaluation JSON: invalid JSON at line {err.lineno} column {err.colno}", p
        ) from None
    except (ValueError, RecursionError) as err:
        raise OmavctlError(f"not an evaluation JSON: {err}", p) from None
    if isinstance(tree, dict) and "schema" not in tree and "command" in tree:
        raise OmavctlError(
            f"not an evaluation JSON: the --json summary `omavctl {str(tree['command'])[:20]}` "
            "prints; report reads the file that `omavctl evaluate --out FILE.json` writes",
            p,
        )
    if not isinstance(tree, dict) or "schema" not in tree:
        raise OmavctlError("not an evaluation JSON: no 'schema' key", p)
    if tree["schema"] != SCHEMA:
        shown = str(tree["schema"])[:60]
        raise OmavctlError(f"schema '{shown}' is not supported (expected {SCHEMA})", p)
    return tree


def _series_meta(tree: Mapping[str, Any], p: Path) -> tuple[Path, str | None, str | None]:
    """Series file, content hash and run id the JSON names (hash/id None: older files)."""
    meta = tree.get("series", {})
    if not isinstance(meta, Mapping):
        raise OmavctlError("'series' must be an object naming the time series file", p)
    name = meta.get("file", series_path(p).name)
    if not isinstance(name, str) or not name or Path(name).name != name:
        raise OmavctlError("'series.file' must be a file name beside the JSON", p)
    digest, run_id = meta.get("sha256"), meta.get(RUN_ID_KEY)
    if (digest is None) != (run_id is None) or not all(
        v is None or isinstance(v, str) for v in (digest, run_id)
    ):
        raise OmavctlError("'series.sha256' and 'series.run_id' must be strings", p)
    return p.with_name(name), digest, run_id


def _read_series(spath: Path, p: Path) -> dict[str, np.ndarray]:
    try:
        with spath.open("rb") as fh:
            data = np.load(fh, allow_pickle=False)
            if not isinstance(data, np.lib.npyio.NpzFile):
                raise ValueError("not an .npz archive")
            with data:
                return {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise OmavctlError(f"its time series file {spath.name} is missing", p) from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as err:
        if "pickle" in str(err).lower():
            reason = "it holds pickled data"
        else:
            reason = "not an .npz file or damaged"
        raise OmavctlError(f"unreadable time series {spath.name}: {reason}", p) from None


def load_evaluation(path: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read an evaluation JSON and its series; refuses other schemas and a series
    that does not belong to the JSON (another run, or changed)."""
    p = Path(path)
    tree = _read_tree(p)
    spath, digest, run_id = _series_meta(tree, p)
    if digest is not None and _run_id(tree, digest) != run_id:
        raise OmavctlError(
            "changed after evaluate wrote it (its content does not match its run id): "
            "run evaluate again",
            p,
        )
    series = _read_series(spath, p)
    if digest is not None:
        stored = series.pop(RUN_ID_KEY, None)
        stored_id = str(stored) if stored is not None and stored.shape == () else None
        if stored_id != run_id or series_digest(series) != digest:
            raise OmavctlError(
                f"its time series file {spath.name} belongs to another run of evaluate "
                "(run id or content hash differs): run evaluate again",
                p,
            )
    return tree, series
