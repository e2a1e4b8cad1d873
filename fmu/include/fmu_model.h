/*
 * fmu_model: the FMI-version-independent part of the grasprom controller FMU.
 *
 * One instance owns its parameters, controller state (gc_state_t) and variable values; there
 * are no globals, so any number of instances can run side by side.  The FMI 2 and FMI 3 glue
 * (fmi2_wrapper.c, fmi3_wrapper.c) translate the FMI calls into these functions.
 *
 * Variables (names, value references, types, start/min/max) are generated from Python by
 * grasprom.export.codegen into "grasp_fmu_config.h", with the unit factors and the SI <-> core
 * conversions gf_core_params() / gf_write_outputs(); the same table produces
 * modelDescription.xml.
 * All values are stored as doubles indexed by value reference (Integer and Boolean values are
 * exact in a double).  Values are SI (m, N, N m, rad, s, Pa); the C core works in mm, MPa.
 *
 * Status policy (documented in the FMU's documentation/index.html):
 *   - a call in the wrong state, on an unknown value reference, of the wrong type, or with an
 *     unusable value (non-finite parameter, material out of range, step size not a multiple of
 *     the sample time, ...) is *rejected*: status error, a logged message, nothing changed;
 *   - a finite Real parameter outside [min, max] is clamped (status warning, logged);
 *   - an input outside [min, max], infinite or NaN is accepted and clamped by the controller
 *     (theta: end stops; NaN holds the last valid angle; theta_dot: clamped, NaN -> 0), status
 *     warning, logged;
 *   - non-finite outputs (never expected) put the instance in the error state (only reset and
 *     free are accepted then).
 */
#ifndef GRASP_FMU_MODEL_H
#define GRASP_FMU_MODEL_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* variable types and causalities of the generated table */
enum { GF_REAL = 0, GF_INTEGER = 1, GF_BOOLEAN = 2, GF_ENUMERATION = 3 };
/* the type a getter/setter asks for: one of the above, or GF_INTEGER_OR_ENUMERATION (FMI 2
 * reads and writes Enumeration variables with fmi2Get/SetInteger; FMI 3 with fmi3Get/SetInt64,
 * which asks for GF_ENUMERATION) */
enum { GF_INTEGER_OR_ENUMERATION = 4 };
enum { GF_INDEPENDENT = 0, GF_PARAMETER = 1, GF_INPUT = 2, GF_OUTPUT = 3 };

typedef struct {
    const char *name;
    int type;       /* GF_REAL, GF_INTEGER, GF_BOOLEAN, GF_ENUMERATION */
    int causality;  /* GF_INDEPENDENT, GF_PARAMETER, GF_INPUT, GF_OUTPUT */
    double start;   /* SI */
    double min;     /* SI, -inf/+inf if unbounded */
    double max;
    int tunable;    /* parameter that may change in step mode (variability="tunable") */
    unsigned int items;     /* Enumeration: bit v set for each item value v (0: not one) */
    const char *items_text; /* Enumeration: its items, for the refusal of another value */
} gf_var_t;

/* statuses: same codes as fmi2Status and fmi3Status (OK, Warning, Discard, Error, Fatal) */
enum { GF_OK = 0, GF_WARNING = 1, GF_DISCARD = 2, GF_ERROR = 3, GF_FATAL = 4 };

/* instance states */
enum {
    GF_INSTANTIATED = 1,
    GF_INITIALIZATION = 2,
    GF_STEP = 4,
    GF_TERMINATED = 8,
    GF_ERROR_STATE = 16
};

/* message sink of the wrapper: ctx is the wrapper's data (gf_wrapper_data) */
typedef void (*gf_logger_t)(void *ctx, const char *instance, int status, const char *category,
                            const char *message);

typedef struct gf_instance gf_instance_t;

/* New instance (NULL on failure, logged): checks the instantiation token; alloc/dealloc are the
 * memory functions to use (calloc/free signature); wrapper_size bytes of zeroed wrapper data are
 * reserved (gf_wrapper_data) and passed as ctx to the logger. */
gf_instance_t *gf_new(const char *instance_name, const char *token, gf_logger_t logger,
                      int logging_on, void *(*alloc)(size_t, size_t), void (*dealloc)(void *),
                      size_t wrapper_size, void (*init_wrapper)(void *data, void *arg),
                      void *arg);
void gf_free(gf_instance_t *inst);
void *gf_wrapper_data(gf_instance_t *inst);
void gf_set_logging(gf_instance_t *inst, int on);
void gf_log(gf_instance_t *inst, int status, const char *fmt, ...)
#ifdef __GNUC__
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* state checks: GF_OK if the state is in allowed_mask, else a logged error naming fn */
int gf_check_state(gf_instance_t *inst, const char *fn, int allowed_mask);
int gf_state(const gf_instance_t *inst);
/* a function this FMU does not support: logged error */
int gf_unsupported(gf_instance_t *inst, const char *fn);

int gf_enter_initialization(gf_instance_t *inst, const char *fn, double start_time);
/* stop time of the experiment (instantiated state): a step past it is an error */
int gf_set_stop_time(gf_instance_t *inst, const char *fn, int defined, double stop_time);
int gf_exit_initialization(gf_instance_t *inst, const char *fn);
int gf_do_step(gf_instance_t *inst, const char *fn, double t, double h);
int gf_terminate(gf_instance_t *inst, const char *fn);
int gf_reset(gf_instance_t *inst, const char *fn);
int gf_set_start_time(gf_instance_t *inst, const char *fn, double start_time);
double gf_time(const gf_instance_t *inst);

/* set/get: gf_access checks the state once per call (set = 1: instantiated, initialization or
 * step mode; set = 0, FMI 2 get: initialization, step, terminated or error state; set = 2,
 * FMI 3 get: those and instantiated); then one value per element (as a double); a rejected
 * element is not stored.  Status = worst of the elements. */
int gf_access(gf_instance_t *inst, const char *fn, int set);
int gf_set_value(gf_instance_t *inst, const char *fn, int type, unsigned int vr, double value);
int gf_get_value(gf_instance_t *inst, const char *fn, int type, unsigned int vr, double *value);

/* FMU state (FMI 2 fmi2GetFMUstate ..., FMI 3 fmi3GetFMUState ...): a copy of the values, the
 * time, the mode and the controller state.  gf_get_state allocates (alloc, calloc signature)
 * or overwrites `reuse`; NULL on error (logged).  A serialized state is gf_state_size() bytes
 * and is accepted only by the same FMU (instantiation token) of the same build. */
size_t gf_state_size(void);
void *gf_get_state(gf_instance_t *inst, const char *fn, void *reuse,
                   void *(*alloc)(size_t, size_t));
int gf_set_state(gf_instance_t *inst, const char *fn, const void *state);
void gf_free_state(void *state, void (*dealloc)(void *));
int gf_serialize_state(gf_instance_t *inst, const char *fn, const void *state,
                       unsigned char *buf, size_t size);
void *gf_deserialize_state(gf_instance_t *inst, const char *fn, const unsigned char *buf,
                           size_t size, void *(*alloc)(size_t, size_t));

#ifdef __cplusplus
}
#endif
#endif
