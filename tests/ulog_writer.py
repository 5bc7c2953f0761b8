"""A minimal PX4 ULog writer for tests (format version 1, float fields only).

pyulog reads ULog but does not write it. This writes what the reader needs:
the file header, the flag bits, one format and one "add logged message" per
topic, then every topic's data messages in time order. Specification:
https://docs.px4.io/main/en/dev_log/ulog_file_format.html
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

MAGIC = b"ULog\x01\x12\x35"


def message(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def write_ulog(path: Path, topics: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]) -> None:
    """Write ``topics``: name -> (timestamps (n,) us, fields name -> (n,) or (n, k) values).

    A field of shape (n, k) becomes ``float[k] name`` (columns ``name[0]``..);
    timestamps are uint64, everything else float32.
    """
    out = bytearray(MAGIC + bytes([1]) + struct.pack("<Q", 0))
    out += message(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    rows: list[tuple[int, int, bytes]] = []
    subscriptions = bytearray()  # after every format: the data section starts with them
    for msg_id, (name, (stamps, fields)) in enumerate(topics.items()):
        arrays = {
            k: np.asarray(v, dtype=np.float32).reshape(len(stamps), -1) for k, v in fields.items()
        }
        spec = "".join(
            f"float[{a.shape[1]}] {k};" if a.shape[1] > 1 else f"float {k};"
            for k, a in arrays.items()
        )
        out += message(b"F", f"{name}:uint64_t timestamp;{spec}".encode())
        subscriptions += message(b"A", struct.pack("<BH", 0, msg_id) + name.encode())
        values = np.concatenate(list(arrays.values()), axis=1)
        for t, row in zip(np.asarray(stamps, dtype=np.uint64), values, strict=True):
            payload = struct.pack("<HQ", msg_id, int(t)) + row.astype("<f4").tobytes()
            rows.append((int(t), msg_id, payload))
    out += subscriptions
    for _, _, payload in sorted(rows, key=lambda r: (r[0], r[1])):
        out += message(b"D", payload)
    path.write_bytes(bytes(out))
