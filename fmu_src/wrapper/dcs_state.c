/*
 * FMU state objects (fmi2Get/Set/FreeFMUstate) and their serialization.
 *
 * A state holds the object returned by slave._get_fmu_state() (restored with
 * slave._set_fmu_state(obj)) and, once asked for, its bytes from
 * slave._fmu_state_to_bytes(obj) (cached); bytes become a state again through
 * slave._fmu_state_from_bytes(bytes). FMI 2.0: fmi2GetFMUstate overwrites a state it is given.
 */
#include "dcs_python.h"

#include <stdlib.h>
#include <string.h>

typedef struct {
    PyObject *obj;
    PyObject *bytes; /* cached serialization */
} DcsFmuState;

/* The live states of this library (any instance's): a handle is valid only if listed. */
static DcsRegistry g_states = DCS_REGISTRY_INIT;

static DcsFmuState *as_state(fmi2FMUstate s)
{
    return dcs_registry_contains(&g_states, s) ? (DcsFmuState *)s : NULL;
}

static void drop(DcsFmuState *st)
{
    dcs_decref(st->obj);
    dcs_decref(st->bytes);
    st->obj = st->bytes = NULL;
}

/* Put obj (a new reference, consumed) into *state, reusing a state given; GIL held. */
static fmi2Status store(DcsInstance *in, fmi2FMUstate *state, PyObject *obj, const char *fn)
{
    DcsFmuState *st = as_state(*state);
    fmi2Status status = fmi2OK;
    if (st == NULL) {
        st = (DcsFmuState *)calloc(1, sizeof *st);
        if (st != NULL && dcs_registry_add(&g_states, st) != 0) {
            free(st);
            st = NULL;
        }
    } else {
        drop(st);
    }
    if (st == NULL) {
        dcs_decref(obj);
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s: out of memory", in->name, fn);
        status = fmi2Error;
    } else {
        st->obj = obj;
        *state = st;
    }
    return status;
}

fmi2Status dcs_state_get(DcsInstance *in, fmi2FMUstate *state)
{
    PyGILState_STATE gil = p_PyGILState_Ensure();
    PyObject *obj = p_PyObject_CallMethodObjArgs(dcs_slave_object(in), dcs_py.get_fmu_state,
                                                 NULL);
    fmi2Status status;
    if (obj == NULL) {
        status = dcs_slave_exception(in, "fmi2GetFMUstate");
    } else {
        status = store(in, state, obj, "fmi2GetFMUstate");
        if (status == fmi2OK) {
            dcs_incref(dcs_py.none);
            status = dcs_slave_status(in, dcs_py.none, "fmi2GetFMUstate");
        }
    }
    dcs_slave_drain(in);
    p_PyGILState_Release(gil);
    return status;
}

fmi2Status dcs_state_set(DcsInstance *in, fmi2FMUstate state)
{
    DcsFmuState *st = as_state(state);
    fmi2Status status = fmi2Error;
    if (st == NULL || st->obj == NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2SetFMUstate: not a state of this FMU",
                in->name);
    } else {
        PyGILState_STATE gil = p_PyGILState_Ensure();
        status = dcs_slave_status(
            in, p_PyObject_CallMethodObjArgs(dcs_slave_object(in), dcs_py.set_fmu_state,
                                             st->obj, NULL),
            "fmi2SetFMUstate");
        status = dcs_slave_leave(in, status, "fmi2SetFMUstate");
        p_PyGILState_Release(gil);
    }
    return status;
}

fmi2Status dcs_state_free(DcsInstance *in, fmi2FMUstate *state)
{
    DcsFmuState *st = state != NULL ? as_state(*state) : NULL;
    fmi2Status status = fmi2OK;
    if (st != NULL && dcs_registry_remove(&g_states, st)) {
        PyGILState_STATE gil = p_PyGILState_Ensure();
        drop(st);
        p_PyGILState_Release(gil);
        free(st);
        *state = NULL;
    } else if (state != NULL && *state != NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2FreeFMUstate: not a state of this "
                "FMU", in->name);
        status = fmi2Error;
    }
    return status;
}

