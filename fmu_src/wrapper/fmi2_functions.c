/*
 * FMI 2.0 co-simulation entry points of the drillcosim wrapper.
 *
 * The calling-sequence rules are the table of MASK_ values below (as in Reference-FMUs'
 * fmi2Functions.c): a function is allowed in the states of its mask, checked once by begin();
 * a call in another state is fmi2Error with a message naming the state. Differences from the
 * FMI 2.0 state machine, kept on purpose:
 *   - fmi2Error leaves the instance usable (the slave reports a bad input or parameter and
 *     the importer may correct it and go on); only fmi2Fatal ends it (state Fatal);
 *   - get/set are allowed in every live state; the slave refuses what it must (e.g. a fixed
 *     parameter after initialization) and fmi2GetReal in initialization mode computes the
 *     initial unknowns;
 *   - after fmi2Discard from fmi2DoStep the instance stays in StepComplete: the slave decides
 *     whether a further doStep is possible (the plant keeps discarding until a saved FMU
 *     state is restored).
 * Every function has one exit; messages queued during a call are handed to the logger at its
 * end (end()), outside the GIL.
 */
#include <stdlib.h>
#include <string.h>

#include "dcs_wrapper.h"

#define LIVE (DCS_INSTANTIATED | DCS_INITIALIZATION_MODE | DCS_STEP_COMPLETE | DCS_TERMINATED)
#define ANY (LIVE | DCS_FATAL)

#define MASK_fmi2SetDebugLogging             ANY
#define MASK_fmi2SetupExperiment             DCS_INSTANTIATED
#define MASK_fmi2EnterInitializationMode     DCS_INSTANTIATED
#define MASK_fmi2ExitInitializationMode      DCS_INITIALIZATION_MODE
#define MASK_fmi2Terminate                   DCS_STEP_COMPLETE
#define MASK_fmi2Reset                       LIVE
#define MASK_fmi2DoStep                      DCS_STEP_COMPLETE
#define MASK_fmi2CancelStep                  0 /* doStep never runs asynchronously */
#define MASK_fmi2GetValue                    LIVE /* fmi2GetReal/Integer/Boolean/String */
#define MASK_fmi2SetValue                    LIVE /* fmi2SetReal/Integer/Boolean/String */
#define MASK_fmi2GetFMUstate                 LIVE
#define MASK_fmi2SetFMUstate                 LIVE
#define MASK_fmi2FreeFMUstate                LIVE
#define MASK_fmi2SerializedFMUstateSize      LIVE
#define MASK_fmi2SerializeFMUstate           LIVE
#define MASK_fmi2DeSerializeFMUstate         LIVE
#define MASK_fmi2GetDirectionalDerivative    0 /* providesDirectionalDerivative = false */
#define MASK_fmi2SetRealInputDerivatives     0 /* canInterpolateInputs = false */
#define MASK_fmi2GetRealOutputDerivatives    0 /* maxOutputDerivativeOrder = 0 */
#define MASK_fmi2GetStatus                   ANY

static const char *state_name(DcsState s)
{
    static const char *const names[] = {"Instantiated (before initialization)",
                                        "InitializationMode", "StepComplete", "Terminated",
                                        "Fatal"};
    size_t i = 0;
    while (i + 1 < sizeof names / sizeof names[0] && !((unsigned)s & (1u << i)))
        i++;
    return names[i];
}

/* The instance of c if it is live and fn is allowed in its state; else fmi2Error (logged). */
static fmi2Status begin(fmi2Component c, int mask, const char *fn, DcsInstance **out)
{
    DcsInstance *in = dcs_instance_of(c);
    fmi2Status status = fmi2OK;
    if (in == NULL) {
        status = fmi2Error; /* no instance: no logger to tell */
    } else if (!(in->state & mask)) {
        char allowed[160] = "";
        int bit;
        for (bit = DCS_INSTANTIATED; bit <= DCS_TERMINATED; bit <<= 1) {
            if (mask & bit) {
                if (allowed[0] != '\0')
                    strncat(allowed, ", ", sizeof allowed - strlen(allowed) - 1);
                strncat(allowed, state_name((DcsState)bit), sizeof allowed - strlen(allowed) - 1);
            }
        }
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s is not allowed in state %s%s%s",
                in->name, fn, state_name(in->state), allowed[0] ? "; allowed in: " : "",
                allowed[0] ? allowed : "; not supported by this FMU");
        status = fmi2Error;
    }
    *out = in;
    return status;
}

