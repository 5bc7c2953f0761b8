"""Seeded mutations of omavctl's inputs: bytes, CSV text, YAML, .npz members, JSON.

Every mutator takes ``(rng, data)`` and returns ``(new_data, description,
must_fail)``: ``must_fail`` is True when the result is invalid by construction
(a command that exits 0 on it is wrong whatever it writes); otherwise a
command may refuse it or succeed with a finite, schema-valid output.
"""

from __future__ import annotations

import io
import json
import random
import zipfile
from collections.abc import Callable
from typing import Any

import numpy as np
import yaml

Mutation = tuple[bytes, str, bool]

#: Replacement cell values for CSVs: (text, invalid by construction?).
BAD_CELLS: list[tuple[str, bool]] = [
    ("nan", True),
    ("NaN", True),
    ("inf", True),
    ("-inf", True),
    ("1e300", True),
    ("-1e300", True),
    ("1e999", True),
    ("", True),
    ("abc", True),
    ("0x10", True),
    ("1e-300", False),
    ("0", False),
    ("-0", False),
    (" 1.5 ", False),
    ("1e6", False),
]

#: Replacement values for numbers in YAML/JSON trees: (value, invalid by construction?).
BAD_NUMBERS: list[tuple[Any, bool]] = [
    (float("nan"), True),
    (float("inf"), True),
    (-float("inf"), True),
    (0.0, False),
    (-1.0, False),
    (1e-300, False),
    (1e300, False),
    ("abc", True),
    (None, False),
    ([], False),
    ({}, False),
    (True, False),
    ([1.0, 2.0], False),
]


# ------------------------------------------------------------------ bytes
def truncate(rng: random.Random, data: bytes) -> Mutation:
    cut = rng.randrange(0, max(1, len(data)))
    return data[:cut], f"truncated to {cut} of {len(data)} bytes", cut == 0


def flip_bits(rng: random.Random, data: bytes) -> Mutation:
    buf = bytearray(data)
    n = rng.choice([1, 2, 8, 64])
    for _ in range(n):
        if buf:
            i = rng.randrange(len(buf))
            buf[i] ^= 1 << rng.randrange(8)
    return bytes(buf), f"{n} bits flipped", False


def overwrite_chunk(rng: random.Random, data: bytes) -> Mutation:
    if not data:
        return data, "empty", True
    i = rng.randrange(len(data))
    n = rng.choice([4, 16, 256, 4096])
    fill = rng.choice([b"\x00", b"\xff", None])
    chunk = bytes(rng.randrange(256) for _ in range(n)) if fill is None else fill * n
    return data[:i] + chunk[: len(data) - i] + data[i + n :], f"{n} bytes overwritten at {i}", False


def delete_chunk(rng: random.Random, data: bytes) -> Mutation:
    if not data:
        return data, "empty", True
    i = rng.randrange(len(data))
    n = rng.choice([1, 7, 100, 1000])
    return data[:i] + data[i + n :], f"{n} bytes deleted at {i}", False


def duplicate_chunk(rng: random.Random, data: bytes) -> Mutation:
    if not data:
        return data, "empty", True
    i = rng.randrange(len(data))
    n = rng.choice([8, 100, 1000])
    return data[:i] + data[i : i + n] + data[i:], f"{n} bytes duplicated at {i}", False


def empty(rng: random.Random, data: bytes) -> Mutation:
    return b"", "emptied", True


def garbage(rng: random.Random, data: bytes) -> Mutation:
    n = rng.choice([1, 10, 1000, 100000])
    return bytes(rng.randrange(256) for _ in range(n)), f"{n} random bytes", True


def text_garbage(rng: random.Random, data: bytes) -> Mutation:
    return b"#ROSBAG V2.0\nthis is not what it claims\n" * 5, "text pretending a header", True


