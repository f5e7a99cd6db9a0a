/* A minimal native FMI 2.0 co-simulation master (no Python in this program).
 *
 * It loads an extracted FMU's binary with dlopen, instantiates it, sets start values,
 * initializes, steps with a fixed step size and prints the requested Real outputs as CSV
 * (one line per step, time first). Messages the FMU logs go to stderr.
 *
 * Build (the FMI 2.0 headers ship with FMPy in fmpy/c-code):
 *     cc -O2 -I<fmpy>/c-code -o fmu_master fmu_master.c -ldl
 * Run (a pythonfmu FMU needs the Python library preloaded and its packages on the path):
 *     LD_PRELOAD=libpython3.11.so PYTHONPATH=<site-packages> \
 *     ./fmu_master DIR MODEL_ID GUID STEP N [r:VR=VALUE] [i:VR=VALUE] [b:VR=0|1] [s:VR=TEXT] [in:VR=VALUE] [out:VR]
 *
 * r:/i:/b:/s: set Real/Integer/Boolean/String start values before initialization; in:VR=VALUE
 * sets a Real input before every step (held); out:VR prints a Real output after every step.
 * The exit code is 0 when every call returned fmi2OK, else the status of the first failure.
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h"

#define MAX_ARGS 256

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list args;
    (void)env;
    fprintf(stderr, "[%s] status %d %s: ", instance, (int)status, category ? category : "");
    va_start(args, message);
    vfprintf(stderr, message, args);
    va_end(args);
    fprintf(stderr, "\n");
}

static void *symbol(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "missing FMI function %s\n", name);
        exit(10);
    }
    return f;
}

#define CHECK(call)                                                              \
    do {                                                                         \
        fmi2Status s_ = (call);                                                  \
        if (s_ != fmi2OK) {                                                      \
            fprintf(stderr, "%s returned status %d\n", #call, (int)s_);          \
            fflush(stdout);                                                      \
            _exit((int)s_);                                                      \
            return (int)s_;                                                      \
        }                                                                        \
    } while (0)

int main(int argc, char **argv) {
    if (argc < 6) {
        fprintf(stderr, "usage: %s DIR MODEL_ID GUID STEP N [r:|i:|b:|s:|in:VR=VALUE] [out:VR]\n", argv[0]);
        return 2;
    }
    const char *dir = argv[1], *model = argv[2], *guid = argv[3];
    double step = atof(argv[4]);
    long n = atol(argv[5]);
    char path[4096], resources[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, model);
    snprintf(resources, sizeof resources, "file://%s/resources", dir);

    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen failed: %s\n", dlerror());
        return 11;
    }
    fmi2InstantiateTYPE *instantiate = symbol(lib, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = symbol(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter = symbol(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exit_init = symbol(lib, "fmi2ExitInitializationMode");
    fmi2SetRealTYPE *set_real = symbol(lib, "fmi2SetReal");
    fmi2SetIntegerTYPE *set_integer = symbol(lib, "fmi2SetInteger");
    fmi2SetBooleanTYPE *set_boolean = symbol(lib, "fmi2SetBoolean");
    fmi2SetStringTYPE *set_string = symbol(lib, "fmi2SetString");
    fmi2GetRealTYPE *get_real = symbol(lib, "fmi2GetReal");
    fmi2DoStepTYPE *do_step = symbol(lib, "fmi2DoStep");
    fmi2TerminateTYPE *terminate = symbol(lib, "fmi2Terminate");
    fmi2FreeInstanceTYPE *free_instance = symbol(lib, "fmi2FreeInstance");

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("native", fmi2CoSimulation, guid, resources, &callbacks, fmi2False, fmi2True);
    if (!c) {
        fprintf(stderr, "fmi2Instantiate failed\n");
        return 12;
    }
    CHECK(setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    CHECK(enter(c));

    fmi2ValueReference in_vr[MAX_ARGS], out_vr[MAX_ARGS];
    fmi2Real in_value[MAX_ARGS], out_value[MAX_ARGS];
    size_t n_in = 0, n_out = 0;
    for (int k = 6; k < argc; k++) {
        char *arg = argv[k], *eq = strchr(arg, '=');
        char *colon = strchr(arg, ':');
        if (!colon) {
            fprintf(stderr, "bad argument %s\n", arg);
            return 2;
        }
        fmi2ValueReference vr = (fmi2ValueReference)strtoul(colon + 1, NULL, 10);
        const char *value = eq ? eq + 1 : "";
        if (strncmp(arg, "out:", 4) == 0 && n_out < MAX_ARGS) {
            out_vr[n_out++] = vr;
        } else if (strncmp(arg, "in:", 3) == 0 && n_in < MAX_ARGS) {
            in_vr[n_in] = vr;
            in_value[n_in++] = atof(value);
        } else if (arg[0] == 'r') {
            fmi2Real x = atof(value);
            CHECK(set_real(c, &vr, 1, &x));
        } else if (arg[0] == 'i') {
            fmi2Integer x = atoi(value);
            CHECK(set_integer(c, &vr, 1, &x));
        } else if (arg[0] == 'b') {
            fmi2Boolean x = atoi(value) != 0;
            CHECK(set_boolean(c, &vr, 1, &x));
        } else if (arg[0] == 's') {
            fmi2String x = value;
            CHECK(set_string(c, &vr, 1, &x));
        } else {
            fprintf(stderr, "bad argument %s\n", arg);
            return 2;
        }
    }
    CHECK(exit_init(c));

    for (long i = 0; i < n; i++) {
        if (n_in) CHECK(set_real(c, in_vr, n_in, in_value));
        CHECK(do_step(c, i * step, step, fmi2True));
        CHECK(get_real(c, out_vr, n_out, out_value));
        printf("%.17g", (i + 1) * step);
        for (size_t j = 0; j < n_out; j++) printf(",%.17g", out_value[j]);
        printf("\n");
    }
    CHECK(terminate(c));
    free_instance(c);
    /* pythonfmu finalizes its Python interpreter from the FMU library's destructor, on a
     * thread of its own, while the exit handlers of the other libraries run: with native
     * extension modules loaded (scipy's libgfortran here) that race can corrupt the heap.
     * All work is done and flushed: leave without the exit handlers. */
    fflush(stdout);
    fflush(stderr);
    _exit(0);
}