/* Leave a call: a fatal status ends the instance; queued messages go to the logger. */
static fmi2Status end(DcsInstance *in, fmi2Status status)
{
    if (in != NULL) {
        if (status == fmi2Fatal)
            in->state = DCS_FATAL;
        dcs_flush(in);
    }
    return status;
}

/* A call that only checks its state (an unsupported feature): begin, then end. Two statements:
 * `end(in, begin(..., &in))` would read `in` in the same call that writes it (the order of
 * argument evaluation is unspecified in C). */
static fmi2Status only_check(fmi2Component c, int mask, const char *fn)
{
    DcsInstance *in;
    fmi2Status status = begin(c, mask, fn, &in);
    return end(in, status);
}

/* ------------------------------------------------------------- inquiry, logging */
FMI2_Export const char *fmi2GetTypesPlatform(void)
{
    return fmi2TypesPlatform;
}

FMI2_Export const char *fmi2GetVersion(void)
{
    return fmi2Version;
}

FMI2_Export fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn,
                                           size_t nCategories, const fmi2String categories[])
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2SetDebugLogging, "fmi2SetDebugLogging", &in);
    if (status == fmi2OK && dcs_set_categories(in, loggingOn != fmi2False, nCategories,
                                               categories) != 0)
        status = fmi2Error;
    return end(in, status);
}

/* -------------------------------------------------------------------- lifecycle */
FMI2_Export fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType,
                                          fmi2String fmuGUID, fmi2String fmuResourceLocation,
                                          const fmi2CallbackFunctions *functions,
                                          fmi2Boolean visible, fmi2Boolean loggingOn)
{
    DcsInstance *in = NULL;
    fmi2Status status = fmi2Error;
    (void)fmuGUID;
    if (functions != NULL && instanceName != NULL)
        in = dcs_instance_new(instanceName, functions, visible != fmi2False,
                              loggingOn != fmi2False);
    if (in == NULL) {
        /* nothing to report to: no callbacks, no name, or out of memory */
    } else if (fmuType != fmi2CoSimulation) {
        dcs_log(in, fmi2Error, "logStatusError",
                "%s: fmi2Instantiate: only co-simulation is supported", in->name);
    } else if (fmuResourceLocation == NULL ||
               (in->resources = dcs_uri_to_path(fmuResourceLocation)) == NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2Instantiate: no resource location",
                in->name);
    } else if (dcs_python_ready(in) == 0) {
        status = dcs_slave_create(in);
    }
    if (in != NULL) {
        dcs_flush(in);
        if (status > fmi2Warning) {
            dcs_instance_free(in);
            in = NULL;
        }
    }
    return in;
}

FMI2_Export void fmi2FreeInstance(fmi2Component c)
{
    DcsInstance *in = dcs_instance_of(c);
    if (in != NULL) {
        dcs_slave_free(in);
        dcs_flush(in);
        dcs_instance_free(in);
    }
}

FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                                           fmi2Real tolerance, fmi2Real startTime,
                                           fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2SetupExperiment, "fmi2SetupExperiment", &in);
    if (status == fmi2OK) {
        status = dcs_slave_setup_experiment(in, toleranceDefined != fmi2False, tolerance,
                                            startTime, stopTimeDefined != fmi2False, stopTime);
        in->last_successful_time = startTime;
    }
    return end(in, status);
}

/* A lifecycle call: the slave's method, then state `next` unless the status is above `worst`. */
static fmi2Status transition(fmi2Component c, int mask, const char *fn, DcsCall call,
                             DcsState next, fmi2Status worst)
{
    DcsInstance *in;
    fmi2Status status = begin(c, mask, fn, &in);
    if (status == fmi2OK) {
        status = dcs_slave_call(in, call);
        if (status <= worst)
            in->state = next;
    }
    return end(in, status);
}

FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    return transition(c, MASK_fmi2EnterInitializationMode, "fmi2EnterInitializationMode",
                      DCS_ENTER_INITIALIZATION_MODE, DCS_INITIALIZATION_MODE, fmi2Warning);
}

FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    return transition(c, MASK_fmi2ExitInitializationMode, "fmi2ExitInitializationMode",
                      DCS_EXIT_INITIALIZATION_MODE, DCS_STEP_COMPLETE, fmi2Warning);
}

FMI2_Export fmi2Status fmi2Terminate(fmi2Component c)
{
    return transition(c, MASK_fmi2Terminate, "fmi2Terminate", DCS_TERMINATE, DCS_TERMINATED,
                      fmi2Error); /* terminated unless fatal */
}

FMI2_Export fmi2Status fmi2Reset(fmi2Component c)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2Reset, "fmi2Reset", &in);
    if (status == fmi2OK) {
        status = dcs_slave_reset(in);
        if (status <= fmi2Warning)
            in->state = DCS_INSTANTIATED;
    }
    return end(in, status);
}

/* ------------------------------------------------------------------- stepping */
FMI2_Export fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                                  fmi2Real communicationStepSize,
                                  fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2DoStep, "fmi2DoStep", &in);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (status == fmi2OK) {
        status = dcs_slave_do_step(in, currentCommunicationPoint, communicationStepSize);
        if (status <= fmi2Warning)
            in->last_successful_time = currentCommunicationPoint + communicationStepSize;
    }
    return end(in, status);
}

FMI2_Export fmi2Status fmi2CancelStep(fmi2Component c)
{
    return only_check(c, MASK_fmi2CancelStep, "fmi2CancelStep");
}

/* ------------------------------------------------------------------ get / set */
/* Get or set nvr values of one type; NULL arrays with nvr > 0 are refused. */
static fmi2Status values(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         void *get, const void *set, DcsType type, const char *fn)
{
    DcsInstance *in;
    int is_get = strncmp(fn, "fmi2Get", 7) == 0;
    fmi2Status status = begin(c, is_get ? MASK_fmi2GetValue : MASK_fmi2SetValue, fn, &in);
    if (status == fmi2OK && nvr > 0 && (vr == NULL || (is_get ? get == NULL : set == NULL))) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: %s: NULL array", in->name, fn);
        status = fmi2Error;
    } else if (status == fmi2OK && nvr > 0 && is_get) {
        status = dcs_slave_get(in, vr, nvr, get, type, fn);
    } else if (status == fmi2OK && nvr > 0) {
        status = dcs_slave_set(in, vr, nvr, set, type, fn);
    }
    return end(in, status);
}

FMI2_Export fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                   fmi2Real value[])
{
    return values(c, vr, nvr, value, NULL, DCS_REAL, "fmi2GetReal");
}

FMI2_Export fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[],
                                      size_t nvr, fmi2Integer value[])
{
    return values(c, vr, nvr, value, NULL, DCS_INTEGER, "fmi2GetInteger");
}

FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[],
                                      size_t nvr, fmi2Boolean value[])
{
    return values(c, vr, nvr, value, NULL, DCS_BOOLEAN, "fmi2GetBoolean");
}

FMI2_Export fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[],
                                     size_t nvr, fmi2String value[])
{
    return values(c, vr, nvr, (void *)value, NULL, DCS_STRING, "fmi2GetString");
}

FMI2_Export fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                   const fmi2Real value[])
{
    return values(c, vr, nvr, NULL, value, DCS_REAL, "fmi2SetReal");
}

FMI2_Export fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[],
                                      size_t nvr, const fmi2Integer value[])
{
    return values(c, vr, nvr, NULL, value, DCS_INTEGER, "fmi2SetInteger");
}

FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[],
                                      size_t nvr, const fmi2Boolean value[])
{
    return values(c, vr, nvr, NULL, value, DCS_BOOLEAN, "fmi2SetBoolean");
}

FMI2_Export fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[],
                                     size_t nvr, const fmi2String value[])
{
    return values(c, vr, nvr, NULL, (const void *)value, DCS_STRING, "fmi2SetString");
}

