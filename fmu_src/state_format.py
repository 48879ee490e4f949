"""The serialized FMU state of every drillcosim FMU, read and written in Python.

Every FMU of the project (the pythonfmu adapters through the C wrapper, and the C controller)
serializes its state (``fmi2SerializeFMUstate``) in one versioned format, written and checked in
C by ``fmu_src/wrapper/dcs_state_format.c``; this module is its second implementation (hashlib's
SHA-256), for tools that look into a state without loading the FMU (checkpoints, tests).
Format version 1 (all integers little-endian; docs/reliability.md, "FMU state"):

======  ======  ===============================================================================
offset  bytes   field
======  ======  ===============================================================================
0       8       magic ``b"DCSSTATE"``
8       4       format version (uint32) = 1
12      4       phase (uint32): the FMI 2.0 state the instance was in when the state was taken:
                1 Instantiated, 2 InitializationMode, 4 StepComplete, 8 Terminated
16      4       length m of the model identifier (uint32, 1..255)
20      4       length b of the build identifier (uint32, 0..255)
24      8       length n of the payload (uint64)
32      m       model identifier (ASCII, modelDescription.xml's ``modelIdentifier``)
32+m    b       build identifier (ASCII): ``build`` of ``resources/dcs_build.json`` (the hash
                of the FMU's code and resources), for the C controller the hash of its sources
32+m+b  n       payload, FMU-specific: UTF-8 JSON for the pythonfmu adapters
                (``{"variables": {name: value}, "internal": {...}}``), a fixed little-endian
                layout for the C controller (``fmu_src/c_controller/fmi2_cosimulation.c``)
end-32  32      SHA-256 of every byte before it
======  ======  ===============================================================================

An FMU refuses (fmi2Error, one line naming why) a state that is too short, has another magic
or version, lengths that do not add up, a checksum that does not match, another model
identifier or another build; the content is then checked as a parameter set would be before
anything of it is applied.
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass

__all__ = ["DIGEST_SIZE", "FORMAT_VERSION", "HEADER_SIZE", "MAGIC", "PHASES", "FmuState",
           "read_state", "write_state"]

MAGIC = b"DCSSTATE"
FORMAT_VERSION = 1
#: Bytes of the fixed header (magic, version, phase, three lengths).
HEADER_SIZE = 32
#: Bytes of the SHA-256 at the end.
DIGEST_SIZE = 32
#: Phase code -> name of the FMI 2.0 state (the wrapper's ``DcsState`` bits).
PHASES: dict[int, str] = {1: "Instantiated", 2: "InitializationMode", 4: "StepComplete",
                          8: "Terminated"}
_HEADER = struct.Struct("<8sIIIIQ")


@dataclass(frozen=True)
class FmuState:
    """One serialized FMU state, its parts decoded.

    Attributes
    ----------
    phase : int
        Key of :data:`PHASES`.
    model_identifier : str
    build : str
        Build identifier ("" if the FMU has none).
    payload : bytes
        The FMU's own part.
    version : int
        Format version.
    """

    phase: int
    model_identifier: str
    build: str
    payload: bytes
    version: int = FORMAT_VERSION


def read_state(blob: bytes) -> FmuState:
    """Decode and check a serialized state (not its payload).

    Raises
    ------
    ValueError
        One line naming what is wrong (the FMU's own checks, in the same order).
    """
    blob = bytes(blob)
    if len(blob) < HEADER_SIZE + DIGEST_SIZE:
        raise ValueError(f"{len(blob)} bytes: too short for a serialized FMU state (at least "
                         f"{HEADER_SIZE + DIGEST_SIZE})")
    magic, version, phase, m, b, n = _HEADER.unpack_from(blob)
    if magic != MAGIC:
        raise ValueError(f"not a serialized drillcosim FMU state (it does not start with "
                         f"{MAGIC.decode()})")
    if version != FORMAT_VERSION:
        raise ValueError(f"format version {version}; this reader reads version {FORMAT_VERSION}")
    if HEADER_SIZE + m + b + n + DIGEST_SIZE != len(blob):
        raise ValueError(f"damaged: the lengths in its header ({m} + {b} + {n}) do not match "
                         f"its {len(blob)} bytes")
    if hashlib.sha256(blob[:-DIGEST_SIZE]).digest() != blob[-DIGEST_SIZE:]:
        raise ValueError("damaged: its SHA-256 checksum does not match its content")
    if phase not in PHASES:
        raise ValueError(f"unknown phase {phase}")
    start = HEADER_SIZE
    model = blob[start:start + m].decode("ascii")
    build = blob[start + m:start + m + b].decode("ascii")
    return FmuState(phase, model, build, blob[start + m + b:-DIGEST_SIZE], version)


def write_state(state: FmuState) -> bytes:
    """The serialized bytes of ``state`` (sealed with its SHA-256)."""
    model = state.model_identifier.encode("ascii")
    build = state.build.encode("ascii")
    body = (_HEADER.pack(MAGIC, state.version, state.phase, len(model), len(build),
                         len(state.payload)) + model + build + state.payload)
    return body + hashlib.sha256(body).digest()
