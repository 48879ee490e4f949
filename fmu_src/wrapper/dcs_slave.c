/*
 * The pythonfmu slave object behind an instance: creating it, calling it, the status protocol,
 * and values in and out (Python calls, or the shared Real buffers without Python).
 *
 * Status of a call (the one protocol; see fmu_src/wrapper/__init__.py):
 *     Python exception                -> fmi2Error (traceback logged, category logStatusError);
 *                                        the instance stays usable
 *     return None / True              -> fmi2OK
 *     return False                    -> fmi2Discard from do_step, fmi2Error otherwise
 *     return an int 0..4 (not bool)   -> that fmi2Status
 *     anything else                   -> do_step: truthy OK / falsy Discard; else OK
 * then, if the slave had an attribute _fmi2_status right after construction and it is not
 * None, the status is raised to it and the attribute reset to None. fmi2Fatal only when Python
 * itself fails (an exception that cannot even be formatted).
 *
 * Real buffers: a slave that defines _fmi2_real_buffers() returns (input_vrs, inputs,
 * output_vrs, outputs), inputs/outputs C-contiguous writable float64 buffers (numpy arrays) of
 * those lengths, fixed for the slave's lifetime. The wrapper keeps a Py_buffer of each (so the
 * memory lives as long as it is used) and then, in step mode, answers fmi2GetReal of those
 * value references and takes fmi2SetReal of the inputs (also in initialization mode) straight
 * from/into that memory, without Python; any other call, or a call mixing other value
 * references, goes to the slave's get_real/set_real.
 *
 * Compiled step (the accelerator a slave may carry; fmu_src/wrapper/__init__.py):
 *  1. A slave that defines _fmi2_compiled_step() is asked for its step after construction and
 *     at the end of every call that enters Python and may change it (every call but the
 *     getters and the FMU-state reads): it returns None (fmi2DoStep calls do_step in Python)
 *     or (function, context), two ints: the address of a C function
 *         int step(void *context, double t, double h)      (numba: int32(voidptr, f8, f8))
 *     and the pointer it gets. The slave keeps everything the context points at alive and
 *     unchanged in place until its next Python call (the wrapper holds no reference).
 *  2. fmi2DoStep then calls step(context, t, h) WITHOUT the GIL and without entering Python.
 *     0: fmi2OK. Any other code c: the wrapper takes the GIL and calls
 *     slave._fmi2_compiled_step_failed(c, t, h); its outcome is the step's status by the
 *     status protocol above (the slave logs what happened, as its do_step would have), and the
 *     compiled step is taken anew.
 *  3. The step reads the inputs buffer and writes the outputs buffer itself; the wrapper moves
 *     nothing else. An unusable answer of _fmi2_compiled_step (not None or two ints, a NULL
 *     function) is fmi2Error of the call it ended, logged, and do_step runs in Python.
 */
#include "dcs_python.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_BUFFER_VR 1000000 /* bound of the value-reference -> slot table */

struct DcsSlave {
    PyObject *cls, *obj, *log_queue;
    PyObject *str_keep;   /* the sequence behind the strings of the last fmi2GetString */
    int has_status;       /* the slave defines _fmi2_status (read after every call) */
    DcsBuffer in_view, out_view;
    int has_buffers;
    double *in, *out;
    int *slot;            /* slot[vr]: k > 0 output k-1, k < 0 input -k-1, 0 neither */
    size_t n_slot;
    int has_compiled;     /* the slave defines _fmi2_compiled_step */
    DcsCompiledStep step; /* its current compiled step, NULL: do_step in Python */
    void *step_context;
    char *model_id;       /* identity of its FMU states: the class (= modelIdentifier) */
    char *build_id;       /* and the build (resources/dcs_build.json; "" if none) */
};

/* --------------------------------------------------------------- messages (GIL held) */
/* Move slave.log_queue into the instance's message queue. */
static void drain_log(DcsInstance *in)
{
    PyObject *q = in->slave != NULL ? in->slave->log_queue : NULL;
    Py_ssize_t i, n = q != NULL && dcs_isinstance(q, dcs_py.list_type) ? p_PyList_Size(q) : 0;
    for (i = 0; i < n; i++) {
        PyObject *item = p_PyList_GetItem(q, i); /* borrowed */
        PyObject *st = p_PyObject_GetAttr(item, dcs_py.status);
        PyObject *cat = p_PyObject_GetAttr(item, dcs_py.category);
        PyObject *msg = p_PyObject_GetAttr(item, dcs_py.msg);
        PyObject *cats = cat != NULL ? p_PyObject_Str(cat) : NULL;
        PyObject *msgs = msg != NULL ? p_PyObject_Str(msg) : NULL;
        long status = st != NULL ? p_PyLong_AsLong(st) : 0;
        const char *ctext = cats != NULL ? p_PyUnicode_AsUTF8AndSize(cats, NULL) : NULL;
        const char *mtext = msgs != NULL ? p_PyUnicode_AsUTF8AndSize(msgs, NULL) : NULL;
        if (p_PyErr_Occurred())
            p_PyErr_Clear();
        if (status < 0 || status > 4)
            status = fmi2OK;
        dcs_log_text(in, (fmi2Status)status, ctext != NULL ? ctext : "logAll",
                     mtext != NULL ? mtext : "(unreadable log message)");
        dcs_decref(st);
        dcs_decref(cat);
        dcs_decref(msg);
        dcs_decref(cats);
        dcs_decref(msgs);
    }
    if (n > 0 && p_PyList_SetSlice(q, 0, n, NULL) != 0)
        p_PyErr_Clear();
}

