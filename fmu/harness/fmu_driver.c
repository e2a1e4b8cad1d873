/*
 * fmu_driver: load an extracted FMU binary with dlopen / LoadLibrary (no Python) and run it.
 *
 *   fmu_driver VERSION LIBRARY TOKEN MODE [N] [options]
 *
 * VERSION 2 or 3; LIBRARY the binary (binaries/<platform>/<id>.so); TOKEN the GUID /
 * instantiation token of modelDescription.xml.  Modes:
 *   run       read theta values (rad, one per line; nan/inf allowed) from stdin; before each
 *             value's doStep set the input, after it print the outputs (%.17g, one line/step)
 *   bench N   N steps of one sample (set theta, doStep, get outputs): ns per FMI step; then
 *             N samples in doSteps of 1000 samples: ns per controller (core) step
 *   leak N    N times: instantiate, set parameters, initialise, 20 steps, terminate, free
 * Options (value references from modelDescription.xml):
 *   -r VR=X   set a Real/Float64 parameter before initialisation (repeatable)
 *   -i VR=N   set an Integer/Int32 parameter      -b VR=0|1  set a Boolean parameter
 *   -e VR=N   set an Enumeration parameter (FMI 2 SetInteger, FMI 3 SetInt64)
 *   -t VR     theta input                          -h H       communication step (s, 0.001)
 *   -o VR,..  Real outputs to print                -O VR,..   Boolean outputs to print
 * Exit status 0 if every call returned OK or Warning, 1 otherwise, 2 on usage errors.
 */
#define _POSIX_C_SOURCE 200809L
#ifdef _WIN32
#include <windows.h> /* LoadLibrary / GetProcAddress: the same driver for the win64 DLL */
#else
#include <dlfcn.h>
#endif
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#define MAXV 64

static int version;
static void *lib;
static int failed;

/* FMI 2 */
static fmi2InstantiateTYPE *f2Instantiate;
static fmi2FreeInstanceTYPE *f2FreeInstance;
static fmi2SetupExperimentTYPE *f2SetupExperiment;
static fmi2EnterInitializationModeTYPE *f2EnterInit;
static fmi2ExitInitializationModeTYPE *f2ExitInit;
static fmi2SetRealTYPE *f2SetReal;
static fmi2SetIntegerTYPE *f2SetInteger;
static fmi2SetBooleanTYPE *f2SetBoolean;
static fmi2GetRealTYPE *f2GetReal;
static fmi2GetBooleanTYPE *f2GetBoolean;
static fmi2DoStepTYPE *f2DoStep;
static fmi2TerminateTYPE *f2Terminate;
/* FMI 3 */
static fmi3InstantiateCoSimulationTYPE *f3Instantiate;
static fmi3FreeInstanceTYPE *f3FreeInstance;
static fmi3EnterInitializationModeTYPE *f3EnterInit;
static fmi3ExitInitializationModeTYPE *f3ExitInit;
static fmi3SetFloat64TYPE *f3SetFloat64;
static fmi3SetInt32TYPE *f3SetInt32;
static fmi3SetInt64TYPE *f3SetInt64;
static fmi3SetBooleanTYPE *f3SetBoolean;
static fmi3GetFloat64TYPE *f3GetFloat64;
static fmi3GetBooleanTYPE *f3GetBoolean;
static fmi3DoStepTYPE *f3DoStep;
static fmi3TerminateTYPE *f3Terminate;

#ifdef _WIN32
static void *sym(const char *name) {
    FARPROC f = GetProcAddress((HMODULE)lib, name);
    void *p;
    if (!f) {
        fprintf(stderr, "fmu_driver: symbol %s not found (error %lu)\n", name,
                (unsigned long)GetLastError());
        exit(2);
    }
    memcpy(&p, &f, sizeof p);
    return p;
}
#else
static void *sym(const char *name) {
    void *p = dlsym(lib, name);
    if (!p) {
        fprintf(stderr, "fmu_driver: symbol %s not found: %s\n", name, dlerror());
        exit(2);
    }
    return p;
}
#endif

