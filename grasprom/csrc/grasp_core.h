/*
 * grasp_core: one step of the grasprom open-loop impedance controller, in C.
 *
 * Shared by the FMU (FMI 2 / FMI 3 co-simulation) and the Arduino export; the Python
 * reference is grasprom.controller.ImpedanceController.  Tables (surrogate curves) and chain
 * constants are generated from the Python objects into "grasp_tables.h" by
 * grasprom.ccore.write_tables_header(); nothing is copied by hand.
 *
 * Units: lengths mm, forces N, torque N m, angles rad (the handle angle theta decreases when
 * closing), time s.  No dynamic memory; gc_step() allocates nothing.
 */
#ifndef GRASP_CORE_H
#define GRASP_CORE_H

#ifdef __cplusplus
extern "C" {
#endif

/* One surrogate curve (one wall thickness): monotone cubic Hermite pieces on ascending gap
 * nodes x[0..n-1]; piece k (k < n-1) is c0 + c1 h + c2 h^2 + c3 h^3 with h = gap - x[k]. */
typedef struct {
    int n;             /* number of nodes */
    const double *x;   /* nodes, mm, ascending (x[n-1] = first touch) */
    const double *c0;  /* n-1 coefficients each */
    const double *c1;
    const double *c2;
    const double *c3;
} gc_curve_t;

/* All curves of one material, ascending thickness; aligned blending across thickness. */
typedef struct {
    int n_curves;
    const double *thickness;  /* mm */
    const double *contact_gap;/* wall-contact gap g_c of each curve, mm */
    const double *inv_dt;     /* 1 / (t[i+1] - t[i]), 1/mm (n_curves - 1 entries, >= 1) */
    const gc_curve_t *curves;
    double diameter;          /* first-touch gap D, mm */
    int aligned;              /* 1: blend in u = (gap - g_c)/(D - g_c); 0: at equal gap */
} gc_material_t;

/* Kinematic chain constants (see grasprom.kinematics.ChainParams). */
typedef struct {
    double L2, d, h, side, L3;     /* mm, side = -1 behind / +1 beyond */
    double gap_closed, gap_per_xc; /* mm, 1 */
    double xc_closed, xc_open;     /* mm */
    double stroke_sign;            /* +-1 */
    double spring_preload;         /* N */
    double theta_lo, theta_hi;     /* rad */
    double theta_lo_deg, theta_hi_deg;
} gc_chain_t;

/* Run-time parameters (grasprom.controller.ControllerParams). */
typedef struct {
    double thickness;        /* mm, inside the material's range (gc_check_params clamps) */
    int material;            /* index into the material table: 0 mr, 1 nh, 2 le */
    double spring_k;         /* N/mm */
    double pulley_radius;    /* mm */
    double damping;          /* N m s / rad at the handle pivot */
    double velocity_cutoff;  /* Hz */
    double torque_limit;     /* N m */
    double sample_time;      /* s */
    double coupling_k;       /* N/mm */
    double force_warning;    /* N */
    double pressure_warning; /* MPa */
    double jaw_length;       /* mm */
    double diameter;         /* mm */
    double encoder_counts;   /* counts per motor revolution, 0 = no quantisation */
    int render_spring;       /* 0/1 */
} gc_params_t;

/* Controller state and constants derived from the parameters at gc_init(). */
typedef struct {
    double prev;       /* last angle, rad */
    int has_prev;
    double v;          /* filtered velocity, rad/s */
    double gp;         /* proxy gap, mm (+inf before the first contact) */
    double a;          /* velocity filter pole */
    double q;          /* encoder quantum, rad */
    double area;       /* contact area for the mean pressure, mm^2 */
    /* thickness blend cached by the step (recomputed if the material or thickness changes) */
    const gc_material_t *b_mat;
    double b_t, b_w, b_v, b_dgc, b_idn, b_sa, b_sb;
    int b_i;
    int hint[2];       /* last Hermite interval of the two blended curves */
} gc_state_t;

typedef struct {
    double torque;               /* N m, after saturation */
    double force_handle;         /* N, torque / pulley radius */
    double force_handle_spring;  /* N */
    double force_jaw;            /* N, through the virtual coupling */
    double force_tissue;         /* N, surrogate at the kinematic gap */
    double gap;                  /* mm */
    double proxy_gap;            /* mm */
    double theta_deg;            /* deg, after quantisation and clamping */
    double velocity;             /* rad/s, filtered */
    int contact;
    int tissue_warning;
    int coupling_active;
    int saturated;
    int theta_clamped;
} gc_output_t;

#define GC_NEWTON_ITERATIONS 3      /* proxy Newton iterations per step (warm start) */
#define GC_COLD_START_ITERATIONS 30 /* on the first contact after gc_init (no warm start) */

/* Surrogate force (N) and stiffness -dF/dgap (N/mm) at (gap mm, thickness mm); returns the
 * out-of-range flag (gap below the last FE point). Thickness must be inside the range. */
int gc_surrogate(const gc_material_t *m, double gap, double thickness, double *force,
                 double *stiffness);

/* Chain at theta (deg, clipped to the range): gap (mm), dgap/dtheta (mm/rad), rod stroke u (mm)
 * and du/dtheta (mm/rad). Handle force: Fi = (Fg g1 - (F0 + k u) du) / L3 (virtual work). */
void gc_chain_state(const gc_chain_t *c, double theta_deg, double *gap, double *g1, double *u,
                    double *du);

/* Validate parameters: returns 0 if usable, else a negative code and a static message; the
 * thickness is clamped into the material's range (flag *clamped). */
int gc_check_params(const gc_params_t *p, const gc_material_t *materials, int n_materials,
                    double *thickness_clamped, int *clamped, const char **message);

void gc_init(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c);

void gc_step(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c, const gc_material_t *m,
             double theta, gc_output_t *out);

/* As gc_step, but the damping acts on a measured handle velocity theta_dot (rad/s, finite)
 * instead of the filtered backward difference (the filter state is still updated; out->velocity
 * reports theta_dot). Used by the FMU when the importer provides the velocity. */
void gc_step_ext(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c,
                 const gc_material_t *m, double theta, double theta_dot, gc_output_t *out);

#ifdef __cplusplus
}
#endif
#endif