BYTE_MUTATORS: list[Callable[[random.Random, bytes], Mutation]] = [
    truncate,
    truncate,
    flip_bits,
    flip_bits,
    overwrite_chunk,
    delete_chunk,
    duplicate_chunk,
    empty,
    garbage,
    text_garbage,
]


# ------------------------------------------------------------------ CSV text
def _rows(data: bytes) -> list[list[str]]:
    return [line.split(",") for line in data.decode().splitlines()]


def _join(rows: list[list[str]]) -> bytes:
    return ("\n".join(",".join(r) for r in rows) + "\n").encode()


def csv_cell(rng: random.Random, data: bytes, required: set[str] | None = None) -> Mutation:
    """Replace one cell. Invalid by construction only in a required column."""
    rows = _rows(data)
    i = rng.randrange(1, len(rows))
    j = rng.randrange(len(rows[0]))
    value, bad = rng.choice(BAD_CELLS)
    rows[i][j] = value
    column = rows[0][j]
    invalid = bad and (required is None or column in required)
    return _join(rows), f"cell row {i} column '{column}' = {value!r}", invalid


def csv_structure(rng: random.Random, data: bytes) -> Mutation:
    rows = _rows(data)
    what = rng.choice(
        ["drop_column", "rename_column", "dup_row", "swap_rows", "keep_rows", "short_row",
         "no_header", "extra_column", "crlf", "bom", "non_utf8", "all_same_t"]
    )  # fmt: skip
    if what == "drop_column":
        j = rng.randrange(len(rows[0]))
        desc = f"column '{rows[0][j]}' dropped"
        rows = [r[:j] + r[j + 1 :] for r in rows]
        return _join(rows), desc, j == 0
    if what == "rename_column":
        j = rng.randrange(len(rows[0]))
        desc = f"column '{rows[0][j]}' renamed"
        rows[0][j] = rows[0][j] + "_x"
        return _join(rows), desc, j == 0
    if what == "dup_row":
        i = rng.randrange(1, len(rows))
        rows.insert(i, list(rows[i]))
        return _join(rows), f"row {i} duplicated", False
    if what == "swap_rows":
        i = rng.randrange(1, len(rows) - 1)
        rows[i], rows[i + 1] = rows[i + 1], rows[i]
        return _join(rows), f"rows {i} and {i + 1} swapped", False
    if what == "keep_rows":
        n = rng.choice([0, 1, 2, 3, 5])
        return _join(rows[: n + 1]), f"only {n} rows kept", n < 2
    if what == "short_row":
        i = rng.randrange(1, len(rows))
        rows[i] = rows[i][: max(1, len(rows[i]) // 2)]
        return _join(rows), f"row {i} cut short", True
    if what == "no_header":
        return _join(rows[1:]), "header removed", True
    if what == "extra_column":
        rows[0].append("extra")
        for r in rows[1:]:
            r.append(str(rng.random()))
        return _join(rows), "extra column", False
    if what == "crlf":
        return data.replace(b"\n", b"\r\n"), "CRLF line ends", False
    if what == "bom":
        return b"\xef\xbb\xbf" + data, "UTF-8 byte-order mark", False
    if what == "non_utf8":
        i = rng.randrange(len(data))
        return data[:i] + b"\xff\xfe" + data[i:], "non-UTF-8 bytes", True
    for r in rows[1:]:
        r[0] = rows[1][0]
    return _join(rows), "every t equal", True


# ------------------------------------------------------------------ YAML / JSON trees
def _leaves(tree: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out: list[tuple[Any, ...]] = []
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += [(*path, k)] if not isinstance(v, dict | list) else []
            out += _leaves(v, (*path, k))
            if isinstance(v, dict | list):
                out.append((*path, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            out += [(*path, i), *_leaves(v, (*path, i))]
    return out


def _set(tree: Any, path: tuple[Any, ...], value: Any) -> None:
    for key in path[:-1]:
        tree = tree[key]
    tree[path[-1]] = value


def _delete(tree: Any, path: tuple[Any, ...]) -> None:
    for key in path[:-1]:
        tree = tree[key]
    del tree[path[-1]]


def tree_mutation(
    rng: random.Random, tree: Any, critical: Callable[[tuple[Any, ...]], bool]
) -> tuple[Any, str, bool]:
    """Mutate one node of a YAML/JSON tree. ``critical(path)``: the node must
    hold a finite number for the input to be valid."""
    leaves = _leaves(tree)
    if not leaves:
        return tree, "nothing to mutate", False
    path = rng.choice(leaves)
    name = ".".join(str(p) for p in path)
    if rng.random() < 0.2:
        _delete(tree, path)
        return tree, f"'{name}' deleted", False
    value, bad = rng.choice(BAD_NUMBERS)
    _set(tree, path, value)
    return tree, f"'{name}' = {value!r}", bad and critical(path)


def yaml_mutation(
    rng: random.Random, data: bytes, critical: Callable[[tuple[Any, ...]], bool]
) -> Mutation:
    roll = rng.random()
    if roll < 0.1:
        return b"mass: [4\n  inertia: {", "invalid YAML", True
    if roll < 0.15:
        return b"- just\n- a list\n", "top level a list", True
    if roll < 0.2:
        return b"\xff\xfe\x00garbage", "binary", True
    tree = yaml.safe_load(data) or {}
    tree, desc, bad = tree_mutation(rng, tree, critical)
    return yaml.safe_dump(tree).encode(), desc, bad


def json_mutation(
    rng: random.Random, data: bytes, critical: Callable[[tuple[Any, ...]], bool]
) -> Mutation:
    roll = rng.random()
    if roll < 0.08:
        cut = rng.randrange(len(data))
        return data[:cut], f"JSON truncated at {cut}", True
    if roll < 0.12:
        return b"[]", "JSON array", True
    if roll < 0.16:
        return (
            data.replace(b'"schema": "omavctl.eval/1"', b'"schema": "omavctl.eval/9"'),
            ("schema version 9"),
            True,
        )
    tree = json.loads(data)
    tree, desc, bad = tree_mutation(rng, tree, critical)
    text = json.dumps(tree, allow_nan=True)  # NaN/Infinity literals on purpose
    return text.encode(), desc, bad


# ------------------------------------------------------------------ .npz members
def npz_mutation(rng: random.Random, data: bytes, critical: Callable[[str], bool]) -> Mutation:
    """Change one member of an .npz (drop it, NaN, wrong shape, wrong dtype, scaled)."""
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    key = rng.choice(sorted(arrays))
    arr = arrays[key]
    what = rng.choice(["drop", "nan", "inf", "shape", "dtype", "scale", "zero", "negate"])
    numeric = np.issubdtype(arr.dtype, np.floating) and arr.size > 0
    bad = critical(key)
    if what == "drop":
        del arrays[key]
    elif what in ("nan", "inf") and numeric:
        flat = arr.astype(float).reshape(-1)
        flat[rng.randrange(flat.size)] = np.nan if what == "nan" else np.inf
        arrays[key] = flat.reshape(arr.shape)
    elif what == "shape" and arr.size > 1:
        arrays[key] = arr.reshape(-1)[: arr.size - 1]
    elif what == "dtype":
        arrays[key] = np.array(["not numbers"])
    elif what == "scale" and numeric:
        arrays[key] = arr * rng.choice([1e-300, 1e300, -1.0])
    elif what == "zero" and numeric:
        arrays[key] = np.zeros_like(arr)
    elif what == "negate" and numeric:
        arrays[key] = -arr
    else:
        what, bad = "kept", False
    if key in arrays and np.array_equal(np.asarray(arrays[key]), arr):
        what, bad = f"{what} (no change)", False
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for k, v in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asarray(v), allow_pickle=False)
            zf.writestr(f"{k}.npy", member.getvalue())
    return buf.getvalue(), f"member '{key}': {what}", bad and what in ("drop", "nan", "inf")
