/*
 * drillcosim native FMI 2.0 co-simulation wrapper for pythonfmu ``Fmi2Slave`` classes.
 *
 * One C99 file, compiled at FMU build time by fmu_src/wrapper/__init__.py:
 *
 *   gcc -std=c99 -O2 -Wall -Wextra -shared -fPIC -I<python include> \
 *       -DDCS_LIBPYTHON=\"...\" -DDCS_PYTHON_EXE=\"...\" dcs_fmi2_native.c -ldl -lpthread
 *
 * Design
 * ------
 * - No link-time dependency on libpython: every Python C-API function is called
 *   through a pointer looked up with dlsym() (table PYAPI below) and no Python data
 *   symbol (Py_None, PyFloat_Type, ...) is referenced, so the library loads in any
 *   host. In a Python host (fmpy, libcosimpy) the symbols are found in the process
 *   (RTLD_DEFAULT) and the running interpreter is used. In a C/C++ host the
 *   libpython recorded at build time (env DRILLCOSIM_LIBPYTHON overrides) is
 *   dlopen()ed with RTLD_GLOBAL (extension modules such as numpy need its symbols
 *   globally), initialised with program name = the build's Python executable
 *   (env DRILLCOSIM_PYTHON overrides; a venv's pyvenv.cfg is honoured) and the GIL
 *   is released with PyEval_SaveThread(). The interpreter is never finalised.
 * - Every FMI call takes the GIL with PyGILState_Ensure/Release; messages
 *   (log_queue of the slave, exception texts) are collected while the GIL is held
 *   and handed to the logger callback after it is released.
 * - Status of a call (see fmu_src/wrapper/__init__.py for the Python side):
 *     Python exception                -> fmi2Error (text logged, category
 *                                        logStatusError); the instance stays usable
 *     return None / True              -> fmi2OK
 *     return False                    -> fmi2Discard from do_step, fmi2Error otherwise
 *     return an int 0..4 (not bool)   -> that fmi2Status
 *     anything else                   -> do_step: truthy OK / falsy Discard; else OK
 *   then, if the slave has a non-None attribute ``_fmi2_status`` (int 0..4), the
 *   status is raised to it and the attribute is reset to None (only for slaves that
 *   have the attribute right after construction: a missing one costs an exception). fmi2Fatal only when
 *   Python itself cannot be used (initialisation failed, exception text unreadable).
 * - The wrapper sets ``slave._fmi2_wrapper = "native"`` after construction.
 * - A small FMI state machine is enforced: doStep only after
 *   fmi2ExitInitializationMode and before fmi2Terminate, init calls in order.
 */
#define PY_SSIZE_T_CLEAN
#define _GNU_SOURCE
#include <Python.h>

#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ FMI 2.0 types */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;

#define fmi2True 1
#define fmi2False 0

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime,
               fmi2Terminated } fmi2StatusKind;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status,
                                   fmi2String, fmi2String, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);

