/* Test shim: the C core with the generated tables behind a flat API for ctypes (one global
 * controller; for parity tests only -- the FMU keeps one state per instance). */
#include "grasp_core.h"
#include "grasp_tables.h"

static gc_params_t P;
static gc_state_t S;

int gcs_init(const gc_params_t *p) {
    double t;
    int clamped, rc;
    const char *msg;
    P = *p;
    rc = gc_check_params(&P, GC_MATERIALS, GC_N_MATERIALS, &t, &clamped, &msg);
    if (rc != 0) return rc;
    P.thickness = t;
    gc_init(&S, &P, &GC_CHAIN);
    return clamped;
}

void gcs_step(double theta, gc_output_t *out) {
    gc_step(&S, &P, &GC_CHAIN, &GC_MATERIALS[P.material], theta, out);
}

void gcs_step_ext(double theta, double theta_dot, gc_output_t *out) {
    gc_step_ext(&S, &P, &GC_CHAIN, &GC_MATERIALS[P.material], theta, theta_dot, out);
}
