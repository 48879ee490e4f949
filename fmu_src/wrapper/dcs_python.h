/*
 * The Python C-API as the wrapper sees it: the stable ABI of CPython 3.10 to 3.13, every
 * function looked up with dlsym() at run time.
 *
 * One binary for every supported version: the header is included with Py_LIMITED_API set to
 * 3.10, so the compiler refuses anything outside the limited API of 3.10 (macros that read
 * object fields, PyConfig and its version-dependent layout); each function pointer takes its
 * type from the header's own declaration (a name missing from the limited API does not
 * compile). The library has no link-time dependency on libpython and references no Python
 * symbol: it loads in any host.
 *
 * Two things are not in the limited API of 3.10 and are declared here by hand:
 *   - the buffer protocol (Py_buffer, PyObject_GetBuffer, PyBuffer_Release): part of the
 *     stable ABI since 3.11 (its layout frozen there) and the same layout in 3.10 (unchanged
 *     since 3.3; tests/test_python_versions.py compares it with each installed version's
 *     headers);
 *   - the legacy global configuration variable Py_IgnoreEnvironmentFlag (a plain int every
 *     3.x libpython exports, read by Py_InitializeEx; deprecated since 3.12, PEP 741's
 *     replacement exists from 3.14 on): the only version-independent way to start an
 *     interpreter that ignores PYTHONHOME/PYTHONPATH (dcs_python.c). Its sibling Py_UTF8Mode
 *     is in the limited API. Py_NoSiteFlag is its kin (a self-contained FMU's runtime is
 *     started without the site module: dcs_runtime.c).
 * Free-threaded builds (3.13t) are not supported (their object header differs).
 */
#ifndef DCS_PYTHON_H
#define DCS_PYTHON_H

#define Py_LIMITED_API 0x030A0000
#include <Python.h>

#include "dcs_wrapper.h"

/* The oldest and newest minor version of Python 3 this wrapper runs on. */
#define DCS_PY_MINOR_MIN 10
#define DCS_PY_MINOR_MAX 13

/* Py_buffer of the stable ABI (3.11+; identical in 3.10). */
typedef struct {
    void *buf;
    PyObject *obj;
    Py_ssize_t len;
    Py_ssize_t itemsize;
    int readonly;
    int ndim;
    char *format;
    Py_ssize_t *shape;
    Py_ssize_t *strides;
    Py_ssize_t *suboffsets;
    void *internal;
} DcsBuffer;

#define DCS_PYBUF_WRITABLE 0x0001
#define DCS_PYBUF_FORMAT 0x0004
#define DCS_PYBUF_ND 0x0008
#define DCS_PYBUF_STRIDES (0x0010 | DCS_PYBUF_ND)
#define DCS_PYBUF_C_CONTIGUOUS (0x0020 | DCS_PYBUF_STRIDES)