/* Log the pending Python exception; fmi2Error, or fmi2Fatal if it cannot be formatted. */
static fmi2Status log_exception(DcsInstance *in, const char *fn)
{
    PyObject *type = NULL, *value = NULL, *tb = NULL, *lines = NULL, *text = NULL;
    const char *s = NULL;
    fmi2Status status = fmi2Error;
    p_PyErr_Fetch(&type, &value, &tb);
    p_PyErr_NormalizeException(&type, &value, &tb);
    if (type != NULL) {
        lines = p_PyObject_CallMethodObjArgs(dcs_py.traceback, dcs_py.format_exception, type,
                                             value ? value : dcs_py.none,
                                             tb ? tb : dcs_py.none, NULL);
        if (lines != NULL)
            text = p_PyUnicode_Join(dcs_py.empty, lines);
        if (text == NULL) {
            p_PyErr_Clear();
            text = value != NULL ? p_PyObject_Str(value) : NULL;
        }
        if (text != NULL)
            s = p_PyUnicode_AsUTF8AndSize(text, NULL);
    }
    if (s == NULL) {
        p_PyErr_Clear();
        s = "(the exception could not be formatted)";
        status = fmi2Fatal;
    }
    drain_log(in); /* messages logged before the exception come first */
    dcs_log(in, status, dcs_status_category(status), "%s: Python exception in %s: %s",
            in->name, fn, s);
    dcs_decref(lines);
    dcs_decref(text);
    dcs_decref(type);
    dcs_decref(value);
    dcs_decref(tb);
    return status;
}

/* status raised to the slave's _fmi2_status (GIL held), which is reset to None. */
static fmi2Status take_status(DcsSlave *s, fmi2Status status)
{
    if (s->has_status && status != fmi2Fatal) {
        PyObject *extra = p_PyObject_GetAttr(s->obj, dcs_py.fmi2_status);
        if (extra == NULL) {
            p_PyErr_Clear();
        } else if (extra != dcs_py.none) {
            long v = p_PyLong_AsLong(extra);
            if (p_PyErr_Occurred()) {
                p_PyErr_Clear();
                v = fmi2Error;
            }
            if (v > (long)status && v <= fmi2Fatal)
                status = (fmi2Status)v;
            if (p_PyObject_SetAttr(s->obj, dcs_py.fmi2_status, dcs_py.none) != 0)
                p_PyErr_Clear();
        }
        dcs_decref(extra);
    }
    return status;
}

/* Status of a call from its result (a new reference, consumed) and _fmi2_status. */
static fmi2Status status_of(DcsInstance *in, PyObject *res, int is_step, const char *fn)
{
    DcsSlave *s = in->slave;
    fmi2Status status = fmi2OK;
    if (res == NULL) {
        status = log_exception(in, fn);
    } else if (res == dcs_py.none || res == dcs_py.true_) {
        status = fmi2OK;
    } else if (res == dcs_py.false_) {
        status = is_step ? fmi2Discard : fmi2Error;
    } else if (dcs_isinstance(res, dcs_py.int_type)) {
        long v = p_PyLong_AsLong(res);
        if (p_PyErr_Occurred() || v < 0 || v > 4) {
            p_PyErr_Clear();
            dcs_log(in, fmi2Error, "logStatusError",
                    "%s: %s returned an integer that is no fmi2Status (0..4)", in->name, fn);
            status = fmi2Error;
        } else {
            status = (fmi2Status)v;
        }
    } else if (is_step) {
        int t = p_PyObject_IsTrue(res);
        status = t < 0 ? log_exception(in, fn) : t ? fmi2OK : fmi2Discard;
    }
    dcs_decref(res);
    return take_status(s, status);
}

/* Take the slave's compiled step anew (GIL held; see the top of this file); returns status,
 * raised to fmi2Error (logged) if the answer is unusable. */
