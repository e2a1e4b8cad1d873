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
    gf_log(inst, GF_ERROR, "%s: not supported by this FMU (co-simulation, no FMU state, "
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

int gf_enter_initialization(gf_instance_t *inst, const char *fn, double start_time) {
    if (gf_set_start_time(inst, fn, start_time) != GF_OK) return GF_ERROR;
    inst->state = GF_INITIALIZATION;
    return GF_OK;
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
    inst->p = p;
    gc_init(&inst->s, &inst->p, &GC_CHAIN);
    gc_build_field(&inst->s, &inst->p, &GC_CHAIN, &GC_MATERIALS[inst->p.material]);
    inst->n = 0;
    inst->v[GF_VR_time] = inst->t_start;
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
    now = inst->v[GF_VR_time];
    if (fabs(t - now) > 0.5 * T) {
        gf_log(inst, GF_ERROR, "%s: communication point %.17g s does not match the FMU time "
                               "%.17g s (no rollback: FMU state not supported)", fn, t, now);
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
    return gf_check_state(inst, fn, set ? GF_INSTANTIATED | GF_INITIALIZATION | GF_STEP
                                        : GF_INITIALIZATION | GF_STEP | GF_TERMINATED |
                                              GF_ERROR_STATE);
}

static const char *type_name(int type) {
    return type == GF_REAL ? "Real/Float64" : type == GF_INTEGER ? "Integer/Int32" : "Boolean";
}

static int lookup(gf_instance_t *inst, const char *fn, int type, unsigned int vr) {
    if (vr >= (unsigned int)GF_N_VARS) {
        gf_log(inst, GF_ERROR, "%s: unknown value reference %u", fn, vr);
        return GF_ERROR;
    }
    if (GF_VARS[vr].type != type) {
        gf_log(inst, GF_ERROR, "%s: variable %s (value reference %u) is not of type %s", fn,
               GF_VARS[vr].name, vr, type_name(type));
        return GF_ERROR;
    }
    return GF_OK;
}

int gf_set_value(gf_instance_t *inst, const char *fn, int type, unsigned int vr, double x) {
    const gf_var_t *var;
    if (lookup(inst, fn, type, vr)) return GF_ERROR;
    var = &GF_VARS[vr];
    if (var->causality == GF_OUTPUT || var->causality == GF_INDEPENDENT) {
        gf_log(inst, GF_ERROR, "%s: %s is an %s and cannot be set", fn, var->name,
               var->causality == GF_OUTPUT ? "output" : "independent variable");
        return GF_ERROR;
    }
    if (var->causality == GF_PARAMETER && inst->state == GF_STEP) {
        gf_log(inst, GF_ERROR, "%s: parameter %s is fixed: set it before "
                               "ExitInitializationMode (or reset the instance)", fn, var->name);
        return GF_ERROR;
    }
    if (type == GF_BOOLEAN) {
        inst->v[vr] = x != 0.0;
        return GF_OK;
    }
    if (type == GF_INTEGER) {
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
            int bad = !(x >= var->min && x <= var->max);
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
