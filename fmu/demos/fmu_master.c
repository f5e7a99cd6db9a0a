/* A native FMI 2.0 / FMI 3.0 co-simulation master (no Python in this program).
 *
 * It loads an extracted FMU's binary with dlopen, instantiates it (several instances if
 * asked), sets start values, initializes, steps with a fixed step size, feeds inputs per
 * step from a file or held values, and prints the requested Real outputs of instance 0 as
 * CSV (one line per step, time first). Messages the FMU logs go to stderr as
 * "[instance] status N category: message".
 *
 * Build (the FMI headers ship in biso_cosim/fmu/native/include and in FMPy's fmpy/c-code):
 *     cc -std=c99 -O2 -I<include> -o fmu_master fmu_master.c -ldl
 * Run:
 *     ./fmu_master [options] DIR MODEL_ID TOKEN STEP N [r:VR=VALUE] [i:VR=VALUE] [b:VR=0|1]
 *                  [s:VR=TEXT] [in:VR=VALUE] [out:VR]
 * Options:
 *     --fmi 2|3        FMI version of the FMU (default 2)
 *     --instances K    run K instances side by side on the same inputs; every one must give
 *                      instance 0's outputs (exit 21 if not): instances share nothing
 *     --inputs FILE    per-step Real inputs: a first line of value references, then one line
 *                      of values per step (steps beyond the file hold the last line)
 *     --check-state    at step N/2 save the state (GetFMUstate, and serialize + deserialize
 *                      it), run to N, restore the deserialized state and run N/2..N again,
 *                      then Reset, initialize again and run 0..N: all three runs must give the
 *                      same outputs bit for bit (exit 20 if not)
 *     --time           print the mean wall time per DoStep (ns) to stderr
 *     --quiet          print no CSV
 * r:/i:/b:/s: set Real/Integer/Boolean/String start values in initialization mode; in:VR=VALUE
 * sets a Real input before every step (held); out:VR prints a Real output after every step.
 * The exit code is 0 when every call returned OK (or warning), else the status of the first
 * failure (2 discard, 3 error, 4 fatal), with what the FMU logged on stderr.
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"

#define MAX_ARGS 512
#define MAX_INSTANCES 8

/* ---- logging -------------------------------------------------------------------------- */

static void logger2(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                    fmi2String message, ...) {
    va_list args;
    (void)env;
    fprintf(stderr, "[%s] status %d %s: ", instance, (int)status, category ? category : "");
    va_start(args, message);
    vfprintf(stderr, message, args);
    va_end(args);
    fprintf(stderr, "\n");
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    fprintf(stderr, "[%s] status %d %s: %s\n", env ? (const char *)env : "", (int)status, category ? category : "",
            message);
}

/* ---- one interface over FMI 2.0 and FMI 3.0 ------------------------------------------------ */

typedef struct {
    int version;
    void *lib;
    /* FMI 2.0 */
    fmi2InstantiateTYPE *instantiate2;
    fmi2SetupExperimentTYPE *setup2;
    fmi2EnterInitializationModeTYPE *enter2;
    fmi2ExitInitializationModeTYPE *exit2;
    fmi2SetRealTYPE *set_real2;
    fmi2SetIntegerTYPE *set_integer2;
    fmi2SetBooleanTYPE *set_boolean2;
    fmi2SetStringTYPE *set_string2;
    fmi2GetRealTYPE *get_real2;
    fmi2DoStepTYPE *do_step2;
    fmi2GetFMUstateTYPE *get_state2;
    fmi2SetFMUstateTYPE *set_state2;
    fmi2FreeFMUstateTYPE *free_state2;
    fmi2SerializedFMUstateSizeTYPE *state_size2;
    fmi2SerializeFMUstateTYPE *serialize2;
    fmi2DeSerializeFMUstateTYPE *deserialize2;
    fmi2ResetTYPE *reset2;
    fmi2TerminateTYPE *terminate2;
    fmi2FreeInstanceTYPE *free2;
    /* FMI 3.0 */
    fmi3InstantiateCoSimulationTYPE *instantiate3;
    fmi3EnterInitializationModeTYPE *enter3;
    fmi3ExitInitializationModeTYPE *exit3;
    fmi3EnterStepModeTYPE *step_mode3;
    fmi3SetFloat64TYPE *set_real3;
    fmi3SetInt32TYPE *set_integer3;
    fmi3SetBooleanTYPE *set_boolean3;
    fmi3SetStringTYPE *set_string3;
    fmi3GetFloat64TYPE *get_real3;
    fmi3DoStepTYPE *do_step3;
    fmi3GetFMUStateTYPE *get_state3;
    fmi3SetFMUStateTYPE *set_state3;
    fmi3FreeFMUStateTYPE *free_state3;
    fmi3SerializedFMUStateSizeTYPE *state_size3;
    fmi3SerializeFMUStateTYPE *serialize3;
    fmi3DeserializeFMUStateTYPE *deserialize3;
    fmi3ResetTYPE *reset3;
    fmi3TerminateTYPE *terminate3;
    fmi3FreeInstanceTYPE *free3;
} api;