static fmi2Status refresh_compiled(DcsInstance *in, fmi2Status status, const char *fn)
{
    DcsSlave *s = in->slave;
    PyObject *res = NULL, *seq = NULL;
    void *fn_ptr = NULL, *ctx = NULL;
    const char *why = NULL;
    if (s != NULL && s->has_compiled && status != fmi2Fatal) {
        s->step = NULL;
        s->step_context = NULL;
        res = p_PyObject_CallMethodObjArgs(s->obj, dcs_py.compiled_step, NULL);
        if (res == NULL) {
            fmi2Status st = log_exception(in, "_fmi2_compiled_step");
            status = st > status ? st : status;
        } else if (res != dcs_py.none) {
            seq = p_PySequence_Tuple(res);
            if (seq == NULL || p_PyTuple_Size(seq) != 2) {
                why = "not None or a pair (function address, context address)";
            } else {
                fn_ptr = p_PyLong_AsVoidPtr(p_PyTuple_GetItem(seq, 0));
                ctx = p_PyLong_AsVoidPtr(p_PyTuple_GetItem(seq, 1));
                if (p_PyErr_Occurred() || fn_ptr == NULL)
                    why = "the function address is not a non-zero integer";
            }
            p_PyErr_Clear();
        }
    }
    if (why != NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s: the slave's _fmi2_compiled_step(): "
                "%s; doStep runs in Python", in->name, fn, why);
        status = status > fmi2Error ? status : fmi2Error;
    } else if (fn_ptr != NULL) {
        /* a data pointer turned into a function pointer: POSIX guarantees this (dlsym) */
        memcpy(&s->step, &fn_ptr, sizeof s->step);
        s->step_context = ctx;
    }
    dcs_decref(seq);
    dcs_decref(res);
    return status;
}

fmi2Status dcs_slave_leave(DcsInstance *in, fmi2Status status, const char *fn)
{
    status = refresh_compiled(in, status, fn);
    drain_log(in);
    return status;
}

/* slave.<name>(*args) (at most 3 arguments), a new reference or NULL. */
static PyObject *call(PyObject *obj, PyObject *name, PyObject **args, size_t nargs)
{
    PyObject *a[3] = {NULL, NULL, NULL};
    size_t i;
    for (i = 0; i < nargs && i < 3; i++)
        a[i] = args[i];
    /* the argument list ends at the first NULL */
    return p_PyObject_CallMethodObjArgs(obj, name, a[0], a[1], a[2], NULL);
}

/* slave.<name>(*args) -> status. */
static fmi2Status call_method(DcsInstance *in, PyObject *name, PyObject **args, size_t nargs,
                              int is_step, const char *fn)
{
    return status_of(in, call(in->slave->obj, name, args, nargs), is_step, fn);
}

/* ------------------------------------------------------------- creating the slave */
/* Import the slave module with resources/ first on sys.path (only during the import). */
static PyObject *import_class(DcsInstance *in, const char *module, const char *cls_name)
{
    PyObject *path = p_PySys_GetObject("path"); /* borrowed: held while importing */
    PyObject *entry = p_PyUnicode_DecodeFSDefault(in->resources);
    PyObject *mod = NULL, *cls = NULL, *cname;
    int inserted = 0;
    int is_list = path != NULL && dcs_isinstance(path, dcs_py.list_type);
    if (entry != NULL && is_list) {
        dcs_incref(path); /* the module may rebind sys.path */
        inserted = p_PyList_Insert(path, 0, entry) == 0;
        if (!inserted)
            dcs_decref(path);
    }
    if (entry != NULL && (inserted || !is_list))
        mod = p_PyImport_ImportModule(module);
    if (inserted) { /* remove exactly the entry inserted above, keep any error */
        PyObject *type, *value, *tb;
        Py_ssize_t i;
        p_PyErr_Fetch(&type, &value, &tb);
        for (i = 0; i < p_PyList_Size(path); i++) {
            if (p_PyList_GetItem(path, i) == entry) {
                if (p_PyList_SetSlice(path, i, i + 1, NULL) != 0)
                    p_PyErr_Clear();
                break;
            }
        }
        p_PyErr_Restore(type, value, tb);
        dcs_decref(path);
    }
    dcs_decref(entry);
    if (mod != NULL) {
        cname = p_PyUnicode_FromString(cls_name);
        if (cname != NULL)
            cls = p_PyObject_GetAttr(mod, cname);
        dcs_decref(cname);
        dcs_decref(mod);
    }
    return cls;
}

static void release_buffers(DcsSlave *s)
{
    if (s->has_buffers) {
        p_PyBuffer_Release(&s->in_view);
        p_PyBuffer_Release(&s->out_view);
    }
    s->has_buffers = 0;
    s->in = s->out = NULL;
    free(s->slot);
    s->slot = NULL;
    s->n_slot = 0;
}

