/*
 * fmi3_wrapper.c: FMI 3.0 co-simulation interface of the grasprom controller FMU.
 * Translates the FMI 3 calls into the model layer (fmu_model.h); one fmi3Instance is one
 * gf_instance_t.  Variables are Float64, Int32, Enumeration (fmi3Get/SetInt64) and Boolean;
 * the FMU state can be got, set and serialized; model exchange, scheduled execution, event
 * mode, clocks and derivatives are not supported (fmi3Error with a logged message).
 */
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmu_model.h"
#include "grasp_fmu_config.h"

#define INST ((gf_instance_t *)instance)
#define NULL_GUARD() \
    if (!instance) return fmi3Error

typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} wrapper3_t;

static void init_wrapper(void *data, void *arg) { memcpy(data, arg, sizeof(wrapper3_t)); }

static void logger3(void *ctx, const char *instance, int status, const char *category,
                    const char *message) {
    const wrapper3_t *w = (const wrapper3_t *)ctx;
    (void)instance;
    if (w && w->log) w->log(w->env, (fmi3Status)status, category, message);
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    (void)nCategories;
    (void)categories;
    NULL_GUARD();
    gf_set_logging(INST, loggingOn);
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    wrapper3_t w;
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    if (eventModeUsed) { /* the modelDescription says hasEventMode="false" */
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "fmi3InstantiateCoSimulation: eventModeUsed = true, but "
                       GF_MODEL_IDENTIFIER " has no event mode (hasEventMode=\"false\")");
        return NULL;
    }
    w.env = instanceEnvironment;
    w.log = logMessage;
    return gf_new(instanceName, instantiationToken, logger3, loggingOn, calloc, free,
                  sizeof(wrapper3_t), init_wrapper, &w);
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateModelExchange: " GF_MODEL_IDENTIFIER
                   " supports co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn; (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: " GF_MODEL_IDENTIFIER
                   " supports co-simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { gf_free(INST); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    int st;
    (void)toleranceDefined; (void)tolerance;
    NULL_GUARD();
    st = gf_set_start_time(INST, "fmi3EnterInitializationMode", startTime);
    if (st == GF_OK)
        st = gf_set_stop_time(INST, "fmi3EnterInitializationMode", stopTimeDefined, stopTime);
    if (st != GF_OK) return (fmi3Status)st;
    return (fmi3Status)gf_enter_initialization(INST, "fmi3EnterInitializationMode", startTime);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    NULL_GUARD();
    return (fmi3Status)gf_exit_initialization(INST, "fmi3ExitInitializationMode");
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    NULL_GUARD();
    return (fmi3Status)gf_terminate(INST, "fmi3Terminate");
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    NULL_GUARD();
    return (fmi3Status)gf_reset(INST, "fmi3Reset");
}

/* ---------------------------------------------------------------- get / set */

#define GET_BODY(FN, TYPE, CAST)                                                         \
    int st, k;                                                                           \
    size_t i;                                                                            \
    double x;                                                                            \
    NULL_GUARD();                                                                        \
    st = gf_access(INST, FN, 2); /* FMI 3: getters also in the Instantiated state */     \
    if (st > GF_WARNING) return (fmi3Status)st;                                          \
    if (nValues != nValueReferences) {                                                   \
        gf_log(INST, GF_ERROR, FN ": nValues %lu != nValueReferences %lu (no arrays)",   \
               (unsigned long)nValues, (unsigned long)nValueReferences);                 \
        return fmi3Error;                                                                \
    }                                                                                    \
    if (nValueReferences && (!valueReferences || !values))                               \
        return (fmi3Status)gf_unsupported(INST, FN " (NULL array)");                     \
    for (i = 0; i < nValueReferences; ++i) {                                             \
        k = gf_get_value(INST, FN, TYPE, valueReferences[i], &x);                        \
        if (k == GF_OK) values[i] = CAST;                                                \
        if (k > st) st = k;                                                              \
    }                                                                                    \
    return (fmi3Status)st