static void *symbol(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "missing FMI function %s\n", name);
        exit(10);
    }
    return f;
}

static void load(api *a, const char *path) {
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen failed: %s\n", dlerror());
        exit(11);
    }
    a->lib = lib;
    if (a->version == 2) {
        a->instantiate2 = symbol(lib, "fmi2Instantiate");
        a->setup2 = symbol(lib, "fmi2SetupExperiment");
        a->enter2 = symbol(lib, "fmi2EnterInitializationMode");
        a->exit2 = symbol(lib, "fmi2ExitInitializationMode");
        a->set_real2 = symbol(lib, "fmi2SetReal");
        a->set_integer2 = symbol(lib, "fmi2SetInteger");
        a->set_boolean2 = symbol(lib, "fmi2SetBoolean");
        a->set_string2 = symbol(lib, "fmi2SetString");
        a->get_real2 = symbol(lib, "fmi2GetReal");
        a->do_step2 = symbol(lib, "fmi2DoStep");
        a->get_state2 = symbol(lib, "fmi2GetFMUstate");
        a->set_state2 = symbol(lib, "fmi2SetFMUstate");
        a->free_state2 = symbol(lib, "fmi2FreeFMUstate");
        a->state_size2 = symbol(lib, "fmi2SerializedFMUstateSize");
        a->serialize2 = symbol(lib, "fmi2SerializeFMUstate");
        a->deserialize2 = symbol(lib, "fmi2DeSerializeFMUstate");
        a->reset2 = symbol(lib, "fmi2Reset");
        a->terminate2 = symbol(lib, "fmi2Terminate");
        a->free2 = symbol(lib, "fmi2FreeInstance");
    } else {
        a->instantiate3 = symbol(lib, "fmi3InstantiateCoSimulation");
        a->enter3 = symbol(lib, "fmi3EnterInitializationMode");
        a->exit3 = symbol(lib, "fmi3ExitInitializationMode");
        a->step_mode3 = symbol(lib, "fmi3EnterStepMode");
        a->set_real3 = symbol(lib, "fmi3SetFloat64");
        a->set_integer3 = symbol(lib, "fmi3SetInt32");
        a->set_boolean3 = symbol(lib, "fmi3SetBoolean");
        a->set_string3 = symbol(lib, "fmi3SetString");
        a->get_real3 = symbol(lib, "fmi3GetFloat64");
        a->do_step3 = symbol(lib, "fmi3DoStep");
        a->get_state3 = symbol(lib, "fmi3GetFMUState");
        a->set_state3 = symbol(lib, "fmi3SetFMUState");
        a->free_state3 = symbol(lib, "fmi3FreeFMUState");
        a->state_size3 = symbol(lib, "fmi3SerializedFMUStateSize");
        a->serialize3 = symbol(lib, "fmi3SerializeFMUState");
        a->deserialize3 = symbol(lib, "fmi3DeserializeFMUState");
        a->reset3 = symbol(lib, "fmi3Reset");
        a->terminate3 = symbol(lib, "fmi3Terminate");
        a->free3 = symbol(lib, "fmi3FreeInstance");
    }
}

