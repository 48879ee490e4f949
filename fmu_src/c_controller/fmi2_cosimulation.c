/* FMI 2.0 co-simulation entry points of StrainControllerC (the law is in model.c).
 *
 * Layout after the Reference-FMUs: config.h holds the value references, model.c the
 * physics, this file the FMI API. The calling-sequence rules are one table of state masks
 * (MASK_fmi2XXX below) checked by BEGIN(), not ifs repeated per function.
 *
 * Statuses (the rules of every drillcosim FMU, docs/reliability.md): a problem the caller can
 * correct (parameter out of range at fmi2ExitInitializationMode, a non-finite input or time at
 * fmi2DoStep, an unknown value reference, a variable that may not be set now, a call out of
 * sequence, an FMU state refused) returns fmi2Error with one log message naming it (category
 * logStatusError, always sent to the logger) and changes nothing: a set call is checked whole
 * before any value is written; the instance stays in its state and usable (a corrected retry
 * is OK), as the native wrapper's FMUs. fmi2Fatal is never returned. Memory: calloc/free
 * (canNotUseMemoryManagementFunctions = true).
 *
 * FMU state: everything of ModelData, the phase (the FMI state it was taken in) included. It is
 * restored only in the phase it was taken in, and only if it passes the checks its parameters
 * would get (check_state); then all of it, else nothing. Serialized: the format every drillcosim
 * FMU shares (dcs_state_format.h: identity, SHA-256) around the payload of put_data/get_data.
 *
 * Handles: an fmi2Component or fmi2FMUstate a host passes in is used only if it is in the
 * registry of live ones this library gave out (dcs_registry.c, shared with the native wrapper):
 * it is looked up, never read before that, so a freed, foreign or made-up handle is refused
 * without touching memory that may be gone. An unknown component: fmi2Error and no message
 * (no instance, no logger), fmi2FreeInstance ignores it; an unknown state: fmi2Error naming it.
 * A handle leaves its registry before it is freed, so a second free finds nothing to free.
 * Serialized states (bytes) are checked by their format instead (dcs_state_format.c).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config.h"
#include "dcs_build.h"
#include "dcs_registry.h"
#include "dcs_state_format.h"
#include "fmi2Functions.h"
#include "model.h"

/* ------------------------------------------------------------------------ states */
/* One bit each, the phases of the state format (DCS_PHASE_*). */
typedef enum {
    Instantiated = DCS_PHASE_INSTANTIATED,
    InitializationMode = DCS_PHASE_INITIALIZATION_MODE,
    StepComplete = DCS_PHASE_STEP_COMPLETE,
    Terminated = DCS_PHASE_TERMINATED
} ModelState;

#define ANY_STATE (Instantiated | InitializationMode | StepComplete | Terminated)
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

/* An FMU state: a copy of the instance's data. */
typedef struct {
    ModelData d;
} SerialState;

/* The payload of a serialized state: ModelData but the phase (in the format's header), field
 * by field in this order, doubles as IEEE 754 binary64 and ints as int32, little-endian:
 * strain[4], force[4], params (gain, force_limit, symmetric_force_limit, switch_on_time,
 * lag_time_constant, mode, enabled), applied (the same), law (force[4], decay_dt, decay), time. */
#define PARAMS_BYTES (5 * 8 + 2 * 4)
#define PAYLOAD_BYTES (8 * N_CHANNELS * 2 + 2 * PARAMS_BYTES + 8 * (N_CHANNELS + 2) + 8)

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

/* fmi2Error with one message; the instance is left as it is (nothing was changed). */
static fmi2Status fail(Instance *inst, const char *call, const char *fmt, ...)
{
    char text[sizeof inst->message];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    LOG_ERROR(inst, "%s: %s", call, text);
    return fmi2Error;
}

