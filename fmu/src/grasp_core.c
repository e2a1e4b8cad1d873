/*
 * grasp_core.c: the controller step of grasprom in C (see grasp_core.h for the build options).
 * The run-time step (and its clipped field, gc_build_field) mirrors
 * grasprom/control/impedance.py, grasprom/control/field.py, grasprom/chain/kinematics.py and
 * the scalar path of grasprom/surrogate operation by operation, so that the results are
 * bit-identical (tests/export/test_ccore.py); the tabulated step (GC_TABULATED) evaluates the
 * tables grasprom.export.arduino computes with the same Python reference.
 */
#include "grasp_core.h"

#include <string.h>
#include <math.h>

#if defined(GC_OLD_GLIBC_EXP) && defined(__linux__) && defined(__x86_64__) && defined(__GLIBC__)
/* Link exp against its glibc 2.2.5 symbol: glibc >= 2.29 adds exp@GLIBC_2.29 (same results,
 * only the SVID error handling dropped), which would stop the FMU from loading on older
 * distributions (RHEL 8: glibc 2.28).  The FMU's binary then needs glibc >= 2.14 (memcpy).
 * Set by grasprom's own FMU build, which links libm (-lm); a rebuild from sources/ by an
 * importer that does not link libm (fmpy compile) gets the plain symbol. */
__asm__(".symver exp,exp@GLIBC_2.2.5");
#endif


#if !defined(GC_TABULATED)
/* =============================================================== run-time (floating point) */

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static const double RAD_TO_DEG = 180.0 / M_PI;
static const double DEG_TO_RAD = M_PI / 180.0;

/* ---------------------------------------------------------------- surrogate curves */

/* index of the last node <= x (bisect_right - 1), for x inside [x[0], x[n-1]) */
static int bisect(const double *x, int n, double v) {
    int lo = 0, hi = n; /* first index with x[i] > v lies in [lo, hi] */
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (v < GC_RD(&x[mid])) hi = mid; else lo = mid + 1;
    }
    return lo - 1;
}

/* force (N) and dF/dgap (N/mm) of one curve; returns 1 below the first node (extrapolated).
 * *hint: last interval used (or -1); checked first, so slowly moving gaps skip the bisection
 * (the interval found is the same either way). */
static int curve_eval_hint(const gc_curve_t *c, double x, double *f, double *dfdg, int *hint) {
    const double *xs = GC_PTR(c->x), *c0 = GC_PTR(c->c0), *c1 = GC_PTR(c->c1);
    int n = GC_RDI(&c->n);
    double x0 = GC_RD(&xs[0]), xn = GC_RD(&xs[n - 1]);
    int last = n - 2;
    int k;
    double h, a1, a2, a3, v;
    if (x >= xn) { *f = 0.0; *dfdg = 0.0; return 0; }
    if (x < x0) {
        v = GC_RD(&c0[0]) + GC_RD(&c1[0]) * (x - x0);
        *f = v > 0.0 ? v : 0.0;
        *dfdg = GC_RD(&c1[0]);
        return 1;
    }
    k = *hint;
    if (!(k >= 0 && k <= last && GC_RD(&xs[k]) <= x && x < GC_RD(&xs[k + 1]))) {
        k = bisect(xs, n, x);
        if (k > last) k = last;
        *hint = k;
    }
    h = x - GC_RD(&xs[k]);
    a1 = GC_RD(&c1[k]); a2 = GC_RD(&GC_PTR(c->c2)[k]); a3 = GC_RD(&GC_PTR(c->c3)[k]);
    v = ((a3 * h + a2) * h + a1) * h + GC_RD(&c0[k]);
    *f = v > 0.0 ? v : 0.0;
    *dfdg = (3.0 * a3 * h + 2.0 * a2) * h + a1;
    return 0;
}

static int curve_eval(const gc_curve_t *c, double x, double *f, double *dfdg) {
    int hint = -1;
    return curve_eval_hint(c, x, f, dfdg, &hint);
}

int gc_surrogate(const gc_material_t *m, double gap, double t, double *force, double *stiffness) {
    int n = GC_RDI(&m->n_curves), i, ba, bb;
    double w, v, fa, fb, da, db, dfdg;
    if (n == 1) {
        ba = curve_eval(&GC_CURVES(m)[0], gap, force, &dfdg);
        *stiffness = -dfdg;
        return ba;
    }
    i = bisect(GC_PTR(m->thickness), n, t);
    if (i < 0) i = 0; else if (i > n - 2) i = n - 2;
    w = (t - GC_RD(&GC_PTR(m->thickness)[i])) * GC_RD(&GC_PTR(m->inv_dt)[i]);
    if (w < 0.0) w = 0.0; else if (w > 1.0) w = 1.0;
    v = 1.0 - w;
    if (GC_RDI(&m->aligned)) {
        double D = GC_RD(&m->diameter), gca = GC_RD(&GC_PTR(m->contact_gap)[i]), gcb = GC_RD(&GC_PTR(m->contact_gap)[i + 1]);
        double dgc = gca - gcb, gct = gca - w * dgc, idn = 1.0 / (D - gct);
        double r = (D - gap) * idn * dgc;
        ba = curve_eval(&GC_CURVES(m)[i], gap + w * r, &fa, &da);
        bb = curve_eval(&GC_CURVES(m)[i + 1], gap - v * r, &fb, &db);
        dfdg = v * (da * ((D - gca) * idn)) + w * (db * ((D - gcb) * idn));
    } else {
        ba = curve_eval(&GC_CURVES(m)[i], gap, &fa, &da);
        bb = curve_eval(&GC_CURVES(m)[i + 1], gap, &fb, &db);
        dfdg = v * da + w * db;
    }
    *force = v * fa + w * fb;
    *stiffness = -dfdg;
    return (ba && v > 0.0) || (bb && w > 0.0);
}

/* thickness blend of the step's material and thickness, computed once (same arithmetic as
 * gc_surrogate, so the results are identical) */
