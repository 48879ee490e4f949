"""A plain byte form of an in-process component's state (numbers, arrays, nested tuples).

In-process components (:mod:`cosim.scenario.inprocess`) save their state as Python objects;
a checkpoint needs bytes, and reading them must run no code (no pickle). :func:`encode` writes
JSON in which a float is a JSON number (Python writes its shortest ``repr``, which reads back
bit for bit; NaN and infinities as Python's JSON extension does), a bool or int itself, a tuple
or list a JSON list, None null, and a numpy array ``{"dtype", "shape", "hex"}`` (its bytes, little-endian,
C order). :func:`decode` returns tuples for lists and arrays for the arrays, and refuses
anything else (ValueError, one line).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

__all__ = ["decode", "encode"]

_DTYPES = ("<f8", "<i8", "|b1")


def _plain(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        arr = np.ascontiguousarray(obj).astype(obj.dtype.newbyteorder("<"), copy=False)
        if arr.dtype.str not in _DTYPES:
            raise TypeError(f"a state array of dtype {obj.dtype} (allowed: {_DTYPES})")
        return {"dtype": arr.dtype.str, "shape": list(arr.shape), "hex": arr.tobytes().hex()}
    if isinstance(obj, (tuple, list)):
        return [_plain(v) for v in obj]
    if obj is None:
        return None
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj)
    raise TypeError(f"a state holds a {type(obj).__name__}; allowed: numbers, arrays, tuples, None")


def encode(state: Any) -> bytes:
    """``state`` (nested tuples/lists of numbers and numpy arrays) as UTF-8 JSON bytes."""
    return json.dumps(_plain(state), separators=(",", ":")).encode("utf-8")


def _object(obj: Any) -> Any:
    if isinstance(obj, list):
        return tuple(_object(v) for v in obj)
    if isinstance(obj, dict):
        if set(obj) != {"dtype", "shape", "hex"} or obj["dtype"] not in _DTYPES:
            raise ValueError(f"not a state array: {sorted(obj)}")
        shape = tuple(int(n) for n in obj["shape"])
        arr = np.frombuffer(bytes.fromhex(obj["hex"]), dtype=np.dtype(obj["dtype"]))
        return arr.reshape(shape).astype(arr.dtype.newbyteorder("="))
    if obj is None or isinstance(obj, (bool, int, float)):
        return obj
    raise ValueError(f"not a state value: {type(obj).__name__}")


def decode(data: bytes) -> Any:
    """The state :func:`encode` wrote; ValueError if ``data`` is not such a state."""
    try:
        return _object(json.loads(bytes(data).decode("utf-8")))
    except (UnicodeDecodeError, json.JSONDecodeError, TypeError, KeyError) as exc:
        raise ValueError(f"not a serialized in-process state ({exc})") from None