/* One float64 buffer of n values; 0 on success, else -1 and *why. */
static int get_view(PyObject *obj, DcsBuffer *view, Py_ssize_t n, const char **why)
{
    int rc = -1;
    if (p_PyObject_GetBuffer(obj, view, DCS_PYBUF_C_CONTIGUOUS | DCS_PYBUF_FORMAT |
                             DCS_PYBUF_WRITABLE) != 0) {
        *why = "not a C-contiguous writable buffer";
    } else {
        const char *f = view->format != NULL ? view->format : "B";
        if (f[0] == '<' || f[0] == '=' || f[0] == '@')
            f++;
        if (strcmp(f, "d") != 0 || view->itemsize != 8 || view->ndim != 1 ||
            view->shape == NULL || view->shape[0] != n) {
            *why = "not a 1-D float64 buffer of one value per value reference";
            p_PyBuffer_Release(view);
        } else {
            rc = 0;
        }
    }
    return rc;
}

/* Fill slot[] from a tuple of value references (sign: -1 inputs, +1 outputs). */
static int add_slots(DcsSlave *s, PyObject *seq, int sign, const char **why)
{
    Py_ssize_t i, n = p_PyTuple_Size(seq);
    int rc = 0;
    for (i = 0; i < n && rc == 0; i++) {
        long vr = p_PyLong_AsLong(p_PyTuple_GetItem(seq, i));
        if (vr < 0 || vr >= MAX_BUFFER_VR) {
            *why = "a value reference is not an integer in [0, 1e6)";
            rc = -1;
        } else if ((size_t)vr >= s->n_slot) {
            size_t cap = (size_t)vr + 1;
            int *grown = (int *)realloc(s->slot, cap * sizeof *grown);
            if (grown == NULL) {
                *why = "out of memory";
                rc = -1;
            } else {
                memset(grown + s->n_slot, 0, (cap - s->n_slot) * sizeof *grown);
                s->slot = grown;
                s->n_slot = cap;
            }
        }
        if (rc == 0 && s->slot[vr] != 0) {
            *why = "a value reference is listed twice";
            rc = -1;
        }
        if (rc == 0)
            s->slot[vr] = sign * (int)(i + 1);
    }
    return rc;
}

/* Take the slave's Real buffers, if it offers them (see the top of this file); 0 on success,
 * also for a slave without them; else -1, logged. */
static int bind_buffers(DcsInstance *in, DcsSlave *s, PyObject *obj)
{
    PyObject *res = NULL, *seq = NULL, *in_vrs = NULL, *out_vrs = NULL;
    const char *why = NULL;
    int rc = 0;
    if (p_PyObject_HasAttr(obj, dcs_py.real_buffers)) {
        res = p_PyObject_CallMethodObjArgs(obj, dcs_py.real_buffers, NULL);
        if (res != NULL)
            seq = p_PySequence_Tuple(res);
        rc = seq != NULL ? 0 : -1;
    }
    if (seq != NULL && p_PyTuple_Size(seq) != 4) {
        why = "it must return (input_vrs, inputs, output_vrs, outputs)";
        rc = -1;
    } else if (seq != NULL) {
        in_vrs = p_PySequence_Tuple(p_PyTuple_GetItem(seq, 0));
        out_vrs = p_PySequence_Tuple(p_PyTuple_GetItem(seq, 2));
        if (in_vrs == NULL || out_vrs == NULL) {
            rc = -1;
        } else if (get_view(p_PyTuple_GetItem(seq, 1), &s->in_view, p_PyTuple_Size(in_vrs),
                            &why) != 0) {
            rc = -1;
        } else if (get_view(p_PyTuple_GetItem(seq, 3), &s->out_view, p_PyTuple_Size(out_vrs),
                            &why) != 0) {
            p_PyBuffer_Release(&s->in_view);
            rc = -1;
        } else {
            s->has_buffers = 1;
            s->in = (double *)s->in_view.buf;
            s->out = (double *)s->out_view.buf;
            if (add_slots(s, in_vrs, -1, &why) != 0 || add_slots(s, out_vrs, 1, &why) != 0) {
                release_buffers(s);
                rc = -1;
            }
        }
    }
    dcs_decref(in_vrs);
    dcs_decref(out_vrs);
    dcs_decref(seq);
    dcs_decref(res);
    if (rc != 0 && why != NULL) {
        p_PyErr_Clear();
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2Instantiate: the slave's "
                "_fmi2_real_buffers(): %s", in->name, why);
    } else if (rc != 0) {
        log_exception(in, "fmi2Instantiate (_fmi2_real_buffers)");
    }
    return rc;
}

