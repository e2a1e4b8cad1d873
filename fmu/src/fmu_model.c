/*
 * fmu_model.c: FMI-independent model layer of the grasprom controller FMU (see fmu_model.h).
 */
#include "fmu_model.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "grasp_core.h"
#define GF_DEFINE_VARS /* the variable table lives in this translation unit */
#include "grasp_fmu_config.h"
#include "grasp_tables.h"

/* bounded work per doStep (issue 14: one doStep of 1e5 s blocked for 27 s) */
#define GF_MAX_SAMPLES_PER_STEP 10000000ULL

struct gf_instance {
    char *name;
    gf_logger_t logger;
    void (*dealloc)(void *);
    void *wrapper;           /* wrapper data (callbacks), allocated with the instance */
    int logging_on;
    int state;
    int theta_warned;        /* an out-of-range theta was logged; log again once back in range */
    double v[GF_N_VARS];     /* variable values by value reference, SI */
    double t_start;          /* s */
    double t_stop;           /* s, if stop_defined */
    int stop_defined;        /* the importer set a stop time (setupExperiment / enterInit.) */
    unsigned long long n;    /* samples done since the start */
    gc_params_t p;           /* core parameters (mm, N, MPa), set at exit of initialization */
    gc_state_t s;
    gc_output_t o;
};

static const char *state_name(int st) {
    switch (st) {
    case GF_INSTANTIATED: return "instantiated";
    case GF_INITIALIZATION: return "initialization mode";
    case GF_STEP: return "step mode";
    case GF_TERMINATED: return "terminated";
    default: return "error state";
    }
}

void gf_log(gf_instance_t *inst, int status, const char *fmt, ...) {
    char buf[512];
    const char *cat;
    va_list ap;
    if (!inst || !inst->logger) return;
    if (status < GF_WARNING && !inst->logging_on) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    cat = status >= GF_ERROR ? "logStatusError" : status == GF_WARNING ? "logStatusWarning"
                                                                        : "logEvents";
    inst->logger(inst->wrapper, inst->name, status, cat, buf);
}

static void load_starts(gf_instance_t *inst) {
    int i;
    for (i = 0; i < GF_N_VARS; ++i) inst->v[i] = GF_VARS[i].start;
    inst->n = 0;
    inst->theta_warned = 0;
    inst->t_start = 0.0;
    inst->t_stop = 0.0;
    inst->stop_defined = 0;
    inst->v[GF_VR_time] = 0.0;
}

gf_instance_t *gf_new(const char *instance_name, const char *token, gf_logger_t logger,
                      int logging_on, void *(*alloc)(size_t, size_t), void (*dealloc)(void *),
                      size_t wrapper_size, void (*init_wrapper)(void *data, void *arg),
                      void *arg) {
    gf_instance_t *inst;
    size_t len;
    if (!alloc || !dealloc) return NULL;
    if (!instance_name) instance_name = "";
    len = strlen(instance_name);
    inst = (gf_instance_t *)alloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->wrapper = wrapper_size ? alloc(1, wrapper_size) : NULL;
    inst->name = (char *)alloc(len + 1, 1);
    if ((wrapper_size && !inst->wrapper) || !inst->name) {
        if (inst->wrapper) dealloc(inst->wrapper);
        if (inst->name) dealloc(inst->name);
        dealloc(inst);
        return NULL;
    }
    memcpy(inst->name, instance_name, len + 1);
    if (init_wrapper) init_wrapper(inst->wrapper, arg);
    inst->logger = logger;
    inst->dealloc = dealloc;
    inst->logging_on = logging_on != 0;
    inst->state = GF_INSTANTIATED;
    load_starts(inst);
    if (!token || strcmp(token, GF_TOKEN) != 0) {
        gf_log(inst, GF_ERROR, "instantiation token/GUID '%s' does not match this FMU's '%s'",
               token ? token : "(null)", GF_TOKEN);
        gf_free(inst);
        return NULL;
    }
    gf_log(inst, GF_OK, "instantiated %s (token %s)", GF_MODEL_IDENTIFIER, GF_TOKEN);
    return inst;
}

void gf_free(gf_instance_t *inst) {
    void (*dealloc)(void *);
    if (!inst) return;
    dealloc = inst->dealloc;
    if (inst->wrapper) dealloc(inst->wrapper);
    dealloc(inst->name);
    dealloc(inst);
}

