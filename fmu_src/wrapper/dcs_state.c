/*
 * FMU state objects (fmi2Get/Set/FreeFMUstate) and their serialization.
 *
 * A state holds the object returned by slave._get_fmu_state() (restored with
 * slave._set_fmu_state(obj)), the phase the instance was in (its FMI 2.0 state) and, once asked
 * for, its serialized bytes (cached): the slave's payload (slave._fmu_state_to_bytes(obj)) sealed
 * in the format of dcs_state_format.h with the FMU's identity (model identifier, build of
 * resources/dcs_build.json) and a SHA-256. Deserializing checks all of that in C first (a
 * damaged, foreign or other-build state is fmi2Error naming why, before Python sees a byte), then
 * the payload becomes a state object through slave._fmu_state_from_bytes(payload), which may
 * refuse it (the status protocol). FMI 2.0: fmi2GetFMUstate overwrites a state it is given.
 *
 * The rules of fmi2SetFMUstate (docs/reliability.md, "FMU state and call order"):
 *   - a state is restored only in the phase it was taken in: fmi2SetFMUstate does not change
 *     the instance's FMI state (FMI 2.0), so a state of another phase is refused, not half
 *     restored;
 *   - the slave checks the content as it checks parameters and applies all or nothing
 *     (fmu_src/slave_support/state.py).
 */
#include "dcs_python.h"
#include "dcs_state_format.h"

#include <ctype.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The phases of the format are the wrapper's DcsState bits (a state records in->state). */
typedef char dcs_phases_are_states[
    (DCS_PHASE_INSTANTIATED == (unsigned)DCS_INSTANTIATED &&
     DCS_PHASE_INITIALIZATION_MODE == (unsigned)DCS_INITIALIZATION_MODE &&
     DCS_PHASE_STEP_COMPLETE == (unsigned)DCS_STEP_COMPLETE &&
     DCS_PHASE_TERMINATED == (unsigned)DCS_TERMINATED) ? 1 : -1];

typedef struct {
    PyObject *obj;
    unsigned phase;      /* DCS_PHASE_* (= the DcsState the instance was in) */
    unsigned char *blob; /* cached serialization (sealed), NULL until asked */
    size_t size;
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
    st->obj = NULL;
    free(st->blob);
    st->blob = NULL;
    st->size = 0;
}

/* Put obj (a new reference, consumed) and phase into *state, reusing a state given; blob
 * (malloc'd, consumed; may be NULL) becomes its cached serialization. GIL held. */
static fmi2Status store(DcsInstance *in, fmi2FMUstate *state, PyObject *obj, unsigned phase,
                        unsigned char *blob, size_t size, const char *fn)
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
        free(blob);
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s: out of memory", in->name, fn);
        status = fmi2Error;
    } else {
        st->obj = obj;
        st->phase = phase;
        st->blob = blob;
        st->size = size;
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
        status = store(in, state, obj, (unsigned)in->state, NULL, 0, "fmi2GetFMUstate");
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
    } else if (st->phase != (unsigned)in->state) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2SetFMUstate: a state taken in %s "
                "cannot be restored in %s (a state is restored only in the phase it was taken "
                "in); the instance is unchanged", in->name, dcs_phase_name(st->phase),
                dcs_phase_name((unsigned)in->state));
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

/* Seal the payload b (the slave's answer; NULL: it raised) into st's cached serialization. */
static fmi2Status seal_payload(DcsInstance *in, DcsFmuState *st, PyObject *b, const char *fn)
{
    fmi2Status status = fmi2OK;
    if (b == NULL) {
        status = dcs_slave_exception(in, fn);
    } else if (!dcs_isinstance(b, dcs_py.bytes_type)) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s: _fmu_state_to_bytes did not return "
                "bytes", in->name, fn);
        status = fmi2Error;
    } else {
        const char *model = dcs_slave_model_id(in), *build = dcs_slave_build_id(in);
        size_t n = (size_t)p_PyBytes_Size(b);
        size_t size = dcs_state_size_for(strlen(model), strlen(build), n);
        unsigned char *blob = size > 0 ? (unsigned char *)malloc(size) : NULL;
        if (blob == NULL) {
            dcs_log(in, fmi2Error, "logStatusError", "%s: %s: out of memory (or an identifier "
                    "longer than %u characters)", in->name, fn, DCS_STATE_MAX_ID);
            status = fmi2Error;
        } else {
            dcs_state_seal(blob, st->phase, model, build,
                           (const unsigned char *)p_PyBytes_AsString(b), n);
            st->blob = blob;
            st->size = size;
        }
    }
    return status;
}