static void load(const char *path) {
#ifdef _WIN32
    lib = (void *)LoadLibraryA(path);
    if (!lib) {
        fprintf(stderr, "fmu_driver: cannot load %s (error %lu)\n", path,
                (unsigned long)GetLastError());
        exit(2);
    }
#else
    lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "fmu_driver: cannot load %s: %s\n", path, dlerror());
        exit(2);
    }
#endif
    /* object <-> function pointer conversion through memcpy (ISO C) */
#define LOAD(var, name)              \
    do {                             \
        void *p_ = sym(name);        \
        memcpy(&var, &p_, sizeof p_); \
    } while (0)
    if (version == 2) {
        LOAD(f2Instantiate, "fmi2Instantiate");
        LOAD(f2FreeInstance, "fmi2FreeInstance");
        LOAD(f2SetupExperiment, "fmi2SetupExperiment");
        LOAD(f2EnterInit, "fmi2EnterInitializationMode");
        LOAD(f2ExitInit, "fmi2ExitInitializationMode");
        LOAD(f2SetReal, "fmi2SetReal");
        LOAD(f2SetInteger, "fmi2SetInteger");
        LOAD(f2SetBoolean, "fmi2SetBoolean");
        LOAD(f2GetReal, "fmi2GetReal");
        LOAD(f2GetBoolean, "fmi2GetBoolean");
        LOAD(f2DoStep, "fmi2DoStep");
        LOAD(f2Terminate, "fmi2Terminate");
    } else {
        LOAD(f3Instantiate, "fmi3InstantiateCoSimulation");
        LOAD(f3FreeInstance, "fmi3FreeInstance");
        LOAD(f3EnterInit, "fmi3EnterInitializationMode");
        LOAD(f3ExitInit, "fmi3ExitInitializationMode");
        LOAD(f3SetFloat64, "fmi3SetFloat64");
        LOAD(f3SetInt32, "fmi3SetInt32");
        LOAD(f3SetInt64, "fmi3SetInt64");
        LOAD(f3SetBoolean, "fmi3SetBoolean");
        LOAD(f3GetFloat64, "fmi3GetFloat64");
        LOAD(f3GetBoolean, "fmi3GetBoolean");
        LOAD(f3DoStep, "fmi3DoStep");
        LOAD(f3Terminate, "fmi3Terminate");
    }
#undef LOAD
}

static void check(int status, const char *what) {
    if (status > 1) {
        fprintf(stderr, "fmu_driver: %s returned status %d\n", what, status);
        failed = 1;
    }
}

static void driver_log2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                 fmi2String category, fmi2String message, ...) {
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s %d %s] ", name ? name : "", (int)status, category ? category : "");
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static void driver_log3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                 fmi3String message) {
    (void)env;
    fprintf(stderr, "[%d %s] %s\n", (int)status, category ? category : "", message);
}

/* parameter settings from the command line */
typedef struct { unsigned vr; double x; char kind; } setting_t;
static setting_t settings[MAXV];
static int n_settings;
static unsigned theta_vr = 1u << 30, out_r[MAXV], out_b[MAXV];
static int n_out_r, n_out_b;
static double h = 1e-3;
static const char *token;
static fmi2CallbackFunctions callbacks2;

static void *instantiate(void) {
    void *c;
    if (version == 2) {
        callbacks2.logger = driver_log2;
        callbacks2.allocateMemory = calloc;
        callbacks2.freeMemory = free;
        c = f2Instantiate("driver", fmi2CoSimulation, token, "", &callbacks2, fmi2False,
                          fmi2False);
    } else {
        c = f3Instantiate("driver", token, "", fmi3False, fmi3False, fmi3False, fmi3False, NULL,
                          0, NULL, driver_log3, NULL);
    }
    if (!c) {
        fprintf(stderr, "fmu_driver: instantiation failed\n");
        exit(1);
    }
    return c;
}

static void set_real(void *c, unsigned vr, double x) {
    if (version == 2) check(f2SetReal(c, &vr, 1, &x), "SetReal");
    else check(f3SetFloat64(c, &vr, 1, &x, 1), "SetFloat64");
}