void *gf_wrapper_data(gf_instance_t *inst) { return inst ? inst->wrapper : NULL; }

void gf_set_logging(gf_instance_t *inst, int on) { inst->logging_on = on != 0; }

int gf_state(const gf_instance_t *inst) { return inst->state; }

double gf_time(const gf_instance_t *inst) { return inst->v[GF_VR_time]; }

int gf_check_state(gf_instance_t *inst, const char *fn, int allowed_mask) {
    if (inst->state & allowed_mask) return GF_OK;
    gf_log(inst, GF_ERROR, "%s: not allowed in %s", fn, state_name(inst->state));
    return GF_ERROR;
}

int gf_unsupported(gf_instance_t *inst, const char *fn) {
    gf_log(inst, GF_ERROR, "%s: not supported by this FMU (co-simulation, "
                           "no derivatives, no events)", fn);
    return GF_ERROR;
}

int gf_set_start_time(gf_instance_t *inst, const char *fn, double start_time) {
    if (gf_check_state(inst, fn, GF_INSTANTIATED)) return GF_ERROR;
    if (!isfinite(start_time)) {
        gf_log(inst, GF_ERROR, "%s: start time %g is not finite", fn, start_time);
        return GF_ERROR;
    }
    inst->t_start = start_time;
    inst->v[GF_VR_time] = start_time;
    return GF_OK;
}

int gf_set_stop_time(gf_instance_t *inst, const char *fn, int defined, double stop_time) {
    if (gf_check_state(inst, fn, GF_INSTANTIATED)) return GF_ERROR;
    if (!defined) {
        inst->stop_defined = 0;
        return GF_OK;
    }
    if (!(isfinite(stop_time) && stop_time >= inst->t_start)) {
        gf_log(inst, GF_ERROR, "%s: stop time %g s must be finite and >= the start time %g s",
               fn, stop_time, inst->t_start);
        return GF_ERROR;
    }
    inst->stop_defined = 1;
    inst->t_stop = stop_time;
    return GF_OK;
}

int gf_enter_initialization(gf_instance_t *inst, const char *fn, double start_time) {
    if (gf_set_start_time(inst, fn, start_time) != GF_OK) return GF_ERROR;
    inst->state = GF_INITIALIZATION;
    return GF_OK;
}

/* the outputs the controller gives for the current inputs, without advancing its state (so
 * importers see the controller at the start angle, not the start values, before the first
 * step; the steps themselves are unchanged) */
static void preview_outputs(gf_instance_t *inst) {
    gc_state_t s = inst->s;
    gc_output_t o;
    const gc_material_t *m = &GC_MATERIALS[inst->p.material];
    if (inst->v[GF_VR_use_theta_dot] != 0.0)
        gc_step_ext(&s, &inst->p, &GC_CHAIN, m, inst->v[GF_VR_theta], inst->v[GF_VR_theta_dot],
                    &o);
    else
        gc_step(&s, &inst->p, &GC_CHAIN, m, inst->v[GF_VR_theta], &o);
    gf_write_outputs(&o, inst->v);
}

int gf_exit_initialization(gf_instance_t *inst, const char *fn) {
    gc_params_t p;
    double t;
    int clamped, rc, status = GF_OK;
    const char *msg;
    if (gf_check_state(inst, fn, GF_INITIALIZATION)) return GF_ERROR;
    gf_core_params(inst->v, &p); /* generated (grasp_fmu_config.h) */
    rc = gc_check_params(&p, GC_MATERIALS, GC_N_MATERIALS, &t, &clamped, &msg);
    if (rc != 0) {
        gf_log(inst, GF_ERROR, "%s: parameters rejected: %s", fn, msg);
        return GF_ERROR;
    }
    if (clamped) {
        /* a thickness within rounding of the table end (m -> mm conversion) is not reported */
        if (fabs(t - p.thickness) > 1e-9 * fabs(t)) {
            status = GF_WARNING;
            gf_log(inst, GF_WARNING,
                   "%s: thickness %g mm outside the tabulated range of material %d: clamped to "
                   "%g mm", fn, p.thickness, p.material, t);
        }
        p.thickness = t;
    }
    if (!(p.diameter > 2.0 * p.thickness)) {
        gf_log(inst, GF_ERROR, "%s: parameters rejected: diameter %g mm must exceed twice the "
                               "wall thickness %g mm", fn, p.diameter, p.thickness);
        return GF_ERROR;
    }
    if (p.encoder_counts != 0.0 && p.encoder_counts < GF_ENCODER_COUNTS_MIN) {
        gf_log(inst, GF_ERROR, "%s: parameters rejected: encoder_counts %g must be 0 (no "
                               "quantisation) or at least %d", fn, p.encoder_counts,
               GF_ENCODER_COUNTS_MIN);
        return GF_ERROR;
    }
    inst->p = p;
    gc_init(&inst->s, &inst->p, &GC_CHAIN);
    gc_build_field(&inst->s, &inst->p, &GC_CHAIN, &GC_MATERIALS[inst->p.material]);
    inst->n = 0;
    inst->v[GF_VR_time] = inst->t_start;
    preview_outputs(inst);
    inst->state = GF_STEP;
    gf_log(inst, GF_OK, "%s: controller initialised, sample time %g s", fn, p.sample_time);
    return status;
}