typedef struct {
    const fmi2CallbackLogger logger;
    const fmi2CallbackAllocateMemory allocateMemory;
    const fmi2CallbackFreeMemory freeMemory;
    const fmi2StepFinished stepFinished;
    const fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#define DCS_EXPORT __attribute__((visibility("default")))

#ifndef DCS_LIBPYTHON
#define DCS_LIBPYTHON "libpython3.so"
#endif
#ifndef DCS_PYTHON_EXE
#define DCS_PYTHON_EXE ""
#endif

/* ---------------------------------------------------- Python C-API through dlsym */
#define PYAPI(X) \
    X(int, Py_IsInitialized, (void)) \
    X(const char *, Py_GetVersion, (void)) \
    X(void, PyConfig_InitPythonConfig, (PyConfig *)) \
    X(PyStatus, PyConfig_SetBytesString, (PyConfig *, wchar_t **, const char *)) \
    X(PyStatus, Py_InitializeFromConfig, (const PyConfig *)) \
    X(void, PyConfig_Clear, (PyConfig *)) \
    X(int, PyStatus_Exception, (PyStatus)) \
    X(PyThreadState *, PyEval_SaveThread, (void)) \
    X(PyGILState_STATE, PyGILState_Ensure, (void)) \
    X(void, PyGILState_Release, (PyGILState_STATE)) \
    X(void, Py_IncRef, (PyObject *)) \
    X(void, Py_DecRef, (PyObject *)) \
    X(PyObject *, Py_BuildValue, (const char *, ...)) \
    X(PyObject *, PyImport_ImportModule, (const char *)) \
    X(PyObject *, PySys_GetObject, (const char *)) \
    X(PyObject *, PyObject_GetAttr, (PyObject *, PyObject *)) \
    X(int, PyObject_SetAttr, (PyObject *, PyObject *, PyObject *)) \
    X(PyObject *, PyObject_Call, (PyObject *, PyObject *, PyObject *)) \
    X(PyObject *, PyObject_VectorcallMethod, (PyObject *, PyObject *const *, size_t, \
                                              PyObject *)) \
    X(PyObject *, PyObject_Str, (PyObject *)) \
    X(int, PyObject_IsTrue, (PyObject *)) \
    X(PyObject *, PyUnicode_InternFromString, (const char *)) \
    X(PyObject *, PyUnicode_FromString, (const char *)) \
    X(PyObject *, PyUnicode_DecodeFSDefault, (const char *)) \
    X(const char *, PyUnicode_AsUTF8AndSize, (PyObject *, Py_ssize_t *)) \
    X(PyObject *, PyUnicode_Join, (PyObject *, PyObject *)) \
    X(PyObject *, PyLong_FromUnsignedLong, (unsigned long)) \
    X(PyObject *, PyLong_FromLong, (long)) \
    X(long, PyLong_AsLong, (PyObject *)) \
    X(PyObject *, PyFloat_FromDouble, (double)) \
    X(double, PyFloat_AsDouble, (PyObject *)) \
    X(PyObject *, PyBool_FromLong, (long)) \
    X(PyObject *, PyList_New, (Py_ssize_t)) \
    X(int, PyList_Insert, (PyObject *, Py_ssize_t, PyObject *)) \
    X(int, PyList_SetSlice, (PyObject *, Py_ssize_t, Py_ssize_t, PyObject *)) \
    X(PyObject *, PySequence_Fast, (PyObject *, const char *)) \
    X(PyObject *, PyTuple_New, (Py_ssize_t)) \
    X(PyObject *, PyDict_New, (void)) \
    X(int, PyDict_SetItemString, (PyObject *, const char *, PyObject *)) \
    X(PyObject *, PyBytes_FromStringAndSize, (const char *, Py_ssize_t)) \
    X(int, PyBytes_AsStringAndSize, (PyObject *, char **, Py_ssize_t *)) \
    X(PyObject *, PyErr_Occurred, (void)) \
    X(void, PyErr_Fetch, (PyObject **, PyObject **, PyObject **)) \
    X(void, PyErr_NormalizeException, (PyObject **, PyObject **, PyObject **)) \
    X(void, PyErr_Clear, (void)) \
    X(void, PyErr_Restore, (PyObject *, PyObject *, PyObject *))

#define DCS_DECLARE(ret, name, args) static ret(*p_##name) args;
PYAPI(DCS_DECLARE)
#undef DCS_DECLARE

static pthread_mutex_t g_init_lock = PTHREAD_MUTEX_INITIALIZER;
static int g_ready = 0;        /* API resolved, interpreter running, names interned */
static char g_init_error[1024] = "";
static void *g_libpython = NULL;

/* interned names and singletons (created once, never released) */
static PyObject *n_setup_experiment, *n_enter_initialization_mode, *n_exit_initialization_mode,
    *n_do_step, *n_terminate, *n_reset, *n_get_real, *n_get_integer, *n_get_boolean,
    *n_get_string, *n_set_real, *n_set_integer, *n_set_boolean, *n_set_string,
    *n_get_fmu_state, *n_set_fmu_state, *n_to_bytes, *n_from_bytes, *n_fmi2_status,
    *n_fmi2_wrapper, *n_log_queue_getter, *n_status, *n_category, *n_msg,
    *n_format_exception;
static PyObject *o_none, *o_true, *o_false, *o_empty_str, *o_native, *o_traceback;

static void dcs_decref(PyObject *o) { if (o != NULL) p_Py_DecRef(o); }
static void dcs_incref(PyObject *o) { if (o != NULL) p_Py_IncRef(o); }

static int resolve_api(void *handle)
{
#define DCS_RESOLVE(ret, name, args) \
    p_##name = (ret(*) args)dlsym(handle, #name); \
    if (p_##name == NULL) { \
        snprintf(g_init_error, sizeof g_init_error, "Python C-API symbol %s not found", #name); \
        return -1; \
    }
    PYAPI(DCS_RESOLVE)
#undef DCS_RESOLVE
    return 0;
}

/* Start an interpreter in a host without Python (called with g_init_lock held). */
static int start_python(void)
{
    const char *exe = getenv("DRILLCOSIM_PYTHON");
    PyConfig config;
    PyStatus st;
    if (exe == NULL || exe[0] == '\0')
        exe = DCS_PYTHON_EXE;
    p_PyConfig_InitPythonConfig(&config);
    config.install_signal_handlers = 0;
    config.parse_argv = 0;
    if (exe[0] != '\0') {
        st = p_PyConfig_SetBytesString(&config, &config.program_name, exe);
        if (p_PyStatus_Exception(st)) {
            p_PyConfig_Clear(&config);
            snprintf(g_init_error, sizeof g_init_error, "cannot set the program name %s", exe);
            return -1;
        }
    }
    st = p_Py_InitializeFromConfig(&config);
    p_PyConfig_Clear(&config);
    if (p_PyStatus_Exception(st)) {
        snprintf(g_init_error, sizeof g_init_error, "Python initialisation failed: %s",
                 st.err_msg != NULL ? st.err_msg : "unknown error");
        return -1;
    }
    p_PyEval_SaveThread(); /* the GIL is taken per call with PyGILState_Ensure */
    return 0;
}

static PyObject *intern(const char *s)
{
    PyObject *o = p_PyUnicode_InternFromString(s);
    return o;
}

static int make_names(void)
{
    PyGILState_STATE g = p_PyGILState_Ensure();
    int ok = 1;
#define N(var, text) if ((var = intern(text)) == NULL) ok = 0;
    N(n_setup_experiment, "setup_experiment")
    N(n_enter_initialization_mode, "enter_initialization_mode")
    N(n_exit_initialization_mode, "exit_initialization_mode")
    N(n_do_step, "do_step")
    N(n_terminate, "terminate")
    N(n_reset, "reset")
    N(n_get_real, "get_real")
    N(n_get_integer, "get_integer")
    N(n_get_boolean, "get_boolean")
    N(n_get_string, "get_string")
    N(n_set_real, "set_real")
    N(n_set_integer, "set_integer")
    N(n_set_boolean, "set_boolean")
    N(n_set_string, "set_string")
    N(n_get_fmu_state, "_get_fmu_state")
    N(n_set_fmu_state, "_set_fmu_state")
    N(n_to_bytes, "_fmu_state_to_bytes")
    N(n_from_bytes, "_fmu_state_from_bytes")
    N(n_fmi2_status, "_fmi2_status")
    N(n_fmi2_wrapper, "_fmi2_wrapper")
    N(n_log_queue_getter, "_get_log_queue")
    N(n_status, "status")
    N(n_category, "category")
    N(n_msg, "msg")
    N(n_format_exception, "format_exception")
    N(o_empty_str, "")
    N(o_native, "native")
#undef N
    o_none = p_Py_BuildValue("");
    o_true = p_PyBool_FromLong(1);
    o_false = p_PyBool_FromLong(0);
    o_traceback = p_PyImport_ImportModule("traceback");
    if (o_none == NULL || o_true == NULL || o_false == NULL || o_traceback == NULL)
        ok = 0;
    if (!ok) {
        snprintf(g_init_error, sizeof g_init_error, "cannot create Python constants");
        p_PyErr_Clear();
    }
    p_PyGILState_Release(g);
    return ok ? 0 : -1;
}

/* Resolve the C-API and make sure an interpreter runs; 0 on success. */
static int ensure_python(void)
{
    int rc = 0;
    pthread_mutex_lock(&g_init_lock);
    if (g_ready) {
        pthread_mutex_unlock(&g_init_lock);
        return 0;
    }
    if (g_init_error[0] != '\0') { /* failed before: do not retry half-way */
        pthread_mutex_unlock(&g_init_lock);
        return -1;
    }
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized") != NULL) {
        rc = resolve_api(RTLD_DEFAULT);
    } else {
        const char *lib = getenv("DRILLCOSIM_LIBPYTHON");
        if (lib == NULL || lib[0] == '\0')
            lib = DCS_LIBPYTHON;
        g_libpython = dlopen(lib, RTLD_NOW | RTLD_GLOBAL);
        if (g_libpython == NULL) {
            const char *why = dlerror();
            snprintf(g_init_error, sizeof g_init_error, "cannot load libpython %s: %s", lib,
                     why != NULL ? why : "unknown error");
            rc = -1;
        } else {
            rc = resolve_api(g_libpython);
        }
    }
    if (rc == 0) {
        const char *v = p_Py_GetVersion(); /* usable before initialisation */
        char want[16];
        snprintf(want, sizeof want, "%d.%d.", PY_MAJOR_VERSION, PY_MINOR_VERSION);
        if (strncmp(v, want, strlen(want)) != 0) {
            snprintf(g_init_error, sizeof g_init_error,
                     "the process runs Python %.20s but this FMU was built for %s",
                     v, PY_VERSION);
            rc = -1;
        } else if (!p_Py_IsInitialized()) {
            rc = start_python();
        }
    }
    if (rc == 0)
        rc = make_names();
    if (rc == 0)
        g_ready = 1;
    else if (g_init_error[0] == '\0')
        snprintf(g_init_error, sizeof g_init_error, "Python could not be started");
    pthread_mutex_unlock(&g_init_lock);
    return rc;
}

/* ---------------------------------------------------------------------- instance */
#define DCS_MAGIC 0x44435346u /* "DCSF" */
#define STATE_MAGIC 0x44435353u

typedef enum { M_INSTANTIATED, M_INIT, M_STEP, M_TERMINATED } Mode;

typedef struct {
    fmi2Status status;
    char *category;
    char *text;
} Msg;

typedef struct {
    unsigned magic;
    char *name;
    char *resources;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    int logging_on;
    char **cats;
    size_t ncats;
    int visible;
    PyObject *cls;
    PyObject *slave;
    PyObject *log_queue;
    PyObject *str_keep; /* bytes objects behind the last fmi2GetString */
    Mode mode;
    int broken;         /* fatal: only fmi2FreeInstance is allowed */
    int has_status;     /* the slave defines _fmi2_status (read after every call) */
    double last_ok_time;
    Msg *msgs;
    size_t nmsgs, capmsgs;
} Inst;

typedef struct {
    unsigned magic;
    PyObject *obj;
    PyObject *bytes; /* cached serialisation */
} State;

static char *dup_str(const char *s)
{
    size_t n = strlen(s ? s : "") + 1;
    char *d = (char *)malloc(n);
    if (d != NULL)
        memcpy(d, s ? s : "", n);
    return d;
}

static int category_enabled(const Inst *in, const char *cat)
{
    size_t i;
    if (in->ncats == 0)
        return 1;
    for (i = 0; i < in->ncats; i++)
        if (strcmp(in->cats[i], cat) == 0 || strcmp(in->cats[i], "logAll") == 0)
            return 1;
    return 0;
}

/* Queue a message (any thread state); delivered by flush() without the GIL. */
static void queue_msg(Inst *in, fmi2Status status, const char *category, const char *text)
{
    Msg *m;
    if (in->logger == NULL)
        return;
    if (status == fmi2OK && !(in->logging_on && category_enabled(in, category)))
        return;
    if (in->nmsgs == in->capmsgs) {
        size_t cap = in->capmsgs ? 2 * in->capmsgs : 8;
        Msg *grown = (Msg *)realloc(in->msgs, cap * sizeof *grown);
        if (grown == NULL)
            return;
        in->msgs = grown;
        in->capmsgs = cap;
    }
    m = &in->msgs[in->nmsgs];
    m->status = status;
    m->category = dup_str(category);
    m->text = dup_str(text);
    if (m->category == NULL || m->text == NULL) {
        free(m->category);
        free(m->text);
        return;
    }
    in->nmsgs++;
}

static void queue_fmt(Inst *in, fmi2Status status, const char *category, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

static void queue_fmt(Inst *in, fmi2Status status, const char *category, const char *fmt, ...)
{
    char buf[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    queue_msg(in, status, category, buf);
}

/* Hand the queued messages to the logger ('%' escaped: the message is a format). */
static void flush(Inst *in)
{
    size_t i;
    for (i = 0; i < in->nmsgs; i++) {
        Msg *m = &in->msgs[i];
        size_t n = 0, k;
        char *esc;
        for (k = 0; m->text[k]; k++)
            n += m->text[k] == '%' ? 2 : 1;
        esc = (char *)malloc(n + 1);
        if (esc != NULL) {
            char *o = esc;
            for (k = 0; m->text[k]; k++) {
                *o++ = m->text[k];
                if (m->text[k] == '%')
                    *o++ = '%';
            }
            *o = '\0';
            in->logger(in->env, in->name, m->status, m->category, esc);
            free(esc);
        }
        free(m->category);
        free(m->text);
    }
    in->nmsgs = 0;
}

static const char *status_category(fmi2Status s)
{
    switch (s) {
    case fmi2OK: return "logAll";
    case fmi2Warning: return "logStatusWarning";
    case fmi2Discard: return "logStatusDiscard";
    case fmi2Error: return "logStatusError";
    default: return "logStatusFatal";
    }
}

/* Move slave.log_queue into the C message queue (GIL held). */
static void drain_log(Inst *in)
{
    Py_ssize_t i, n;
    if (in->log_queue == NULL || !PyList_Check(in->log_queue))
        return;
    n = PyList_GET_SIZE(in->log_queue);
    if (n == 0)
        return;
    for (i = 0; i < n; i++) {
        PyObject *item = PyList_GET_ITEM(in->log_queue, i);
        PyObject *st = p_PyObject_GetAttr(item, n_status);
        PyObject *cat = p_PyObject_GetAttr(item, n_category);
        PyObject *msg = p_PyObject_GetAttr(item, n_msg);
        PyObject *cats = cat != NULL ? p_PyObject_Str(cat) : NULL;
        PyObject *msgs = msg != NULL ? p_PyObject_Str(msg) : NULL;
        long status = st != NULL ? p_PyLong_AsLong(st) : 0;
        const char *ctext = cats != NULL ? p_PyUnicode_AsUTF8AndSize(cats, NULL) : NULL;
        const char *mtext = msgs != NULL ? p_PyUnicode_AsUTF8AndSize(msgs, NULL) : NULL;
        if (p_PyErr_Occurred())
            p_PyErr_Clear();
        if (status < 0 || status > 4)
            status = fmi2OK;
        queue_msg(in, (fmi2Status)status, ctext != NULL ? ctext : "logAll",
                  mtext != NULL ? mtext : "(unreadable log message)");
        dcs_decref(st);
        dcs_decref(cat);
        dcs_decref(msg);
        dcs_decref(cats);
        dcs_decref(msgs);
    }
    if (p_PyList_SetSlice(in->log_queue, 0, n, NULL) != 0)
        p_PyErr_Clear();
}

/* Log the pending Python exception (GIL held); fmi2Error, or fmi2Fatal if unreadable. */
static fmi2Status log_exception(Inst *in, const char *fn)
{
    PyObject *type = NULL, *value = NULL, *tb = NULL, *lines = NULL, *text = NULL;
    const char *s = NULL;
    fmi2Status status = fmi2Error;
    p_PyErr_Fetch(&type, &value, &tb);
    p_PyErr_NormalizeException(&type, &value, &tb);
    if (type != NULL) {
        PyObject *args[4] = {o_traceback, type, value ? value : o_none, tb ? tb : o_none};
        lines = p_PyObject_VectorcallMethod(n_format_exception, args,
                                            4 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
        if (lines != NULL)
            text = p_PyUnicode_Join(o_empty_str, lines);
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
    queue_fmt(in, status, status_category(status), "%s: Python exception in %s: %s",
              in->name, fn, s);
    dcs_decref(lines);
    dcs_decref(text);
    dcs_decref(type);
    dcs_decref(value);
    dcs_decref(tb);
    return status;
}

/* Status from a method's result (new reference, consumed); GIL held. */
static fmi2Status status_of(Inst *in, PyObject *res, int is_step, const char *fn)
{
    fmi2Status status = fmi2OK;
    PyObject *extra;
    if (res == NULL)
        return log_exception(in, fn);
    if (res == o_none || res == o_true) {
        status = fmi2OK;
    } else if (res == o_false) {
        status = is_step ? fmi2Discard : fmi2Error;
    } else if (PyLong_Check(res)) {
        long v = p_PyLong_AsLong(res);
        if (p_PyErr_Occurred() || v < 0 || v > 4) {
            p_PyErr_Clear();
            queue_fmt(in, fmi2Error, "logStatusError",
                      "%s: %s returned an integer that is no fmi2Status (0..4)", in->name, fn);
            status = fmi2Error;
        } else {
            status = (fmi2Status)v;
        }
    } else if (is_step) {
        int t = p_PyObject_IsTrue(res);
        if (t < 0) {
            dcs_decref(res);
            return log_exception(in, fn);
        }
        status = t ? fmi2OK : fmi2Discard;
    }
    dcs_decref(res);
    if (!in->has_status)
        return status;
    extra = p_PyObject_GetAttr(in->slave, n_fmi2_status);
    if (extra == NULL) {
        p_PyErr_Clear();
    } else {
        if (extra != o_none) {
            long v = p_PyLong_AsLong(extra);
            if (p_PyErr_Occurred()) {
                p_PyErr_Clear();
                v = fmi2Error;
            }
            if (v > (long)status && v <= fmi2Fatal)
                status = (fmi2Status)v;
            if (p_PyObject_SetAttr(in->slave, n_fmi2_status, o_none) != 0)
                p_PyErr_Clear();
        }
        dcs_decref(extra);
    }
    return status;
}

static int valid(fmi2Component c)
{
    return c != NULL && ((Inst *)c)->magic == DCS_MAGIC;
}

/* Entering/leaving a call: every fmi2 function below has this frame. */
#define BEGIN(fn) \
    Inst *in = (Inst *)c; \
    PyGILState_STATE gil; \
    fmi2Status status = fmi2OK; \
    if (!valid(c)) return fmi2Error; \
    if (in->broken) { \
        queue_fmt(in, fmi2Error, "logStatusError", "%s: %s called after fmi2Fatal", \
                  in->name, fn); \
        flush(in); \
        return fmi2Error; \
    } \
    gil = p_PyGILState_Ensure();

#define END() \
    drain_log(in); \
    p_PyGILState_Release(gil); \
    if (status == fmi2Fatal) in->broken = 1; \
    flush(in); \
    return status;

static fmi2Status refuse(Inst *in, const char *fn, const char *why)
{
    queue_fmt(in, fmi2Error, "logStatusError", "%s: %s not allowed: %s", in->name, fn, why);
    flush(in);
    return fmi2Error;
}

/* Call slave.<name>(*args); status from the result. */
static fmi2Status call_method(Inst *in, PyObject *name, PyObject **args, size_t nargs,
                              int is_step, const char *fn)
{
    PyObject *buf[8];
    size_t i;
    PyObject *res;
    buf[0] = in->slave;
    for (i = 0; i < nargs; i++)
        buf[i + 1] = args[i];
    res = p_PyObject_VectorcallMethod(name, buf, (nargs + 1) | PY_VECTORCALL_ARGUMENTS_OFFSET,
                                      NULL);
    return status_of(in, res, is_step, fn);
}

/* New list of Python ints for the value references (NULL + exception on failure). */
static PyObject *vr_list(const fmi2ValueReference vr[], size_t nvr)
{
    size_t i;
    PyObject *l = p_PyList_New((Py_ssize_t)nvr);
    if (l == NULL)
        return NULL;
    for (i = 0; i < nvr; i++) {
        PyObject *v = p_PyLong_FromUnsignedLong(vr[i]);
        if (v == NULL) {
            dcs_decref(l);
            return NULL;
        }
        PyList_SET_ITEM(l, (Py_ssize_t)i, v);
    }
    return l;
}

/* Create the slave object (GIL held); 0 on success. */
static int create_slave(Inst *in)
{
    PyObject *args = NULL, *kwargs = NULL, *slave = NULL, *q = NULL, *tmp;
    int rc = -1;
    args = p_PyTuple_New(0);
    kwargs = p_PyDict_New();
    if (args == NULL || kwargs == NULL)
        goto done;
    tmp = p_PyUnicode_FromString(in->name);
    if (tmp == NULL || p_PyDict_SetItemString(kwargs, "instance_name", tmp) != 0) {
        dcs_decref(tmp);
        goto done;
    }
    dcs_decref(tmp);
    tmp = p_PyUnicode_DecodeFSDefault(in->resources);
    if (tmp == NULL || p_PyDict_SetItemString(kwargs, "resources", tmp) != 0) {
        dcs_decref(tmp);
        goto done;
    }
    dcs_decref(tmp);
    if (p_PyDict_SetItemString(kwargs, "visible", in->visible ? o_true : o_false) != 0)
        goto done;
    slave = p_PyObject_Call(in->cls, args, kwargs);
    if (slave == NULL)
        goto done;
    if (p_PyObject_SetAttr(slave, n_fmi2_wrapper, o_native) != 0)
        goto done;
    {
        PyObject *self_only[1] = {slave};
        q = p_PyObject_VectorcallMethod(n_log_queue_getter, self_only,
                                        1 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
    }
    if (q == NULL)
        goto done;
    tmp = p_PyObject_GetAttr(slave, n_fmi2_status);
    in->has_status = tmp != NULL;
    if (tmp == NULL)
        p_PyErr_Clear();
    dcs_decref(tmp);
    dcs_decref(in->slave);
    dcs_decref(in->log_queue);
    in->slave = slave;
    in->log_queue = q;
    slave = NULL;
    rc = 0;
done:
    dcs_decref(args);
    dcs_decref(kwargs);
    dcs_decref(slave);
    return rc;
}

/* First line of resources/<file>, stripped; malloc'd or NULL. */
static char *read_line(const char *dir, const char *file)
{
    char path[4096], line[512];
    FILE *f;
    size_t n;
    snprintf(path, sizeof path, "%s/%s", dir, file);
    f = fopen(path, "r");
    if (f == NULL)
        return NULL;
    if (fgets(line, sizeof line, f) == NULL) {
        fclose(f);
        return NULL;
    }
    fclose(f);
    n = strlen(line);
    while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r' || line[n - 1] == ' '))
        line[--n] = '\0';
    return n > 0 ? dup_str(line) : NULL;
}

/* modelIdentifier = file name of this library without ".so". */
static char *own_model_identifier(void)
{
    Dl_info info;
    const char *base, *dot;
    char *out;
    if (dladdr((void *)&own_model_identifier, &info) == 0 || info.dli_fname == NULL)
        return NULL;
    base = strrchr(info.dli_fname, '/');
    base = base != NULL ? base + 1 : info.dli_fname;
    dot = strrchr(base, '.');
    out = dup_str(base);
    if (out != NULL && dot != NULL)
        out[dot - base] = '\0';
    return out;
}

/* "file:///a%20b/resources/" -> "/a b/resources" (malloc'd). */
static char *uri_to_path(const char *uri)
{
    const char *p = uri;
    char *out, *o;
    if (strncmp(p, "file://", 7) == 0) {
        p += 7;
        if (*p != '/') { /* file://host/path */
            const char *slash = strchr(p, '/');
            p = slash != NULL ? slash : p + strlen(p);
        }
    } else if (strncmp(p, "file:", 5) == 0) {
        p += 5;
    }
    out = (char *)malloc(strlen(p) + 1);
    if (out == NULL)
        return NULL;
    for (o = out; *p; p++) {
        if (p[0] == '%' && p[1] && p[2]) {
            char hex[3] = {p[1], p[2], 0};
            char *end;
            long v = strtol(hex, &end, 16);
            if (*end == '\0') {
                *o++ = (char)v;
                p += 2;
                continue;
            }
        }
        *o++ = *p;
    }
    *o = '\0';
    while (o > out + 1 && o[-1] == '/')
        *--o = '\0';
    return out;
}

/* Import the slave module with resources first on sys.path (only during the import). */
static PyObject *import_class(Inst *in, const char *module, const char *cls_name)
{
    PyObject *path = p_PySys_GetObject("path"); /* borrowed: held while importing */
    PyObject *entry = p_PyUnicode_DecodeFSDefault(in->resources);
    PyObject *mod = NULL, *cls = NULL, *cname;
    int inserted = 0;
    if (entry == NULL)
        return NULL;
    if (path != NULL && PyList_Check(path)) {
        dcs_incref(path); /* the module may rebind sys.path */
        if (p_PyList_Insert(path, 0, entry) != 0) {
            dcs_decref(path);
            dcs_decref(entry);
            return NULL;
        }
        inserted = 1;
    }
    mod = p_PyImport_ImportModule(module);
    if (inserted) { /* remove exactly the entry inserted above, keep any error */
        PyObject *type, *value, *tb;
        Py_ssize_t i;
        p_PyErr_Fetch(&type, &value, &tb);
        for (i = 0; i < PyList_GET_SIZE(path); i++) {
            if (PyList_GET_ITEM(path, i) == entry) {
                if (p_PyList_SetSlice(path, i, i + 1, NULL) != 0)
                    p_PyErr_Clear();
                break;
            }
        }
        p_PyErr_Restore(type, value, tb);
        dcs_decref(path);
    }
    dcs_decref(entry);
    if (mod == NULL)
        return NULL;
    cname = p_PyUnicode_FromString(cls_name);
    if (cname != NULL)
        cls = p_PyObject_GetAttr(mod, cname);
    dcs_decref(cname);
    dcs_decref(mod);
    return cls;
}

static void free_inst(Inst *in)
{
    size_t i;
    in->magic = 0;
    for (i = 0; i < in->ncats; i++)
        free(in->cats[i]);
    free(in->cats);
    for (i = 0; i < in->nmsgs; i++) {
        free(in->msgs[i].category);
        free(in->msgs[i].text);
    }
    free(in->msgs);
    free(in->name);
    free(in->resources);
    free(in);
}

/* ------------------------------------------------------------------ FMI functions */
DCS_EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
DCS_EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

DCS_EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType,
                                         fmi2String fmuGUID, fmi2String fmuResourceLocation,
                                         const fmi2CallbackFunctions *functions,
                                         fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Inst *in;
    PyGILState_STATE gil;
    char *module = NULL, *cls_name = NULL;
    int ok = 0;
    (void)fmuGUID;
    if (functions == NULL || instanceName == NULL)
        return NULL;
    in = (Inst *)calloc(1, sizeof *in);
    if (in == NULL)
        return NULL;
    in->magic = DCS_MAGIC;
    in->name = dup_str(instanceName);
    in->logger = functions->logger;
    in->env = functions->componentEnvironment;
    in->logging_on = loggingOn != fmi2False;
    in->visible = visible != fmi2False;
    in->mode = M_INSTANTIATED;
    if (in->name == NULL) {
        free_inst(in);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        queue_fmt(in, fmi2Error, "logStatusError",
                  "%s: fmi2Instantiate: only co-simulation is supported", in->name);
        flush(in);
        free_inst(in);
        return NULL;
    }
    if (fmuResourceLocation == NULL || (in->resources = uri_to_path(fmuResourceLocation)) == NULL) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2Instantiate: no resource location",
                  in->name);
        flush(in);
        free_inst(in);
        return NULL;
    }
    if (ensure_python() != 0) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2Instantiate: %s", in->name,
                  g_init_error);
        flush(in);
        free_inst(in);
        return NULL;
    }
    module = read_line(in->resources, "slavemodule.txt");
    cls_name = read_line(in->resources, "slaveclass.txt");
    if (cls_name == NULL)
        cls_name = own_model_identifier();
    if (module == NULL || cls_name == NULL) {
        queue_fmt(in, fmi2Error, "logStatusError",
                  "%s: fmi2Instantiate: cannot read %s/slavemodule.txt (or the class name)",
                  in->name, in->resources);
        flush(in);
        free(module);
        free(cls_name);
        free_inst(in);
        return NULL;
    }
    gil = p_PyGILState_Ensure();
    in->cls = import_class(in, module, cls_name);
    if (in->cls == NULL) {
        char what[512];
        snprintf(what, sizeof what, "fmi2Instantiate (importing class %.100s of module %.100s "
                 "from %.250s)", cls_name, module, in->resources);
        log_exception(in, what);
    } else if (create_slave(in) != 0) {
        log_exception(in, "fmi2Instantiate (creating the slave)");
    } else {
        ok = 1;
    }
    if (in->slave != NULL)
        drain_log(in);
    if (!ok) {
        dcs_decref(in->cls);
        dcs_decref(in->slave);
        dcs_decref(in->log_queue);
        in->cls = in->slave = in->log_queue = NULL;
    }
    p_PyGILState_Release(gil);
    flush(in);
    free(module);
    free(cls_name);
    if (!ok) {
        free_inst(in);
        return NULL;
    }
    return in;
}

DCS_EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Inst *in = (Inst *)c;
    if (!valid(c))
        return;
    if (g_ready) {
        PyGILState_STATE gil = p_PyGILState_Ensure();
        if (in->slave != NULL)
            drain_log(in);
        dcs_decref(in->str_keep);
        dcs_decref(in->log_queue);
        dcs_decref(in->slave);
        dcs_decref(in->cls);
        in->str_keep = in->log_queue = in->slave = in->cls = NULL;
        p_PyGILState_Release(gil);
    }
    flush(in);
    free_inst(in);
}