/* Functions of the limited API of 3.10, in the order they are resolved. */
#define DCS_PYAPI(X) \
    X(Py_IsInitialized) \
    X(Py_GetVersion) \
    X(Py_SetProgramName) \
    X(Py_SetPythonHome) \
    X(Py_InitializeEx) \
    X(PyEval_SaveThread) \
    X(PyGILState_Ensure) \
    X(PyGILState_Release) \
    X(Py_IncRef) \
    X(Py_DecRef) \
    X(Py_BuildValue) \
    X(PyImport_ImportModule) \
    X(PySys_GetObject) \
    X(PySys_SetObject) \
    X(PyObject_GetAttr) \
    X(PyObject_GetAttrString) \
    X(PyObject_SetAttr) \
    X(PyObject_HasAttr) \
    X(PyObject_Call) \
    X(PyObject_CallMethodObjArgs) \
    X(PyObject_Str) \
    X(PyObject_IsTrue) \
    X(PyObject_IsInstance) \
    X(PyUnicode_InternFromString) \
    X(PyUnicode_FromString) \
    X(PyUnicode_DecodeFSDefault) \
    X(PyUnicode_AsUTF8AndSize) \
    X(PyUnicode_Join) \
    X(PyLong_FromUnsignedLong) \
    X(PyLong_FromLong) \
    X(PyLong_AsLong) \
    X(PyLong_AsVoidPtr) \
    X(PyFloat_FromDouble) \
    X(PyFloat_AsDouble) \
    X(PyBool_FromLong) \
    X(PyList_New) \
    X(PyList_Size) \
    X(PyList_GetItem) \
    X(PyList_SetItem) \
    X(PyList_Insert) \
    X(PyList_SetSlice) \
    X(PySequence_Tuple) \
    X(PyTuple_New) \
    X(PyTuple_Size) \
    X(PyTuple_GetItem) \
    X(PyDict_New) \
    X(PyDict_SetItemString) \
    X(PyBytes_FromStringAndSize) \
    X(PyBytes_Size) \
    X(PyBytes_AsString) \
    X(PyErr_Occurred) \
    X(PyErr_Fetch) \
    X(PyErr_NormalizeException) \
    X(PyErr_Clear) \
    X(PyErr_Restore)

/* Deprecated names (Py_SetProgramName in 3.11, PyErr_Fetch in 3.12, ...) are still exported
 * by every supported version; the declarations only borrow their types. */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
#define DCS_DECLARE(name) extern __typeof__(name) *p_##name;
DCS_PYAPI(DCS_DECLARE)
#undef DCS_DECLARE
extern __typeof__(Py_UTF8Mode) *p_Py_UTF8Mode;
#pragma GCC diagnostic pop

/* Declared by hand (see the top of this file). */
extern int *p_Py_IgnoreEnvironmentFlag;
extern int *p_Py_NoSiteFlag;
extern int (*p_PyObject_GetBuffer)(PyObject *, DcsBuffer *, int);
extern void (*p_PyBuffer_Release)(DcsBuffer *);

/* Interned method and attribute names, singletons and builtin types (created once, never
 * released). */
typedef struct {
    PyObject *setup_experiment, *enter_initialization_mode, *exit_initialization_mode,
        *do_step, *terminate, *reset, *get_real, *get_integer, *get_boolean, *get_string,
        *set_real, *set_integer, *set_boolean, *set_string, *get_fmu_state, *set_fmu_state,
        *to_bytes, *from_bytes, *fmi2_status, *real_buffers, *compiled_step,
        *compiled_step_failed, *get_log_queue, *status,
        *category, *msg, *format_exception;
    PyObject *none, *true_, *false_, *empty, *traceback;
    PyObject *int_type, *str_type, *bytes_type, *list_type; /* for isinstance */
} DcsNames;

extern DcsNames dcs_py;

/* isinstance(o, t) for a builtin type of dcs_py (0 on an error, which is cleared). */
int dcs_isinstance(PyObject *o, PyObject *type);

/* The slave object and its protocol, for dcs_state.c (dcs_slave.c; GIL held). */
PyObject *dcs_slave_object(DcsInstance *in);
const char *dcs_slave_model_id(DcsInstance *in); /* identity of its states (dcs_state.c) */
const char *dcs_slave_build_id(DcsInstance *in);
fmi2Status dcs_slave_exception(DcsInstance *in, const char *fn);
fmi2Status dcs_slave_status(DcsInstance *in, PyObject *result, const char *fn);
void dcs_slave_drain(DcsInstance *in);
/* End of a Python call that may change the slave: take its compiled step anew (see
 * dcs_slave.c) and drain its log; returns status, raised if the compiled step is unusable. */
fmi2Status dcs_slave_leave(DcsInstance *in, fmi2Status status, const char *fn);

static inline void dcs_decref(PyObject *o)
{
    if (o != NULL)
        p_Py_DecRef(o);
}

static inline void dcs_incref(PyObject *o)
{
    if (o != NULL)
        p_Py_IncRef(o);
}

#endif
