/* FMI 2.0 co-simulation entry points of StrainControllerC (the law is in model.c).
 *
 * Layout after the Reference-FMUs: config.h holds the value references, model.c the
 * physics, this file the FMI API. The calling-sequence rules are one table of state masks
 * (MASK_fmi2XXX below) checked by BEGIN(), not ifs repeated per function.
 *
 * Statuses: a problem the caller can correct (parameter out of range at
 * fmi2ExitInitializationMode, a non-finite input or time at fmi2DoStep, an unknown value
 * reference, a variable that may not be set now, a call out of sequence) returns fmi2Error
 * with one log message naming it (category logStatusError, always sent to the logger).
 * After fmi2Error the instance accepts only fmi2Reset, fmi2SetFMUstate, fmi2FreeFMUstate,
 * fmi2FreeInstance and the logging/version calls (FMI 2.0 section 2.1.3). fmi2Fatal is never
 * returned. Memory: calloc/free (canNotUseMemoryManagementFunctions = true).
 *
 * Handles: an fmi2Component or fmi2FMUstate a host passes in is used only if it is in the
 * registry of live ones this library gave out (dcs_registry.c, shared with the native wrapper):
 * it is looked up, never read before that, so a freed, foreign or made-up handle is refused
 * without touching memory that may be gone. An unknown component: fmi2Error and no message
 * (no instance, no logger), fmi2FreeInstance ignores it; an unknown state: fmi2Error naming it.
 * A handle leaves its registry before it is freed, so a second free finds nothing to free.
 * Serialized states (bytes) are checked by size, magic number and version instead.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config.h"
#include "dcs_registry.h"
#include "fmi2Functions.h"
#include "model.h"

/* ------------------------------------------------------------------------ states */
typedef enum {
    Instantiated = 1 << 0,
    InitializationMode = 1 << 1,
    StepComplete = 1 << 2,
    Terminated = 1 << 3,
    Error = 1 << 4
} ModelState;

#define ANY_STATE (Instantiated | InitializationMode | StepComplete | Terminated | Error)
#define RUNNING (InitializationMode | StepComplete | Terminated)

#define MASK_fmi2SetDebugLogging ANY_STATE
#define MASK_fmi2FreeInstance ANY_STATE
#define MASK_fmi2SetupExperiment Instantiated
#define MASK_fmi2EnterInitializationMode Instantiated
#define MASK_fmi2ExitInitializationMode InitializationMode
#define MASK_fmi2Terminate StepComplete
#define MASK_fmi2Reset ANY_STATE
#define MASK_fmi2GetReal RUNNING
#define MASK_fmi2GetInteger RUNNING
#define MASK_fmi2GetBoolean RUNNING
#define MASK_fmi2GetString RUNNING
#define MASK_fmi2SetReal (Instantiated | InitializationMode | StepComplete)
#define MASK_fmi2SetInteger (Instantiated | InitializationMode | StepComplete)
#define MASK_fmi2SetBoolean (Instantiated | InitializationMode | StepComplete)
#define MASK_fmi2SetString (Instantiated | InitializationMode | StepComplete)
#define MASK_fmi2GetFMUstate (Instantiated | RUNNING)
#define MASK_fmi2SetFMUstate ANY_STATE
#define MASK_fmi2FreeFMUstate ANY_STATE
#define MASK_fmi2SerializedFMUstateSize (Instantiated | RUNNING)
#define MASK_fmi2SerializeFMUstate (Instantiated | RUNNING)
#define MASK_fmi2DeSerializeFMUstate ANY_STATE
#define MASK_fmi2GetDirectionalDerivative RUNNING
#define MASK_fmi2SetRealInputDerivatives (Instantiated | InitializationMode | StepComplete)
#define MASK_fmi2GetRealOutputDerivatives (StepComplete | Terminated)
#define MASK_fmi2DoStep StepComplete
#define MASK_fmi2CancelStep StepComplete
#define MASK_fmi2GetStatus (StepComplete | Terminated)

/* ------------------------------------------------------------------------ instance */
/* Everything an FMU state holds: variables, law state, where the instance is. */
typedef struct {
    double strain[N_CHANNELS];   /* inputs [1] */
    double force[N_CHANNELS];    /* outputs [N] */
    LawParams params;            /* parameter variables as set */
    LawParams applied;           /* parameters the law runs with (validated) */
    LawState law;
    double time;                 /* [s] end of the last successful step */
    ModelState state;
} ModelData;