DCS_EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn,
                                          size_t nCategories, const fmi2String categories[])
{
    Inst *in = (Inst *)c;
    size_t i;
    if (!valid(c))
        return fmi2Error;
    for (i = 0; i < in->ncats; i++)
        free(in->cats[i]);
    free(in->cats);
    in->cats = NULL;
    in->ncats = 0;
    in->logging_on = loggingOn != fmi2False;
    if (nCategories > 0 && categories != NULL) {
        in->cats = (char **)calloc(nCategories, sizeof *in->cats);
        if (in->cats == NULL)
            return fmi2Error;
        for (i = 0; i < nCategories; i++) {
            in->cats[i] = dup_str(categories[i]);
            if (in->cats[i] == NULL)
                return fmi2Error;
            in->ncats++;
        }
    }
    return fmi2OK;
}

DCS_EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                                          fmi2Real tolerance, fmi2Real startTime,
                                          fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    PyObject *args[3];
    if (valid(c) && ((Inst *)c)->mode != M_INSTANTIATED)
        return refuse((Inst *)c, "fmi2SetupExperiment", "only after fmi2Instantiate");
    {
        BEGIN("fmi2SetupExperiment")
        args[0] = p_PyFloat_FromDouble(startTime);
        args[1] = stopTimeDefined ? p_PyFloat_FromDouble(stopTime) : (dcs_incref(o_none), o_none);
        args[2] = toleranceDefined ? p_PyFloat_FromDouble(tolerance)
                                   : (dcs_incref(o_none), o_none);
        if (args[0] == NULL || args[1] == NULL || args[2] == NULL)
            status = log_exception(in, "fmi2SetupExperiment");
        else
            status = call_method(in, n_setup_experiment, args, 3, 0, "fmi2SetupExperiment");
        dcs_decref(args[0]);
        dcs_decref(args[1]);
        dcs_decref(args[2]);
        in->last_ok_time = startTime;
        END()
    }
}