int gf_do_step(gf_instance_t *inst, const char *fn, double t, double h) {
    double T, ratio, now;
    unsigned long long k, i;
    const gc_material_t *m;
    int use_ext;
    if (gf_check_state(inst, fn, GF_STEP)) return GF_ERROR;
    T = inst->p.sample_time;
    if (!(isfinite(t) && isfinite(h) && h > 0.0)) {
        gf_log(inst, GF_ERROR, "%s: communication point %g s and step size %g s must be finite "
                               "with a positive step", fn, t, h);
        return GF_ERROR;
    }
    ratio = h / T;
    if (!(ratio >= 0.5 && ratio < 1e12)) {
        gf_log(inst, GF_ERROR, "%s: communication step size %g s must be a multiple of the "
                               "controller sample time %g s", fn, h, T);
        return GF_ERROR;
    }
    k = (unsigned long long)floor(ratio + 0.5);
    if (fabs(ratio - (double)k) > 1e-9 * (double)k) {
        gf_log(inst, GF_ERROR, "%s: communication step size %g s is not a multiple of the "
                               "controller sample time %g s (ratio %.12g)", fn, h, T, ratio);
        return GF_ERROR;
    }
    if (k > GF_MAX_SAMPLES_PER_STEP) {
        gf_log(inst, GF_ERROR, "%s: a communication step of %g s is %llu controller samples, "
                               "more than %llu per doStep (split it: one sample takes about "
                               "0.2 us, so this bound is about 2 s of work)", fn, h,
               (unsigned long long)k, (unsigned long long)GF_MAX_SAMPLES_PER_STEP);
        return GF_ERROR;
    }
    now = inst->v[GF_VR_time];
    if (fabs(t - now) > 0.5 * T) {
        gf_log(inst, GF_ERROR, "%s: communication point %.17g s does not match the FMU time "
                               "%.17g s (to go back, restore an FMU state)", fn, t, now);
        return GF_ERROR;
    }
    if (inst->stop_defined && t + h > inst->t_stop + 1e-9 * fmax(1.0, fabs(inst->t_stop))) {
        gf_log(inst, GF_ERROR, "%s: step from %.17g s by %g s goes past the stop time %.17g s",
               fn, t, h, inst->t_stop);
        return GF_ERROR;
    }
    m = &GC_MATERIALS[inst->p.material];
    use_ext = inst->v[GF_VR_use_theta_dot] != 0.0;
    for (i = 0; i < k; ++i) {
        if (use_ext)
            gc_step_ext(&inst->s, &inst->p, &GC_CHAIN, m, inst->v[GF_VR_theta],
                        inst->v[GF_VR_theta_dot], &inst->o);
        else
            gc_step(&inst->s, &inst->p, &GC_CHAIN, m, inst->v[GF_VR_theta], &inst->o);
    }
    inst->n += k;
    inst->v[GF_VR_time] = inst->t_start + (double)inst->n * T;
    gf_write_outputs(&inst->o, inst->v); /* generated (grasp_fmu_config.h) */
    if (!(isfinite(inst->o.torque) && isfinite(inst->o.force_handle) &&
          isfinite(inst->o.force_jaw) && isfinite(inst->o.force_tissue) &&
          isfinite(inst->o.gap) && isfinite(inst->o.velocity))) {
        inst->state = GF_ERROR_STATE;
        gf_log(inst, GF_ERROR, "%s: non-finite controller output at t = %g s", fn,
               inst->v[GF_VR_time]);
        return GF_ERROR;
    }
    return GF_OK;
}