static void blend_prepare(gc_state_t *s, const gc_material_t *m, double t) {
    int n = GC_RDI(&m->n_curves), i;
    double w;
    s->b_mat = m;
    s->b_t = t;
    s->hint[0] = s->hint[1] = -1;
    if (n == 1) { s->b_i = 0; s->b_w = 0.0; s->b_v = 1.0; return; }
    i = bisect(GC_PTR(m->thickness), n, t);
    if (i < 0) i = 0; else if (i > n - 2) i = n - 2;
    w = (t - GC_RD(&GC_PTR(m->thickness)[i])) * GC_RD(&GC_PTR(m->inv_dt)[i]);
    if (w < 0.0) w = 0.0; else if (w > 1.0) w = 1.0;
    s->b_i = i;
    s->b_w = w;
    s->b_v = 1.0 - w;
    if (GC_RDI(&m->aligned)) {
        double D = GC_RD(&m->diameter), gca = GC_RD(&GC_PTR(m->contact_gap)[i]), gcb = GC_RD(&GC_PTR(m->contact_gap)[i + 1]);
        double dgc = gca - gcb, gct = gca - w * dgc, idn = 1.0 / (D - gct);
        s->b_dgc = dgc;
        s->b_idn = idn;
        s->b_sa = (D - gca) * idn;
        s->b_sb = (D - gcb) * idn;
    }
}

static int surrogate_fast(gc_state_t *s, double gap, double *force, double *stiffness) {
    const gc_material_t *m = s->b_mat;
    int i = s->b_i, ba, bb;
    double w = s->b_w, v = s->b_v, fa, fb, da, db, dfdg;
    if (GC_RDI(&m->n_curves) == 1) {
        ba = curve_eval_hint(&GC_CURVES(m)[0], gap, force, &dfdg, &s->hint[0]);
        *stiffness = -dfdg;
        return ba;
    }
    if (GC_RDI(&m->aligned)) {
        double r = (GC_RD(&m->diameter) - gap) * s->b_idn * s->b_dgc;
        ba = curve_eval_hint(&GC_CURVES(m)[i], gap + w * r, &fa, &da, &s->hint[0]);
        bb = curve_eval_hint(&GC_CURVES(m)[i + 1], gap - v * r, &fb, &db, &s->hint[1]);
        dfdg = v * (da * s->b_sa) + w * (db * s->b_sb);
    } else {
        ba = curve_eval_hint(&GC_CURVES(m)[i], gap, &fa, &da, &s->hint[0]);
        bb = curve_eval_hint(&GC_CURVES(m)[i + 1], gap, &fb, &db, &s->hint[1]);
        dfdg = v * da + w * db;
    }
    *force = v * fa + w * fb;
    *stiffness = -dfdg;
    return (ba && v > 0.0) || (bb && w > 0.0);
}

/* ---------------------------------------------------------------- kinematic chain */

void gc_chain_state(const gc_chain_t *c, double theta_deg, double *gap, double *g1, double *u,
                    double *du) {
    /* mirrors kinematics._theta_rad (clip) and _scalar_state */
    double td = theta_deg, t, sn, cs, yb, xb, s, cb, tb, xc, d1;
    if (td < c->theta_lo_deg) td = c->theta_lo_deg;
    if (td > c->theta_hi_deg) td = c->theta_hi_deg;
    t = td * DEG_TO_RAD;
    sn = sin(t); cs = cos(t);
    yb = c->h * sn + c->d * cs;
    xb = c->h * cs - c->d * sn;
    s = (yb - c->d) / c->L2;
    cb = sqrt(1.0 - s * s);
    tb = s / cb;
    xc = xb + c->side * c->L2 * cb;
    d1 = -yb - c->side * xb * tb;
    *gap = c->gap_closed + c->gap_per_xc * (xc - c->xc_closed);
    *g1 = c->gap_per_xc * d1;
    *du = -d1 * c->stroke_sign;
    *u = (c->xc_open - xc) * c->stroke_sign;
}

/* ---------------------------------------------------------------- parameters and state */