DCS_EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    if (valid(c) && ((Inst *)c)->mode != M_INSTANTIATED)
        return refuse((Inst *)c, "fmi2EnterInitializationMode", "only after fmi2Instantiate "
                      "(and fmi2SetupExperiment)");
    {
        BEGIN("fmi2EnterInitializationMode")
        status = call_method(in, n_enter_initialization_mode, NULL, 0, 0,
                             "fmi2EnterInitializationMode");
        if (status <= fmi2Warning)
            in->mode = M_INIT;
        END()
    }
}

DCS_EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    if (valid(c) && ((Inst *)c)->mode != M_INIT)
        return refuse((Inst *)c, "fmi2ExitInitializationMode",
                      "only in initialization mode (after fmi2EnterInitializationMode)");
    {
        BEGIN("fmi2ExitInitializationMode")
        status = call_method(in, n_exit_initialization_mode, NULL, 0, 0,
                             "fmi2ExitInitializationMode");
        if (status <= fmi2Warning)
            in->mode = M_STEP;
        END()
    }
}

DCS_EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    if (valid(c) && ((Inst *)c)->mode != M_STEP)
        return refuse((Inst *)c, "fmi2Terminate", "only after fmi2ExitInitializationMode");
    {
        BEGIN("fmi2Terminate")
        status = call_method(in, n_terminate, NULL, 0, 0, "fmi2Terminate");
        in->mode = M_TERMINATED;
        END()
    }
}

