/*
 * grasp_core.c: the controller step of grasprom in C (see grasp_core.h).
 * Mirrors grasprom/controller.py, grasprom/kinematics.py and the scalar path of
 * grasprom/surrogate.py operation by operation, so that results agree to rounding.
 */
#include "grasp_core.h"

#include <math.h>

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
        if (v < x[mid]) hi = mid; else lo = mid + 1;
    }
    return lo - 1;
}

/* force (N) and dF/dgap (N/mm) of one curve; returns 1 below the first node (extrapolated).
 * *hint: last interval used (or -1); checked first, so slowly moving gaps skip the bisection
 * (the interval found is the same either way). */
static int curve_eval_hint(const gc_curve_t *c, double x, double *f, double *dfdg, int *hint) {
    double x0 = c->x[0], xn = c->x[c->n - 1];
    int last = c->n - 2;
    int k;
    double h, a1, a2, a3, v;
    if (x >= xn) { *f = 0.0; *dfdg = 0.0; return 0; }
    if (x < x0) {
        v = c->c0[0] + c->c1[0] * (x - x0);
        *f = v > 0.0 ? v : 0.0;
        *dfdg = c->c1[0];
        return 1;
    }
    k = *hint;
    if (!(k >= 0 && k <= last && c->x[k] <= x && x < c->x[k + 1])) {
        k = bisect(c->x, c->n, x);
        if (k > last) k = last;
        *hint = k;
    }
    h = x - c->x[k];
    a1 = c->c1[k]; a2 = c->c2[k]; a3 = c->c3[k];
    v = ((a3 * h + a2) * h + a1) * h + c->c0[k];
    *f = v > 0.0 ? v : 0.0;
    *dfdg = (3.0 * a3 * h + 2.0 * a2) * h + a1;
    return 0;
}

static int curve_eval(const gc_curve_t *c, double x, double *f, double *dfdg) {
    int hint = -1;
    return curve_eval_hint(c, x, f, dfdg, &hint);
}

int gc_surrogate(const gc_material_t *m, double gap, double t, double *force, double *stiffness) {
    int n = m->n_curves, i, ba, bb;
    double w, v, fa, fb, da, db, dfdg;
    if (n == 1) {
        ba = curve_eval(&m->curves[0], gap, force, &dfdg);
        *stiffness = -dfdg;
        return ba;
    }
    i = bisect(m->thickness, n, t);
    if (i < 0) i = 0; else if (i > n - 2) i = n - 2;
    w = (t - m->thickness[i]) * m->inv_dt[i];
    if (w < 0.0) w = 0.0; else if (w > 1.0) w = 1.0;
    v = 1.0 - w;
    if (m->aligned) {
        double D = m->diameter, gca = m->contact_gap[i], gcb = m->contact_gap[i + 1];
        double dgc = gca - gcb, gct = gca - w * dgc, idn = 1.0 / (D - gct);
        double r = (D - gap) * idn * dgc;
        ba = curve_eval(&m->curves[i], gap + w * r, &fa, &da);
        bb = curve_eval(&m->curves[i + 1], gap - v * r, &fb, &db);
        dfdg = v * (da * ((D - gca) * idn)) + w * (db * ((D - gcb) * idn));
    } else {
        ba = curve_eval(&m->curves[i], gap, &fa, &da);
        bb = curve_eval(&m->curves[i + 1], gap, &fb, &db);
        dfdg = v * da + w * db;
    }
    *force = v * fa + w * fb;
    *stiffness = -dfdg;
    return (ba && v > 0.0) || (bb && w > 0.0);
}

/* thickness blend of the step's material and thickness, computed once (same arithmetic as
 * gc_surrogate, so the results are identical) */
