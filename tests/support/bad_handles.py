"""Pass an FMU's C library handles a host should not pass, and print what it returned.

``python bad_handles.py LIB GUID CASE`` (``tests/`` on ``PYTHONPATH``) loads the shared
library ``LIB`` with ctypes (no fmpy FMU2Slave: fmpy would refuse some of these calls
itself), makes live, initialized instances with the token ``GUID`` (no resource location: the
C controller needs none) and runs one case of :data:`CASES`; it prints one JSON line
``{"calls": {call: status}, "errors": [message, ...]}`` (the fmi2Error messages sent to the
logger, without the instance name). A library that reads or frees the handle's memory crashes
here (glibc aborts a double free; under AddressSanitizer any such access aborts with a
report); one that looks handles up answers :data:`EXPECTED`. One case per process: the first
crash would hide the rest.
"""

from __future__ import annotations

import ctypes
import json
import sys
from ctypes import byref, c_char_p, c_double, c_int, c_size_t, c_uint, c_void_p

from support.fmi_logging import RecordingCallbacks

OK, ERROR = 0, 3
#: Never a valid handle: Linux maps nothing below ``vm.mmap_min_addr`` (64 KiB by default).
MADE_UP = 0x1000
NOT_A_STATE = "not a state of this FMU"

#: What each case returns once handles are looked up (FMI 2.0: a call with an invalid argument
#: is fmi2Error; fmi2FreeInstance has no status; fmi2GetFMUstate of a state it does not know
#: makes a new one), and the fmi2Error messages the live instances log.
EXPECTED: dict[str, dict] = {
    "instance used after its free": {
        "calls": {"fmi2DoStep": ERROR, "fmi2GetReal": ERROR, "fmi2SetReal": ERROR,
                  "fmi2GetFMUstate": ERROR, "fmi2Reset": ERROR, "fmi2Terminate": ERROR},
        "errors": []},  # no instance, no logger: nothing can be said
    "instance freed twice": {"calls": {"second fmi2DoStep": ERROR}, "errors": []},
    "state freed twice": {
        "calls": {"fmi2GetFMUstate": OK, "fmi2FreeFMUstate": OK, "second fmi2FreeFMUstate": ERROR},
        "errors": [f"fmi2FreeFMUstate: {NOT_A_STATE}"]},
    "state used after its free": {
        "calls": {"fmi2GetFMUstate": OK, "fmi2FreeFMUstate": OK,
                  "fmi2SerializedFMUstateSize": ERROR, "fmi2SerializeFMUstate": ERROR,
                  "fmi2SetFMUstate": ERROR, "fmi2GetFMUstate into it": OK,
                  "fmi2DeSerializeFMUstate into it": OK, "fmi2FreeFMUstate (new ones)": OK},
        "errors": [f"fmi2SerializedFMUstateSize: {NOT_A_STATE}",
                   f"fmi2SerializeFMUstate: {NOT_A_STATE}", f"fmi2SetFMUstate: {NOT_A_STATE}"]},
    "made-up pointer": {
        "calls": {"fmi2DoStep": ERROR, "fmi2SetupExperiment": ERROR, "fmi2SetFMUstate": ERROR,
                  "fmi2FreeFMUstate": ERROR},
        "errors": [f"fmi2SetFMUstate: {NOT_A_STATE}", f"fmi2FreeFMUstate: {NOT_A_STATE}"]},
}
CASES = tuple(EXPECTED)

def _declare(lib: ctypes.CDLL) -> None:
    lib.fmi2Instantiate.restype = c_void_p
    lib.fmi2Instantiate.argtypes = [c_char_p, c_int, c_char_p, c_char_p, c_void_p, c_int, c_int]
    for name in ("fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Reset",
                 "fmi2Terminate", "fmi2FreeInstance"):
        getattr(lib, name).argtypes = [c_void_p]
    lib.fmi2FreeInstance.restype = None
    lib.fmi2SetupExperiment.argtypes = [c_void_p, c_int, c_double, c_double, c_int, c_double]
    lib.fmi2DoStep.argtypes = [c_void_p, c_double, c_double, c_int]
    lib.fmi2GetReal.argtypes = lib.fmi2SetReal.argtypes = [c_void_p, c_void_p, c_size_t,
                                                           c_void_p]
    lib.fmi2GetFMUstate.argtypes = lib.fmi2FreeFMUstate.argtypes = [c_void_p, c_void_p]
    lib.fmi2SetFMUstate.argtypes = [c_void_p, c_void_p]
    lib.fmi2SerializedFMUstateSize.argtypes = [c_void_p, c_void_p, c_void_p]
    lib.fmi2SerializeFMUstate.argtypes = [c_void_p, c_void_p, c_void_p, c_size_t]
    lib.fmi2DeSerializeFMUstate.argtypes = [c_void_p, c_void_p, c_size_t, c_void_p]