DCS_EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    PyObject *meth;
    BEGIN("fmi2Reset")
    meth = p_PyObject_GetAttr(in->slave, n_reset);
    if (meth != NULL) {
        dcs_decref(meth);
        status = call_method(in, n_reset, NULL, 0, 0, "fmi2Reset");
    } else {
        p_PyErr_Clear();
        drain_log(in);
        if (create_slave(in) != 0) /* the old slave is kept on failure */
            status = log_exception(in, "fmi2Reset (re-instantiating the slave)");
    }
    if (status <= fmi2Warning)
        in->mode = M_INSTANTIATED;
    END()
}

DCS_EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                                 fmi2Real communicationStepSize,
                                 fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    PyObject *args[2];
    (void)noSetFMUStatePriorToCurrentPoint;
    if (valid(c) && ((Inst *)c)->mode != M_STEP)
        return refuse((Inst *)c, "fmi2DoStep",
                      ((Inst *)c)->mode == M_TERMINATED ? "the instance is terminated"
                      : "called before initialization (fmi2ExitInitializationMode)");
    {
        BEGIN("fmi2DoStep")
        args[0] = p_PyFloat_FromDouble(currentCommunicationPoint);
        args[1] = p_PyFloat_FromDouble(communicationStepSize);
        if (args[0] == NULL || args[1] == NULL)
            status = log_exception(in, "fmi2DoStep");
        else
            status = call_method(in, n_do_step, args, 2, 1, "fmi2DoStep");
        dcs_decref(args[0]);
        dcs_decref(args[1]);
        if (status <= fmi2Warning)
            in->last_ok_time = currentCommunicationPoint + communicationStepSize;
        END()
    }
}