int gc_check_params(const gc_params_t *p, const gc_material_t *materials, int n_materials,
                    double *thickness_clamped, int *clamped, const char **message) {
    const gc_material_t *m;
    double lo, hi, t = p->thickness;
    int i;
    *clamped = 0;
    *thickness_clamped = t;
    /* a code (0 mr, 1 nh, 2 le) with curves: a material the export's surrogate does not
     * cover has a row without (short message: on the AVR the strings take RAM) */
    if (p->material < 0 || p->material >= n_materials ||
        GC_RDI(&materials[p->material].n_curves) < 1) {
        *message = "material code not in this export's tables";
        return -1;
    }
#define GC_POS(x, name) if (!(isfinite(x) && (x) > 0.0)) { *message = name " must be finite and > 0"; return -2; }
    GC_POS(p->pulley_radius, "pulley_radius");
    GC_POS(p->velocity_cutoff, "velocity_cutoff");
    GC_POS(p->torque_limit, "torque_limit");
    GC_POS(p->sample_time, "sample_time");
    GC_POS(p->coupling_k, "coupling_stiffness");
    GC_POS(p->force_warning, "force_warning");
    GC_POS(p->pressure_warning, "pressure_warning");
    GC_POS(p->jaw_length, "jaw_length");
    GC_POS(p->diameter, "diameter");
    GC_POS(p->stiffness_limit, "stiffness_limit");
#undef GC_POS
    if (!(isfinite(p->spring_k) && p->spring_k >= 0.0)) { *message = "spring_k must be >= 0"; return -3; }
    if (!(isfinite(p->damping) && p->damping >= 0.0)) { *message = "damping must be >= 0"; return -3; }
    if (!(isfinite(p->tissue_scale) && p->tissue_scale > 0.0)) {
        *message = "tissue_scale must be finite and > 0"; return -3;
    }
    if (!(isfinite(p->friction_vthr) && p->friction_vthr > 0.0)) {
        *message = "friction_velocity_threshold must be finite and > 0"; return -3;
    }
#define GC_NONNEG(x, name) if (!(isfinite(x) && (x) >= 0.0)) { *message = name " must be >= 0"; return -3; }
    GC_NONNEG(p->jaw_compliance, "jaw_compliance");
    GC_NONNEG(p->backlash_deg, "backlash");
    GC_NONNEG(p->friction_coulomb, "friction_coulomb");
    GC_NONNEG(p->friction_load, "friction_load_coefficient");
    GC_NONNEG(p->friction_viscous, "friction_viscous");
    for (i = 0; i < GC_PRONY_MAX; ++i) {
        GC_NONNEG(p->prony_g[i], "prony_g");
        if (!(isfinite(p->prony_tau[i]) && p->prony_tau[i] > 0.0)) {
            *message = "prony_tau must be finite and > 0"; return -3;
        }
    }
#undef GC_NONNEG
    if (p->rendering != GC_RENDER_COUPLING && p->rendering != GC_RENDER_CLIPPED) {
        *message = "rendering must be 0 (coupling) or 1 (clipped)"; return -6;
    }
#if GC_FIELD_N == 0
    if (p->rendering == GC_RENDER_CLIPPED) {
        *message = "rendering 1 (clipped) needs the field table, which this build leaves out "
                   "(GC_FIELD_N = 0, the default on the AVR): use rendering 0 (coupling)";
        return -6;
    }
#endif
    if (p->passivity_observer != 0 && p->passivity_observer != 1) {
        *message = "passivity_observer must be 0 or 1"; return -7;
    }
    if (!(isfinite(p->observer_stiffness_factor) && p->observer_stiffness_factor >= 1.0)) {
        *message = "observer_stiffness_factor must be finite and >= 1"; return -7;
    }
    if (!(isfinite(p->observer_max_damping) && p->observer_max_damping > 0.0)) {
        *message = "observer_max_damping must be finite and > 0"; return -7;
    }
    if (p->observer_delay < 0 || p->observer_delay > GC_OBS_DELAY_MAX) {
        *message = "observer_delay must be 0 .. 4 samples"; return -7;
    }
    if (p->passivity_observer && p->rendering != GC_RENDER_CLIPPED) {
        *message = "passivity_observer needs rendering 1 (clipped)"; return -7;
    }
    if (!(isfinite(p->encoder_counts) && p->encoder_counts >= 0.0)) {
        *message = "encoder_counts must be >= 0"; return -3;
    }
    if (!(p->velocity_cutoff < 0.5 / p->sample_time)) {
        *message = "velocity_cutoff must be below the Nyquist frequency"; return -4;
    }
    if (!isfinite(t)) { *message = "thickness must be finite"; return -5; }
    m = &materials[p->material];
    lo = GC_RD(&GC_PTR(m->thickness)[0]);
    hi = GC_RD(&GC_PTR(m->thickness)[GC_RDI(&m->n_curves) - 1]);
    if (t < lo) { *thickness_clamped = lo; *clamped = 1; }
    if (t > hi) { *thickness_clamped = hi; *clamped = 1; }
    *message = *clamped ? "thickness clamped into the tabulated range" : "ok";
    return 0;
}

void gc_init(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c) {
    int i;
    s->prev = 0.0;
    s->has_prev = 0;
    s->v = 0.0;
    s->gp = INFINITY;
    s->a = exp(-2.0 * M_PI * p->velocity_cutoff * p->sample_time);
    s->q = p->encoder_counts > 0.0 ? 2.0 * M_PI * p->pulley_radius / (p->encoder_counts * c->L3)
                                   : 0.0;
    s->area = p->jaw_length * (0.5 * M_PI * (p->diameter - p->thickness));
    s->b_mat = 0;
    s->b_t = NAN;
    s->play = 0.0;
    s->has_play = 0;
    s->sdir = 0.0;
    s->fg_prev = 0.0;
    for (i = 0; i < GC_PRONY_MAX; ++i) {
        s->h[i] = 0.0;
        s->pa[i] = exp(-p->sample_time / p->prony_tau[i]);
    }
    s->hb = 0.5 * (p->backlash_deg * DEG_TO_RAD);
    s->prony_on = 0;
    for (i = 0; i < GC_PRONY_MAX; ++i) s->prony_on |= p->prony_g[i] != 0.0;
    s->f_mat = 0;
    s->f_t = NAN;
    s->f_th_lo = c->theta_lo;
    s->f_dth = 0.0;
    s->f_kg = 0.0;
    s->po_w = 0.0;
    s->po_theta = 0.0;
    s->po_has = 0;
    s->po_fs_prev = 0.0;
    for (i = 0; i <= GC_OBS_DELAY_MAX; ++i) {
        s->po_fh[i] = 0.0;
        s->po_pc[i] = 0.0;
    }
    s->po_alpha = 0.0;
}

/* ---------------------------------------------------------------- the step */

/* tissue force and stiffness at a gap, scaled (grasprom.control.ImpedanceController._tissue) */
static void tissue(gc_state_t *s, const gc_params_t *p, double gap, double *f, double *k) {
    surrogate_fast(s, gap, f, k);
    if (p->tissue_scale != 1.0) {
        *f = *f * p->tissue_scale;
        *k = *k * p->tissue_scale;
    }
}

/* ---------------------------------------------------------------- the clipped field */
#if GC_FIELD_N > 0
/* tissue force (N, scaled) at a gap (mm): the field's `tissue` callable */
static double field_tissue(gc_state_t *s, const gc_params_t *p, double gap) {
    double f, k;
    tissue(s, p, gap, &f, &k);
    return f;
}