static void blend_prepare(gc_state_t *s, const gc_material_t *m, double t) {
    int n = m->n_curves, i;
    double w;
    s->b_mat = m;
    s->b_t = t;
    s->hint[0] = s->hint[1] = -1;
    if (n == 1) { s->b_i = 0; s->b_w = 0.0; s->b_v = 1.0; return; }
    i = bisect(m->thickness, n, t);
    if (i < 0) i = 0; else if (i > n - 2) i = n - 2;
    w = (t - m->thickness[i]) * m->inv_dt[i];
    if (w < 0.0) w = 0.0; else if (w > 1.0) w = 1.0;
    s->b_i = i;
    s->b_w = w;
    s->b_v = 1.0 - w;
    if (m->aligned) {
        double D = m->diameter, gca = m->contact_gap[i], gcb = m->contact_gap[i + 1];
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
    if (m->n_curves == 1) {
        ba = curve_eval_hint(&m->curves[0], gap, force, &dfdg, &s->hint[0]);
        *stiffness = -dfdg;
        return ba;
    }
    if (m->aligned) {
        double r = (m->diameter - gap) * s->b_idn * s->b_dgc;
        ba = curve_eval_hint(&m->curves[i], gap + w * r, &fa, &da, &s->hint[0]);
        bb = curve_eval_hint(&m->curves[i + 1], gap - v * r, &fb, &db, &s->hint[1]);
        dfdg = v * (da * s->b_sa) + w * (db * s->b_sb);
    } else {
        ba = curve_eval_hint(&m->curves[i], gap, &fa, &da, &s->hint[0]);
        bb = curve_eval_hint(&m->curves[i + 1], gap, &fb, &db, &s->hint[1]);
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
    *clamped = 0;
    *thickness_clamped = t;
    if (p->material < 0 || p->material >= n_materials) {
        *message = "material must be 0 (mr), 1 (nh) or 2 (le)";
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
#undef GC_POS
    if (!(isfinite(p->spring_k) && p->spring_k >= 0.0)) { *message = "spring_k must be >= 0"; return -3; }
    if (!(isfinite(p->damping) && p->damping >= 0.0)) { *message = "damping must be >= 0"; return -3; }
    if (!(isfinite(p->encoder_counts) && p->encoder_counts >= 0.0)) {
        *message = "encoder_counts must be >= 0"; return -3;
    }
    if (!(p->velocity_cutoff < 0.5 / p->sample_time)) {
        *message = "velocity_cutoff must be below the Nyquist frequency"; return -4;
    }
    if (!isfinite(t)) { *message = "thickness must be finite"; return -5; }
    m = &materials[p->material];
    lo = m->thickness[0];
    hi = m->thickness[m->n_curves - 1];
    if (t < lo) { *thickness_clamped = lo; *clamped = 1; }
    if (t > hi) { *thickness_clamped = hi; *clamped = 1; }
    *message = *clamped ? "thickness clamped into the tabulated range" : "ok";
    return 0;
}

void gc_init(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c) {
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
}

/* ---------------------------------------------------------------- the step */

/* the step; use_ext: damp the external velocity ext_v (rad/s) instead of the filtered estimate */
static void step_impl(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c,
                      const gc_material_t *m, double theta, int use_ext, double ext_v,
                      gc_output_t *o) {
    double th = theta, v_raw, th_deg, g, g1, u, du, fs, f_g, k_g, kc, gp, fg, hi;
    double fi, fi_spring, r_m, torque, lim;
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

    gc_chain_state(c, th_deg, &g, &g1, &u, &du);
    if (s->b_mat != m || !(s->b_t == p->thickness)) blend_prepare(s, m, p->thickness);
    surrogate_fast(s, g, &f_g, &k_g);
    contact = f_g > 0.0;
    kc = p->coupling_k;
    if (contact) {
        double f_p, k_p, r;
        int n_iter = isinf(s->gp) ? GC_COLD_START_ITERATIONS : GC_NEWTON_ITERATIONS;
        hi = g + f_g / kc;
        gp = s->gp;
        if (gp < g) gp = g;
        if (gp > hi) gp = hi;
        for (i = 0; i < n_iter; ++i) {
            surrogate_fast(s, gp, &f_p, &k_p);
            r = kc * (gp - g) - f_p;
            gp = gp - r / (kc + k_p);
            if (gp < g) gp = g;
            if (gp > hi) gp = hi;
        }
        fg = kc * (gp - g);
        surrogate_fast(s, gp, &f_p, &k_p);
        active = k_p > kc;
    } else {
        gp = g;
        fg = 0.0;
    }
    s->gp = gp;

    fs = c->spring_preload + p->spring_k * u;
    fi_spring = -fs * du / c->L3;
    fi = (fg * g1 - fs * du) / c->L3;
    if (!p->render_spring) fi -= fi_spring;
    fi -= p->damping * (use_ext ? ext_v : s->v) / (c->L3 * 1e-3);
    r_m = p->pulley_radius * 1e-3;
    torque = fi * r_m;
    lim = p->torque_limit;
    o->saturated = fabs(torque) > lim;
    if (o->saturated) torque = copysign(lim, torque);

    o->torque = torque;
    o->force_handle = torque / r_m;
    o->force_handle_spring = fi_spring;
    o->force_jaw = fg;
    o->force_tissue = f_g;
    o->gap = g;
    o->proxy_gap = gp;
    o->theta_deg = th_deg;
    o->velocity = use_ext ? ext_v : s->v;
    o->contact = contact;
    o->tissue_warning = f_g >= p->force_warning || f_g / s->area >= p->pressure_warning;
    o->coupling_active = active;
    o->theta_clamped = clamped;
}

void gc_step(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c, const gc_material_t *m,
             double theta, gc_output_t *o) {
    step_impl(s, p, c, m, theta, 0, 0.0, o);
}

void gc_step_ext(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c,
                 const gc_material_t *m, double theta, double theta_dot, gc_output_t *o) {
    step_impl(s, p, c, m, theta, 1, theta_dot, o);
}