/* ------------------------------------------------------------------ FMU state */
FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2GetFMUstate, "fmi2GetFMUstate", &in);
    if (status == fmi2OK && FMUstate == NULL) {
        dcs_log(in, fmi2Error, "logStatusError", "%s: fmi2GetFMUstate: NULL pointer", in->name);
        status = fmi2Error;
    } else if (status == fmi2OK) {
        status = dcs_state_get(in, FMUstate);
    }
    return end(in, status);
}

FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2SetFMUstate, "fmi2SetFMUstate", &in);
    if (status == fmi2OK)
        status = dcs_state_set(in, FMUstate);
    return end(in, status);
}

FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2FreeFMUstate, "fmi2FreeFMUstate", &in);
    if (status == fmi2OK)
        status = dcs_state_free(in, FMUstate);
    return end(in, status);
}

FMI2_Export fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate,
                                                  size_t *size)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2SerializedFMUstateSize,
                              "fmi2SerializedFMUstateSize", &in);
    if (status == fmi2OK)
        status = dcs_state_size(in, FMUstate, size);
    return end(in, status);
}

FMI2_Export fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                             fmi2Byte serializedState[], size_t size)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2SerializeFMUstate, "fmi2SerializeFMUstate", &in);
    if (status == fmi2OK)
        status = dcs_state_serialize(in, FMUstate, serializedState, size);
    return end(in, status);
}

FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component c,
                                               const fmi2Byte serializedState[], size_t size,
                                               fmi2FMUstate *FMUstate)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2DeSerializeFMUstate, "fmi2DeSerializeFMUstate", &in);
    if (status == fmi2OK)
        status = dcs_state_deserialize(in, serializedState, size, FMUstate);
    return end(in, status);
}

/* --------------------------------------------------- unsupported FMI 2.0 features */
FMI2_Export fmi2Status fmi2GetDirectionalDerivative(fmi2Component c,
                                                    const fmi2ValueReference vUnknown_ref[],
                                                    size_t nUnknown,
                                                    const fmi2ValueReference vKnown_ref[],
                                                    size_t nKnown, const fmi2Real dvKnown[],
                                                    fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown;
    (void)dvUnknown;
    return only_check(c, MASK_fmi2GetDirectionalDerivative, "fmi2GetDirectionalDerivative");
}

FMI2_Export fmi2Status fmi2SetRealInputDerivatives(fmi2Component c,
                                                   const fmi2ValueReference vr[], size_t nvr,
                                                   const fmi2Integer order[],
                                                   const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return only_check(c, MASK_fmi2SetRealInputDerivatives, "fmi2SetRealInputDerivatives");
}

FMI2_Export fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c,
                                                    const fmi2ValueReference vr[], size_t nvr,
                                                    const fmi2Integer order[],
                                                    fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return only_check(c, MASK_fmi2GetRealOutputDerivatives, "fmi2GetRealOutputDerivatives");
}

/* Status inquiries: no asynchronous doStep, so only fmi2LastSuccessfulTime is known. */
static fmi2Status status_query(fmi2Component c, const char *fn)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2GetStatus, fn, &in);
    return end(in, status == fmi2OK ? fmi2Discard : status);
}

FMI2_Export fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s,
                                     fmi2Status *value)
{
    (void)s; (void)value;
    return status_query(c, "fmi2GetStatus");
}

FMI2_Export fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s,
                                         fmi2Real *value)
{
    DcsInstance *in;
    fmi2Status status = begin(c, MASK_fmi2GetStatus, "fmi2GetRealStatus", &in);
    if (status == fmi2OK && s == fmi2LastSuccessfulTime && value != NULL)
        *value = in->last_successful_time;
    else if (status == fmi2OK)
        status = fmi2Discard;
    return end(in, status);
}

FMI2_Export fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s,
                                            fmi2Integer *value)
{
    (void)s; (void)value;
    return status_query(c, "fmi2GetIntegerStatus");
}

FMI2_Export fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s,
                                            fmi2Boolean *value)
{
    (void)s; (void)value;
    return status_query(c, "fmi2GetBooleanStatus");
}

FMI2_Export fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s,
                                           fmi2String *value)
{
    (void)s; (void)value;
    return status_query(c, "fmi2GetStringStatus");
}