/* grasprom.control.field.compliant_force_N: F = tissue(gap + C F) by bisection */
static double compliant_force(gc_state_t *s, const gc_params_t *p, double gap, double C) {
    double f0 = field_tissue(s, p, gap), lo, hi, mid;
    int i;
    if (C == 0.0 || f0 <= 0.0) return f0;
    lo = 0.0;
    hi = f0;
    for (i = 0; i < GC_COMPLIANCE_BISECTIONS; ++i) {
        mid = 0.5 * (lo + hi);
        if (mid - field_tissue(s, p, gap + C * mid) > 0.0) hi = mid;
        else lo = mid;
    }
    return 0.5 * (lo + hi);
}

/* the static handle force of node j: Fi_s = F_t a + S, with a = g'/L3 and S the spring's */
static void field_node(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c, int j,
                       double *fis, double *a, double *sp) {
    double th_deg, g, g1, u, du, ft;
    th_deg = j < GC_FIELD_N - 1 ? (s->f_th_lo + (double)j * s->f_dth) * RAD_TO_DEG
                                : c->theta_hi_deg;
    gc_chain_state(c, th_deg, &g, &g1, &u, &du);
    ft = compliant_force(s, p, g, p->jaw_compliance);
    *a = g1 / c->L3;
    *sp = 0.0;
    if (p->render_spring) {
        double fs = c->spring_preload + p->spring_k * u;
        *sp = -fs * du / c->L3;
    }
    *fis = ft * *a + *sp;
}
#endif

/* grasprom.control.field.build_field.  The slope-limited track runs from the open end, so one
 * backward pass computes each node's static force and its track (same values as Python's
 * separate passes: every node value is a function of the node alone). */
void gc_build_field(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c,
                    const gc_material_t *m) {
#if GC_FIELD_N > 0
    double sum_g = 0.0, lim, fis, a, sp, fir, next = 0.0, klim = p->stiffness_limit;
    int i, j;
    if (p->rendering != GC_RENDER_CLIPPED) return;
    if (p->passivity_observer) klim = p->stiffness_limit * p->observer_stiffness_factor;
    if (s->b_mat != m || !(s->b_t == p->thickness)) blend_prepare(s, m, p->thickness);
    /* prony_factor = 1.0 + sum(prony_g): Python's sum, left to right from 0 (the padded
     * g = 0 terms add exactly 0) */
    for (i = 0; i < GC_PRONY_MAX; ++i) sum_g += p->prony_g[i];
    s->f_th_lo = c->theta_lo;
    s->f_dth = (c->theta_hi - c->theta_lo) / (double)(GC_FIELD_N - 1);
    s->f_kg = klim / (c->L3 * 1e-3) / (1.0 + sum_g);
    lim = s->f_kg * s->f_dth;
    for (j = GC_FIELD_N - 1; j >= 0; --j) {
        field_node(s, p, c, j, &fis, &a, &sp);
        fir = fis;
        if (j < GC_FIELD_N - 1) {
            double lo = next - lim, hi = next + lim;
            if (fir < lo) fir = lo;
            else if (fir > hi) fir = hi;
        }
        next = fir;
        {
            double fr = (fir - sp) / a; /* the jaws cannot pull: >= 0 */
            s->f_force[j] = fr > 0.0 ? fr : 0.0;
        }
        s->f_clipped[j] = fir != fis;
    }
    s->f_mat = m;
    s->f_t = p->thickness;
#else
    (void)s; (void)p; (void)c; (void)m;
#endif
}

#if GC_FIELD_N > 0
/* Field.jaw_force_N: linear interpolation at the chain angle th (rad); *active: the interval
 * is clipped (either node) */
static double field_force(const gc_state_t *s, double th, int *active) {
    double u = (th - s->f_th_lo) / s->f_dth, fj = floor(u), w, f0;
    int j = fj < 0.0 ? 0 : fj > (double)(GC_FIELD_N - 2) ? GC_FIELD_N - 2 : (int)fj;
    w = u - (double)j;
    f0 = s->f_force[j];
    *active = s->f_clipped[j] || s->f_clipped[j + 1];
    return f0 + w * (s->f_force[j + 1] - f0);
}
#endif

/* Passivity observer / controller (ImpedanceController._observe): the damping to add, N m s/rad.
 * th encoder angle (rad), v velocity of the damping (rad/s), fstat static handle force (N). */
static double observe(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c, double th,
                      double v, double fstat, double *pc_new) {
    int d = p->observer_delay, i;
    double fsm, pending = 0.0, we, alpha = 0.0;
    if (!s->po_has) {
        s->po_theta = th;
        s->po_fs_prev = fstat;
        s->po_has = 1;
    }
    fsm = 0.5 * (s->po_fs_prev + fstat);
    s->po_w = s->po_w + (s->po_fh[d] - fsm) * (c->L3 * 1e-3) * (th - s->po_theta);
    s->po_theta = th;
    s->po_fs_prev = fstat;
    for (i = 0; i < d; ++i) pending += s->po_pc[i];
    we = s->po_w - pending;
    *pc_new = 0.0;
    if (we > 0.0 && v != 0.0) {
        double amax = p->observer_max_damping, tv = p->sample_time * (v * v);
        alpha = we >= amax * tv ? amax : we / tv;
        *pc_new = alpha * tv;
    }
    s->po_alpha = alpha;
    return alpha;
}

/* remember the step's saturated handle force fh (N) and planned dissipation (J) */
static void observer_push(gc_state_t *s, const gc_params_t *p, double fh, double pc_new) {
    int i;
    for (i = p->observer_delay; i > 0; --i) {
        s->po_fh[i] = s->po_fh[i - 1];
        s->po_pc[i] = s->po_pc[i - 1];
    }
    s->po_fh[0] = fh;
    s->po_pc[0] = pc_new;
}