int gf_terminate(gf_instance_t *inst, const char *fn) {
    if (gf_check_state(inst, fn, GF_STEP)) return GF_ERROR;
    inst->state = GF_TERMINATED;
    return GF_OK;
}

int gf_reset(gf_instance_t *inst, const char *fn) {
    if (gf_check_state(inst, fn,
                       GF_INSTANTIATED | GF_INITIALIZATION | GF_STEP | GF_TERMINATED |
                           GF_ERROR_STATE))
        return GF_ERROR;
    load_starts(inst);
    inst->state = GF_INSTANTIATED;
    return GF_OK;
}

int gf_access(gf_instance_t *inst, const char *fn, int set) {
    int get = GF_INITIALIZATION | GF_STEP | GF_TERMINATED | GF_ERROR_STATE;
    if (set == 2) get |= GF_INSTANTIATED; /* FMI 3 getters */
    return gf_check_state(inst, fn, set == 1 ? GF_INSTANTIATED | GF_INITIALIZATION | GF_STEP
                                             : get);
}

static const char *type_name(int type) {
    switch (type) {
    case GF_REAL: return "Real/Float64";
    case GF_INTEGER: return "Integer/Int32";
    case GF_ENUMERATION: return "Enumeration (FMI 3: Int64)";
    case GF_INTEGER_OR_ENUMERATION: return "Integer or Enumeration";
    default: return "Boolean";
    }
}

static int type_matches(int var_type, int asked) {
    if (asked == GF_INTEGER_OR_ENUMERATION)
        return var_type == GF_INTEGER || var_type == GF_ENUMERATION;
    return var_type == asked;
}

static int lookup(gf_instance_t *inst, const char *fn, int type, unsigned int vr) {
    if (vr >= (unsigned int)GF_N_VARS) {
        gf_log(inst, GF_ERROR, "%s: unknown value reference %u", fn, vr);
        return GF_ERROR;
    }
    if (!type_matches(GF_VARS[vr].type, type)) {
        gf_log(inst, GF_ERROR, "%s: variable %s (value reference %u) is not of type %s", fn,
               GF_VARS[vr].name, vr, type_name(type));
        return GF_ERROR;
    }
    return GF_OK;
}

/* a tunable parameter changed in step mode: the core parameters are regenerated from the
 * values and only the tunable fields taken over (the rest of the core's parameters and its
 * state stay as initialised) */
static void apply_tunable(gf_instance_t *inst) {
    gc_params_t p;
    gf_core_params(inst->v, &p);   /* generated (grasp_fmu_config.h) */
    GF_COPY_TUNABLE(&inst->p, &p); /* generated from the tunable variables */
}

static int store_value(gf_instance_t *inst, const char *fn, const gf_var_t *var,
                       unsigned int vr, double x);

int gf_set_value(gf_instance_t *inst, const char *fn, int type, unsigned int vr, double x) {
    const gf_var_t *var;
    if (lookup(inst, fn, type, vr)) return GF_ERROR;
    var = &GF_VARS[vr];
    if (var->causality == GF_OUTPUT || var->causality == GF_INDEPENDENT) {
        gf_log(inst, GF_ERROR, "%s: %s is an %s and cannot be set", fn, var->name,
               var->causality == GF_OUTPUT ? "output" : "independent variable");
        return GF_ERROR;
    }
    if (var->causality == GF_PARAMETER && inst->state == GF_STEP && !var->tunable) {
        gf_log(inst, GF_ERROR, "%s: parameter %s is fixed: set it before "
                               "ExitInitializationMode (or reset the instance)", fn, var->name);
        return GF_ERROR;
    }
    if (var->causality == GF_PARAMETER && inst->state == GF_STEP) {
        int st = store_value(inst, fn, var, vr, x); /* the checks of any parameter */
        if (st <= GF_WARNING) apply_tunable(inst);
        return st;
    }
    return store_value(inst, fn, var, vr, x);
}

/* store one value after the checks of its type and causality (rejected: not stored) */
/* theta within this of an end stop counts as inside (clamped without a warning): importers
 * that interpolate an input held at the end stop land an ulp outside it (rad) */
#define GF_THETA_SLACK 1e-9