DCS_EXPORT fmi2Status fmi2CancelStep(fmi2Component c)
{
    if (!valid(c))
        return fmi2Error;
    return refuse((Inst *)c, "fmi2CancelStep", "doStep is never asynchronous");
}

/* ------------------------------------------------------------------ get / set */
typedef enum { T_REAL, T_INTEGER, T_BOOLEAN, T_STRING } VType;

static fmi2Status get_values(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                             void *out, VType type, PyObject *meth, const char *fn)
{
    PyObject *vrs, *res = NULL, *seq = NULL;
    size_t i;
    BEGIN(fn)
    if (nvr > 0 && (vr == NULL || out == NULL)) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: %s: NULL array", in->name, fn);
        status = fmi2Error;
        END()
    }
    vrs = vr_list(vr, nvr);
    if (vrs != NULL) {
        PyObject *args[2] = {in->slave, vrs};
        res = p_PyObject_VectorcallMethod(meth, args, 2 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
        dcs_decref(vrs);
    }
    if (res == NULL) {
        status = log_exception(in, fn);
        END()
    }
    seq = p_PySequence_Fast(res, "get_* must return a sequence");
    dcs_decref(res);
    if (seq == NULL) {
        status = log_exception(in, fn);
        END()
    }
    if ((size_t)PySequence_Fast_GET_SIZE(seq) != nvr) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: %s: the slave returned %zd values "
                  "for %zu value references", in->name, fn, PySequence_Fast_GET_SIZE(seq), nvr);
        dcs_decref(seq);
        status = fmi2Error;
        END()
    }
    if (type == T_STRING) {
        dcs_decref(in->str_keep); /* the strings live as long as the sequence */
        in->str_keep = seq;
        dcs_incref(seq);
    }
    for (i = 0; i < nvr && status != fmi2Error; i++) {
        PyObject *item = PySequence_Fast_GET_ITEM(seq, (Py_ssize_t)i);
        switch (type) {
        case T_REAL:
            ((fmi2Real *)out)[i] = p_PyFloat_AsDouble(item);
            break;
        case T_INTEGER: {
            long v = p_PyLong_AsLong(item);
            if (v > 2147483647L || v < -2147483647L - 1L) {
                queue_fmt(in, fmi2Error, "logStatusError", "%s: %s: value of vr %u does not "
                          "fit an fmi2Integer", in->name, fn, vr[i]);
                status = fmi2Error;
            }
            ((fmi2Integer *)out)[i] = (fmi2Integer)v;
            break;
        }
        case T_BOOLEAN: {
            int t = p_PyObject_IsTrue(item);
            ((fmi2Boolean *)out)[i] = t > 0 ? fmi2True : fmi2False;
            break;
        }
        case T_STRING: {
            const char *s = PyUnicode_Check(item) ? p_PyUnicode_AsUTF8AndSize(item, NULL) : NULL;
            if (s == NULL && !p_PyErr_Occurred()) {
                queue_fmt(in, fmi2Error, "logStatusError", "%s: %s: value of vr %u is not a "
                          "str", in->name, fn, vr[i]);
                status = fmi2Error;
            }
            ((fmi2String *)out)[i] = s != NULL ? s : "";
            break;
        }
        }
        if (p_PyErr_Occurred()) {
            status = log_exception(in, fn);
            break;
        }
    }
    dcs_decref(seq);
    if (status != fmi2Error && status != fmi2Fatal) {
        PyObject *none = o_none;
        dcs_incref(none);
        status = status_of(in, none, 0, fn); /* _fmi2_status escalation */
    }
    END()
}