/* The serialized bytes of a state, cached in it; NULL (logged, *status set) on failure. */
static PyObject *state_bytes(DcsInstance *in, DcsFmuState *st, const char *fn,
                             fmi2Status *status)
{
    if (st->bytes == NULL) {
        PyObject *b = p_PyObject_CallMethodObjArgs(dcs_slave_object(in), dcs_py.to_bytes,
                                                   st->obj, NULL);
        if (b == NULL) {
            *status = dcs_slave_exception(in, fn);
        } else if (!dcs_isinstance(b, dcs_py.bytes_type)) {
            dcs_decref(b);
            dcs_log(in, fmi2Error, "logStatusError", "%s: %s: _fmu_state_to_bytes did not "
                    "return bytes", in->name, fn);
            *status = fmi2Error;
        } else {
            st->bytes = b;
        }
    }
    return st->bytes;
}

fmi2Status dcs_state_size(DcsInstance *in, fmi2FMUstate state, size_t *size)
{
    DcsFmuState *st = as_state(state);
    fmi2Status status = fmi2OK;
    if (st == NULL || st->obj == NULL || size == NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2SerializedFMUstateSize: invalid "
                "arguments", in->name);
        status = fmi2Error;
    } else {
        PyGILState_STATE gil = p_PyGILState_Ensure();
        PyObject *b = state_bytes(in, st, "fmi2SerializedFMUstateSize", &status);
        if (b != NULL)
            *size = (size_t)p_PyBytes_Size(b);
        dcs_slave_drain(in);
        p_PyGILState_Release(gil);
    }
    return status;
}

fmi2Status dcs_state_serialize(DcsInstance *in, fmi2FMUstate state, fmi2Byte out[],
                               size_t size)
{
    DcsFmuState *st = as_state(state);
    fmi2Status status = fmi2OK;
    if (st == NULL || st->obj == NULL || (out == NULL && size > 0)) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2SerializeFMUstate: invalid "
                "arguments", in->name);
        status = fmi2Error;
    } else {
        PyGILState_STATE gil = p_PyGILState_Ensure();
        PyObject *b = state_bytes(in, st, "fmi2SerializeFMUstate", &status);
        size_t n = b != NULL ? (size_t)p_PyBytes_Size(b) : 0;
        if (b != NULL && size < n) {
            dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2SerializeFMUstate: buffer of "
                    "%zu bytes, %zu needed", in->name, size, n);
            status = fmi2Error;
        } else if (b != NULL) {
            memcpy(out, p_PyBytes_AsString(b), n);
        }
        dcs_slave_drain(in);
        p_PyGILState_Release(gil);
    }
    return status;
}

fmi2Status dcs_state_deserialize(DcsInstance *in, const fmi2Byte bytes[], size_t size,
                                 fmi2FMUstate *state)
{
    fmi2Status status = fmi2OK;
    if (state == NULL || (bytes == NULL && size > 0)) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2DeSerializeFMUstate: invalid "
                "arguments", in->name);
        status = fmi2Error;
    } else {
        PyGILState_STATE gil = p_PyGILState_Ensure();
        PyObject *obj = NULL, *b = p_PyBytes_FromStringAndSize(bytes, (Py_ssize_t)size);
        if (b != NULL) {
            obj = p_PyObject_CallMethodObjArgs(dcs_slave_object(in), dcs_py.from_bytes, b,
                                               NULL);
            dcs_decref(b);
        }
        if (obj == NULL)
            status = dcs_slave_exception(in, "fmi2DeSerializeFMUstate");
        else
            status = store(in, state, obj, "fmi2DeSerializeFMUstate");
        dcs_slave_drain(in);
        p_PyGILState_Release(gil);
    }
    return status;
}