typedef struct {
    ModelData d;
    char *instance_name;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    int logging_on;
    char message[512];
} Instance;

#define SERIAL_MAGIC 0x44435343u /* "DCSC" */
#define SERIAL_VERSION 1u

typedef struct {
    unsigned magic;
    unsigned version;
    ModelData d;
} SerialState;

/* The live handles of this library (of every instance): valid only if listed. */
static DcsRegistry g_instances = DCS_REGISTRY_INIT;
static DcsRegistry g_states = DCS_REGISTRY_INIT;

static Instance *instance_of(fmi2Component c)
{
    return dcs_registry_contains(&g_instances, c) ? (Instance *)c : NULL;
}

/* A live state of this library (any instance's), else NULL. */
static SerialState *state_of(fmi2FMUstate s)
{
    return dcs_registry_contains(&g_states, s) ? (SerialState *)s : NULL;
}

/* ------------------------------------------------------------------------ logging */
#if defined(__MINGW_PRINTF_FORMAT) /* mingw-w64: its C99 printf (ms_printf knows no %zu) */
#define PRINTF_LIKE(f, a) __attribute__((format(__MINGW_PRINTF_FORMAT, f, a)))
#elif defined(__GNUC__)
#define PRINTF_LIKE(f, a) __attribute__((format(printf, f, a)))
#else
#define PRINTF_LIKE(f, a)
#endif

static void log_message(Instance *inst, fmi2Status status, const char *category,
                        const char *fmt, ...) PRINTF_LIKE(4, 5);
static fmi2Status fail(Instance *inst, const char *call, const char *fmt, ...) PRINTF_LIKE(3, 4);

static void log_message(Instance *inst, fmi2Status status, const char *category,
                        const char *fmt, ...)
{
    if (!inst->logger || (status == fmi2OK && !inst->logging_on)) {
        return;
    }
    char text[sizeof inst->message];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    inst->logger(inst->env, inst->instance_name, status, category, "%s: %s",
                 inst->instance_name, text);
}

#define LOG_ERROR(inst, ...) log_message((inst), fmi2Error, "logStatusError", __VA_ARGS__)

static fmi2Status fail(Instance *inst, const char *call, const char *fmt, ...)
{
    char text[sizeof inst->message];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    LOG_ERROR(inst, "%s: %s", call, text);
    inst->d.state = Error;
    return fmi2Error;
}

static const char *state_name(ModelState s)
{
    switch (s) {
    case Instantiated: return "Instantiated";
    case InitializationMode: return "InitializationMode";
    case StepComplete: return "StepComplete";
    case Terminated: return "Terminated";
    default: return "Error";
    }
}

/* The check of every function: c must be a live instance (looked up, not read), and its
 * state in the mask. */