static fmi2Status set_values(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                             const void *values, VType type, PyObject *meth, const char *fn)
{
    PyObject *vrs = NULL, *vals = NULL;
    size_t i;
    BEGIN(fn)
    if (nvr > 0 && (vr == NULL || values == NULL)) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: %s: NULL array", in->name, fn);
        status = fmi2Error;
        END()
    }
    vrs = vr_list(vr, nvr);
    vals = p_PyList_New((Py_ssize_t)nvr);
    for (i = 0; vrs != NULL && vals != NULL && i < nvr; i++) {
        PyObject *v = NULL;
        switch (type) {
        case T_REAL: v = p_PyFloat_FromDouble(((const fmi2Real *)values)[i]); break;
        case T_INTEGER: v = p_PyLong_FromLong(((const fmi2Integer *)values)[i]); break;
        case T_BOOLEAN: v = p_PyBool_FromLong(((const fmi2Boolean *)values)[i] != fmi2False);
            break;
        case T_STRING: {
            const char *s = ((const fmi2String *)values)[i];
            v = p_PyUnicode_FromString(s != NULL ? s : "");
            break;
        }
        }
        if (v == NULL)
            break;
        PyList_SET_ITEM(vals, (Py_ssize_t)i, v);
    }
    if (vrs == NULL || vals == NULL || i < nvr) {
        status = log_exception(in, fn);
    } else {
        PyObject *args[2] = {vrs, vals};
        status = call_method(in, meth, args, 2, 0, fn);
    }
    dcs_decref(vrs);
    dcs_decref(vals);
    END()
}

DCS_EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                  fmi2Real value[])
{
    return get_values(c, vr, nvr, value, T_REAL, n_get_real, "fmi2GetReal");
}

DCS_EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[],
                                     size_t nvr, fmi2Integer value[])
{
    return get_values(c, vr, nvr, value, T_INTEGER, n_get_integer, "fmi2GetInteger");
}

DCS_EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[],
                                     size_t nvr, fmi2Boolean value[])
{
    return get_values(c, vr, nvr, value, T_BOOLEAN, n_get_boolean, "fmi2GetBoolean");
}

DCS_EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[],
                                    size_t nvr, fmi2String value[])
{
    return get_values(c, vr, nvr, (void *)value, T_STRING, n_get_string, "fmi2GetString");
}

DCS_EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                  const fmi2Real value[])
{
    return set_values(c, vr, nvr, value, T_REAL, n_set_real, "fmi2SetReal");
}

DCS_EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[],
                                     size_t nvr, const fmi2Integer value[])
{
    return set_values(c, vr, nvr, value, T_INTEGER, n_set_integer, "fmi2SetInteger");
}

DCS_EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[],
                                     size_t nvr, const fmi2Boolean value[])
{
    return set_values(c, vr, nvr, value, T_BOOLEAN, n_set_boolean, "fmi2SetBoolean");
}

DCS_EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[],
                                    size_t nvr, const fmi2String value[])
{
    return set_values(c, vr, nvr, (const void *)value, T_STRING, n_set_string,
                      "fmi2SetString");
}

/* ------------------------------------------------------------------ FMU state */
static State *as_state(fmi2FMUstate s)
{
    State *st = (State *)s;
    return st != NULL && st->magic == STATE_MAGIC ? st : NULL;
}

static void drop_state(State *st)
{
    dcs_decref(st->obj);
    dcs_decref(st->bytes);
    st->obj = st->bytes = NULL;
}

DCS_EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    PyObject *self_only[1], *obj;
    State *st;
    BEGIN("fmi2GetFMUstate")
    if (FMUstate == NULL) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2GetFMUstate: NULL pointer",
                  in->name);
        status = fmi2Error;
        END()
    }
    self_only[0] = in->slave;
    obj = p_PyObject_VectorcallMethod(n_get_fmu_state, self_only,
                                      1 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
    if (obj == NULL) {
        status = log_exception(in, "fmi2GetFMUstate");
        END()
    }
    st = as_state(*FMUstate);
    if (st == NULL) {
        st = (State *)calloc(1, sizeof *st);
        if (st == NULL) {
            dcs_decref(obj);
            queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2GetFMUstate: out of memory",
                      in->name);
            status = fmi2Error;
            END()
        }
        st->magic = STATE_MAGIC;
    } else {
        drop_state(st); /* FMI 2.0: a given state is overwritten */
    }
    st->obj = obj;
    *FMUstate = st;
    {
        PyObject *none = o_none;
        dcs_incref(none);
        status = status_of(in, none, 0, "fmi2GetFMUstate");
    }
    END()
}