/* the step; use_ext: damp the external velocity ext_v (rad/s) instead of the filtered estimate */
static void step_impl(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c,
                      const gc_material_t *m, double theta, int use_ext, double ext_v,
                      gc_output_t *o) {
    double th = theta, v_raw, th_deg, thc, thc_deg, g, g1, u, du, fs, f_g, k_g, kc, gp, fg, hi;
    double fgr, fi, fi_spring, fi_fric = 0.0, v_damp, r_m, torque, lim, fstat, pc_new = 0.0;
    int clamped = 0, contact, active = 0, i;

    if (isnan(th)) {
        th = s->has_prev ? s->prev : c->theta_hi;
        clamped = 1;
    } else if (isinf(th)) {
        th = th > 0 ? c->theta_hi : c->theta_lo;
        clamped = 1;
    } else {
        clamped = !(c->theta_lo <= th && th <= c->theta_hi);
        if (s->q > 0.0) th = s->q * floor(th / s->q + 0.5);
    }
    if (th < c->theta_lo) th = c->theta_lo;
    if (th > c->theta_hi) th = c->theta_hi;
    if (!s->has_prev) { s->prev = th; s->has_prev = 1; }
    v_raw = (th - s->prev) / p->sample_time;
    s->prev = th;
    s->v = s->a * s->v + (1.0 - s->a) * v_raw;
    th_deg = th * RAD_TO_DEG;

    /* backlash: the linkage follows the encoder through a play of width 2 hb */
    thc = th;
    if (s->hb > 0.0) {
        double y = s->has_play ? s->play : th;
        if (y < th - s->hb) y = th - s->hb;
        if (y > th + s->hb) y = th + s->hb;
        if (y < c->theta_lo) y = c->theta_lo;
        if (y > c->theta_hi) y = c->theta_hi;
        s->play = y;
        s->has_play = 1;
        thc = y;
    }
    thc_deg = thc * RAD_TO_DEG;

    gc_chain_state(c, thc_deg, &g, &g1, &u, &du);
    if (s->b_mat != m || !(s->b_t == p->thickness)) blend_prepare(s, m, p->thickness);
    tissue(s, p, g, &f_g, &k_g);
    contact = f_g > 0.0;
    kc = p->coupling_k;
    if (p->jaw_compliance != 0.0) kc = 1.0 / (1.0 / kc + p->jaw_compliance);
#if GC_FIELD_N > 0
    if (p->rendering == GC_RENDER_CLIPPED) {
        /* the stiffness-clipped field (built at initialisation; here only if it was not) */
        if (s->f_mat != m || !(s->f_t == p->thickness)) gc_build_field(s, p, c, m);
        fg = field_force(s, thc, &active);
        gp = g;
    } else
#endif
    if (contact) {
        double f_p, k_p, r;
        int n_iter = isinf(s->gp) ? GC_COLD_START_ITERATIONS : GC_NEWTON_ITERATIONS;
        hi = g + f_g / kc;
        gp = s->gp;
        if (gp < g) gp = g;
        if (gp > hi) gp = hi;
        for (i = 0; i < n_iter; ++i) {
            tissue(s, p, gp, &f_p, &k_p);
            r = kc * (gp - g) - f_p;
            gp = gp - r / (kc + k_p);
            if (gp < g) gp = g;
            if (gp > hi) gp = hi;
        }
        fg = kc * (gp - g);
        tissue(s, p, gp, &f_p, &k_p);
        active = k_p > kc;
    } else {
        gp = g;
        fg = 0.0;
    }
    s->gp = gp;

    /* viscoelastic (quasi-linear Prony) rendering of the jaw force; g = 0 terms add exactly 0,
     * so the loop is skipped when every g is 0 (parameters are fixed after gc_init) */
    fgr = fg;
    if (s->prony_on) {
        double d = fg - s->fg_prev, acc = 0.0;
        s->fg_prev = fg;
        for (i = 0; i < GC_PRONY_MAX; ++i) {
            s->h[i] = s->pa[i] * s->h[i] + d;
            acc += p->prony_g[i] * s->h[i];
        }
        fgr = fg + acc;
        if (fgr < 0.0) fgr = 0.0;
    }

    fs = c->spring_preload + p->spring_k * u;
    fi_spring = -fs * du / c->L3;
    fi = (fgr * g1 - fs * du) / c->L3;
    if (!p->render_spring) fi -= fi_spring;
    fstat = fi; /* static handle force: field or coupling, Prony terms, spring */
    v_damp = use_ext ? ext_v : s->v;
    if (p->friction_coulomb > 0.0 || p->friction_load > 0.0 || p->friction_viscous > 0.0) {
        double vf = -v_damp * c->L3, fit;
        if (vf > p->friction_vthr) s->sdir = 1.0;
        else if (vf < -p->friction_vthr) s->sdir = -1.0;
        fit = fgr * g1 / c->L3;
        fi_fric = (p->friction_coulomb + p->friction_load * fabs(fit)) * s->sdir
                  + p->friction_viscous * vf;
        fi += fi_fric;
    }
    fi -= p->damping * v_damp / (c->L3 * 1e-3);
    if (p->passivity_observer)
        fi -= observe(s, p, c, th, v_damp, fstat, &pc_new) * v_damp / (c->L3 * 1e-3);
    r_m = p->pulley_radius * 1e-3;
    torque = fi * r_m;
    lim = p->torque_limit;
    o->saturated = fabs(torque) > lim;
    if (o->saturated) torque = copysign(lim, torque);
    if (p->passivity_observer) observer_push(s, p, torque / r_m, pc_new);

    o->torque = torque;
    o->force_handle = torque / r_m;
    o->force_handle_spring = fi_spring;
    o->force_jaw = fgr;
    o->force_tissue = f_g;
    o->gap = g;
    o->proxy_gap = gp;
    o->theta_deg = th_deg;
    o->velocity = v_damp;
    o->contact = contact;
    o->tissue_warning = f_g >= p->force_warning || f_g / s->area >= p->pressure_warning;
    o->coupling_active = active;
    o->theta_clamped = clamped;
    o->theta_chain_deg = thc_deg;
    o->force_handle_friction = fi_fric;
}

