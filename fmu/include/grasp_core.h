/*
 * grasp_core: one step of the grasprom open-loop impedance controller, in C -- the one core of
 * the FMU (FMI 2 / FMI 3 co-simulation) and of the Arduino export.  The Python reference is
 * grasprom.control.ImpedanceController; tables and constants are generated from the Python
 * objects (grasprom.export.codegen, grasprom.export.arduino); nothing is copied by hand.
 *
 * Build options (one source, three arithmetics):
 *
 *   default        run-time step, floating point: chain by trigonometry, tissue from the
 *                  Hermite surrogate curves ("grasp_tables.h", grasprom.export.codegen), virtual
 *                  coupling by three warm-started Newton iterations.  `double` on the host and
 *                  in the FMU (bit-identical to Python); compiled by avr-gcc it is the *float*
 *                  build (avr-gcc's double is 32-bit), tables in PROGMEM.
 *   GC_TABULATED   tabulated step for microcontrollers: what the run-time step computes with
 *                  trigonometry and Newton iterations is tabulated along the handle angle (in
 *                  encoder counts) by grasprom.export.arduino ("grasp_fixed_config.h",
 *                  "grasp_fixed_tables.h", PROGMEM); integer arithmetic (bit-identical on the
 *                  host and the AVR), or float with GF_FLOAT (set by the generated config).
 *   GC_FIELD_N     run-time step: storage of the clipped rendering's field table in gc_state_t,
 *                  GC_FIELD_POINTS (default) or 0 (the default on the AVR: 2 KB of RAM), which
 *                  leaves the clipped rendering out (gc_check_params refuses rendering = 1).
 *
 * Measured on the ATmega328P (simavr, 16 MHz; README and benchmarks/bench_arduino.py): the
 * float run-time build and the float tabulated build both exceed the 1,600-cycle (1 kHz) budget;
 * the fixed-point tabulated build meets it, hence it is the Arduino default.
 *
 * Run-time step units: lengths mm, forces N, torque N m, angles rad (the handle angle theta
 * decreases when closing), time s.  No dynamic memory; the steps allocate nothing.
 */
#ifndef GRASP_CORE_H
#define GRASP_CORE_H

/* Build selection: the Arduino export ships "grasp_build.h" (defines GC_TABULATED), so the
 * sketch builds in the Arduino IDE without compiler flags; other builds (FMU, host tests) pass
 * their options on the command line. */
#if defined(__has_include)
#if __has_include("grasp_build.h")
#include "grasp_build.h"
#endif
#endif

/* ---------------------------------------------------------------- table access (both builds) */
/* Tables are ordinary constant arrays on the host; on the AVR they live in flash (PROGMEM) and
 * are read with the pgm_read_* functions (the generated headers mark them GC_TABLE). */
#ifdef __AVR__
#include <avr/pgmspace.h>
#define GC_TABLE PROGMEM
#define GC_RD(p) pgm_read_float(p)         /* double (32-bit on the AVR) */
#define GC_RDI(p) ((int)pgm_read_word(p))  /* int (16-bit on the AVR) */
#define GC_RDP(p) pgm_read_ptr(p)          /* pointer */
#define GC_RD16(p) pgm_read_word(p)
#define GC_RD8(p) pgm_read_byte(p)
#define GC_MEMCPY(d, s, n) memcpy_P((d), (s), (n))
#else
#define GC_TABLE
#define GC_RD(p) (*(p))
#define GC_RDI(p) (*(p))
#define GC_RDP(p) (*(p))
#define GC_RD16(p) (*(p))
#define GC_RD8(p) (*(p))
#define GC_MEMCPY(d, s, n) memcpy((d), (s), (n))
#endif
#define GC_PTR(field) ((const double *)GC_RDP(&(field)))
#define GC_CURVES(m) ((const gc_curve_t *)GC_RDP(&(m)->curves))

