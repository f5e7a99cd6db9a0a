/* The C shell of a Python-based FMU (BisoVehicle): CPython embedded without linking it.
 *
 * The Python C API is looked up at run time (dlsym), so one binary serves
 *   - a Python host (FMPy, libcosimpy, ...): the host's interpreter is used, whether its
 *     libpython is shared (libpython3.X.so) or linked into the executable (a static build
 *     exports the API for its extension modules);
 *   - a native host (a C master, libcosim's command line ...): the shared libpython named in
 *     resources/python.txt (the one of the Python that built the FMU; BISO_COSIM_LIBPYTHON
 *     overrides it) is loaded and initialised once. A Python built without a shared library
 *     cannot serve a native host: the instantiation then fails with a message saying so.
 * Python is initialised only if nobody has, never finalised (an FMU must not end an
 * interpreter the host or another instance may still use), and every call holds the GIL
 * for its duration only (PyGILState_Ensure/Release), from whichever thread the host calls.
 *
 * Each FMI call is forwarded to a method of the instance's Python bridge
 * (biso_cosim.fmu._embedded.Bridge) with its arguments as numbers; the bridge returns an
 * FMI status and logs through bp_log_trampoline. */
#ifndef BISO_PYTHON_H
#define BISO_PYTHON_H

#include <stddef.h>

enum { BP_OK = 0, BP_WARNING = 1, BP_DISCARD = 2, BP_ERROR = 3, BP_FATAL = 4 };
/* kinds of value arrays (biso_cosim.fmu._embedded._KINDS) */
enum { BP_FLOAT64 = 0, BP_INT32 = 1, BP_BOOL_INT = 2, BP_BOOL_BYTE = 3, BP_STRING = 4 };

struct bp_instance;
typedef void (*bp_log_function)(struct bp_instance *inst, int status, const char *category, const char *message);

typedef struct bp_instance {
    void *bridge;            /* the Python Bridge (a PyObject *) */
    char name[256];
    bp_log_function log;     /* the shell's: into the host's logger */
    void *shell;             /* the shell's callbacks and environment */
    double time;             /* the time after the last successful step */
} bp_instance;

/* Create the Python bridge of an instance (Python started first if needed). fmu: the model
 * identifier; resources: FMI 2.0's resource URI or FMI 3.0's path; resource_dir: a file
 * path of the resources folder (to read python.txt). 0: ready; else the reason was logged. */
int bp_instantiate(bp_instance *inst, const char *fmu, const char *resources, const char *resource_dir,
                   int fmi_version, int logging_on);
/* Call a method of the bridge: format as Py_BuildValue's, always a tuple "(...)". Returns the
 * method's integer result, or -1 (the Python error logged) when it raised. */
long long bp_call(bp_instance *inst, const char *method, const char *format, ...);
/* A status from bp_call's result (-1: error). */
int bp_status(long long result);
/* FreeInstance: the bridge's free(), then its reference dropped. */
void bp_free(bp_instance *inst);
/* log a message of the shell itself through the instance's logger */
void bp_message(bp_instance *inst, int status, const char *message);

#endif
