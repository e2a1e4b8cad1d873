/*
 * fmi2_wrapper.c: FMI 2.0 co-simulation interface of the grasprom controller FMU.
 * Translates the FMI 2 calls into the model layer (fmu_model.h); one fmi2Component is one
 * gf_instance_t.  Model exchange, derivatives and asynchronous steps are not supported (those
 * calls return fmi2Error with a logged message); the FMU state can be got, set and serialized.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_model.h"
#include "grasp_fmu_config.h"

#define INST ((gf_instance_t *)c)
#define NULL_GUARD(c) \
    if (!(c)) return fmi2Error

/* wrapper data: a copy of the importer's callbacks */
static void init_wrapper(void *data, void *arg) {
    memcpy(data, arg, sizeof(fmi2CallbackFunctions));
}

/* FMI 2 loggers take a printf format: pass the message with '%' escaped */
static void logger2(void *ctx, const char *instance, int status, const char *category,
                    const char *message) {
    const fmi2CallbackFunctions *f = (const fmi2CallbackFunctions *)ctx;
    char buf[1024];
    size_t i = 0;
    if (!f || !f->logger) return;
    for (; *message && i + 2 < sizeof buf; ++message) {
        if (*message == '%') buf[i++] = '%';
        buf[i++] = *message;
    }
    buf[i] = '\0';
    f->logger(f->componentEnvironment, instance, (fmi2Status)status, category, buf);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    (void)nCategories;
    (void)categories;
    NULL_GUARD(c);
    gf_set_logging(INST, loggingOn);
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    fmi2CallbackFunctions cb;
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions) return NULL;
    cb = *functions;
    if (fmuType != fmi2CoSimulation) {
        if (cb.logger)
            cb.logger(cb.componentEnvironment, instanceName ? instanceName : "",
                      fmi2Error, "logStatusError",
                      "fmi2Instantiate: " GF_MODEL_IDENTIFIER " supports co-simulation only");
        return NULL;
    }
    return gf_new(instanceName, fmuGUID, logger2, loggingOn,
                  cb.allocateMemory ? cb.allocateMemory : calloc,
                  cb.freeMemory ? cb.freeMemory : free, sizeof(fmi2CallbackFunctions),
                  init_wrapper, &cb);
}

void fmi2FreeInstance(fmi2Component c) { gf_free(INST); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    int st;
    (void)toleranceDefined;
    (void)tolerance;
    NULL_GUARD(c);
    st = gf_set_start_time(INST, "fmi2SetupExperiment", startTime);
    if (st != GF_OK) return (fmi2Status)st;
    return (fmi2Status)gf_set_stop_time(INST, "fmi2SetupExperiment", stopTimeDefined, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    NULL_GUARD(c);
    return (fmi2Status)gf_enter_initialization(INST, "fmi2EnterInitializationMode",
                                               gf_time(INST));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    NULL_GUARD(c);
    return (fmi2Status)gf_exit_initialization(INST, "fmi2ExitInitializationMode");
}

fmi2Status fmi2Terminate(fmi2Component c) {
    NULL_GUARD(c);
    return (fmi2Status)gf_terminate(INST, "fmi2Terminate");
}

fmi2Status fmi2Reset(fmi2Component c) {
    NULL_GUARD(c);
    return (fmi2Status)gf_reset(INST, "fmi2Reset");
}

/* ---------------------------------------------------------------- get / set */

#define GET_BODY(FN, TYPE, CAST)                                                         \
    int st, k;                                                                           \
    size_t i;                                                                            \
    double x;                                                                            \
    NULL_GUARD(c);                                                                       \
    st = gf_access(INST, FN, 0);                                                         \
    if (st > GF_WARNING) return (fmi2Status)st;                                          \
    if (nvr && (!vr || !value)) return (fmi2Status)gf_unsupported(INST, FN " (NULL array)"); \
    for (i = 0; i < nvr; ++i) {                                                          \
        k = gf_get_value(INST, FN, TYPE, vr[i], &x);                                     \
        if (k == GF_OK) value[i] = CAST;                                                 \
        if (k > st) st = k;                                                              \
    }                                                                                    \
    return (fmi2Status)st

#define SET_BODY(FN, TYPE, CONV)                                                         \
    int st, k;                                                                           \
    size_t i;                                                                            \
    NULL_GUARD(c);                                                                       \
    st = gf_access(INST, FN, 1);                                                         \
    if (st > GF_WARNING) return (fmi2Status)st;                                          \
    if (nvr && (!vr || !value)) return (fmi2Status)gf_unsupported(INST, FN " (NULL array)"); \
    for (i = 0; i < nvr; ++i) {                                                          \
        k = gf_set_value(INST, FN, TYPE, vr[i], CONV);                                   \
        if (k > st) st = k;                                                              \
    }                                                                                    \
    return (fmi2Status)st

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    GET_BODY("fmi2GetReal", GF_REAL, x);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    GET_BODY("fmi2GetInteger", GF_INTEGER_OR_ENUMERATION, (fmi2Integer)x);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    GET_BODY("fmi2GetBoolean", GF_BOOLEAN, x != 0.0 ? fmi2True : fmi2False);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    (void)vr;
    (void)value;
    NULL_GUARD(c);
    if (nvr == 0) return fmi2OK;
    return (fmi2Status)gf_unsupported(INST, "fmi2GetString (the FMU has no String variables)");
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    SET_BODY("fmi2SetReal", GF_REAL, value[i]);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    SET_BODY("fmi2SetInteger", GF_INTEGER_OR_ENUMERATION, (double)value[i]);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    SET_BODY("fmi2SetBoolean", GF_BOOLEAN, value[i] ? 1.0 : 0.0);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    (void)vr;
    (void)value;
    NULL_GUARD(c);
    if (nvr == 0) return fmi2OK;
    return (fmi2Status)gf_unsupported(INST, "fmi2SetString (the FMU has no String variables)");
}

