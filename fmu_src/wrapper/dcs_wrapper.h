/*
 * drillcosim native FMI 2.0 co-simulation wrapper: the declarations its files share.
 *
 * Files by job (all compiled into one shared library by fmu_src/wrapper/__init__.py):
 *   fmi2_functions.c  FMI entry points; the calling-sequence rules as a state-mask table
 *   dcs_instance.c    instance memory, resource files, log queue -> the host's logger
 *   dcs_python.c      the Python C-API looked up at run time; attaching to / starting an
 *                     interpreter
 *   dcs_discover.c    finding a Python for a host without one (checked in child processes)
 *   dcs_platform_*.c  the operating system (libraries, files, environment, child processes,
 *                     installed Pythons): one file per platform behind dcs_platform.h
 *   dcs_slave.c       the pythonfmu slave object: calls, the status protocol, values, buffers
 *   dcs_state.c       FMU state objects and their serialization; the rules of restoring one
 *   dcs_state_format.c the serialized state format (identity, SHA-256; dcs_state_format.h,
 *                     which the C controller FMU shares)
 *   dcs_registry.c    the sets of live instances and states (handles are looked up, never
 *                     probed through a pointer that may be freed; dcs_registry.h, which the
 *                     C controller FMU shares)
 * Only dcs_python.c, dcs_slave.c and dcs_state.c include Python.h (dcs_python.h).
 */
#ifndef DCS_WRAPPER_H
#define DCS_WRAPPER_H

#include <stddef.h>

#include "dcs_platform.h" /* the operating system: one file per platform */
#include "dcs_registry.h" /* DcsRegistry: the sets of live handles */
#include "fmi2/fmi2Functions.h"

/* FMI 2.0 co-simulation states of an instance, one bit each (masks in fmi2_functions.c). */
typedef enum {
    DCS_INSTANTIATED = 1 << 0,
    DCS_INITIALIZATION_MODE = 1 << 1,
    DCS_STEP_COMPLETE = 1 << 2,
    DCS_TERMINATED = 1 << 3,
    DCS_FATAL = 1 << 4 /* only fmi2FreeInstance (and the status queries) remain */
} DcsState;

typedef enum { DCS_REAL, DCS_INTEGER, DCS_BOOLEAN, DCS_STRING } DcsType;

typedef struct {
    fmi2Status status;
    char *category;
    char *text;
} DcsMessage;

typedef struct DcsSlave DcsSlave; /* Python side of an instance (dcs_slave.c) */

/* A slave's compiled step (dcs_slave.c): 0 = step done, else a code for the slave. */
typedef int (*DcsCompiledStep)(void *context, double t, double h);

typedef struct {
    DcsState state;
    char *name;
    char *resources; /* file system path of resources/, no trailing slash */
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    int logging_on;
    char **categories;
    size_t n_categories;
    int visible;
    fmi2Real last_successful_time;
    DcsMessage *messages;
    size_t n_messages, cap_messages;
    DcsSlave *slave;
} DcsInstance;

/* ------------------------------------------------------------- dcs_instance.c */
DcsInstance *dcs_instance_new(fmi2String name, const fmi2CallbackFunctions *functions,
                              int visible, int logging_on);
DcsInstance *dcs_instance_of(fmi2Component c); /* NULL unless a live instance (registry) */
void dcs_instance_free(DcsInstance *in);
int dcs_set_categories(DcsInstance *in, int logging_on, size_t n, const fmi2String categories[]);
char *dcs_uri_to_path(const char *uri);
char *dcs_read_resource_line(const char *resources, const char *file);
char *dcs_own_model_identifier(void);
char *dcs_strdup(const char *s);
/* printf into a new string (malloc'd; NULL if out of memory). */
char *dcs_format(const char *fmt, ...) DCS_PRINTF(1, 2);
/* Queue a message (any thread, GIL or not); delivered by dcs_flush without the GIL. */
void dcs_log(DcsInstance *in, fmi2Status status, const char *category, const char *fmt, ...)
    DCS_PRINTF(4, 5);
void dcs_log_text(DcsInstance *in, fmi2Status status, const char *category, const char *text);
void dcs_flush(DcsInstance *in);
const char *dcs_status_category(fmi2Status status);

/* --------------------------------------------------------------- dcs_python.c */
/* Make sure an interpreter runs in this process (attach to the host's, else find and start
 * one); 0 on success, else -1 with ONE message logged on the instance. */
int dcs_python_ready(DcsInstance *in);
int dcs_python_started(void); /* whether the C-API is usable (for freeing) */

/* ---------------------------------------------------------------- dcs_slave.c */
typedef enum { DCS_ENTER_INITIALIZATION_MODE, DCS_EXIT_INITIALIZATION_MODE, DCS_TERMINATE }
    DcsCall;
fmi2Status dcs_slave_create(DcsInstance *in);
void dcs_slave_free(DcsInstance *in);
fmi2Status dcs_slave_setup_experiment(DcsInstance *in, int tolerance_defined, double tolerance,
                                      double start_time, int stop_time_defined,
                                      double stop_time);
fmi2Status dcs_slave_call(DcsInstance *in, DcsCall call);
fmi2Status dcs_slave_do_step(DcsInstance *in, double t, double h);
fmi2Status dcs_slave_reset(DcsInstance *in);
fmi2Status dcs_slave_get(DcsInstance *in, const fmi2ValueReference vr[], size_t nvr,
                         void *values, DcsType type, const char *fn);
fmi2Status dcs_slave_set(DcsInstance *in, const fmi2ValueReference vr[], size_t nvr,
                         const void *values, DcsType type, const char *fn);

/* ---------------------------------------------------------------- dcs_state.c */
fmi2Status dcs_state_get(DcsInstance *in, fmi2FMUstate *state);
fmi2Status dcs_state_set(DcsInstance *in, fmi2FMUstate state);
fmi2Status dcs_state_free(DcsInstance *in, fmi2FMUstate *state);
fmi2Status dcs_state_size(DcsInstance *in, fmi2FMUstate state, size_t *size);
fmi2Status dcs_state_serialize(DcsInstance *in, fmi2FMUstate state, fmi2Byte out[],
                               size_t size);
fmi2Status dcs_state_deserialize(DcsInstance *in, const fmi2Byte bytes[], size_t size,
                                 fmi2FMUstate *state);
/* The "build" of <resources>/dcs_build.json ("" if none), malloc'd (NULL: out of memory). */
char *dcs_state_read_build(const char *resources);

#endif