static int store_value(gf_instance_t *inst, const char *fn, const gf_var_t *var,
                       unsigned int vr, double x) {
    if (var->type == GF_BOOLEAN) {
        inst->v[vr] = x != 0.0;
        return GF_OK;
    }
    if (var->type == GF_INTEGER || var->type == GF_ENUMERATION) {
        /* an enumeration takes its items only, which may skip values (the materials of a
         * surrogate without nh: 0 mr, 2 le); the refusal names them */
        if (var->type == GF_ENUMERATION && var->items != 0u &&
            !(x >= 0.0 && x < 32.0 && ((var->items >> (unsigned int)x) & 1u))) {
            gf_log(inst, GF_ERROR, "%s: %s = %.0f is not an item of this FMU (%s): rejected", fn,
                   var->name, x, var->items_text);
            return GF_ERROR;
        }
        if (!(x >= var->min && x <= var->max)) {
            gf_log(inst, GF_ERROR, "%s: %s = %.0f outside [%.0f, %.0f]: rejected", fn,
                   var->name, x, var->min, var->max);
            return GF_ERROR;
        }
        inst->v[vr] = x;
        return GF_OK;
    }
    if (var->causality == GF_INPUT) {
        if (vr == GF_VR_theta) {
            /* stored as is: the controller clamps, and holds the last angle on NaN; warning
             * status every time, logged once per excursion (no flood at 1 kHz) */
            int bad = !(x >= var->min - GF_THETA_SLACK && x <= var->max + GF_THETA_SLACK);
            inst->v[vr] = x;
            if (!bad) {
                inst->theta_warned = 0;
                return GF_OK;
            }
            if (!inst->theta_warned) {
                inst->theta_warned = 1;
                if (isnan(x))
                    gf_log(inst, GF_WARNING, "%s: theta is NaN: the controller holds the last "
                                             "valid angle (logged once per excursion)", fn);
                else
                    gf_log(inst, GF_WARNING, "%s: theta = %g rad outside [%g, %g] rad: clamped "
                                             "to the end stop (logged once per excursion)", fn,
                           x, var->min, var->max);
            }
            return GF_WARNING;
        }
        if (isnan(x)) {
            inst->v[vr] = 0.0;
            gf_log(inst, GF_WARNING, "%s: %s is NaN: replaced by 0", fn, var->name);
            return GF_WARNING;
        }
    } else if (!isfinite(x)) {
        gf_log(inst, GF_ERROR, "%s: parameter %s = %g is not finite: rejected", fn, var->name, x);
        return GF_ERROR;
    }
    if (x < var->min || x > var->max) {
        double c = x < var->min ? var->min : var->max;
        gf_log(inst, GF_WARNING, "%s: %s = %g outside [%g, %g]: clamped to %g", fn, var->name, x,
               var->min, var->max, c);
        inst->v[vr] = c;
        return GF_WARNING;
    }
    inst->v[vr] = x;
    return GF_OK;
}

int gf_get_value(gf_instance_t *inst, const char *fn, int type, unsigned int vr, double *x) {
    if (lookup(inst, fn, type, vr)) return GF_ERROR;
    *x = inst->v[vr];
    return GF_OK;
}

/* ---------------------------------------------------------------------------------------- */
/* FMU state: a copy of everything that evolves (values, time, core state, mode)            */

#define GF_SNAPSHOT_MAGIC 0x47465331u /* "GFS1" */

typedef struct {
    unsigned int magic;
    unsigned int size;       /* sizeof(gf_snapshot_t): a serialized state from another build
                                of the FMU is rejected */
    char token[64];          /* GF_TOKEN of the FMU that wrote it */
    int state;
    int theta_warned;
    int stop_defined;
    int material;            /* to re-point the core's material pointers after deserializing */
    double v[GF_N_VARS];
    double t_start, t_stop;
    unsigned long long n;
    gc_params_t p;
    gc_state_t s;
    gc_output_t o;
} gf_snapshot_t;

size_t gf_state_size(void) { return sizeof(gf_snapshot_t); }