static void initialise(void *c) {
    int i;
    for (i = 0; i < n_settings; ++i) {
        setting_t *s = &settings[i];
        if (s->kind == 'r') {
            set_real(c, s->vr, s->x);
        } else if (s->kind == 'i' || (s->kind == 'e' && version == 2)) {
            if (version == 2) {
                fmi2Integer v = (fmi2Integer)s->x;
                check(f2SetInteger(c, &s->vr, 1, &v), "SetInteger");
            } else {
                fmi3Int32 v = (fmi3Int32)s->x;
                check(f3SetInt32(c, &s->vr, 1, &v, 1), "SetInt32");
            }
        } else if (s->kind == 'e') {
            fmi3Int64 v = (fmi3Int64)s->x;
            check(f3SetInt64(c, &s->vr, 1, &v, 1), "SetInt64");
        } else {
            if (version == 2) {
                fmi2Boolean v = s->x != 0.0;
                check(f2SetBoolean(c, &s->vr, 1, &v), "SetBoolean");
            } else {
                fmi3Boolean v = s->x != 0.0;
                check(f3SetBoolean(c, &s->vr, 1, &v, 1), "SetBoolean");
            }
        }
    }
    if (version == 2) {
        check(f2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0), "SetupExperiment");
        check(f2EnterInit(c), "EnterInitializationMode");
        check(f2ExitInit(c), "ExitInitializationMode");
    } else {
        check(f3EnterInit(c, fmi3False, 0.0, 0.0, fmi3False, 0.0), "EnterInitializationMode");
        check(f3ExitInit(c), "ExitInitializationMode");
    }
}

static void do_step(void *c, double t, double step) {
    if (version == 2) {
        check(f2DoStep(c, t, step, fmi2True), "DoStep");
    } else {
        fmi3Boolean ev, term, early;
        fmi3Float64 last;
        check(f3DoStep(c, t, step, fmi3True, &ev, &term, &early, &last), "DoStep");
    }
}

static void get_outputs(void *c, double *r, int *b) {
    int i;
    if (version == 2) {
        fmi2Boolean bb[MAXV];
        if (n_out_r) check(f2GetReal(c, out_r, (size_t)n_out_r, r), "GetReal");
        if (n_out_b) check(f2GetBoolean(c, out_b, (size_t)n_out_b, bb), "GetBoolean");
        for (i = 0; i < n_out_b; ++i) b[i] = bb[i] != 0;
    } else {
        fmi3Boolean bb[MAXV];
        if (n_out_r)
            check(f3GetFloat64(c, out_r, (size_t)n_out_r, r, (size_t)n_out_r), "GetFloat64");
        if (n_out_b)
            check(f3GetBoolean(c, out_b, (size_t)n_out_b, bb, (size_t)n_out_b), "GetBoolean");
        for (i = 0; i < n_out_b; ++i) b[i] = bb[i] != 0;
    }
}

static void terminate_free(void *c) {
    if (version == 2) {
        check(f2Terminate(c), "Terminate");
        f2FreeInstance(c);
    } else {
        check(f3Terminate(c), "Terminate");
        f3FreeInstance(c);
    }
}

static double now_s(void) {
#ifdef _WIN32
    LARGE_INTEGER f, c;
    QueryPerformanceFrequency(&f);
    QueryPerformanceCounter(&c);
    return (double)c.QuadPart / (double)f.QuadPart;
#else
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#endif
}

static int parse_list(const char *s, unsigned *out) {
    int n = 0;
    char *end;
    while (*s && n < MAXV) {
        out[n++] = (unsigned)strtoul(s, &end, 10);
        if (*end == ',') end++;
        if (end == s) break;
        s = end;
    }
    return n;
}

static int usage(void) {
    fprintf(stderr, "usage: fmu_driver 2|3 LIBRARY TOKEN run|bench N|leak N [-r VR=X] "
                    "[-i VR=N] [-b VR=0|1] [-t VR] [-h STEP] [-o VR,..] [-O VR,..]\n");
    return 2;
}