/* Construct the slave object into s (replacing a previous one); 0 on success. */
static int construct(DcsInstance *in, DcsSlave *s)
{
    PyObject *args = p_PyTuple_New(0), *kwargs = p_PyDict_New(), *obj = NULL, *q = NULL, *tmp;
    DcsSlave fresh;
    int rc = -1;
    memset(&fresh, 0, sizeof fresh);
    if (args != NULL && kwargs != NULL) {
        rc = 0;
        tmp = p_PyUnicode_FromString(in->name);
        rc |= tmp == NULL || p_PyDict_SetItemString(kwargs, "instance_name", tmp) != 0;
        dcs_decref(tmp);
        tmp = p_PyUnicode_DecodeFSDefault(in->resources);
        rc |= tmp == NULL || p_PyDict_SetItemString(kwargs, "resources", tmp) != 0;
        dcs_decref(tmp);
        rc |= p_PyDict_SetItemString(kwargs, "visible",
                                     in->visible ? dcs_py.true_ : dcs_py.false_) != 0;
        rc = rc ? -1 : 0;
    }
    if (rc == 0)
        obj = p_PyObject_Call(s->cls, args, kwargs);
    if (obj != NULL)
        q = p_PyObject_CallMethodObjArgs(obj, dcs_py.get_log_queue, NULL);
    rc = q != NULL ? 0 : -1;
    if (rc == 0)
        rc = bind_buffers(in, &fresh, obj) == 0 ? 0 : -2; /* -2: already logged */
    if (rc == 0) {
        fresh.has_status = p_PyObject_HasAttr(obj, dcs_py.fmi2_status);
        fresh.has_compiled = p_PyObject_HasAttr(obj, dcs_py.compiled_step);
        release_buffers(s);
        dcs_decref(s->obj);
        dcs_decref(s->log_queue);
        s->obj = obj;
        s->log_queue = q;
        s->has_status = fresh.has_status;
        s->has_compiled = fresh.has_compiled;
        s->step = NULL;
        s->step_context = NULL;
        s->in_view = fresh.in_view;
        s->out_view = fresh.out_view;
        s->has_buffers = fresh.has_buffers;
        s->in = fresh.in;
        s->out = fresh.out;
        s->slot = fresh.slot;
        s->n_slot = fresh.n_slot;
        obj = q = NULL;
    }
    dcs_decref(obj);
    dcs_decref(q);
    dcs_decref(args);
    dcs_decref(kwargs);
    return rc;
}

fmi2Status dcs_slave_create(DcsInstance *in)
{
    char *module = dcs_read_resource_line(in->resources, "slavemodule.txt");
    char *cls_name = dcs_read_resource_line(in->resources, "slaveclass.txt");
    fmi2Status status = fmi2OK;
    PyGILState_STATE gil;
    DcsSlave *s = (DcsSlave *)calloc(1, sizeof *s);
    if (cls_name == NULL)
        cls_name = dcs_own_model_identifier();
    if (s == NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2Instantiate: out of memory",
                in->name);
        status = fmi2Error;
    } else if (module == NULL || cls_name == NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2Instantiate: cannot read "
                "%s/slavemodule.txt (or the class name)", in->name, in->resources);
        status = fmi2Error;
        free(s);
        s = NULL;
    } else {
        int rc;
        in->slave = s;
        gil = p_PyGILState_Ensure();
        s->cls = import_class(in, module, cls_name);
        if (s->cls == NULL) {
            char what[512];
            snprintf(what, sizeof what, "fmi2Instantiate (importing class %.100s of module "
                     "%.100s from %.250s)", cls_name, module, in->resources);
            status = log_exception(in, what);
        } else if ((rc = construct(in, s)) != 0) {
            status = rc == -2 ? fmi2Error
                              : log_exception(in, "fmi2Instantiate (creating the slave)");
        } else if ((s->model_id = dcs_strdup(cls_name)) == NULL ||
                   (s->build_id = dcs_state_read_build(in->resources)) == NULL) {
            dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2Instantiate: out of memory",
                    in->name);
            status = fmi2Error;
        } else {
            /* a problem the constructor reported (logged, e.g. a bad resource file) */
            status = take_status(s, status);
            if (status <= fmi2Warning)
                status = refresh_compiled(in, status, "fmi2Instantiate");
        }
        drain_log(in);
        if (status > fmi2Warning) {
            dcs_decref(s->cls);
            dcs_decref(s->obj);
            dcs_decref(s->log_queue);
            free(s->model_id);
            free(s->build_id);
            free(s);
            in->slave = NULL;
        }
        p_PyGILState_Release(gil);
    }
    free(module);
    free(cls_name);
    return status;
}