#define BEGIN(F)                                                                            \
    Instance *inst = instance_of(c);                                                        \
    if (!inst) {                                                                            \
        return fmi2Error;                                                                   \
    }                                                                                       \
    if (!(inst->d.state & (MASK_##F))) {                                                    \
        return fail(inst, #F, "not allowed in state %s", state_name(inst->d.state));        \
    }

/* ------------------------------------------------------------------------ helpers */
static void set_start_values(ModelData *d)
{
    memset(d, 0, sizeof *d);
    d->params.gain = START_GAIN;
    d->params.force_limit = START_FORCE_LIMIT;
    d->params.symmetric_force_limit = START_SYMMETRIC_FORCE_LIMIT;
    d->params.switch_on_time = START_SWITCH_ON_TIME;
    d->params.mode = START_MODE;
    d->params.lag_time_constant = START_LAG_TIME_CONSTANT;
    d->params.enabled = START_ENABLED;
    d->applied = d->params;
    law_reset(&d->law);
    d->state = Instantiated;
}

static int tunables_differ(const LawParams *a, const LawParams *b)
{
    /* != as the Python adapter compares them (a NaN is always "changed") */
    return a->gain != b->gain || a->force_limit != b->force_limit ||
           a->symmetric_force_limit != b->symmetric_force_limit ||
           a->switch_on_time != b->switch_on_time;
}

/* Whether a parameter may be set now: fixed ones only before initialization ends. */
static int settable(Instance *inst, const char *call, fmi2ValueReference vr, int fixed)
{
    if (fixed && inst->d.state == StepComplete) {
        fail(inst, call, "value reference %u is a fixed parameter: it can be set only before "
             "fmi2ExitInitializationMode", vr);
        return 0;
    }
    return 1;
}

/* ------------------------------------------------------------------------ common */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation;
    (void)visible;
    fmi2CallbackLogger logger = functions ? functions->logger : NULL;
    fmi2ComponentEnvironment env = functions ? functions->componentEnvironment : NULL;
    const char *name = instanceName ? instanceName : "?";
    if (!instanceName || !*instanceName) {
        if (logger) logger(env, name, fmi2Error, "logStatusError",
                           "fmi2Instantiate: missing instance name");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        if (logger) logger(env, name, fmi2Error, "logStatusError",
                           "%s: fmi2Instantiate: only co-simulation is supported", name);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        if (logger) logger(env, name, fmi2Error, "logStatusError",
                           "%s: fmi2Instantiate: GUID %s does not match %s", name,
                           fmuGUID ? fmuGUID : "(null)", INSTANTIATION_TOKEN);
        return NULL;
    }
    Instance *inst = calloc(1, sizeof *inst);
    if (!inst || !(inst->instance_name = malloc(strlen(instanceName) + 1))) {
        free(inst);
        if (logger) logger(env, name, fmi2Error, "logStatusError",
                           "%s: fmi2Instantiate: out of memory", name);
        return NULL;
    }
    strcpy(inst->instance_name, instanceName);
    inst->logger = logger;
    inst->env = env;
    inst->logging_on = loggingOn ? 1 : 0;
    set_start_values(&inst->d);
    if (dcs_registry_add(&g_instances, inst) != 0) {
        free(inst->instance_name);
        free(inst);
        if (logger) logger(env, name, fmi2Error, "logStatusError",
                           "%s: fmi2Instantiate: out of memory", name);
        return NULL;
    }
    return inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    /* out of the registry first: a second free (or a foreign handle) finds nothing */
    if (!dcs_registry_remove(&g_instances, c)) {
        return;
    }
    Instance *inst = (Instance *)c;
    free(inst->instance_name);
    free(inst);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    BEGIN(fmi2SetDebugLogging)
    (void)nCategories;
    (void)categories;
    inst->logging_on = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    BEGIN(fmi2SetupExperiment)
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    inst->d.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    BEGIN(fmi2EnterInitializationMode)
    inst->d.state = InitializationMode;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    BEGIN(fmi2ExitInitializationMode)
    if (law_check_params(&inst->d.params, inst->message, sizeof inst->message)) {
        return fail(inst, "fmi2ExitInitializationMode", "invalid parameter: %s; reset or "
                    "re-instantiate with valid parameters", inst->message);
    }
    inst->d.applied = inst->d.params;
    law_reset(&inst->d.law);
    inst->d.state = StepComplete;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    BEGIN(fmi2Terminate)
    inst->d.state = Terminated;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    BEGIN(fmi2Reset)
    set_start_values(&inst->d);
    return fmi2OK;
}

/* ------------------------------------------------------------------------ get/set */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[])
{
    BEGIN(fmi2GetReal)
    const ModelData *d = &inst->d;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case vr_strain1_C: case vr_strain1_E: case vr_strain2_C: case vr_strain2_E:
            value[i] = d->strain[vr[i] - vr_strain1_C];
            break;
        case vr_actuator1_force_C: case vr_actuator1_force_E:
        case vr_actuator2_force_C: case vr_actuator2_force_E:
            value[i] = d->force[vr[i] - vr_actuator1_force_C];
            break;
        case vr_gain: value[i] = d->params.gain; break;
        case vr_force_limit: value[i] = d->params.force_limit; break;
        case vr_symmetric_force_limit: value[i] = d->params.symmetric_force_limit; break;
        case vr_switch_on_time: value[i] = d->params.switch_on_time; break;
        case vr_lag_time_constant: value[i] = d->params.lag_time_constant; break;
        default:
            value[i] = NAN;
            return fail(inst, "fmi2GetReal", "no Real variable has value reference %u", vr[i]);
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    BEGIN(fmi2SetReal)
    ModelData *d = &inst->d;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case vr_strain1_C: case vr_strain1_E: case vr_strain2_C: case vr_strain2_E:
            d->strain[vr[i] - vr_strain1_C] = value[i];
            break;
        case vr_gain: d->params.gain = value[i]; break;
        case vr_force_limit: d->params.force_limit = value[i]; break;
        case vr_symmetric_force_limit: d->params.symmetric_force_limit = value[i]; break;
        case vr_switch_on_time: d->params.switch_on_time = value[i]; break;
        case vr_lag_time_constant:
            if (!settable(inst, "fmi2SetReal", vr[i], 1)) return fmi2Error;
            d->params.lag_time_constant = value[i];
            break;
        case vr_actuator1_force_C: case vr_actuator1_force_E:
        case vr_actuator2_force_C: case vr_actuator2_force_E:
            return fail(inst, "fmi2SetReal", "value reference %u is an output and cannot be "
                        "set", vr[i]);
        default:
            return fail(inst, "fmi2SetReal", "no Real variable has value reference %u", vr[i]);
        }
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    BEGIN(fmi2GetInteger)
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != vr_mode) {
            value[i] = 0;
            return fail(inst, "fmi2GetInteger", "no Integer variable has value reference %u",
                        vr[i]);
        }
        value[i] = inst->d.params.mode;
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    BEGIN(fmi2SetInteger)
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != vr_mode) {
            return fail(inst, "fmi2SetInteger", "no Integer variable has value reference %u",
                        vr[i]);
        }
        if (!settable(inst, "fmi2SetInteger", vr[i], 1)) return fmi2Error;
        inst->d.params.mode = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[])
{
    BEGIN(fmi2GetBoolean)
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != vr_enabled) {
            value[i] = fmi2False;
            return fail(inst, "fmi2GetBoolean", "no Boolean variable has value reference %u",
                        vr[i]);
        }
        value[i] = inst->d.params.enabled ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    BEGIN(fmi2SetBoolean)
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != vr_enabled) {
            return fail(inst, "fmi2SetBoolean", "no Boolean variable has value reference %u",
                        vr[i]);
        }
        if (!settable(inst, "fmi2SetBoolean", vr[i], 1)) return fmi2Error;
        inst->d.params.enabled = value[i] ? 1 : 0;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    BEGIN(fmi2GetString)
    for (size_t i = 0; i < nvr; i++) {
        value[i] = "";
    }
    if (nvr > 0) {
        return fail(inst, "fmi2GetString", "no String variable has value reference %u", vr[0]);
    }
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    BEGIN(fmi2SetString)
    (void)value;
    if (nvr > 0) {
        return fail(inst, "fmi2SetString", "no String variable has value reference %u", vr[0]);
    }
    return fmi2OK;
}