#ifdef __cplusplus
extern "C" {
#endif

#if !defined(GC_TABULATED)
/* =============================================================== run-time (floating point) */

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

/* Kinematic chain constants (see grasprom.chain.kinematics.ChainParams). */
typedef struct {
    double L2, d, h, side, L3;     /* mm, side = -1 behind / +1 beyond */
    double gap_closed, gap_per_xc; /* mm, 1 */
    double xc_closed, xc_open;     /* mm */
    double stroke_sign;            /* +-1 */
    double spring_preload;         /* N */
    double theta_lo, theta_hi;     /* rad */
    double theta_lo_deg, theta_hi_deg;
} gc_chain_t;

/* Prony terms of the viscoelastic rendering: grasprom.control.MAX_PRONY_TERMS (checked by
 * tests/export/test_interface.py and, in the FMU, by the generated grasp_fmu_config.h) */
#define GC_PRONY_MAX 4

/* Run-time parameters (grasprom.control.ControllerParams).  Mirrored in Python by the ctypes
 * structure generated from grasprom.export.variables.PARAMS_FIELDS (layout tested). */
typedef struct {
    double thickness;        /* mm, inside the material's range (gc_check_params clamps) */
    int material;            /* material code, index into the material table: 0 mr, 1 nh,
                                2 le (a row without curves: not in this export) */
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
    /* rendering of the effects a sim-to-real diagnosis found (grasprom diagnose); the neutral
     * values (1, 0, ..., 0) leave the step bit-identical to the plain controller */
    double tissue_scale;     /* tissue force and stiffness factor, 1 */
    double jaw_compliance;   /* series compliance of jaw + mechanism, mm/N (k_c -> 1/(1/k_c + C)) */
    double backlash_deg;     /* play between encoder and linkage, total width, deg */
    double friction_coulomb; /* Coulomb friction at the finger, N */
    double friction_load;    /* load-proportional Coulomb coefficient (x |tissue handle force|), 1 */
    double friction_viscous; /* viscous friction at the finger, N s/mm */
    double friction_vthr;    /* finger speed that sets the friction direction, mm/s (> 0) */
    double prony_g[GC_PRONY_MAX];   /* Prony (QLV) coefficients on the rendered jaw force, 1 */
    double prony_tau[GC_PRONY_MAX]; /* their time constants, s (> 0) */
    /* rendering scheme of the tissue (grasprom.control.params.RENDERINGS) */
    int rendering;           /* GC_RENDER_COUPLING (0) or GC_RENDER_CLIPPED (1) */
    double stiffness_limit;  /* K_lim of the clipped rendering, N m/rad at the pivot (> 0) */
    /* time-domain passivity observer / controller (grasprom.control.impedance; clipped only) */
    int passivity_observer;           /* 0/1; 1 needs rendering = GC_RENDER_CLIPPED */
    double observer_stiffness_factor; /* the field is built with K_lim x factor when on, >= 1 */
    double observer_max_damping;      /* cap of the added damping, N m s/rad at the pivot, > 0 */
    int observer_delay;               /* samples from a step's output to its torque acting on
                                       * the handle, 0 .. GC_OBS_DELAY_MAX */
} gc_params_t;

/* Largest observer_delay: grasprom.control.params.OBSERVER_DELAY_MAX (tested). */
#define GC_OBS_DELAY_MAX 4

/* Rendering schemes (gc_params_t.rendering): the virtual coupling, or the stiffness-clipped
 * field tabulated by gc_build_field() (grasprom.control.field). */
#define GC_RENDER_COUPLING 0
#define GC_RENDER_CLIPPED 1

/* Nodes of the clipped field along the handle angle: grasprom.control.field.FIELD_POINTS
 * (checked by tests/export/test_interface.py and, in the FMU, by grasp_fmu_config.h). */
#define GC_FIELD_POINTS 1025
/* Halvings of the bisection behind a series jaw compliance: field.COMPLIANCE_BISECTIONS. */
#define GC_COMPLIANCE_BISECTIONS 60

/* Storage of the field table in gc_state_t: GC_FIELD_POINTS nodes (about 9 KB), or 0 to leave
 * the table (and the clipped rendering) out of the build; gc_check_params() then refuses
 * rendering = 1.  Default: 0 on the AVR (the ATmega328P has 2 KB of RAM), else the table. */
#ifndef GC_FIELD_N
#if defined(__AVR__)
#define GC_FIELD_N 0
#else
#define GC_FIELD_N GC_FIELD_POINTS
#endif
#endif
#if GC_FIELD_N != 0 && GC_FIELD_N != GC_FIELD_POINTS
#error "GC_FIELD_N must be 0 (no clipped rendering) or GC_FIELD_POINTS"
#endif

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
    /* augmented rendering */
    double play;       /* chain angle behind the backlash, rad */
    int has_play;
    double sdir;       /* friction direction: +1 closing, -1 opening, 0 not yet moved */
    double fg_prev;    /* last coupled jaw force, N */
    double h[GC_PRONY_MAX];  /* Prony states, N */
    double pa[GC_PRONY_MAX]; /* exp(-T / tau_i) */
    double hb;         /* half the backlash, rad */
    int prony_on;      /* any prony_g != 0 */
    /* clipped rendering: the field table of gc_build_field() (material and thickness it was
     * built for; f_mat = 0: not built) */
    const gc_material_t *f_mat;
    double f_t;
    double f_th_lo, f_dth; /* first node and node spacing, rad */
    double f_kg;           /* K_g, the bound on the slope of the handle force, N/rad at the grip */
    /* passivity observer (p->passivity_observer = 1) */
    double po_w;       /* observed energy beyond the reference, J */
    double po_theta;   /* encoder angle of the last step, rad */
    int po_has;        /* 0 before the first step */
    double po_fs_prev; /* static handle force of the last step, N */
    double po_fh[GC_OBS_DELAY_MAX + 1]; /* saturated handle forces of steps k-1 .. k-1-d, N */
    double po_pc[GC_OBS_DELAY_MAX + 1]; /* planned dissipation of the same steps, J */
    double po_alpha;   /* damping added in the last step, N m s/rad */
#if GC_FIELD_N > 0
    double f_force[GC_FIELD_N];         /* rendered jaw force Fr_j at the nodes, N */
    unsigned char f_clipped[GC_FIELD_N];/* 1: the stiffness limit acts at the node */
#endif
} gc_state_t;