void dcs_slave_free(DcsInstance *in)
{
    DcsSlave *s = in->slave;
    if (s != NULL && dcs_python_started()) {
        PyGILState_STATE gil = p_PyGILState_Ensure();
        drain_log(in);
        release_buffers(s);
        dcs_decref(s->str_keep);
        dcs_decref(s->log_queue);
        dcs_decref(s->obj);
        dcs_decref(s->cls);
        p_PyGILState_Release(gil);
        free(s->model_id);
        free(s->build_id);
        free(s);
        in->slave = NULL;
    }
}

/* ------------------------------------------------------------------ the calls */
fmi2Status dcs_slave_setup_experiment(DcsInstance *in, int tolerance_defined, double tolerance,
                                      double start_time, int stop_time_defined,
                                      double stop_time)
{
    PyGILState_STATE gil = p_PyGILState_Ensure();
    PyObject *args[3];
    fmi2Status status;
    args[0] = p_PyFloat_FromDouble(start_time);
    args[1] = stop_time_defined ? p_PyFloat_FromDouble(stop_time) : dcs_py.none;
    args[2] = tolerance_defined ? p_PyFloat_FromDouble(tolerance) : dcs_py.none;
    if (!stop_time_defined)
        dcs_incref(dcs_py.none);
    if (!tolerance_defined)
        dcs_incref(dcs_py.none);
    if (args[0] == NULL || args[1] == NULL || args[2] == NULL)
        status = log_exception(in, "fmi2SetupExperiment");
    else
        status = call_method(in, dcs_py.setup_experiment, args, 3, 0, "fmi2SetupExperiment");
    dcs_decref(args[0]);
    dcs_decref(args[1]);
    dcs_decref(args[2]);
    status = dcs_slave_leave(in, status, "fmi2SetupExperiment");
    p_PyGILState_Release(gil);
    return status;
}

fmi2Status dcs_slave_call(DcsInstance *in, DcsCall call)
{
    static const char *const fns[] = {"fmi2EnterInitializationMode",
                                      "fmi2ExitInitializationMode", "fmi2Terminate"};
    PyObject *const names[] = {dcs_py.enter_initialization_mode,
                               dcs_py.exit_initialization_mode, dcs_py.terminate};
    PyGILState_STATE gil = p_PyGILState_Ensure();
    fmi2Status status = call_method(in, names[call], NULL, 0, 0, fns[call]);
    status = dcs_slave_leave(in, status, fns[call]);
    p_PyGILState_Release(gil);
    return status;
}

/* The Python part of a step: do_step(t, h), or _fmi2_compiled_step_failed(code, t, h) after
 * a compiled step returned code != 0. */
static fmi2Status do_step_in_python(DcsInstance *in, double t, double h, int code)
{
    PyGILState_STATE gil = p_PyGILState_Ensure();
    PyObject *args[3] = {NULL, NULL, NULL};
    fmi2Status status;
    args[0] = p_PyFloat_FromDouble(t);
    args[1] = p_PyFloat_FromDouble(h);
    if (code != 0)
        args[2] = p_PyLong_FromLong(code);
    if (args[0] == NULL || args[1] == NULL || (code != 0 && args[2] == NULL)) {
        status = log_exception(in, "fmi2DoStep");
    } else if (code != 0) {
        PyObject *failed[3] = {args[2], args[0], args[1]};
        status = call_method(in, dcs_py.compiled_step_failed, failed, 3, 1, "fmi2DoStep");
    } else {
        status = call_method(in, dcs_py.do_step, args, 2, 1, "fmi2DoStep");
    }
    dcs_decref(args[0]);
    dcs_decref(args[1]);
    dcs_decref(args[2]);
    status = dcs_slave_leave(in, status, "fmi2DoStep");
    p_PyGILState_Release(gil);
    return status;
}

fmi2Status dcs_slave_do_step(DcsInstance *in, double t, double h)
{
    DcsSlave *s = in->slave;
    int compiled = s->step != NULL, code = 0;
    fmi2Status status = fmi2OK;
    if (compiled)
        code = s->step(s->step_context, t, h); /* no GIL, no Python */
    if (!compiled || code != 0)
        status = do_step_in_python(in, t, h, code);
    return status;
}

fmi2Status dcs_slave_reset(DcsInstance *in)
{
    PyGILState_STATE gil = p_PyGILState_Ensure();
    fmi2Status status = fmi2OK;
    int rc;
    if (p_PyObject_HasAttr(in->slave->obj, dcs_py.reset)) {
        status = call_method(in, dcs_py.reset, NULL, 0, 0, "fmi2Reset");
    } else {
        drain_log(in);
        rc = construct(in, in->slave); /* the old slave is kept on failure */
        if (rc == -1)
            status = log_exception(in, "fmi2Reset (re-instantiating the slave)");
        else if (rc == -2)
            status = fmi2Error;
    }
    status = dcs_slave_leave(in, status, "fmi2Reset");
    p_PyGILState_Release(gil);
    return status;
}