static void snap_store(const gf_instance_t *inst, gf_snapshot_t *sn) {
    memset(sn, 0, sizeof *sn);
    sn->magic = GF_SNAPSHOT_MAGIC;
    sn->size = (unsigned int)sizeof *sn;
    strncpy(sn->token, GF_TOKEN, sizeof sn->token - 1);
    sn->state = inst->state;
    sn->theta_warned = inst->theta_warned;
    sn->stop_defined = inst->stop_defined;
    sn->material = inst->p.material;
    memcpy(sn->v, inst->v, sizeof sn->v);
    sn->t_start = inst->t_start;
    sn->t_stop = inst->t_stop;
    sn->n = inst->n;
    sn->p = inst->p;
    sn->s = inst->s;
    sn->o = inst->o;
}

static int snap_valid(gf_instance_t *inst, const char *fn, const gf_snapshot_t *sn) {
    if (!sn || sn->magic != GF_SNAPSHOT_MAGIC || sn->size != sizeof *sn ||
        strncmp(sn->token, GF_TOKEN, sizeof sn->token) != 0 || sn->material < 0 ||
        sn->material >= GC_N_MATERIALS) {
        gf_log(inst, GF_ERROR, "%s: not an FMU state of this FMU (%s)", fn, GF_TOKEN);
        return 0;
    }
    return 1;
}

void *gf_get_state(gf_instance_t *inst, const char *fn, void *reuse,
                   void *(*alloc)(size_t, size_t)) {
    gf_snapshot_t *sn = (gf_snapshot_t *)reuse;
    if (gf_check_state(inst, fn, GF_INSTANTIATED | GF_INITIALIZATION | GF_STEP | GF_TERMINATED))
        return NULL;
    if (!sn) sn = (gf_snapshot_t *)alloc(1, sizeof *sn);
    if (!sn) {
        gf_log(inst, GF_ERROR, "%s: out of memory", fn);
        return NULL;
    }
    snap_store(inst, sn);
    return sn;
}

int gf_set_state(gf_instance_t *inst, const char *fn, const void *state) {
    const gf_snapshot_t *sn = (const gf_snapshot_t *)state;
    const gc_material_t *m;
    if (gf_check_state(inst, fn, GF_INSTANTIATED | GF_INITIALIZATION | GF_STEP | GF_TERMINATED))
        return GF_ERROR;
    if (!snap_valid(inst, fn, sn)) return GF_ERROR;
    inst->state = sn->state;
    inst->theta_warned = sn->theta_warned;
    inst->stop_defined = sn->stop_defined;
    memcpy(inst->v, sn->v, sizeof inst->v);
    inst->t_start = sn->t_start;
    inst->t_stop = sn->t_stop;
    inst->n = sn->n;
    inst->p = sn->p;
    inst->s = sn->s;
    inst->o = sn->o;
    /* the core caches pointers to its material table: valid in this process only */
    m = &GC_MATERIALS[sn->material];
    if (inst->s.b_mat) inst->s.b_mat = m;
    if (inst->s.f_mat) inst->s.f_mat = m;
    return GF_OK;
}

void gf_free_state(void *state, void (*dealloc)(void *)) {
    if (state) dealloc(state);
}

int gf_serialize_state(gf_instance_t *inst, const char *fn, const void *state,
                       unsigned char *buf, size_t size) {
    if (!snap_valid(inst, fn, (const gf_snapshot_t *)state)) return GF_ERROR;
    if (size < sizeof(gf_snapshot_t)) {
        gf_log(inst, GF_ERROR, "%s: buffer of %lu bytes, the state needs %lu", fn,
               (unsigned long)size, (unsigned long)sizeof(gf_snapshot_t));
        return GF_ERROR;
    }
    memcpy(buf, state, sizeof(gf_snapshot_t));
    return GF_OK;
}

void *gf_deserialize_state(gf_instance_t *inst, const char *fn, const unsigned char *buf,
                           size_t size, void *(*alloc)(size_t, size_t)) {
    gf_snapshot_t tmp, *sn;
    if (size != sizeof tmp) {
        gf_log(inst, GF_ERROR, "%s: %lu bytes is not a serialized state of this FMU (%lu)", fn,
               (unsigned long)size, (unsigned long)sizeof tmp);
        return NULL;
    }
    memcpy(&tmp, buf, sizeof tmp);
    if (!snap_valid(inst, fn, &tmp)) return NULL;
    sn = (gf_snapshot_t *)alloc(1, sizeof *sn);
    if (!sn) {
        gf_log(inst, GF_ERROR, "%s: out of memory", fn);
        return NULL;
    }
    *sn = tmp;
    return sn;
}
