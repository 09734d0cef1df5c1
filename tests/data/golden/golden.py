"""The golden files of this folder: what the code before gave on the tests' inputs, recorded
once by ``record.py`` from a git revision that still held that code (README.md).

A golden file is a compressed ``.npz``: its arrays by name, and ``facts``, one JSON document
of plain values (numbers, strings, lists, mappings) beside them. Floats go through JSON as
Python writes them (``repr``), which reads back to the same bits; ``plain`` turns the
results the tests compare (dataclasses, enums, NumPy arrays and scalars) into such values, so
that a result of the code now and its recorded twin compare equal exactly when they were
equal field by field.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


class Golden:
    """A golden file read: ``facts`` (the JSON document) and its arrays by name (``g[name]``)."""

    def __init__(self, name: str):
        path = HERE / f"{name}.npz"
        if not path.exists():
            raise FileNotFoundError(f"{path} is missing: record it with "
                                    f"python tests/data/golden/record.py (README.md there)")
        with np.load(path, allow_pickle=False) as z:
            self.arrays = {k: z[k] for k in z.files if k != "facts"}
            self.facts = json.loads(str(z["facts"]))
        self.name = name

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]

    def check_inputs(self, digest: str) -> None:
        """Refuse to compare results of other inputs than those the file was recorded on."""
        assert digest == self.facts["inputs"], (
            f"the inputs of {self.name} are not those it was recorded on (the test's input "
            f"generator changed?): record it again, tests/data/golden/README.md")


def save(name: str, facts: dict, **arrays: np.ndarray) -> Path:
    path = HERE / f"{name}.npz"
    np.savez_compressed(path, facts=np.array(json.dumps(plain(facts), sort_keys=True)), **arrays)
    return path


def plain(obj):
    """``obj`` as plain JSON values: a dataclass as a mapping of its fields (and its class's
    name), an enum as its value, an array as its dtype, shape and values."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {"class": type(obj).__name__,
                **{f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}}
    if isinstance(obj, enum.Enum):
        return plain(obj.value)
    if isinstance(obj, np.ndarray):
        return {"dtype": str(obj.dtype), "shape": list(obj.shape), "values": plain(obj.tolist())}
    if isinstance(obj, np.generic):
        return plain(obj.item())
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, bool) or obj is None or isinstance(obj, (int, str)):
        return obj
    if isinstance(obj, float):
        return float(obj)
    raise TypeError(f"no plain form for {type(obj).__name__}")


def as_recorded(obj):
    """``obj`` as it reads back from a golden file (to compare with ``==``)."""
    return json.loads(json.dumps(plain(obj), sort_keys=True))


def fingerprint(*objs) -> str:
    """SHA-256 of the values of ``objs``: arrays by dtype, shape and bytes, floats by their
    bits, dataclasses by class name and fields."""
    h = hashlib.sha256()
    for obj in objs:
        _feed(h, obj)
    return h.hexdigest()


def _feed(h, obj) -> None:
    if isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"a{a.dtype.str}{a.shape}".encode())
        h.update(a.data)
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(f"d{type(obj).__name__}".encode())
        for f in dataclasses.fields(obj):
            _feed(h, getattr(obj, f.name))
    elif isinstance(obj, (list, tuple)):
        h.update(f"l{len(obj)}".encode())
        for v in obj:
            _feed(h, v)
    elif isinstance(obj, dict):
        h.update(f"m{len(obj)}".encode())
        for k in sorted(obj):
            _feed(h, k)
            _feed(h, obj[k])
    elif isinstance(obj, (float, np.floating)):
        h.update(b"f" + float(obj).hex().encode() if math.isfinite(obj) else repr(obj).encode())
    else:
        h.update(f"{type(obj).__name__}:{obj!r}".encode())


def pack(arrays: list) -> tuple[np.ndarray, np.ndarray]:
    """A list of 1-D arrays (or None) as one array of their values and one of their lengths
    (-1 for None)."""
    lengths = np.array([-1 if a is None else len(a) for a in arrays], np.int64)
    kept = [a for a in arrays if a is not None]
    return (np.concatenate(kept) if kept else np.zeros(0)), lengths


def unpack(values: np.ndarray, lengths: np.ndarray) -> list:
    out, at = [], 0
    for n in lengths.tolist():
        out.append(None if n < 0 else values[at:at + n])
        at += max(n, 0)
    return out


def array_digest(a: np.ndarray) -> str:
    """SHA-256 of an array's dtype, shape and bytes (particle sets kept as their digests)."""
    return fingerprint(np.asarray(a))