/* ------------------------------------------------------------------ get / set */
/* fmi2GetReal from the output/input buffers without Python; 1 if served. */
static int get_from_buffers(const DcsInstance *in, const fmi2ValueReference vr[], size_t nvr,
                            fmi2Real out[])
{
    const DcsSlave *s = in->slave;
    size_t i;
    int served = s->has_buffers && (in->state & (DCS_STEP_COMPLETE | DCS_TERMINATED));
    for (i = 0; i < nvr && served; i++)
        served = vr[i] < s->n_slot && s->slot[vr[i]] != 0;
    for (i = 0; i < nvr && served; i++) {
        int k = s->slot[vr[i]];
        out[i] = k > 0 ? s->out[k - 1] : s->in[-k - 1];
    }
    return served;
}

/* fmi2SetReal of inputs into the input buffer without Python; 1 if served. */
static int set_into_buffers(const DcsInstance *in, const fmi2ValueReference vr[], size_t nvr,
                            const fmi2Real values[])
{
    const DcsSlave *s = in->slave;
    size_t i;
    int served = s->has_buffers &&
                 (in->state & (DCS_INITIALIZATION_MODE | DCS_STEP_COMPLETE));
    for (i = 0; i < nvr && served; i++)
        served = vr[i] < s->n_slot && s->slot[vr[i]] < 0;
    for (i = 0; i < nvr && served; i++)
        s->in[-s->slot[vr[i]] - 1] = values[i];
    return served;
}

/* New list of Python ints for the value references (NULL + exception on failure). */
static PyObject *vr_list(const fmi2ValueReference vr[], size_t nvr)
{
    size_t i;
    PyObject *l = p_PyList_New((Py_ssize_t)nvr);
    for (i = 0; l != NULL && i < nvr; i++) {
        PyObject *v = p_PyLong_FromUnsignedLong(vr[i]);
        if (v == NULL) {
            dcs_decref(l);
            l = NULL;
        } else if (p_PyList_SetItem(l, (Py_ssize_t)i, v) != 0) { /* steals v */
            dcs_decref(l);
            l = NULL;
        }
    }
    return l;
}

static PyObject *getter_name(DcsType type)
{
    PyObject *names[] = {dcs_py.get_real, dcs_py.get_integer, dcs_py.get_boolean,
                         dcs_py.get_string};
    return names[type];
}

static PyObject *setter_name(DcsType type)
{
    PyObject *names[] = {dcs_py.set_real, dcs_py.set_integer, dcs_py.set_boolean,
                         dcs_py.set_string};
    return names[type];
}

/* Convert the slave's returned values into the caller's array (GIL held). */
static fmi2Status convert_out(DcsInstance *in, PyObject *seq, const fmi2ValueReference vr[],
                              size_t nvr, void *out, DcsType type, const char *fn)
{
    fmi2Status status = fmi2OK;
    size_t i;
    for (i = 0; i < nvr && status < fmi2Error; i++) {
        PyObject *item = p_PyTuple_GetItem(seq, (Py_ssize_t)i); /* borrowed */
        switch (type) {
        case DCS_REAL:
            ((fmi2Real *)out)[i] = p_PyFloat_AsDouble(item);
            break;
        case DCS_INTEGER: {
            long v = p_PyLong_AsLong(item);
            if (v > 2147483647L || v < -2147483647L - 1L) {
                dcs_log(in, fmi2Error, "logStatusError", "%s: %s: value of vr %u does not "
                        "fit an fmi2Integer", in->name, fn, vr[i]);
                status = fmi2Error;
            }
            ((fmi2Integer *)out)[i] = (fmi2Integer)v;
            break;
        }
        case DCS_BOOLEAN:
            ((fmi2Boolean *)out)[i] = p_PyObject_IsTrue(item) > 0 ? fmi2True : fmi2False;
            break;
        case DCS_STRING: {
            const char *s = dcs_isinstance(item, dcs_py.str_type)
                            ? p_PyUnicode_AsUTF8AndSize(item, NULL) : NULL;
            if (s == NULL && !p_PyErr_Occurred()) {
                dcs_log(in, fmi2Error, "logStatusError", "%s: %s: value of vr %u is not a "
                        "str", in->name, fn, vr[i]);
                status = fmi2Error;
            }
            ((fmi2String *)out)[i] = s != NULL ? s : "";
            break;
        }
        }
        if (p_PyErr_Occurred())
            status = log_exception(in, fn);
    }
    return status;
}

