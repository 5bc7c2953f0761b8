"""The evaluation's time series as an MCAP file for Foxglove Studio and PlotJuggler.

One channel per series, JSON encoding with a JSON schema, on the log's own
time stamps (the log's clock: ``t0`` of the log + the grid time), so that the
file opens beside the flight's own topics:

- ``/omavctl/measured`` measured angular acceleration {x, y, z}, rad/s^2;
- ``/omavctl/nominal`` the nominal (rigid-body) prediction;
- ``/omavctl/physics`` nominal + the model's fitted effects (physics only);
- ``/omavctl/predicted`` nominal + effects + GP mean;
- ``/omavctl/band_2sigma`` the predicted ±2 sigma band {x_low, x_high, ...};
- ``/omavctl/worst_segments`` a marker at the start (active 1) and the end
  (active 0) of each worst segment, with its rank, RMSE and what the vehicle did.

With several models, each model's channels carry its index: ``/omavctl/model1/predicted``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from omavctl.base.atomic import atomic_path
from omavctl.base.replace import is_mcap_from
from omavctl.diagnose.verdict import activity

__all__ = ["TOPICS", "is_series_mcap", "mcap_path", "write_series_mcap"]

AXES = ("x", "y", "z")
PREFIX = "/omavctl"
TOPICS = ("measured", "nominal", "physics", "predicted", "band_2sigma", "worst_segments")

_VECTOR = {
    "title": "omavctl.AngularAcceleration",
    "description": "Angular acceleration in the body frame (FLU), rad/s^2",
    "type": "object",
    "properties": {a: {"type": "number"} for a in AXES},
    "required": list(AXES),
}
_BAND = {
    "title": "omavctl.Band2Sigma",
    "description": "Predicted angular acceleration ±2 sigma per body axis, rad/s^2",
    "type": "object",
    "properties": {f"{a}_{s}": {"type": "number"} for a in AXES for s in ("low", "high")},
}
_SEGMENT = {
    "title": "omavctl.WorstSegment",
    "description": "Start (active 1) or end (active 0) of a worst segment of the model",
    "type": "object",
    "properties": {
        "rank": {"type": "integer"},
        "active": {"type": "integer"},
        "start": {"type": "number"},
        "end": {"type": "number"},
        "rmse_x": {"type": "number"},
        "rmse_y": {"type": "number"},
        "rmse_z": {"type": "number"},
        "activity": {"type": "string"},
    },
}


def _ns(seconds: float) -> int:
    return max(round(seconds * 1e9), 0)


def _finite(v: Any) -> float | None:
    return float(v) if math.isfinite(v) else None


def _vec(row: np.ndarray) -> dict[str, float | None]:
    return {a: _finite(v) for a, v in zip(AXES, row, strict=True)}


def _messages(
    tree: Mapping[str, Any], series: Mapping[str, np.ndarray]
) -> list[tuple[int, str, dict[str, Any]]]:
    """(log time ns, topic, message) of every series sample and segment marker."""
    t = np.asarray(series["t"], float)
    log_id = np.asarray(series["log"]).astype(int)
    logs = tree.get("logs") or []
    t0 = np.array([float(lg.get("t0", 0.0) or 0.0) for lg in logs] or [0.0])
    # nanoseconds: the log's start and the grid offset rounded separately (float
    # seconds since the epoch hold only ~0.2 us)
    base = np.array([round(v * 1e9) for v in t0], dtype=np.int64)
    stamp = base[np.clip(log_id, 0, t0.size - 1)] + np.round(t * 1e9).astype(np.int64)
    nominal = np.asarray(series["nominal"], float)
    n_models = len(tree.get("models") or []) or 1
    per_topic: dict[str, np.ndarray] = {
        f"{PREFIX}/measured": np.asarray(series["measured"], float),
        f"{PREFIX}/nominal": nominal,
    }
    bands: dict[str, np.ndarray] = {}
    for j in range(n_models):
        if f"mean_{j}" not in series:
            continue
        pre = f"{PREFIX}/model{j}" if n_models > 1 else PREFIX
        mean = nominal + np.asarray(series[f"mean_{j}"], float)
        std = np.asarray(series[f"std_{j}"], float)
        if f"effects_{j}" in series:
            per_topic[f"{pre}/physics"] = nominal + np.asarray(series[f"effects_{j}"], float)
        per_topic[f"{pre}/predicted"] = mean
        bands[f"{pre}/band_2sigma"] = np.stack([mean - 2 * std, mean + 2 * std], axis=-1)
    out: list[tuple[int, str, dict[str, Any]]] = []
    for topic, values in per_topic.items():
        out += [(int(s), topic, _vec(v)) for s, v in zip(stamp, values, strict=True)]
    for topic, band in bands.items():
        for s, row in zip(stamp, band, strict=True):
            band_msg = {
                f"{a}_{k}": _finite(row[i, j])
                for i, a in enumerate(AXES)
                for j, k in ((0, "low"), (1, "high"))
            }
            out.append((int(s), topic, band_msg))
    names = [str(lg.get("name", "")) for lg in logs]
    for rank, seg in enumerate(tree.get("worst_segments") or [], start=1):
        i = names.index(seg.get("log")) if seg.get("log") in names else 0
        origin = float(t0[min(i, t0.size - 1)])
        start, end = float(seg.get("start", 0.0)), float(seg.get("end", 0.0))
        rmse = seg.get("rmse") or {}
        msg: dict[str, Any] = {
            "rank": rank,
            "start": origin + start,
            "end": origin + end,
            **{f"rmse_{a}": float(rmse.get(a, 0.0)) for a in AXES},
            "activity": activity(seg),
        }
        b = int(base[min(i, base.size - 1)])
        out.append((b + _ns(start), f"{PREFIX}/worst_segments", {**msg, "active": 1}))
        out.append((b + _ns(end), f"{PREFIX}/worst_segments", {**msg, "active": 0}))
    out.sort(key=lambda m: m[0])
    return out


def _schema_of(topic: str) -> tuple[str, dict[str, Any]]:
    if topic.endswith("/band_2sigma"):
        return "omavctl.Band2Sigma", _BAND
    if topic.endswith("/worst_segments"):
        return "omavctl.WorstSegment", _SEGMENT
    return "omavctl.AngularAcceleration", _VECTOR


def is_series_mcap(path: Path) -> bool:
    """Whether ``path`` is an MCAP file :func:`write_series_mcap` wrote (library
    ``omavctl``, no profile; ``simulate``'s logs have the ``ros2`` profile): what
    ``evaluate --mcap`` may replace."""
    return is_mcap_from(path, "omavctl", "")


def write_series_mcap(
    out: str | Path, tree: Mapping[str, Any], series: Mapping[str, np.ndarray]
) -> list[str]:
    """Write the MCAP file atomically; returns its topics (one channel each)."""
    from mcap.writer import Writer

    messages = _messages(tree, series)
    topics: list[str] = list(dict.fromkeys(topic for _, topic, _ in messages))
    with atomic_path(Path(out)) as tmp, tmp.open("wb") as fh:
        writer = Writer(fh)
        writer.start(profile="", library="omavctl")
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}
        for topic in topics:
            name, schema = _schema_of(topic)
            if name not in schemas:
                schemas[name] = writer.register_schema(
                    name=name, encoding="jsonschema", data=json.dumps(schema).encode()
                )
            channels[topic] = writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schemas[name]
            )
        seq: dict[str, int] = dict.fromkeys(topics, 0)
        for ns, topic, msg in messages:
            writer.add_message(
                channel_id=channels[topic],
                log_time=ns,
                publish_time=ns,
                sequence=seq[topic],
                data=json.dumps(msg, allow_nan=False).encode(),
            )
            seq[topic] += 1
        writer.finish()
    return topics


def mcap_path(out: str | Path) -> Path:
    """Default MCAP beside an evaluation JSON: ``<stem>.series.mcap``."""
    p = Path(out)
    return p.with_name(p.stem + ".series.mcap")