static const char *state_name(ModelState s)
{
    return dcs_phase_name((unsigned)s);
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

/* Why value reference vr may not be set now through call (type: 'R', 'I', 'B', 'S'), in
 * inst->message, or 0 if it may. A set call checks every value reference before it writes any. */
static int set_problem(Instance *inst, fmi2ValueReference vr, char type)
{
    char have = 0;
    int fixed = 0, output = 0;
    switch (vr) {
    case vr_strain1_C: case vr_strain1_E: case vr_strain2_C: case vr_strain2_E:
    case vr_gain: case vr_force_limit: case vr_symmetric_force_limit: case vr_switch_on_time:
        have = 'R';
        break;
    case vr_actuator1_force_C: case vr_actuator1_force_E:
    case vr_actuator2_force_C: case vr_actuator2_force_E:
        have = 'R';
        output = 1;
        break;
    case vr_lag_time_constant: have = 'R'; fixed = 1; break;
    case vr_mode: have = 'I'; fixed = 1; break;
    case vr_enabled: have = 'B'; fixed = 1; break;
    default: break;
    }
    const char *kind = type == 'R' ? "Real" : type == 'I' ? "Integer" : type == 'B' ? "Boolean"
                                                                                 : "String";
    if (have != type) {
        snprintf(inst->message, sizeof inst->message, "no %s variable has value reference %u",
                 kind, vr);
    } else if (output) {
        snprintf(inst->message, sizeof inst->message, "value reference %u is an output and "
                 "cannot be set", vr);
    } else if (fixed && inst->d.state != Instantiated && inst->d.state != InitializationMode) {
        snprintf(inst->message, sizeof inst->message, "value reference %u (%s) is a fixed "
                 "parameter: it can be set only before fmi2ExitInitializationMode", vr,
                 vr == vr_mode ? "mode" : vr == vr_enabled ? "enabled" : "lag_time_constant");
    } else {
        return 0;
    }
    return 1;
}

/* The first value reference of vr[] that may not be set (message in inst->message), or nvr. */
static size_t first_refused(Instance *inst, const fmi2ValueReference vr[], size_t nvr, char type)
{
    size_t i = 0;
    while (i < nvr && !set_problem(inst, vr[i], type)) {
        i++;
    }
    return i;
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
        return fail(inst, "fmi2ExitInitializationMode", "invalid parameter: %s; correct it "
                    "and call fmi2ExitInitializationMode again (or reset)", inst->message);
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
    if (first_refused(inst, vr, nvr, 'R') < nvr) {
        return fail(inst, "fmi2SetReal", "%s (nothing of this call was set)", inst->message);
    }
    ModelData *d = &inst->d;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case vr_gain: d->params.gain = value[i]; break;
        case vr_force_limit: d->params.force_limit = value[i]; break;
        case vr_symmetric_force_limit: d->params.symmetric_force_limit = value[i]; break;
        case vr_switch_on_time: d->params.switch_on_time = value[i]; break;
        case vr_lag_time_constant: d->params.lag_time_constant = value[i]; break;
        default: d->strain[vr[i] - vr_strain1_C] = value[i]; break; /* an input (checked) */
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
    if (first_refused(inst, vr, nvr, 'I') < nvr) {
        return fail(inst, "fmi2SetInteger", "%s (nothing of this call was set)", inst->message);
    }
    for (size_t i = 0; i < nvr; i++) {
        inst->d.params.mode = value[i]; /* the only Integer (checked) */
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
    if (first_refused(inst, vr, nvr, 'B') < nvr) {
        return fail(inst, "fmi2SetBoolean", "%s (nothing of this call was set)", inst->message);
    }
    for (size_t i = 0; i < nvr; i++) {
        inst->d.params.enabled = value[i] ? 1 : 0; /* the only Boolean (checked) */
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
    if (first_refused(inst, vr, nvr, 'S') < nvr) {
        return fail(inst, "fmi2SetString", "%s (nothing of this call was set)", inst->message);
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

/* Whether the data of a state may be restored into inst, checked as its parameters would be
 * (law_check_params, as fmi2ExitInitializationMode) once the state is past initialization; why
 * not in inst->message. */
static int state_problem(Instance *inst, const ModelData *d)
{
    char *msg = inst->message;
    const size_t size = sizeof inst->message;
    if (d->state != inst->d.state) {
        snprintf(msg, size, "a state taken in %s cannot be restored in %s (a state is restored "
                 "only in the phase it was taken in)", state_name(d->state),
                 state_name(inst->d.state));
        return 1;
    }
    if (d->state == StepComplete || d->state == Terminated) {
        char why[300];
        if (law_check_params(&d->params, why, sizeof why) ||
            law_check_params(&d->applied, why, sizeof why)) {
            snprintf(msg, size, "invalid parameter: %s", why);
            return 1;
        }
        if (d->params.lag_time_constant != d->applied.lag_time_constant ||
            d->params.mode != d->applied.mode || d->params.enabled != d->applied.enabled) {
            snprintf(msg, size, "its fixed parameters differ from those its law runs with");
            return 1;
        }
    }
    for (int i = 0; i < N_CHANNELS; i++) {
        if (!isfinite(d->law.force[i])) {
            snprintf(msg, size, "its lag state of channel %d is not finite (%.17g)", i + 1,
                     d->law.force[i]);
            return 1;
        }
    }
    if (!isfinite(d->time) || !isfinite(d->law.decay) ||
        !(isnan(d->law.decay_dt) || (isfinite(d->law.decay_dt) && d->law.decay_dt >= 0.0))) {
        snprintf(msg, size, "its time or cached lag decay is not a valid number");
        return 1;
    }
    if ((d->params.enabled != 0 && d->params.enabled != 1) ||
        (d->applied.enabled != 0 && d->applied.enabled != 1)) {
        snprintf(msg, size, "its enabled flag is neither 0 nor 1");
        return 1;
    }
    return 0;
}

static unsigned char *put_params(unsigned char *p, const LawParams *q)
{
    dcs_put_f64(p, q->gain);
    dcs_put_f64(p + 8, q->force_limit);
    dcs_put_f64(p + 16, q->symmetric_force_limit);
    dcs_put_f64(p + 24, q->switch_on_time);
    dcs_put_f64(p + 32, q->lag_time_constant);
    dcs_put_u32(p + 40, (uint32_t)q->mode);
    dcs_put_u32(p + 44, (uint32_t)q->enabled);
    return p + PARAMS_BYTES;
}

static const unsigned char *get_params(const unsigned char *p, LawParams *q)
{
    q->gain = dcs_get_f64(p);
    q->force_limit = dcs_get_f64(p + 8);
    q->symmetric_force_limit = dcs_get_f64(p + 16);
    q->switch_on_time = dcs_get_f64(p + 24);
    q->lag_time_constant = dcs_get_f64(p + 32);
    q->mode = (int)(int32_t)dcs_get_u32(p + 40);
    q->enabled = (int)(int32_t)dcs_get_u32(p + 44);
    return p + PARAMS_BYTES;
}

/* The payload of d (PAYLOAD_BYTES, see SerialState). */
static void put_data(unsigned char *p, const ModelData *d)
{
    for (int i = 0; i < N_CHANNELS; i++, p += 8) dcs_put_f64(p, d->strain[i]);
    for (int i = 0; i < N_CHANNELS; i++, p += 8) dcs_put_f64(p, d->force[i]);
    p = put_params(p, &d->params);
    p = put_params(p, &d->applied);
    for (int i = 0; i < N_CHANNELS; i++, p += 8) dcs_put_f64(p, d->law.force[i]);
    dcs_put_f64(p, d->law.decay_dt);
    dcs_put_f64(p + 8, d->law.decay);
    dcs_put_f64(p + 16, d->time);
}

static void get_data(const unsigned char *p, ModelData *d)
{
    for (int i = 0; i < N_CHANNELS; i++, p += 8) d->strain[i] = dcs_get_f64(p);
    for (int i = 0; i < N_CHANNELS; i++, p += 8) d->force[i] = dcs_get_f64(p);
    p = get_params(p, &d->params);
    p = get_params(p, &d->applied);
    for (int i = 0; i < N_CHANNELS; i++, p += 8) d->law.force[i] = dcs_get_f64(p);
    d->law.decay_dt = dcs_get_f64(p);
    d->law.decay = dcs_get_f64(p + 8);
    d->time = dcs_get_f64(p + 16);
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
    s->d = inst->d;
    *FMUstate = s;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    BEGIN(fmi2SetFMUstate)
    const SerialState *s = state_of(FMUstate);
    if (!s) {
        return fail(inst, "fmi2SetFMUstate", "not a state of this FMU");
    }
    if (state_problem(inst, &s->d)) {
        return fail(inst, "fmi2SetFMUstate", "refused: %s; the instance is unchanged",
                    inst->message);
    }
    inst->d = s->d; /* all of it, checked */
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

/* Bytes of a serialized state of this FMU. */
static size_t serialized_size(void)
{
    return dcs_state_size_for(strlen(MODEL_IDENTIFIER_STRING), strlen(DCS_BUILD_ID),
                              PAYLOAD_BYTES);
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
    *size = serialized_size();
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
    if (!serializedState || size < serialized_size()) {
        return fail(inst, "fmi2SerializeFMUstate", "need a buffer of %lu bytes, got %lu",
                    (unsigned long)serialized_size(),
                    (unsigned long)(serializedState ? size : 0));
    }
    unsigned char payload[PAYLOAD_BYTES];
    put_data(payload, &s->d);
    dcs_state_seal((unsigned char *)serializedState, (unsigned)s->d.state,
                   MODEL_IDENTIFIER_STRING, DCS_BUILD_ID, payload, sizeof payload);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate)
{
    BEGIN(fmi2DeSerializeFMUstate)
    DcsStateView view;
    if (!FMUstate) {
        return fail(inst, "fmi2DeSerializeFMUstate", "FMUstate must not be NULL");
    }
    if (dcs_state_open((const unsigned char *)serializedState, size, MODEL_IDENTIFIER_STRING,
                       DCS_BUILD_ID, &view, inst->message, sizeof inst->message)) {
        return fail(inst, "fmi2DeSerializeFMUstate", "refused: %s", inst->message);
    }
    if (view.payload_len != PAYLOAD_BYTES) {
        return fail(inst, "fmi2DeSerializeFMUstate", "refused: a payload of %lu bytes, not %d",
                    (unsigned long)view.payload_len, PAYLOAD_BYTES);
    }
    SerialState tmp;
    memset(&tmp, 0, sizeof tmp);
    get_data(view.payload, &tmp.d);
    tmp.d.state = (ModelState)view.phase;
    SerialState *s = state_to_fill(FMUstate);
    if (!s) {
        return fail(inst, "fmi2DeSerializeFMUstate", "out of memory");
    }
    *s = tmp;
    *FMUstate = s;
    return fmi2OK;
}