/* The sealed bytes of a state, made and cached on first use (GIL held); fmi2Error (logged) if
 * the slave cannot encode it. */
static fmi2Status seal(DcsInstance *in, DcsFmuState *st, const char *fn)
{
    fmi2Status status = fmi2OK;
    if (st->blob == NULL) {
        PyObject *b = p_PyObject_CallMethodObjArgs(dcs_slave_object(in), dcs_py.to_bytes,
                                                   st->obj, NULL);
        status = seal_payload(in, st, b, fn);
        dcs_decref(b);
    }
    return status;
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
        status = seal(in, st, "fmi2SerializedFMUstateSize");
        if (status == fmi2OK)
            *size = st->size;
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
        status = seal(in, st, "fmi2SerializeFMUstate");
        if (status == fmi2OK && size < st->size) {
            dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2SerializeFMUstate: buffer of "
                    "%zu bytes, %zu needed", in->name, size, st->size);
            status = fmi2Error;
        } else if (status == fmi2OK) {
            memcpy(out, st->blob, st->size);
        }
        dcs_slave_drain(in);
        p_PyGILState_Release(gil);
    }
    return status;
}

fmi2Status dcs_state_deserialize(DcsInstance *in, const fmi2Byte bytes[], size_t size,
                                 fmi2FMUstate *state)
{
    const char *fn = "fmi2DeSerializeFMUstate";
    fmi2Status status = fmi2Error;
    DcsStateView view;
    char why[400];
    if (state == NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s: NULL state pointer", in->name, fn);
    } else if (dcs_state_open((const unsigned char *)bytes, size, dcs_slave_model_id(in),
                              dcs_slave_build_id(in), &view, why, sizeof why) != 0) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s: refused: %s", in->name, fn, why);
    } else {
        PyGILState_STATE gil = p_PyGILState_Ensure();
        unsigned char *copy = (unsigned char *)malloc(size);
        PyObject *obj = NULL, *payload = NULL;
        if (copy != NULL)
            payload = p_PyBytes_FromStringAndSize((const char *)view.payload,
                                                  (Py_ssize_t)view.payload_len);
        if (payload != NULL) {
            obj = p_PyObject_CallMethodObjArgs(dcs_slave_object(in), dcs_py.from_bytes, payload,
                                               NULL);
            dcs_decref(payload);
        }
        if (obj == NULL) {
            free(copy);
            status = copy == NULL ? fmi2Error : dcs_slave_exception(in, fn);
            if (copy == NULL)
                dcs_log(in, fmi2Error, "logStatusError", "%s: %s: out of memory", in->name, fn);
        } else {
            dcs_incref(dcs_py.none);
            status = dcs_slave_status(in, dcs_py.none, fn); /* the slave may refuse it */
            if (status > fmi2Warning) {
                dcs_decref(obj);
                free(copy);
            } else {
                memcpy(copy, bytes, size);
                status = store(in, state, obj, view.phase, copy, size, fn);
            }
        }
        dcs_slave_drain(in);
        p_PyGILState_Release(gil);
    }
    return status;
}

/* Where the value of "build" starts in text (*at) and its length (0: none). The file is ours
 * (fmu_src/build.py, json.dumps): "build": "<hex digits>". */
static size_t find_build(const char *text, const char **at)
{
    const char quote = 34; /* the double quote */
    const char *p = strstr(text, "\"build\"");
    size_t len = 0;
    if (p != NULL) {
        p += strlen("\"build\"");
        p += strspn(p, " \t\r\n");
        p += *p == ':';
        p += strspn(p, " \t\r\n");
        if (*p == quote) {
            p++;
            while (len < DCS_STATE_MAX_ID && isalnum((unsigned char)p[len]))
                len++;
            len = p[len] == quote ? len : 0;
        }
    }
    *at = p;
    return len;
}

char *dcs_state_read_build(const char *resources)
{
    char path[4096], text[8192], *out;
    const char *at = NULL;
    size_t n = 0, len;
    FILE *f;
    snprintf(path, sizeof path, "%s/dcs_build.json", resources);
    f = fopen(path, "rb");
    if (f != NULL) {
        n = fread(text, 1, sizeof text - 1, f);
        fclose(f);
    }
    text[n] = '\0';
    len = find_build(text, &at);
    out = (char *)malloc(len + 1);
    if (out != NULL) {
        if (len > 0)
            memcpy(out, at, len);
        out[len] = '\0';
    }
    return out;
}