#define SET_BODY(FN, TYPE, CONV)                                                         \
    int st, k;                                                                           \
    size_t i;                                                                            \
    NULL_GUARD();                                                                        \
    st = gf_access(INST, FN, 1);                                                         \
    if (st > GF_WARNING) return (fmi3Status)st;                                          \
    if (nValues != nValueReferences) {                                                   \
        gf_log(INST, GF_ERROR, FN ": nValues %lu != nValueReferences %lu (no arrays)",   \
               (unsigned long)nValues, (unsigned long)nValueReferences);                 \
        return fmi3Error;                                                                \
    }                                                                                    \
    if (nValueReferences && (!valueReferences || !values))                               \
        return (fmi3Status)gf_unsupported(INST, FN " (NULL array)");                     \
    for (i = 0; i < nValueReferences; ++i) {                                             \
        k = gf_set_value(INST, FN, TYPE, valueReferences[i], CONV);                      \
        if (k > st) st = k;                                                              \
    }                                                                                    \
    return (fmi3Status)st

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    GET_BODY("fmi3GetFloat64", GF_REAL, x);
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues) {
    GET_BODY("fmi3GetInt32", GF_INTEGER, (fmi3Int32)x);
}

fmi3Status fmi3GetInt64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int64 values[], size_t nValues) {
    GET_BODY("fmi3GetInt64", GF_ENUMERATION, (fmi3Int64)x); /* the Enumeration variables */
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues) {
    GET_BODY("fmi3GetBoolean", GF_BOOLEAN, x != 0.0);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    SET_BODY("fmi3SetFloat64", GF_REAL, values[i]);
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int32 values[], size_t nValues) {
    SET_BODY("fmi3SetInt32", GF_INTEGER, (double)values[i]);
}

fmi3Status fmi3SetInt64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int64 values[], size_t nValues) {
    SET_BODY("fmi3SetInt64", GF_ENUMERATION, (double)values[i]); /* range-checked */
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[], size_t nValues) {
    SET_BODY("fmi3SetBoolean", GF_BOOLEAN, values[i] ? 1.0 : 0.0);
}

/* types without variables in this FMU: only empty calls succeed */
#define NO_VARS(FN)                                                                      \
    (void)valueReferences; (void)values; (void)nValues;                                  \
    NULL_GUARD();                                                                        \
    if (nValueReferences == 0) return fmi3OK;                                            \
    gf_log(INST, GF_ERROR, FN ": this FMU has no variables of this type");               \
    return fmi3Error

#define NO_VARS_GET(NAME, T)                                                             \
    fmi3Status fmi3Get##NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                             size_t nValueReferences, T values[], size_t nValues) {      \
        NO_VARS("fmi3Get" #NAME);                                                        \
    }
#define NO_VARS_SET(NAME, T)                                                             \
    fmi3Status fmi3Set##NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                             size_t nValueReferences, const T values[], size_t nValues) { \
        NO_VARS("fmi3Set" #NAME);                                                        \
    }

NO_VARS_GET(Float32, fmi3Float32)
NO_VARS_GET(Int8, fmi3Int8)
NO_VARS_GET(UInt8, fmi3UInt8)
NO_VARS_GET(Int16, fmi3Int16)
NO_VARS_GET(UInt16, fmi3UInt16)
NO_VARS_GET(UInt32, fmi3UInt32)
NO_VARS_GET(UInt64, fmi3UInt64)
NO_VARS_GET(String, fmi3String)
NO_VARS_SET(Float32, fmi3Float32)
NO_VARS_SET(Int8, fmi3Int8)
NO_VARS_SET(UInt8, fmi3UInt8)
NO_VARS_SET(Int16, fmi3Int16)
NO_VARS_SET(UInt16, fmi3UInt16)
NO_VARS_SET(UInt32, fmi3UInt32)
NO_VARS_SET(UInt64, fmi3UInt64)
NO_VARS_SET(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues) {
    (void)valueSizes;
    NO_VARS("fmi3GetBinary");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)valueSizes;
    NO_VARS("fmi3SetBinary");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[]) {
    size_t nValues = 0;
    NO_VARS("fmi3GetClock");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[]) {
    size_t nValues = 0;
    NO_VARS("fmi3SetClock");
}

/* ---------------------------------------------------------------- dependencies */

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    NULL_GUARD();
    return (fmi3Status)gf_unsupported(INST, "fmi3GetNumberOfVariableDependencies");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents;
    (void)elementIndicesOfIndependents; (void)dependencyKinds; (void)nDependencies;
    NULL_GUARD();
    return (fmi3Status)gf_unsupported(INST, "fmi3GetVariableDependencies");
}

/* ---------------------------------------------------------------- co-simulation */

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    int st;
    (void)noSetFMUStatePriorToCurrentPoint;
    NULL_GUARD();
    st = gf_do_step(INST, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = gf_time(INST);
    return (fmi3Status)st;
}