void gc_step(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c, const gc_material_t *m,
             double theta, gc_output_t *o) {
    step_impl(s, p, c, m, theta, 0, 0.0, o);
}

void gc_step_ext(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c,
                 const gc_material_t *m, double theta, double theta_dot, gc_output_t *o) {
    step_impl(s, p, c, m, theta, 1, theta_dot, o);
}

#else /* GC_TABULATED */
/* ============================================================= tabulated (fixed or float) */
/*
 * Step, per sample (Python reference: grasprom.control.ImpedanceController.step):
 *  1. clamp the count into [GF_N_LO, GF_N_TOP] (flag GF_THETA_CLAMPED);
 *  2. velocity: w += (1 - a) (dn - w), dn the count difference, w in counts/sample Q16,
 *     (1 - a) = GF_VEL_B / 2^16 with a = exp(-2 pi fc T) (exact discretisation, as Python);
 *  3. static rendered jaw force of the export's rendering (virtual coupling or stiffness-clipped
 *     field): linear interpolation of the (thickness-blended)
 *     node values y[] on the material's dyadic grid x[] (segment widths 2^k counts, so the
 *     interpolation is a shift, no division); 0 from GF_N_CONTACT on (no contact);
 *  4. handle force by virtual work: Fi = Fg * a(theta) + b(theta), a = g'(theta) / L3 (Q15) and
 *     b = spring handle force (mN) on a uniform grid of 2^GF_CH_SHIFT counts;
 *  5. damping: Fi -= KD * w (GF_KD: mN per count/sample, Q GF_KD_SHIFT);
 *  6. saturation |Fi| <= GF_FI_LIMIT_MN (= torque limit / pulley radius), torque = Fi r;
 *  7. flags: contact (count < GF_N_CONTACT), tissue warning (count <= warn_count) and coupling
 *     active (count <= active_count; with the clipped rendering: stiffness limit active),
 *     thresholds blended over the thickness at gf_init().
 */
#define GF_PROGMEM GC_TABLE
#define GF_RD16(p) GC_RD16(p)
#define GF_RD8(p) GC_RD8(p)
#define GF_MEMCPY(d, s, n) GC_MEMCPY(d, s, n)

/* one material: dyadic grid, thickness nodes, node values per thickness, flag thresholds */
typedef struct {
    const uint16_t *x;      /* nx grid counts, ascending, x[0] = GF_N_LO */
    const uint8_t *k;       /* nx - 1 segment widths, log2 counts */
    const uint16_t *t;      /* nt thicknesses, um, ascending */
    const uint16_t *y;      /* nt rows of nx jaw forces, units of 2^GF_FG_SHIFT mN */
    const int16_t *warn;    /* nt tissue-warning thresholds, counts */
    const int16_t *active;  /* nt coupling-active (clipped: limit-active) thresholds, counts */
    uint8_t nx;
    uint8_t nt;
} gf_material_t;

#include "grasp_fixed_tables.h"

#define GF_RD16S(p) ((int16_t)GF_RD16((const uint16_t *)(p)))

/* floor(a * b / 2^16), exact; two 16 x 16 -> 32 bit multiplications (cheap on the AVR) */
static inline int32_t mulq16(int32_t a, uint16_t b) {
    int32_t hi = (int32_t)(int16_t)(a >> 16) * (int32_t)b;
    uint32_t lo = ((uint32_t)(uint16_t)a * (uint32_t)b) >> 16;
    return hi + (int32_t)lo;
}

/* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) of n bytes of a table, continued from crc;
 * four bits at a time (a 16-entry table: about 40 AVR cycles per byte) */
static const uint16_t GF_CRC_NIB[16] = {0x0000u, 0x1021u, 0x2042u, 0x3063u, 0x4084u, 0x50A5u,
                                        0x60C6u, 0x70E7u, 0x8108u, 0x9129u, 0xA14Au, 0xB16Bu,
                                        0xC18Cu, 0xD1ADu, 0xE1CEu, 0xF1EFu};

static uint16_t gf_crc_bytes(uint16_t crc, const uint8_t *p, uint16_t n) {
    while (n--) {
        uint8_t v = GF_RD8(p++);
        crc = (uint16_t)((crc << 4) ^ GF_CRC_NIB[(uint8_t)((crc >> 12) ^ (v >> 4))]);
        crc = (uint16_t)((crc << 4) ^ GF_CRC_NIB[(uint8_t)((crc >> 12) ^ (v & 0x0Fu))]);
    }
    return crc;
}

uint16_t gf_table_crc(void) {
    uint16_t crc = 0xFFFFu;
    uint8_t i;
    gf_material_t m;
    crc = gf_crc_bytes(crc, (const uint8_t *)gf_ch_a, (uint16_t)sizeof gf_ch_a);
    crc = gf_crc_bytes(crc, (const uint8_t *)gf_ch_b, (uint16_t)sizeof gf_ch_b);
    for (i = 0; i < GF_N_MATERIALS; ++i) {
        GF_MEMCPY(&m, &gf_materials[i], sizeof m);
        if (m.nt == 0) continue; /* a material not in this export: no tables */
        crc = gf_crc_bytes(crc, (const uint8_t *)m.x, (uint16_t)(2u * m.nx));
        crc = gf_crc_bytes(crc, m.k, (uint16_t)(m.nx - 1u));
        crc = gf_crc_bytes(crc, (const uint8_t *)m.t, (uint16_t)(2u * m.nt));
        crc = gf_crc_bytes(crc, (const uint8_t *)m.y, (uint16_t)(2u * m.nt * m.nx));
        crc = gf_crc_bytes(crc, (const uint8_t *)m.warn, (uint16_t)(2u * m.nt));
        crc = gf_crc_bytes(crc, (const uint8_t *)m.active, (uint16_t)(2u * m.nt));
    }
    return crc;
}