def run(path: str, guid: str, case: str) -> dict:
    """Run ``case`` on the library at ``path``; returns ``{"calls": ..., "errors": ...}``."""
    lib = ctypes.CDLL(path)
    _declare(lib)
    recorder = RecordingCallbacks()  # formats the variadic message (fmpy's logger proxy)
    live: list[int] = []

    def instantiate() -> int:
        c = lib.fmi2Instantiate(b"bad", 1, guid.encode(), None, byref(recorder.callbacks), 0, 0)
        assert c, "fmi2Instantiate failed"
        assert (lib.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0), lib.fmi2EnterInitializationMode(c),
                lib.fmi2ExitInitializationMode(c)) == (OK, OK, OK)
        live.append(c)
        return c

    vr, value = (c_uint * 1)(0), (c_double * 1)(1e-6)
    calls: dict[str, int] = {}
    if case == "instance used after its free":
        c = instantiate()
        live.remove(c)
        lib.fmi2FreeInstance(c)
        state = c_void_p()
        calls = {"fmi2DoStep": lib.fmi2DoStep(c, 0.0, 1e-3, 1),
                 "fmi2GetReal": lib.fmi2GetReal(c, vr, 1, value),
                 "fmi2SetReal": lib.fmi2SetReal(c, vr, 1, value),
                 "fmi2GetFMUstate": lib.fmi2GetFMUstate(c, byref(state)),
                 "fmi2Reset": lib.fmi2Reset(c), "fmi2Terminate": lib.fmi2Terminate(c)}
    elif case == "instance freed twice":
        c = instantiate()
        live.remove(c)
        lib.fmi2FreeInstance(c)
        lib.fmi2FreeInstance(c)  # ignored
        calls = {"second fmi2DoStep": lib.fmi2DoStep(c, 0.0, 1e-3, 1)}
    elif case == "state freed twice":
        c = instantiate()
        state = c_void_p()
        calls["fmi2GetFMUstate"] = lib.fmi2GetFMUstate(c, byref(state))
        again = c_void_p(state.value)
        calls["fmi2FreeFMUstate"] = lib.fmi2FreeFMUstate(c, byref(state))
        calls["second fmi2FreeFMUstate"] = lib.fmi2FreeFMUstate(c, byref(again))
    elif case == "state used after its free":
        # a fresh instance per call: an fmi2Error leaves the instance in its error state
        c = instantiate()
        state = c_void_p()
        calls["fmi2GetFMUstate"] = lib.fmi2GetFMUstate(c, byref(state))
        freed = state.value
        size = c_size_t(0)
        blob = (ctypes.c_char * 4096)()
        calls["fmi2FreeFMUstate"] = lib.fmi2FreeFMUstate(c, byref(state))
        calls["fmi2SerializedFMUstateSize"] = lib.fmi2SerializedFMUstateSize(
            instantiate(), freed, byref(size))
        calls["fmi2SerializeFMUstate"] = lib.fmi2SerializeFMUstate(instantiate(), freed, blob,
                                                                   len(blob))
        calls["fmi2SetFMUstate"] = lib.fmi2SetFMUstate(instantiate(), freed)
        # FMI 2.0: a state given to fmi2GetFMUstate is overwritten: one not (any more) known
        # must not be written through, a new one is made
        c = instantiate()
        into = c_void_p(freed)
        calls["fmi2GetFMUstate into it"] = lib.fmi2GetFMUstate(c, byref(into))
        good = c_void_p()
        assert lib.fmi2GetFMUstate(c, byref(good)) == OK
        assert lib.fmi2SerializedFMUstateSize(c, good, byref(size)) == OK
        assert lib.fmi2SerializeFMUstate(c, good, blob, size.value) == OK
        into2 = c_void_p(freed)
        calls["fmi2DeSerializeFMUstate into it"] = lib.fmi2DeSerializeFMUstate(
            c, blob, size.value, byref(into2))
        # the allocator may give a new state the freed one's address: free each once
        calls["fmi2FreeFMUstate (new ones)"] = max(
            lib.fmi2FreeFMUstate(c, byref(c_void_p(p)))
            for p in dict.fromkeys(s.value for s in (into, good, into2)))
    elif case == "made-up pointer":
        c = instantiate()
        lib.fmi2FreeInstance(MADE_UP)  # ignored
        calls["fmi2DoStep"] = lib.fmi2DoStep(MADE_UP, 0.0, 1e-3, 1)
        calls["fmi2SetupExperiment"] = lib.fmi2SetupExperiment(MADE_UP, 0, 0.0, 0.0, 0, 0.0)
        calls["fmi2SetFMUstate"] = lib.fmi2SetFMUstate(c, MADE_UP)
        made_up = c_void_p(MADE_UP)
        calls["fmi2FreeFMUstate"] = lib.fmi2FreeFMUstate(instantiate(), byref(made_up))
    else:
        raise SystemExit(f"unknown case {case!r}; one of {', '.join(CASES)}")
    for c in live:
        lib.fmi2FreeInstance(c)
    errors = [m.removeprefix("bad: ") for status, m in recorder.messages if status == ERROR]
    return {"calls": calls, "errors": errors}


if __name__ == "__main__":
    print(json.dumps(run(*sys.argv[1:4])))