/* ---------------------------------------------------------------- co-simulation */

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    NULL_GUARD(c);
    return (fmi2Status)gf_do_step(INST, "fmi2DoStep", currentCommunicationPoint,
                                  communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2CancelStep");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2SetRealInputDerivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2GetRealOutputDerivatives");
}

/* doStep never returns fmi2Pending/fmi2Discard: the status queries have nothing to report */
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    NULL_GUARD(c);
    gf_log(INST, GF_WARNING, "fmi2GetStatus: no asynchronous step: nothing to report");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    NULL_GUARD(c);
    if (s == fmi2LastSuccessfulTime && value) {
        *value = gf_time(INST);
        return fmi2OK;
    }
    gf_log(INST, GF_WARNING, "fmi2GetRealStatus: status kind %d not available", (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    NULL_GUARD(c);
    gf_log(INST, GF_WARNING, "fmi2GetIntegerStatus: no integer status");
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    NULL_GUARD(c);
    if (s == fmi2Terminated && value) {
        *value = fmi2False; /* the FMU never asks to terminate */
        return fmi2OK;
    }
    gf_log(INST, GF_WARNING, "fmi2GetBooleanStatus: status kind %d not available", (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    NULL_GUARD(c);
    gf_log(INST, GF_WARNING, "fmi2GetStringStatus: no string status");
    return fmi2Discard;
}

/* ---------------------------------------------------------------- not supported */

/* ---------------------------------------------------------------- FMU state */

#define CALLBACKS ((const fmi2CallbackFunctions *)gf_wrapper_data(INST))

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    void *sn;
    NULL_GUARD(c);
    if (!FMUstate) return (fmi2Status)gf_unsupported(INST, "fmi2GetFMUstate (NULL pointer)");
    sn = gf_get_state(INST, "fmi2GetFMUstate", *FMUstate, CALLBACKS->allocateMemory);
    if (!sn) return fmi2Error;
    *FMUstate = sn;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    NULL_GUARD(c);
    return (fmi2Status)gf_set_state(INST, "fmi2SetFMUstate", FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    NULL_GUARD(c);
    if (!FMUstate) return fmi2OK;
    gf_free_state(*FMUstate, CALLBACKS->freeMemory);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    NULL_GUARD(c);
    if (!size) return (fmi2Status)gf_unsupported(INST, "fmi2SerializedFMUstateSize (NULL)");
    *size = gf_state_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                 size_t size) {
    NULL_GUARD(c);
    return (fmi2Status)gf_serialize_state(INST, "fmi2SerializeFMUstate", FMUstate,
                                          (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    void *sn;
    NULL_GUARD(c);
    if (!FMUstate || !serializedState)
        return (fmi2Status)gf_unsupported(INST, "fmi2DeSerializeFMUstate (NULL pointer)");
    sn = gf_deserialize_state(INST, "fmi2DeSerializeFMUstate",
                              (const unsigned char *)serializedState, size,
                              CALLBACKS->allocateMemory);
    if (!sn) return fmi2Error;
    if (*FMUstate) gf_free_state(*FMUstate, CALLBACKS->freeMemory);
    *FMUstate = sn;
    return fmi2OK;
}

/* ---------------------------------------------------------------- not supported */

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown;
    (void)dvUnknown;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2GetDirectionalDerivative");
}

/* model exchange: not provided by this co-simulation FMU */
fmi2Status fmi2EnterEventMode(fmi2Component c) {
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2EnterEventMode");
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *fmi2eventInfo) {
    (void)fmi2eventInfo;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2NewDiscreteStates");
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2EnterContinuousTimeMode");
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2CompletedIntegratorStep");
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    (void)time;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2SetTime");
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    (void)x; (void)nx;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2SetContinuousStates");
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    (void)derivatives; (void)nx;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2GetDerivatives");
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators; (void)ni;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2GetEventIndicators");
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    (void)x; (void)nx;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2GetContinuousStates");
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    (void)x_nominal; (void)nx;
    NULL_GUARD(c);
    return (fmi2Status)gf_unsupported(INST, "fmi2GetNominalsOfContinuousStates");
}