int8_t gf_init(gf_state_t *s, uint8_t material, uint16_t thickness_um) {
    gf_material_t m;
    uint8_t j = 0, i;
    int8_t rc = 0;
    int32_t w14 = 0;
    uint16_t t = thickness_um, t0, t1;
    if (material >= GF_N_MATERIALS) return -1;
    GF_MEMCPY(&m, &gf_materials[material], sizeof m);
    if (m.nt == 0) return -1; /* not in this export's tables */
    t0 = GF_RD16(&m.t[0]);
    t1 = GF_RD16(&m.t[m.nt - 1]);
    if (t < t0) { t = t0; rc |= GF_THICKNESS_CLAMPED; }
    if (t > t1) { t = t1; rc |= GF_THICKNESS_CLAMPED; }
    if (m.nt > 1) {
        while (j < m.nt - 2 && GF_RD16(&m.t[j + 1]) <= t) ++j;
        t0 = GF_RD16(&m.t[j]);
        t1 = GF_RD16(&m.t[j + 1]);
        w14 = (int32_t)((((uint32_t)(t - t0)) << 14) / (uint32_t)(t1 - t0));
    }
    s->material = material;
    s->thickness_um = t;
    s->nx = m.nx;
    s->x = m.x;
    s->k = m.k;
    for (i = 0; i < m.nx; ++i) {
        int32_t ya = GF_RD16(&m.y[(uint16_t)j * m.nx + i]);
        int32_t yb = m.nt > 1 ? (int32_t)GF_RD16(&m.y[(uint16_t)(j + 1) * m.nx + i]) : ya;
        s->y[i] = (uint16_t)(ya + (((yb - ya) * w14 + 8192) >> 14));
    }
    {
        int32_t wa = GF_RD16S(&m.warn[j]), aa = GF_RD16S(&m.active[j]);
        int32_t wb = m.nt > 1 ? GF_RD16S(&m.warn[j + 1]) : wa;
        int32_t ab = m.nt > 1 ? GF_RD16S(&m.active[j + 1]) : aa;
        s->warn_count = (int16_t)(wa + (((wb - wa) * w14 + 8192) >> 14));
        s->active_count = (int16_t)(aa + (((ab - aa) * w14 + 8192) >> 14));
    }
    s->w = 0;
    s->prev = 0;
    s->has_prev = 0;
#if GF_BACKLASH_HB > 0
    s->play = 0;
    s->has_play = 0;
#endif
#if GF_FRICTION
    s->sdir = 0;
#endif
#if GF_N_PRONY > 0
    s->fg_prev = 0;
    for (i = 0; i < GF_N_PRONY; ++i) s->h[i] = 0;
#endif
    return rc;
}

/* index of the segment [x[i], x[i+1]) holding n (x[0] <= n < x[nx-1]) */
static uint8_t gf_segment(const gf_state_t *s, int16_t n) {
    uint8_t lo = 0, hi = (uint8_t)(s->nx - 1);
    while ((uint8_t)(hi - lo) > 1) {
        uint8_t mid = (uint8_t)((lo + hi) >> 1);
        if (n < (int16_t)GF_RD16(&s->x[mid])) hi = mid; else lo = mid;
    }
    return lo;
}