/* Outputs of a step; mirrored by the ctypes structure generated from
 * grasprom.export.variables.OUTPUT_FIELDS (layout tested; the int fields are FLAG_NAMES). */
typedef struct {
    double torque;               /* N m, after saturation */
    double force_handle;         /* N, torque / pulley radius */
    double force_handle_spring;  /* N */
    double force_jaw;            /* N, rendered: coupling or clipped field (+ Prony terms) */
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
    double theta_chain_deg;      /* deg, the linkage's angle behind the backlash */
    double force_handle_friction;/* N, rendered friction at the handle */
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

/* Reset the state and derive the constants of the parameters (not the field table). */
void gc_init(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c);

/* The field table of the clipped rendering (p->rendering = GC_RENDER_CLIPPED) for the material
 * m and p->thickness, tabulated as grasprom.control.field.build_field does, operation for
 * operation; call after gc_init() (not real-time: GC_FIELD_POINTS surrogate evaluations, times
 * 61 with a jaw compliance).  Nothing to do for the coupling or in a build without the table
 * (GC_FIELD_N = 0).  The step builds it itself if it was not built for its material and
 * thickness, so calling it is what keeps the first step real-time. */
void gc_build_field(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c,
                    const gc_material_t *m);

void gc_step(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c, const gc_material_t *m,
             double theta, gc_output_t *out);

/* As gc_step, but the damping acts on a measured handle velocity theta_dot (rad/s, finite)
 * instead of the filtered backward difference (the filter state is still updated; out->velocity
 * reports theta_dot). Used by the FMU when the importer provides the velocity. */
void gc_step_ext(gc_state_t *s, const gc_params_t *p, const gc_chain_t *c,
                 const gc_material_t *m, double theta, double theta_dot, gc_output_t *out);

#else /* GC_TABULATED */
/* ============================================================= tabulated (fixed or float) */
/*
 * Integer interface (units in the names):
 *   count  handle angle in encoder counts, theta = count * GF_Q_RAD (rad), the absolute angle
 *          of the handle (count 0 = theta 0; the chain's closed end is GF_N_LO, open GF_N_TOP)
 *   torque micro newton metre (uN m = mN mm); handle and jaw forces in mN
 *   velocity in encoder counts per sample, Q16
 *
 * Allocation-free; gf_step() has no division and no loop other than the binary search of
 * the angle grid (<= log2(GF_NX_MAX) + 1 iterations).
 */
#include <stdint.h>

/* generated by grasprom.export.arduino: scalar constants (GF_NX_MAX, GF_N_TOP, ...) */
#include "grasp_fixed_config.h"

/* output flags (gf_output_t.flags), bit i = grasprom.export.variables.FLAG_NAMES[i] (tested) */
#define GF_CONTACT 0x01u          /* jaws touch the tissue (kinematic gap < diameter) */
#define GF_TISSUE_WARNING 0x02u   /* tissue force or mean pressure at the warning level */
#define GF_COUPLING_ACTIVE 0x04u  /* tissue stiffer than the virtual coupling */
#define GF_SATURATED 0x08u        /* torque limited */
#define GF_THETA_CLAMPED 0x10u    /* count outside [GF_N_LO, GF_N_TOP], clamped */

/* gf_init() return bits */
#define GF_THICKNESS_CLAMPED 0x01

typedef struct {
    int32_t torque_uNm;      /* motor torque after saturation, uN m */
    int32_t force_handle_mN; /* rendered handle force = torque / pulley radius, mN */
    int32_t force_jaw_mN;    /* rendered jaw force through the virtual coupling, mN */
    int32_t velocity_q16;    /* filtered handle velocity, counts/sample, Q16 */
    int16_t count;           /* handle angle after clamping, counts */
    uint8_t flags;           /* GF_* flags above */
} gf_output_t;

typedef struct {
    int32_t w;             /* filtered velocity, counts/sample Q16 */
    int32_t prev;          /* last position, counts Q8 (end stops between counts) */
    uint8_t has_prev;
    uint8_t material;
    uint8_t nx;            /* grid nodes of the material */
    uint16_t thickness_um; /* after clamping */
    int16_t warn_count;    /* tissue warning for count <= warn_count (-32768: never) */
    int16_t active_count;  /* coupling active for count <= active_count */
    const uint16_t *x;     /* grid counts (PROGMEM on AVR) */
    const uint8_t *k;      /* log2 of each segment width (PROGMEM on AVR) */
    uint16_t y[GF_NX_MAX]; /* jaw force at the grid nodes, blended for the thickness */
#if GF_BACKLASH_HB > 0
    int16_t play;          /* linkage angle behind the backlash, counts */
    uint8_t has_play;
#endif
#if GF_FRICTION
    int8_t sdir;           /* friction direction: +1 closing, -1 opening, 0 not yet moved */
#endif
#if GF_N_PRONY > 0
    int32_t fg_prev;       /* last coupled jaw force, mN */
    int32_t h[GF_N_PRONY]; /* Prony states g_i h_i, mN Q8 */
#endif
} gf_state_t;

/* Select material (code 0 mr, 1 nh, 2 le) and wall thickness (um; clamped into the tabulated
 * range and flagged); resets the state.  Returns GF_THICKNESS_CLAMPED bits, or -1 for an
 * unknown material or one not in this export's tables (no thickness nodes; the state is then
 * unchanged).  Not real-time (blends the thickness tables into RAM). */
int8_t gf_init(gf_state_t *s, uint8_t material, uint16_t thickness_um);

/* One controller step with the handle angle in encoder counts. */
void gf_step(gf_state_t *s, int16_t count, gf_output_t *out);

/* CRC-16/CCITT-FALSE of the PROGMEM tables (chain, then per material x, k, t, y, warn,
 * active; little-endian bytes): the firmware compares it with the export's GF_TABLE_CRC. */
uint16_t gf_table_crc(void);

#endif /* GC_TABULATED */

#ifdef __cplusplus
}
#endif
#endif