/* ------------------------------------------------------------------------ stepping */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    BEGIN(fmi2DoStep)
    (void)noSetFMUStatePriorToCurrentPoint;
    ModelData *d = &inst->d;
    if (tunables_differ(&d->params, &d->applied)) {
        LawParams next = d->applied;
        next.gain = d->params.gain;
        next.force_limit = d->params.force_limit;
        next.symmetric_force_limit = d->params.symmetric_force_limit;
        next.switch_on_time = d->params.switch_on_time;
        if (law_check_params(&next, inst->message, sizeof inst->message)) {
            return fail(inst, "fmi2DoStep", "invalid parameter: %s; step rejected",
                        inst->message);
        }
        d->applied = next;
        law_params_changed(&d->law); /* keeps the lag state */
    }
    if (law_step(&d->law, &d->applied, currentCommunicationPoint, communicationStepSize,
                 d->strain, inst->message, sizeof inst->message)) {
        return fail(inst, "fmi2DoStep", "at t = %.17g: %s; step rejected",
                    currentCommunicationPoint, inst->message);
    }
    memcpy(d->force, d->law.force, sizeof d->force);
    d->time = currentCommunicationPoint + communicationStepSize;
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    BEGIN(fmi2CancelStep)
    return fail(inst, "fmi2CancelStep", "not supported (doStep never runs asynchronously)");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[])
{
    BEGIN(fmi2SetRealInputDerivatives)
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return fail(inst, "fmi2SetRealInputDerivatives", "not supported (canInterpolateInputs "
                "= false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[])
{
    BEGIN(fmi2GetRealOutputDerivatives)
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return fail(inst, "fmi2GetRealOutputDerivatives", "not supported "
                "(maxOutputDerivativeOrder = 0)");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                        size_t nUnknown, const fmi2ValueReference vKnown[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[])
{
    BEGIN(fmi2GetDirectionalDerivative)
    (void)vUnknown;
    (void)nUnknown;
    (void)vKnown;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    return fail(inst, "fmi2GetDirectionalDerivative", "not supported "
                "(providesDirectionalDerivative = false)");
}

/* Only fmi2GetRealStatus(fmi2LastSuccessfulTime) has an answer: doStep is synchronous. */
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    BEGIN(fmi2GetStatus)
    (void)s;
    (void)value;
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    BEGIN(fmi2GetStatus)
    if (s != fmi2LastSuccessfulTime || !value) {
        return fmi2Discard;
    }
    *value = inst->d.time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    BEGIN(fmi2GetStatus)
    (void)s;
    (void)value;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    BEGIN(fmi2GetStatus)
    (void)s;
    (void)value;
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    BEGIN(fmi2GetStatus)
    (void)s;
    (void)value;
    return fmi2Discard;
}

/* ------------------------------------------------------------------------ FMU state */
/* *FMUstate if it is a live state (FMI 2.0: a state given is overwritten), else a new one
 * (registered); NULL if out of memory. A pointer not in the registry is never written through. */
static SerialState *state_to_fill(fmi2FMUstate *FMUstate)
{
    SerialState *s = state_of(*FMUstate);
    if (!s && (s = calloc(1, sizeof *s)) != NULL && dcs_registry_add(&g_states, s) != 0) {
        free(s);
        s = NULL;
    }
    return s;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    BEGIN(fmi2GetFMUstate)
    if (!FMUstate) {
        return fail(inst, "fmi2GetFMUstate", "FMUstate must not be NULL");
    }
    SerialState *s = state_to_fill(FMUstate);
    if (!s) {
        return fail(inst, "fmi2GetFMUstate", "out of memory");
    }
    s->magic = SERIAL_MAGIC;
    s->version = SERIAL_VERSION;
    s->d = inst->d;
    *FMUstate = s;
    return fmi2OK;
}

/* Whether the bytes of a serialized state (copied into s) are one of this FMU's. */
static int valid_serial_state(const SerialState *s)
{
    return s->magic == SERIAL_MAGIC && s->version == SERIAL_VERSION &&
           (s->d.state == Instantiated || s->d.state == InitializationMode ||
            s->d.state == StepComplete || s->d.state == Terminated);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    BEGIN(fmi2SetFMUstate)
    const SerialState *s = state_of(FMUstate);
    if (!s) {
        return fail(inst, "fmi2SetFMUstate", "not a state of this FMU");
    }
    inst->d = s->d;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    BEGIN(fmi2FreeFMUstate)
    if (!FMUstate || !*FMUstate) {
        return fmi2OK; /* nothing to free */
    }
    /* out of the registry first: a second free (or a foreign pointer) finds nothing */
    if (!dcs_registry_remove(&g_states, *FMUstate)) {
        return fail(inst, "fmi2FreeFMUstate", "not a state of this FMU");
    }
    free(*FMUstate);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    BEGIN(fmi2SerializedFMUstateSize)
    if (!state_of(FMUstate)) {
        return fail(inst, "fmi2SerializedFMUstateSize", "not a state of this FMU");
    }
    if (!size) {
        return fail(inst, "fmi2SerializedFMUstateSize", "size must not be NULL");
    }
    *size = sizeof(SerialState);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size)
{
    BEGIN(fmi2SerializeFMUstate)
    const SerialState *s = state_of(FMUstate);
    if (!s) {
        return fail(inst, "fmi2SerializeFMUstate", "not a state of this FMU");
    }
    if (!serializedState || size < sizeof *s) {
        return fail(inst, "fmi2SerializeFMUstate", "need a buffer of %zu bytes, got %zu",
                    sizeof *s, serializedState ? size : (size_t)0);
    }
    memcpy(serializedState, s, sizeof *s);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate)
{
    BEGIN(fmi2DeSerializeFMUstate)
    SerialState tmp;
    if (!serializedState || !FMUstate || size != sizeof tmp) {
        return fail(inst, "fmi2DeSerializeFMUstate", "not a serialized state of this FMU "
                    "(%zu bytes, expected %zu)", size, sizeof tmp);
    }
    memcpy(&tmp, serializedState, sizeof tmp);
    if (!valid_serial_state(&tmp)) {
        return fail(inst, "fmi2DeSerializeFMUstate", "not a serialized state of this FMU");
    }
    SerialState *s = state_to_fill(FMUstate);
    if (!s) {
        return fail(inst, "fmi2DeSerializeFMUstate", "out of memory");
    }
    *s = tmp;
    *FMUstate = s;
    return fmi2OK;
}