static fmi2CallbackFunctions callbacks2 = {logger2, calloc, free, NULL, NULL};
static char instance_names[MAX_INSTANCES][32];

static void *instantiate(api *a, int k, const char *guid, const char *resources) {
    snprintf(instance_names[k], sizeof instance_names[k], "native%d", k);
    if (a->version == 2)
        return a->instantiate2(instance_names[k], fmi2CoSimulation, guid, resources, &callbacks2, fmi2False, fmi2True);
    return a->instantiate3(instance_names[k], guid, resources, fmi3False, fmi3True, fmi3False, fmi3False, NULL, 0,
                           instance_names[k], logger3, NULL);
}

static int enter_init(api *a, void *c) {
    if (a->version == 2) {
        int s = a->setup2(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        return s ? s : (int)a->enter2(c);
    }
    return (int)a->enter3(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
}

static int exit_init(api *a, void *c) {
    if (a->version == 2) return (int)a->exit2(c);
    {
        int s = (int)a->exit3(c);
        return s ? s : (int)a->step_mode3(c);
    }
}

static int set_real(api *a, void *c, const unsigned *vr, size_t n, const double *v) {
    return a->version == 2 ? (int)a->set_real2(c, vr, n, v) : (int)a->set_real3(c, vr, n, v, n);
}

static int set_integer(api *a, void *c, unsigned vr, int v) {
    fmi3Int32 v3 = v;
    return a->version == 2 ? (int)a->set_integer2(c, &vr, 1, &v) : (int)a->set_integer3(c, &vr, 1, &v3, 1);
}

static int set_boolean(api *a, void *c, unsigned vr, int v) {
    fmi3Boolean b3 = v != 0;
    return a->version == 2 ? (int)a->set_boolean2(c, &vr, 1, &v) : (int)a->set_boolean3(c, &vr, 1, &b3, 1);
}

static int set_string(api *a, void *c, unsigned vr, const char *v) {
    return a->version == 2 ? (int)a->set_string2(c, &vr, 1, &v) : (int)a->set_string3(c, &vr, 1, &v, 1);
}

static int get_real(api *a, void *c, const unsigned *vr, size_t n, double *v) {
    return a->version == 2 ? (int)a->get_real2(c, vr, n, v) : (int)a->get_real3(c, vr, n, v, n);
}

static int do_step(api *a, void *c, double t, double h) {
    bool event, terminate, early;
    double last;
    if (a->version == 2) return (int)a->do_step2(c, t, h, fmi2True);
    return (int)a->do_step3(c, t, h, fmi3True, &event, &terminate, &early, &last);
}

static int get_state(api *a, void *c, void **s) {
    return a->version == 2 ? (int)a->get_state2(c, s) : (int)a->get_state3(c, s);
}

static int set_state(api *a, void *c, void *s) {
    return a->version == 2 ? (int)a->set_state2(c, s) : (int)a->set_state3(c, s);
}

static int free_state(api *a, void *c, void **s) {
    return a->version == 2 ? (int)a->free_state2(c, s) : (int)a->free_state3(c, s);
}

/* serialize the state and deserialize it into a new one */
static int round_trip(api *a, void *c, void *s, void **out) {
    size_t size = 0;
    char *bytes;
    int status = a->version == 2 ? (int)a->state_size2(c, s, &size) : (int)a->state_size3(c, s, &size);
    if (status) return status;
    bytes = malloc(size);
    if (!bytes) return 4;
    status = a->version == 2 ? (int)a->serialize2(c, s, bytes, size) : (int)a->serialize3(c, s, (fmi3Byte *)bytes, size);
    if (!status)
        status = a->version == 2 ? (int)a->deserialize2(c, bytes, size, out)
                                 : (int)a->deserialize3(c, (const fmi3Byte *)bytes, size, out);
    free(bytes);
    return status;
}

static int reset(api *a, void *c) { return a->version == 2 ? (int)a->reset2(c) : (int)a->reset3(c); }
static int terminate(api *a, void *c) { return a->version == 2 ? (int)a->terminate2(c) : (int)a->terminate3(c); }

static void free_instance(api *a, void *c) {
    if (a->version == 2)
        a->free2(c);
    else
        a->free3(c);
}

/* ---- the run --------------------------------------------------------------------------- */

typedef struct {
    size_t n_cols, n_rows;
    unsigned vr[MAX_ARGS];
    double *values; /* n_rows × n_cols */
} input_table;

static void read_inputs(const char *path, input_table *t) {
    FILE *f = fopen(path, "r");
    char *line = NULL, *p, *end;
    size_t cap = 0, rows_cap = 0;
    if (!f) {
        fprintf(stderr, "cannot open inputs file %s\n", path);
        exit(2);
    }
    if (getline(&line, &cap, f) < 0) {
        fprintf(stderr, "inputs file %s is empty\n", path);
        exit(2);
    }
    for (p = line; t->n_cols < MAX_ARGS; p = end) {
        unsigned long vr = strtoul(p, &end, 10);
        if (end == p) break;
        t->vr[t->n_cols++] = (unsigned)vr;
    }
    while (getline(&line, &cap, f) >= 0) {
        size_t j;
        if (t->n_rows == rows_cap) {
            rows_cap = rows_cap ? 2 * rows_cap : 1024;
            t->values = realloc(t->values, rows_cap * t->n_cols * sizeof(double));
        }
        for (j = 0, p = line; j < t->n_cols; j++, p = end) t->values[t->n_rows * t->n_cols + j] = strtod(p, &end);
        t->n_rows++;
    }
    free(line);
    fclose(f);
}

typedef struct {
    api *a;
    void *c[MAX_INSTANCES];
    int n_instances;
    double step;
    input_table *table;
    unsigned held_vr[MAX_ARGS], out_vr[MAX_ARGS];
    double held[MAX_ARGS];
    size_t n_held, n_out;
} run_ctx;

static int first_failure = 0;

#define CHECK(call)                                                              \
    do {                                                                         \
        int s_ = (call);                                                         \
        if (s_ > 1) {                                                            \
            fprintf(stderr, "%s returned status %d\n", #call, s_);               \
            fflush(stdout);                                                      \
            if (!first_failure) first_failure = s_;                              \
            return s_;                                                           \
        }                                                                        \
    } while (0)

/* steps [from, to) of every instance; outputs of instance 0 into out (rows of n_out) */
static int run_steps(run_ctx *r, long from, long to, double *out, int print) {
    long i;
    int k;
    size_t j;
    double values[MAX_ARGS];
    for (i = from; i < to; i++) {
        for (k = 0; k < r->n_instances; k++) {
            if (r->n_held) CHECK(set_real(r->a, r->c[k], r->held_vr, r->n_held, r->held));
            if (r->table && r->table->n_rows) {
                size_t row = (size_t)i < r->table->n_rows ? (size_t)i : r->table->n_rows - 1;
                CHECK(set_real(r->a, r->c[k], r->table->vr, r->table->n_cols, r->table->values + row * r->table->n_cols));
            }
            CHECK(do_step(r->a, r->c[k], i * r->step, r->step));
            CHECK(get_real(r->a, r->c[k], r->out_vr, r->n_out, values));
            if (k == 0) {
                if (out) memcpy(out + (size_t)i * r->n_out, values, r->n_out * sizeof(double));
                if (print) {
                    printf("%.17g", (i + 1) * r->step);
                    for (j = 0; j < r->n_out; j++) printf(",%.17g", values[j]);
                    printf("\n");
                }
            } else if (out && memcmp(out + (size_t)i * r->n_out, values, r->n_out * sizeof(double)) != 0) {
                fprintf(stderr, "instance %d differs from instance 0 at step %ld\n", k, i);
                if (!first_failure) first_failure = 21;
                return 21;
            }
        }
    }
    return 0;
}

static double now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e9 + ts.tv_nsec;
}

static int apply_start(run_ctx *r, int argc, char **argv, int first_arg) {
    int k, a;
    for (k = 0; k < r->n_instances; k++) {
        for (a = first_arg; a < argc; a++) {
            char *arg = argv[a], *eq = strchr(arg, '='), *colon = strchr(arg, ':');
            unsigned vr = (unsigned)strtoul(colon + 1, NULL, 10);
            const char *value = eq ? eq + 1 : "";
            if (strncmp(arg, "out:", 4) == 0 || strncmp(arg, "in:", 3) == 0) continue;
            if (arg[0] == 'r') {
                double x = atof(value);
                CHECK(set_real(r->a, r->c[k], &vr, 1, &x));
            } else if (arg[0] == 'i') {
                CHECK(set_integer(r->a, r->c[k], vr, atoi(value)));
            } else if (arg[0] == 'b') {
                CHECK(set_boolean(r->a, r->c[k], vr, atoi(value) != 0));
            } else if (arg[0] == 's') {
                CHECK(set_string(r->a, r->c[k], vr, value));
            }
        }
    }
    return 0;
}

static int initialize(run_ctx *r, int argc, char **argv, int first_arg) {
    int k;
    for (k = 0; k < r->n_instances; k++) CHECK(enter_init(r->a, r->c[k]));
    CHECK(apply_start(r, argc, argv, first_arg));
    for (k = 0; k < r->n_instances; k++) CHECK(exit_init(r->a, r->c[k]));
    return 0;
}

static int run(run_ctx *r, long n, int check_state, int timing, int quiet, int argc, char **argv, int first_arg) {
    double *first = calloc((size_t)(n + 1) * (r->n_out + 1), sizeof(double));
    double *again = calloc((size_t)(n + 1) * (r->n_out + 1), sizeof(double));
    double t0, t1;
    int status = 0, k;
    long half = n / 2;
    void *state = NULL, *restored = NULL;
    if (!first || !again) return 4;
    if ((status = initialize(r, argc, argv, first_arg))) goto done;
    t0 = now_ns();
    if (check_state) {
        if ((status = run_steps(r, 0, half, first, !quiet))) goto done;
        if ((status = get_state(r->a, r->c[0], &state))) goto done;
        if ((status = round_trip(r->a, r->c[0], state, &restored))) goto done;
        if ((status = run_steps(r, half, n, first, !quiet))) goto done;
        /* back to the middle from the deserialized state (instance 0; the others restart too) */
        if ((status = set_state(r->a, r->c[0], restored))) goto done;
        for (k = 1; k < r->n_instances; k++)
            if ((status = set_state(r->a, r->c[k], state))) goto done;
        memcpy(again, first, (size_t)half * r->n_out * sizeof(double));
        if ((status = run_steps(r, half, n, again, 0))) goto done;
        if (memcmp(first, again, (size_t)n * r->n_out * sizeof(double)) != 0) {
            fprintf(stderr, "the run from the restored state differs from the first\n");
            status = 20;
            goto done;
        }
        /* Reset: the same parameters and inputs give the same run again */
        for (k = 0; k < r->n_instances; k++)
            if ((status = reset(r->a, r->c[k]))) goto done;
        if ((status = initialize(r, argc, argv, first_arg))) goto done;
        memset(again, 0, (size_t)n * r->n_out * sizeof(double));
        if ((status = run_steps(r, 0, n, again, 0))) goto done;
        if (memcmp(first, again, (size_t)n * r->n_out * sizeof(double)) != 0) {
            fprintf(stderr, "the run after Reset differs from the first\n");
            status = 20;
            goto done;
        }
    } else {
        if ((status = run_steps(r, 0, n, first, !quiet))) goto done;
    }
    t1 = now_ns();
    if (timing)
        fprintf(stderr, "time per DoStep: %.1f ns (%ld steps x %d instance(s))\n",
                (t1 - t0) / ((double)n * r->n_instances * (check_state ? 2.5 : 1.0)), n, r->n_instances);
    for (k = 0; k < r->n_instances; k++)
        if ((status = terminate(r->a, r->c[k]))) goto done;
done:
    if (state) free_state(r->a, r->c[0], &state);
    if (restored) free_state(r->a, r->c[0], &restored);
    free(first);
    free(again);
    if (status && !first_failure) first_failure = status;
    return status;
}

int main(int argc, char **argv) {
    api a;
    run_ctx r;
    input_table table;
    const char *dir, *model, *guid, *inputs = NULL;
    char path[4096], resources[4096];
    long n;
    int arg = 1, check_state = 0, timing = 0, quiet = 0, k, status;
    memset(&a, 0, sizeof a);
    memset(&r, 0, sizeof r);
    memset(&table, 0, sizeof table);
    a.version = 2;
    r.n_instances = 1;
    for (; arg < argc && strncmp(argv[arg], "--", 2) == 0; arg++) {
        if (strcmp(argv[arg], "--fmi") == 0 && arg + 1 < argc)
            a.version = atoi(argv[++arg]);
        else if (strcmp(argv[arg], "--instances") == 0 && arg + 1 < argc)
            r.n_instances = atoi(argv[++arg]);
        else if (strcmp(argv[arg], "--inputs") == 0 && arg + 1 < argc)
            inputs = argv[++arg];
        else if (strcmp(argv[arg], "--check-state") == 0)
            check_state = 1;
        else if (strcmp(argv[arg], "--time") == 0)
            timing = 1;
        else if (strcmp(argv[arg], "--quiet") == 0)
            quiet = 1;
        else {
            fprintf(stderr, "unknown option %s\n", argv[arg]);
            return 2;
        }
    }
    if (argc - arg < 5 || (a.version != 2 && a.version != 3) || r.n_instances < 1 || r.n_instances > MAX_INSTANCES) {
        fprintf(stderr, "usage: %s [--fmi 2|3] [--instances K] [--inputs FILE] [--check-state] [--time] [--quiet] "
                "DIR MODEL_ID TOKEN STEP N [r:|i:|b:|s:|in:VR=VALUE] [out:VR]\n", argv[0]);
        return 2;
    }
    dir = argv[arg];
    model = argv[arg + 1];
    guid = argv[arg + 2];
    r.step = atof(argv[arg + 3]);
    n = atol(argv[arg + 4]);
    arg += 5;
    snprintf(path, sizeof path, "%s/binaries/%s/%s.so", dir, a.version == 2 ? "linux64" : "x86_64-linux", model);
    if (a.version == 2)
        snprintf(resources, sizeof resources, "file://%s/resources", dir);
    else
        snprintf(resources, sizeof resources, "%s/resources/", dir);
    for (k = arg; k < argc; k++) {
        char *colon = strchr(argv[k], ':'), *eq = strchr(argv[k], '=');
        if (!colon || (!eq && strncmp(argv[k], "out:", 4) != 0)) {
            fprintf(stderr, "bad argument %s\n", argv[k]);
            return 2;
        }
        if (strncmp(argv[k], "out:", 4) == 0 && r.n_out < MAX_ARGS)
            r.out_vr[r.n_out++] = (unsigned)strtoul(colon + 1, NULL, 10);
        else if (strncmp(argv[k], "in:", 3) == 0 && r.n_held < MAX_ARGS) {
            r.held_vr[r.n_held] = (unsigned)strtoul(colon + 1, NULL, 10);
            r.held[r.n_held++] = atof(eq + 1);
        }
    }
    if (inputs) {
        read_inputs(inputs, &table);
        r.table = &table;
    }
    load(&a, path);
    r.a = &a;
    for (k = 0; k < r.n_instances; k++) {
        r.c[k] = instantiate(&a, k, guid, resources);
        if (!r.c[k]) {
            fprintf(stderr, "instantiate failed\n");
            return 12;
        }
    }
    status = run(&r, n, check_state, timing, quiet, argc, argv, arg);
    for (k = 0; k < r.n_instances; k++) free_instance(&a, r.c[k]);
    free(table.values);
    dlclose(a.lib);
    fflush(stdout);
    return status ? status : first_failure;
}