DCS_EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    State *st = as_state(FMUstate);
    PyObject *args[1];
    BEGIN("fmi2SetFMUstate")
    if (st == NULL || st->obj == NULL) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2SetFMUstate: not a state of this "
                  "FMU", in->name);
        status = fmi2Error;
        END()
    }
    args[0] = st->obj;
    status = call_method(in, n_set_fmu_state, args, 1, 0, "fmi2SetFMUstate");
    END()
}

DCS_EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    State *st;
    BEGIN("fmi2FreeFMUstate")
    st = FMUstate != NULL ? as_state(*FMUstate) : NULL;
    if (st != NULL) {
        drop_state(st);
        st->magic = 0;
        free(st);
        *FMUstate = NULL;
    } else if (FMUstate != NULL && *FMUstate != NULL) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2FreeFMUstate: not a state of this "
                  "FMU", in->name);
        status = fmi2Error;
    }
    END()
}

/* Serialised bytes of a state, cached in it (GIL held); NULL + logged on failure. */
static PyObject *state_bytes(Inst *in, State *st, const char *fn, fmi2Status *status)
{
    if (st->bytes == NULL) {
        PyObject *args[2] = {in->slave, st->obj};
        PyObject *b = p_PyObject_VectorcallMethod(n_to_bytes, args,
                                                  2 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
        if (b == NULL) {
            *status = log_exception(in, fn);
            return NULL;
        }
        if (!PyBytes_Check(b)) {
            dcs_decref(b);
            queue_fmt(in, fmi2Error, "logStatusError", "%s: %s: _fmu_state_to_bytes did not "
                      "return bytes", in->name, fn);
            *status = fmi2Error;
            return NULL;
        }
        st->bytes = b;
    }
    return st->bytes;
}

DCS_EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate,
                                                 size_t *size)
{
    State *st = as_state(FMUstate);
    BEGIN("fmi2SerializedFMUstateSize")
    if (st == NULL || st->obj == NULL || size == NULL) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2SerializedFMUstateSize: invalid "
                  "arguments", in->name);
        status = fmi2Error;
    } else {
        PyObject *b = state_bytes(in, st, "fmi2SerializedFMUstateSize", &status);
        if (b != NULL)
            *size = (size_t)PyBytes_GET_SIZE(b);
    }
    END()
}

DCS_EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                            fmi2Byte serializedState[], size_t size)
{
    State *st = as_state(FMUstate);
    BEGIN("fmi2SerializeFMUstate")
    if (st == NULL || st->obj == NULL || (serializedState == NULL && size > 0)) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2SerializeFMUstate: invalid "
                  "arguments", in->name);
        status = fmi2Error;
    } else {
        PyObject *b = state_bytes(in, st, "fmi2SerializeFMUstate", &status);
        if (b != NULL) {
            size_t n = (size_t)PyBytes_GET_SIZE(b);
            if (size < n) {
                queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2SerializeFMUstate: buffer "
                          "of %zu bytes, %zu needed", in->name, size, n);
                status = fmi2Error;
            } else {
                memcpy(serializedState, PyBytes_AS_STRING(b), n);
            }
        }
    }
    END()
}

DCS_EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                              size_t size, fmi2FMUstate *FMUstate)
{
    PyObject *b, *obj = NULL;
    BEGIN("fmi2DeSerializeFMUstate")
    if (FMUstate == NULL || (serializedState == NULL && size > 0)) {
        queue_fmt(in, fmi2Error, "logStatusError", "%s: fmi2DeSerializeFMUstate: invalid "
                  "arguments", in->name);
        status = fmi2Error;
        END()
    }
    b = p_PyBytes_FromStringAndSize(serializedState, (Py_ssize_t)size);
    if (b != NULL) {
        PyObject *args[2] = {in->slave, b};
        obj = p_PyObject_VectorcallMethod(n_from_bytes, args,
                                          2 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
        dcs_decref(b);
    }
    if (obj == NULL) {
        status = log_exception(in, "fmi2DeSerializeFMUstate");
    } else {
        State *st = as_state(*FMUstate);
        if (st == NULL) {
            st = (State *)calloc(1, sizeof *st);
            if (st != NULL)
                st->magic = STATE_MAGIC;
        } else {
            drop_state(st);
        }
        if (st == NULL) {
            dcs_decref(obj);
            status = fmi2Error;
        } else {
            st->obj = obj;
            *FMUstate = st;
        }
    }
    END()
}

/* --------------------------------------------------- unsupported FMI 2.0 features */
DCS_EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c,
                                                   const fmi2ValueReference vUnknown_ref[],
                                                   size_t nUnknown,
                                                   const fmi2ValueReference vKnown_ref[],
                                                   size_t nKnown, const fmi2Real dvKnown[],
                                                   fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown;
    (void)dvUnknown;
    if (!valid(c))
        return fmi2Error;
    return refuse((Inst *)c, "fmi2GetDirectionalDerivative",
                  "providesDirectionalDerivative is false");
}

DCS_EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c,
                                                  const fmi2ValueReference vr[], size_t nvr,
                                                  const fmi2Integer order[],
                                                  const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!valid(c))
        return fmi2Error;
    return refuse((Inst *)c, "fmi2SetRealInputDerivatives", "canInterpolateInputs is false");
}

DCS_EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c,
                                                   const fmi2ValueReference vr[], size_t nvr,
                                                   const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!valid(c))
        return fmi2Error;
    return refuse((Inst *)c, "fmi2GetRealOutputDerivatives", "maxOutputDerivativeOrder is 0");
}

DCS_EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s; (void)value;
    return valid(c) ? fmi2Discard : fmi2Error; /* no asynchronous doStep */
}

DCS_EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s,
                                        fmi2Real *value)
{
    if (!valid(c))
        return fmi2Error;
    if (s == fmi2LastSuccessfulTime && value != NULL) {
        *value = ((Inst *)c)->last_ok_time;
        return fmi2OK;
    }
    return fmi2Discard;
}

DCS_EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s,
                                           fmi2Integer *value)
{
    (void)s; (void)value;
    return valid(c) ? fmi2Discard : fmi2Error;
}

DCS_EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s,
                                           fmi2Boolean *value)
{
    (void)s; (void)value;
    return valid(c) ? fmi2Discard : fmi2Error;
}

DCS_EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s,
                                          fmi2String *value)
{
    (void)s; (void)value;
    return valid(c) ? fmi2Discard : fmi2Error;
}