static fmi2Status get_through_python(DcsInstance *in, const fmi2ValueReference vr[],
                                     size_t nvr, void *values, DcsType type, const char *fn)
{
    fmi2Status status = fmi2OK;
    PyGILState_STATE gil = p_PyGILState_Ensure();
    PyObject *vrs, *res = NULL, *seq = NULL;
    vrs = vr_list(vr, nvr);
    if (vrs != NULL) {
        res = p_PyObject_CallMethodObjArgs(in->slave->obj, getter_name(type), vrs, NULL);
        dcs_decref(vrs);
    }
    if (res != NULL) {
        seq = p_PySequence_Tuple(res); /* get_* must return a sequence */
        dcs_decref(res);
    }
    if (seq == NULL) {
        status = log_exception(in, fn);
    } else if ((size_t)p_PyTuple_Size(seq) != nvr) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s: the slave returned %zd values for "
                "%zu value references", in->name, fn, p_PyTuple_Size(seq), nvr);
        status = fmi2Error;
    } else {
        if (type == DCS_STRING) { /* the strings live as long as the sequence */
            dcs_decref(in->slave->str_keep);
            in->slave->str_keep = seq;
            dcs_incref(seq);
        }
        status = convert_out(in, seq, vr, nvr, values, type, fn);
    }
    dcs_decref(seq);
    if (status < fmi2Error) {
        dcs_incref(dcs_py.none);
        status = status_of(in, dcs_py.none, 0, fn); /* _fmi2_status of the get */
    }
    drain_log(in);
    p_PyGILState_Release(gil);
    return status;
}

fmi2Status dcs_slave_get(DcsInstance *in, const fmi2ValueReference vr[], size_t nvr,
                         void *values, DcsType type, const char *fn)
{
    fmi2Status status = fmi2OK; /* the hot path (buffers) needs no Python and logs nothing */
    if (type != DCS_REAL || !get_from_buffers(in, vr, nvr, (fmi2Real *)values))
        status = get_through_python(in, vr, nvr, values, type, fn);
    return status;
}

/* New Python value of one FMI value (NULL + exception on failure). */
static PyObject *value_in(const void *values, size_t i, DcsType type)
{
    PyObject *v = NULL;
    switch (type) {
    case DCS_REAL: v = p_PyFloat_FromDouble(((const fmi2Real *)values)[i]); break;
    case DCS_INTEGER: v = p_PyLong_FromLong(((const fmi2Integer *)values)[i]); break;
    case DCS_BOOLEAN: v = p_PyBool_FromLong(((const fmi2Boolean *)values)[i] != fmi2False);
        break;
    case DCS_STRING: {
        const char *s = ((const fmi2String *)values)[i];
        v = p_PyUnicode_FromString(s != NULL ? s : "");
        break;
    }
    }
    return v;
}

static fmi2Status set_through_python(DcsInstance *in, const fmi2ValueReference vr[],
                                     size_t nvr, const void *values, DcsType type,
                                     const char *fn)
{
    fmi2Status status = fmi2OK;
    PyGILState_STATE gil = p_PyGILState_Ensure();
    PyObject *vrs, *vals;
    size_t i;
    vrs = vr_list(vr, nvr);
    vals = p_PyList_New((Py_ssize_t)nvr);
    for (i = 0; vrs != NULL && vals != NULL && i < nvr; i++) {
        PyObject *v = value_in(values, i, type);
        if (v == NULL || p_PyList_SetItem(vals, (Py_ssize_t)i, v) != 0) /* steals v */
            break;
    }
    if (vrs == NULL || vals == NULL || i < nvr) {
        status = log_exception(in, fn);
    } else {
        PyObject *args[2] = {vrs, vals};
        status = call_method(in, setter_name(type), args, 2, 0, fn);
    }
    dcs_decref(vrs);
    dcs_decref(vals);
    status = dcs_slave_leave(in, status, fn);
    p_PyGILState_Release(gil);
    return status;
}

fmi2Status dcs_slave_set(DcsInstance *in, const fmi2ValueReference vr[], size_t nvr,
                         const void *values, DcsType type, const char *fn)
{
    fmi2Status status = fmi2OK; /* the hot path (buffers) needs no Python */
    if (type != DCS_REAL || !set_into_buffers(in, vr, nvr, (const fmi2Real *)values))
        status = set_through_python(in, vr, nvr, values, type, fn);
    return status;
}

/* ------------------------------------------------- for dcs_state.c (GIL held) */

PyObject *dcs_slave_object(DcsInstance *in)
{
    return in->slave->obj;
}

const char *dcs_slave_model_id(DcsInstance *in)
{
    return in->slave->model_id;
}

const char *dcs_slave_build_id(DcsInstance *in)
{
    return in->slave->build_id;
}

fmi2Status dcs_slave_exception(DcsInstance *in, const char *fn)
{
    return log_exception(in, fn);
}

fmi2Status dcs_slave_status(DcsInstance *in, PyObject *result, const char *fn)
{
    return status_of(in, result, 0, fn);
}

void dcs_slave_drain(DcsInstance *in)
{
    drain_log(in);
}