int main(int argc, char **argv) {
    const char *mode;
    long n = 0;
    int i, k;
    double r[MAXV];
    int b[MAXV];
    void *c;
    if (argc < 5) return usage();
    version = atoi(argv[1]);
    if (version != 2 && version != 3) return usage();
    token = argv[3];
    mode = argv[4];
    i = 5;
    if (!strcmp(mode, "bench") || !strcmp(mode, "leak")) {
        if (argc < 6) return usage();
        n = atol(argv[5]);
        i = 6;
    }
    for (; i < argc; ++i) {
        const char *a = argv[i];
        if (i + 1 >= argc) return usage();
        if (!strcmp(a, "-r") || !strcmp(a, "-i") || !strcmp(a, "-e") ||
            !strcmp(a, "-b")) {
            char *eq;
            if (n_settings >= MAXV) return usage();
            settings[n_settings].kind = a[1];
            settings[n_settings].vr = (unsigned)strtoul(argv[i + 1], &eq, 10);
            if (*eq != '=') return usage();
            settings[n_settings].x = strtod(eq + 1, NULL);
            n_settings++;
        } else if (!strcmp(a, "-t")) {
            theta_vr = (unsigned)strtoul(argv[i + 1], NULL, 10);
        } else if (!strcmp(a, "-h")) {
            h = strtod(argv[i + 1], NULL);
        } else if (!strcmp(a, "-o")) {
            n_out_r = parse_list(argv[i + 1], out_r);
        } else if (!strcmp(a, "-O")) {
            n_out_b = parse_list(argv[i + 1], out_b);
        } else {
            return usage();
        }
        ++i;
    }
    load(argv[2]);

    if (!strcmp(mode, "run")) {
        char line[128];
        long step = 0;
        c = instantiate();
        initialise(c);
        while (fgets(line, sizeof line, stdin)) {
            double th = strtod(line, NULL);
            set_real(c, theta_vr, th);
            do_step(c, (double)step * h, h);
            step++;
            get_outputs(c, r, b);
            for (k = 0; k < n_out_r; ++k) printf("%s%.17g", k ? " " : "", r[k]);
            for (k = 0; k < n_out_b; ++k) printf("%s%d", (k || n_out_r) ? " " : "", b[k]);
            putchar('\n');
        }
        terminate_free(c);
    } else if (!strcmp(mode, "bench")) {
        double t0, t1, sink = 0.0, lo = 0.0, hi = 0.38; /* rad, inside the range */
        long j, m = n / 1000 > 0 ? n / 1000 : 1;
        c = instantiate();
        initialise(c);
        t0 = now_s();
        for (j = 0; j < n; ++j) {
            /* a grasp-release cycle every 2000 samples */
            double ph = (double)(j % 2000) / 2000.0;
            set_real(c, theta_vr, lo + (hi - lo) * 0.5 * (1.0 + cos(6.283185307179586 * ph)));
            do_step(c, (double)j * h, h);
            get_outputs(c, r, b);
            sink += n_out_r ? r[0] : 0.0;
        }
        t1 = now_s();
        printf("fmi_step_ns %.2f\n", 1e9 * (t1 - t0) / (double)n);
        t0 = now_s();
        for (j = 0; j < m; ++j) {
            set_real(c, theta_vr, lo + (hi - lo) * (double)(j % 7) / 6.0);
            do_step(c, (double)(n + 1000 * j) * h, 1000.0 * h);
        }
        t1 = now_s();
        printf("core_step_ns %.2f\n", 1e9 * (t1 - t0) / (double)(1000 * m));
        printf("checksum %.6g\n", sink);
        terminate_free(c);
    } else if (!strcmp(mode, "leak")) {
        long j;
        for (j = 0; j < n; ++j) {
            c = instantiate();
            initialise(c);
            for (k = 0; k < 20; ++k) {
                set_real(c, theta_vr, 0.02 * (double)k);
                do_step(c, (double)k * h, h);
                get_outputs(c, r, b);
            }
            terminate_free(c);
        }
        printf("leak cycles %ld\n", n);
    } else {
        return usage();
    }
#ifdef _WIN32
    FreeLibrary((HMODULE)lib);
#else
    dlclose(lib);
#endif
    return failed;
}