void gf_step(gf_state_t *s, int16_t count, gf_output_t *o) {
    uint8_t flags = 0, ci;
    int16_t n = count, nc, cm;
    int32_t pos, dp;
    uint16_t cf;
#ifdef GF_FLOAT
    float fg = 0.0f, fi, fa, fb, v;
#else
    int32_t fg = 0, fi, fa, fb;
#endif

    /* position for the velocity, counts Q8: a clamped angle sits at the end stop itself, which
     * lies between two counts (as in the reference: theta clamped into [theta_lo, theta_hi]) */
    pos = (int32_t)n << 8;
    if (n < GF_N_LO) {
        n = GF_N_LO;
        pos = ((int32_t)GF_N_LO << 8) - GF_LO_FRAC_Q8;
        flags |= GF_THETA_CLAMPED;
    } else if (n > GF_N_TOP) {
        n = GF_N_TOP;
        pos = ((int32_t)GF_N_TOP << 8) + GF_TOP_FRAC_Q8;
        flags |= GF_THETA_CLAMPED;
    }
    if (!s->has_prev) { s->prev = pos; s->has_prev = 1; }
    dp = pos - s->prev;
    s->prev = pos;
    s->w += mulq16((dp << 8) - s->w, GF_VEL_B);

    nc = n; /* the linkage's count: behind the backlash, if rendered */
#if GF_BACKLASH_HB > 0
    {
        int16_t y = s->has_play ? s->play : n;
        if (y < n - GF_BACKLASH_HB) y = n - GF_BACKLASH_HB;
        if (y > n + GF_BACKLASH_HB) y = n + GF_BACKLASH_HB;
        if (y < GF_N_LO) y = GF_N_LO;
        if (y > GF_N_TOP) y = GF_N_TOP;
        s->play = y;
        s->has_play = 1;
        nc = y;
    }
#endif

    if (nc < GF_N_CONTACT) {
        uint8_t i = gf_segment(s, nc);
        int16_t x0 = (int16_t)GF_RD16(&s->x[i]);
        uint8_t k = GF_RD8(&s->k[i]);
        int32_t y0 = s->y[i], dy = (int32_t)s->y[i + 1] - y0;
        flags |= GF_CONTACT;
#ifdef GF_FLOAT
        fg = ldexpf((float)y0 + ldexpf((float)dy * (float)(nc - x0), -(int)k), GF_FG_SHIFT);
#else
        /* y0 + floor(dy (nc - x0) / 2^k) as a 16 x 16 bit product and a 16-bit shift (k >= 1) */
        fg = y0 + (((int32_t)(int16_t)dy * (int32_t)(uint16_t)((uint16_t)(nc - x0) << (16 - k)))
                   >> 16); /* units of 2^GF_FG_SHIFT mN */
#endif
        if (nc <= s->warn_count) flags |= GF_TISSUE_WARNING;
        if (nc <= s->active_count) flags |= GF_COUPLING_ACTIVE;
    }

    cm = nc - GF_N_LO;
    ci = (uint8_t)(cm >> GF_CH_SHIFT);
    cf = (uint16_t)(cm & ((1 << GF_CH_SHIFT) - 1));
    {
        int32_t a0 = GF_RD16(&gf_ch_a[ci]), a1 = GF_RD16(&gf_ch_a[ci + 1]);
        int32_t b0 = GF_RD16S(&gf_ch_b[ci]), b1 = GF_RD16S(&gf_ch_b[ci + 1]);
#ifdef GF_FLOAT
        fa = ldexpf((float)a0 + ldexpf((float)(a1 - a0) * (float)cf, -GF_CH_SHIFT), -15);
        fb = (float)b0 + ldexpf((float)(b1 - b0) * (float)cf, -GF_CH_SHIFT);
#else
        uint16_t cf16 = (uint16_t)(cf << (16 - GF_CH_SHIFT));
        fa = a0 + (((int32_t)(int16_t)(a1 - a0) * (int32_t)cf16) >> 16); /* Q15 */
        fb = b0 + (((int32_t)(int16_t)(b1 - b0) * (int32_t)cf16) >> 16); /* mN */
#endif
    }

#ifdef GF_FLOAT
    v = ldexpf((float)s->w, -16);
    fi = fg * fa;
    if (GF_RENDER_SPRING) fi += fb;
    if (GF_KD != 0) fi -= ldexpf((float)GF_KD, -GF_KD_SHIFT) * v;
    if (fi > (float)GF_FI_LIMIT_MN) { fi = (float)GF_FI_LIMIT_MN; flags |= GF_SATURATED; }
    else if (fi < -(float)GF_FI_LIMIT_MN) { fi = -(float)GF_FI_LIMIT_MN; flags |= GF_SATURATED; }
    o->force_handle_mN = (int32_t)(fi >= 0.0f ? fi + 0.5f : fi - 0.5f);
    o->torque_uNm = (int32_t)(fi * (float)GF_R_Q8 / 256.0f);
    o->force_jaw_mN = (int32_t)(fg + 0.5f);
#else
#if GF_N_PRONY > 0
    {
        /* quasi-linear viscoelastic rendering: h_i <- a_i h_i + dFg, Fg_r = Fg + sum g_i h_i */
        int32_t fgm = fg << GF_FG_SHIFT, acc = 0; /* mN */
        int16_t d;
        {
            int32_t d32 = fgm - s->fg_prev;
            if (d32 > 32767) d32 = 32767; /* one step changes the jaw force by far less */
            if (d32 < -32767) d32 = -32767;
            d = (int16_t)d32;
        }
        s->fg_prev = fgm;
        /* y_i = g_i h_i (mN Q8): y_i <- y_i - b_i y_i + g_i d, b_i = 1 - exp(-T / tau_i); the
         * terms are unrolled with their constants (GF_PRONY_B_i Q16, GF_PRONY_G_i Q11) */
#define GF_PRONY_TERM(i)                                                                  \
        s->h[i] += (((int32_t)d * (int16_t)GF_PRONY_G_##i) >> 3) - mulq16(s->h[i], GF_PRONY_B_##i); \
        acc += s->h[i];
        GF_PRONY_TERM(0)
#if GF_N_PRONY > 1
        GF_PRONY_TERM(1)
#endif
#if GF_N_PRONY > 2
        GF_PRONY_TERM(2)
#endif
#if GF_N_PRONY > 3
        GF_PRONY_TERM(3)
#endif
#undef GF_PRONY_TERM
        fgm += acc >> 8;
        if (fgm < 0) fgm = 0;
        {
            /* (Fg_r mN x a Q15) >> 15 as one 16 x 16 bit product and byte shifts */
            uint16_t f16 = (uint16_t)fgm, a16 = (uint16_t)fa;
            uint32_t pr = (uint32_t)f16 * a16;
            fi = (int32_t)(((pr >> 16) << 1) | ((uint16_t)pr >> 15));
        }
        fg = fgm; /* reported in mN below */
    }
#else
    fi = (int32_t)(((uint32_t)(uint16_t)fg * (uint32_t)(uint16_t)fa) >> (15 - GF_FG_SHIFT));
#endif
#if GF_FRICTION
    {
        /* Coulomb + load-proportional friction at the finger in the direction of the last
         * motion faster than the threshold (closing: counts decrease, w < 0) */
        int32_t ff = GF_FRIC_C_MN + (mulq16(fi, GF_FRIC_MU_Q14) << 2); /* mu |Fi_t|, Q14 */
        if (s->w < -GF_FRIC_THR_Q16) s->sdir = 1;
        else if (s->w > GF_FRIC_THR_Q16) s->sdir = -1;
        if (s->sdir > 0) fi += ff;
        else if (s->sdir < 0) fi -= ff;
    }
#endif
    if (GF_RENDER_SPRING) fi += fb;
    if (GF_KD != 0) fi -= mulq16(s->w, GF_KD) >> GF_KD_SHIFT;
    if (fi > GF_FI_LIMIT_MN) { fi = GF_FI_LIMIT_MN; flags |= GF_SATURATED; }
    else if (fi < -GF_FI_LIMIT_MN) { fi = -GF_FI_LIMIT_MN; flags |= GF_SATURATED; }
    o->force_handle_mN = fi;
    o->torque_uNm = (fi * GF_R_Q8) >> 8;
#if GF_N_PRONY > 0
    o->force_jaw_mN = fg;
#else
    o->force_jaw_mN = fg << GF_FG_SHIFT;
#endif
#endif
    o->velocity_q16 = s->w;
    o->count = n;
    o->flags = flags;
}
#endif /* GC_TABULATED */