/* ---------------------------------------------------------------- not supported */

#define UNSUPPORTED(FN) \
    NULL_GUARD();       \
    return (fmi3Status)gf_unsupported(INST, FN)

fmi3Status fmi3EnterEventMode(fmi3Instance instance) { UNSUPPORTED("fmi3EnterEventMode"); }
fmi3Status fmi3EnterStepMode(fmi3Instance instance) { UNSUPPORTED("fmi3EnterStepMode"); }
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    UNSUPPORTED("fmi3EnterConfigurationMode");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    UNSUPPORTED("fmi3ExitConfigurationMode");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    UNSUPPORTED("fmi3EvaluateDiscreteStates");
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    UNSUPPORTED("fmi3EnterContinuousTimeMode");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    void *sn;
    NULL_GUARD();
    if (!FMUState) return (fmi3Status)gf_unsupported(INST, "fmi3GetFMUState (NULL pointer)");
    sn = gf_get_state(INST, "fmi3GetFMUState", *FMUState, calloc);
    if (!sn) return fmi3Error;
    *FMUState = sn;
    return fmi3OK;
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    NULL_GUARD();
    return (fmi3Status)gf_set_state(INST, "fmi3SetFMUState", FMUState);
}
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    NULL_GUARD();
    if (!FMUState) return fmi3OK;
    gf_free_state(*FMUState, free);
    *FMUState = NULL;
    return fmi3OK;
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    (void)FMUState;
    NULL_GUARD();
    if (!size) return (fmi3Status)gf_unsupported(INST, "fmi3SerializedFMUStateSize (NULL)");
    *size = gf_state_size();
    return fmi3OK;
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    NULL_GUARD();
    return (fmi3Status)gf_serialize_state(INST, "fmi3SerializeFMUState", FMUState,
                                          (unsigned char *)serializedState, size);
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    void *sn;
    NULL_GUARD();
    if (!FMUState || !serializedState)
        return (fmi3Status)gf_unsupported(INST, "fmi3DeserializeFMUState (NULL pointer)");
    sn = gf_deserialize_state(INST, "fmi3DeserializeFMUState",
                              (const unsigned char *)serializedState, size, calloc);
    if (!sn) return fmi3Error;
    if (*FMUState) gf_free_state(*FMUState, free);
    *FMUState = sn;
    return fmi3OK;
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance,
                                        const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    UNSUPPORTED("fmi3GetDirectionalDerivative");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    UNSUPPORTED("fmi3GetAdjointDerivative");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers;
    UNSUPPORTED("fmi3GetIntervalDecimal");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    (void)qualifiers;
    UNSUPPORTED("fmi3GetIntervalFraction");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    UNSUPPORTED("fmi3GetShiftDecimal");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    UNSUPPORTED("fmi3GetShiftFraction");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
    (void)valueReferences; (void)nValueReferences; (void)intervals;
    UNSUPPORTED("fmi3SetIntervalDecimal");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    UNSUPPORTED("fmi3SetIntervalFraction");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    UNSUPPORTED("fmi3SetShiftDecimal");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    UNSUPPORTED("fmi3SetShiftFraction");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate; (void)terminateSimulation;
    (void)nominalsOfContinuousStatesChanged; (void)valuesOfContinuousStatesChanged;
    (void)nextEventTimeDefined; (void)nextEventTime;
    UNSUPPORTED("fmi3UpdateDiscreteStates");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    UNSUPPORTED("fmi3CompletedIntegratorStep");
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    UNSUPPORTED("fmi3SetTime");
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    UNSUPPORTED("fmi3SetContinuousStates");
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    (void)derivatives; (void)nContinuousStates;
    UNSUPPORTED("fmi3GetContinuousStateDerivatives");
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    (void)eventIndicators; (void)nEventIndicators;
    UNSUPPORTED("fmi3GetEventIndicators");
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    UNSUPPORTED("fmi3GetContinuousStates");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    (void)nominals; (void)nContinuousStates;
    UNSUPPORTED("fmi3GetNominalsOfContinuousStates");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    NULL_GUARD();
    if (nEventIndicators) *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    NULL_GUARD();
    if (nContinuousStates) *nContinuousStates = 0;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                    const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    UNSUPPORTED("fmi3GetOutputDerivatives");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    UNSUPPORTED("fmi3ActivateModelPartition");
}
