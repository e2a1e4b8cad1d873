/*
 * grasp_fixed.c: integer controller step of grasprom for the ATmega328P (see grasp_fixed.h).
 *
 * Step, per sample (Python reference: grasprom.controller.ImpedanceController.step):
 *  1. clamp the count into [GF_N_LO, GF_N_TOP] (flag GF_THETA_CLAMPED);
 *  2. velocity: w += (1 - a) (dn - w), dn the count difference, w in counts/sample Q16,
 *     (1 - a) = GF_VEL_B / 2^16 with a = exp(-2 pi fc T) (exact discretisation, as Python);
 *  3. jaw force through the virtual coupling: linear interpolation of the (thickness-blended)
 *     node values y[] on the material's dyadic grid x[] (segment widths 2^k counts, so the
 *     interpolation is a shift, no division); 0 from GF_N_CONTACT on (no contact);
 *  4. handle force by virtual work: Fi = Fg * a(theta) + b(theta), a = g'(theta) / L3 (Q15) and
 *     b = spring handle force (mN) on a uniform grid of 2^GF_CH_SHIFT counts;
 *  5. damping: Fi -= KD * w (GF_KD: mN per count/sample, Q GF_KD_SHIFT);
 *  6. saturation |Fi| <= GF_FI_LIMIT_MN (= torque limit / pulley radius), torque = Fi r;
 *  7. flags: contact (count < GF_N_CONTACT), tissue warning (count <= warn_count) and coupling
 *     active (count <= active_count), thresholds blended over the thickness at gf_init().
 */
#include "grasp_fixed.h"

#include <string.h>
#ifdef GF_FLOAT
#include <math.h>
#endif

#ifdef __AVR__
#include <avr/pgmspace.h>
#define GF_PROGMEM PROGMEM
#define GF_RD16(p) pgm_read_word(p)
#define GF_RD8(p) pgm_read_byte(p)
#define GF_MEMCPY(d, s, n) memcpy_P((d), (s), (n))
#else
#define GF_PROGMEM
#define GF_RD16(p) (*(p))
#define GF_RD8(p) (*(p))
#define GF_MEMCPY(d, s, n) memcpy((d), (s), (n))
#endif

/* one material: dyadic grid, thickness nodes, node values per thickness, flag thresholds */
typedef struct {
    const uint16_t *x;      /* nx grid counts, ascending, x[0] = GF_N_LO */
    const uint8_t *k;       /* nx - 1 segment widths, log2 counts */
    const uint16_t *t;      /* nt thicknesses, um, ascending */
    const uint16_t *y;      /* nt rows of nx jaw forces, units of 2^GF_FG_SHIFT mN */
    const int16_t *warn;    /* nt tissue-warning thresholds, counts */
    const int16_t *active;  /* nt coupling-active thresholds, counts */
    uint8_t nx;
    uint8_t nt;
} gf_material_t;

#include "grasp_fixed_tables.h"

#define GF_RD16S(p) ((int16_t)GF_RD16((const uint16_t *)(p)))

/* floor(a * b / 2^16), exact; two 16 x 16 -> 32 bit multiplications (cheap on the AVR) */
static int32_t mulq16(int32_t a, uint16_t b) {
    int32_t hi = (int32_t)(int16_t)(a >> 16) * (int32_t)b;
    uint32_t lo = ((uint32_t)(uint16_t)a * (uint32_t)b) >> 16;
    return hi + (int32_t)lo;
}

int8_t gf_init(gf_state_t *s, uint8_t material, uint16_t thickness_um) {
    gf_material_t m;
    uint8_t j = 0, i;
    int8_t rc = 0;
    int32_t w14 = 0;
    uint16_t t = thickness_um, t0, t1;
    if (material >= GF_N_MATERIALS) return -1;
    GF_MEMCPY(&m, &gf_materials[material], sizeof m);
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
    int16_t n = count, dn, cm;
    uint16_t cf;
#ifdef GF_FLOAT
    float fg = 0.0f, fi, fa, fb, v;
#else
    int32_t fg = 0, fi, fa, fb;
#endif

    if (n < GF_N_LO) { n = GF_N_LO; flags |= GF_THETA_CLAMPED; }
    else if (n > GF_N_TOP) { n = GF_N_TOP; flags |= GF_THETA_CLAMPED; }
    if (!s->has_prev) { s->prev = n; s->has_prev = 1; }
    dn = n - s->prev;
    s->prev = n;
    s->w += mulq16((((int32_t)dn) << 16) - s->w, GF_VEL_B);

    if (n < GF_N_CONTACT) {
        uint8_t i = gf_segment(s, n);
        int16_t x0 = (int16_t)GF_RD16(&s->x[i]);
        uint8_t k = GF_RD8(&s->k[i]);
        int32_t y0 = s->y[i], dy = (int32_t)s->y[i + 1] - y0;
        flags |= GF_CONTACT;
#ifdef GF_FLOAT
        fg = ldexpf((float)y0 + ldexpf((float)dy * (float)(n - x0), -(int)k), GF_FG_SHIFT);
#else
        /* y0 + floor(dy (n - x0) / 2^k) as a 16 x 16 bit product and a 16-bit shift (k >= 1) */
        fg = y0 + (((int32_t)(int16_t)dy * (int32_t)(uint16_t)((uint16_t)(n - x0) << (16 - k)))
                   >> 16); /* units of 2^GF_FG_SHIFT mN */
#endif
        if (n <= s->warn_count) flags |= GF_TISSUE_WARNING;
        if (n <= s->active_count) flags |= GF_COUPLING_ACTIVE;
    }

    cm = n - GF_N_LO;
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
    fi = (int32_t)(((uint32_t)(uint16_t)fg * (uint32_t)(uint16_t)fa) >> (15 - GF_FG_SHIFT));
    if (GF_RENDER_SPRING) fi += fb;
    if (GF_KD != 0) fi -= mulq16(s->w, GF_KD) >> GF_KD_SHIFT;
    if (fi > GF_FI_LIMIT_MN) { fi = GF_FI_LIMIT_MN; flags |= GF_SATURATED; }
    else if (fi < -GF_FI_LIMIT_MN) { fi = -GF_FI_LIMIT_MN; flags |= GF_SATURATED; }
    o->force_handle_mN = fi;
    o->torque_uNm = (fi * GF_R_Q8) >> 8;
    o->force_jaw_mN = fg << GF_FG_SHIFT;
#endif
    o->velocity_q16 = s->w;
    o->count = n;
    o->flags = flags;
}
