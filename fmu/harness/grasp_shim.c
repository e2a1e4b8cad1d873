/* Test shim: the C core with the generated tables behind a flat API for ctypes (one global
 * controller; for parity tests only -- the FMU keeps one state per instance). */
#include <string.h>

#include "grasp_core.h"
#include "grasp_tables.h"

static gc_params_t P;
static gc_state_t S;
static const char *MSG = "";

int gcs_init(const gc_params_t *p) {
    double t;
    int clamped, rc;
    P = *p;
    rc = gc_check_params(&P, GC_MATERIALS, GC_N_MATERIALS, &t, &clamped, &MSG);
    if (rc != 0) return rc;
    P.thickness = t;
    gc_init(&S, &P, &GC_CHAIN);
    gc_build_field(&S, &P, &GC_CHAIN, &GC_MATERIALS[P.material]);
    return clamped;
}

/* the message of the last gc_check_params() */
const char *gcs_message(void) { return MSG; }

void gcs_step(double theta, gc_output_t *out) {
    gc_step(&S, &P, &GC_CHAIN, &GC_MATERIALS[P.material], theta, out);
}

void gcs_step_ext(double theta, double theta_dot, gc_output_t *out) {
    gc_step_ext(&S, &P, &GC_CHAIN, &GC_MATERIALS[P.material], theta, theta_dot, out);
}

/* The field table of the clipped rendering: node count (0 if not built), first node and
 * spacing (rad), K_g (N/rad at the grip); forces (N) and clipped flags into arrays of
 * GC_FIELD_POINTS elements (if not NULL). */
int gcs_field(double *theta_lo, double *dtheta, double *kg, double *force,
              unsigned char *clipped) {
#if GC_FIELD_N > 0
    if (!S.f_mat) return 0;
    *theta_lo = S.f_th_lo;
    *dtheta = S.f_dth;
    *kg = S.f_kg;
    if (force) memcpy(force, S.f_force, sizeof S.f_force);
    if (clipped) memcpy(clipped, S.f_clipped, sizeof S.f_clipped);
    return GC_FIELD_N;
#else
    (void)theta_lo; (void)dtheta; (void)kg; (void)force; (void)clipped;
    return 0;
#endif
}

/* The passivity observer's energy (J) and the damping of the last step (N m s/rad). */
void gcs_observer(double *energy, double *alpha) {
    *energy = S.po_w;
    *alpha = S.po_alpha;
}
