/* Embedding CPython for a Python-based FMU (see biso_python.h). */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE /* RTLD_DEFAULT */
#endif
#include "biso_python.h"

#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <wchar.h>

typedef void PyObject;
typedef int PyGILState_STATE;
typedef void PyThreadState;

/* the part of the Python C API the shell uses (all in the stable ABI but the home setting) */
static struct {
    int (*Py_IsInitialized)(void);
    void (*Py_InitializeEx)(int);
    PyThreadState *(*PyEval_SaveThread)(void);
    PyGILState_STATE (*PyGILState_Ensure)(void);
    void (*PyGILState_Release)(PyGILState_STATE);
    const char *(*Py_GetVersion)(void);
    PyObject *(*PyImport_ImportModule)(const char *);
    PyObject *(*PyObject_GetAttrString)(PyObject *, const char *);
    PyObject *(*PyObject_CallObject)(PyObject *, PyObject *);
    PyObject *(*Py_VaBuildValue)(const char *, va_list);
    PyObject *(*PyObject_Str)(PyObject *);
    const char *(*PyUnicode_AsUTF8)(PyObject *);
    long long (*PyLong_AsLongLong)(PyObject *);
    void (*Py_DecRef)(PyObject *);
    PyObject *(*PyErr_Occurred)(void);
    void (*PyErr_Fetch)(PyObject **, PyObject **, PyObject **);
    void (*PyErr_Clear)(void);
    /* optional: only to point a Python we start at its installation */
    void (*Py_SetPythonHome)(const wchar_t *);
    wchar_t *(*Py_DecodeLocale)(const char *, size_t *);
} api;

static pthread_mutex_t start_lock = PTHREAD_MUTEX_INITIALIZER;
static int api_ready = 0;
static wchar_t *python_home = NULL; /* kept for the interpreter's lifetime (Py_SetPythonHome) */

void bp_message(bp_instance *inst, int status, const char *message) {
    if (inst->log) inst->log(inst, status, status >= BP_ERROR ? "logStatusError" : "logEvents", message);
}

static void messagef(bp_instance *inst, int status, const char *fmt, ...) {
    char text[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    bp_message(inst, status, text);
}

/* the bridge logs through this (its address is passed at instantiation) */
static void bp_log_trampoline(void *context, int status, const char *category, const char *message) {
    bp_instance *inst = (bp_instance *)context;
    if (inst && inst->log) inst->log(inst, status, category ? category : "logEvents", message ? message : "");
}

/* ---- resources/python.txt: key=value lines written by the build ------------------------------- */

typedef struct {
    char libpython[1024], home[1024], version[32];
    char paths[16][1024];
    int n_paths;
} python_config;

static void read_config(const char *resource_dir, python_config *cfg) {
    char file[1200], line[1100];
    FILE *fh;
    memset(cfg, 0, sizeof *cfg);
    if (!resource_dir) return;
    snprintf(file, sizeof file, "%s/python.txt", resource_dir);
    fh = fopen(file, "r");
    if (!fh) return;
    while (fgets(line, sizeof line, fh)) {
        char *eq = strchr(line, '='), *end = line + strlen(line);
        while (end > line && (end[-1] == '\n' || end[-1] == '\r')) *--end = 0;
        if (!eq) continue;
        *eq = 0;
        if (strcmp(line, "libpython") == 0)
            snprintf(cfg->libpython, sizeof cfg->libpython, "%s", eq + 1);
        else if (strcmp(line, "home") == 0)
            snprintf(cfg->home, sizeof cfg->home, "%s", eq + 1);
        else if (strcmp(line, "version") == 0)
            snprintf(cfg->version, sizeof cfg->version, "%s", eq + 1);
        else if (strcmp(line, "path") == 0 && cfg->n_paths < 16)
            snprintf(cfg->paths[cfg->n_paths++], sizeof cfg->paths[0], "%s", eq + 1);
    }
    fclose(fh);
}

/* ---- finding and starting Python ------------------------------------------------------------- */

static int resolve(void *handle, bp_instance *inst) {
#define SYM(name, required)                                                                    \
    do {                                                                                       \
        *(void **)&api.name = dlsym(handle, #name);                                            \
        if (!api.name && required) {                                                           \
            messagef(inst, BP_ERROR, "instantiation: the Python library has no %s", #name);   \
            return -1;                                                                         \
        }                                                                                      \
    } while (0)
    SYM(Py_IsInitialized, 1);
    SYM(Py_InitializeEx, 1);
    SYM(PyEval_SaveThread, 1);
    SYM(PyGILState_Ensure, 1);
    SYM(PyGILState_Release, 1);
    SYM(Py_GetVersion, 1);
    SYM(PyImport_ImportModule, 1);
    SYM(PyObject_GetAttrString, 1);
    SYM(PyObject_CallObject, 1);
    SYM(Py_VaBuildValue, 1);
    SYM(PyObject_Str, 1);
    SYM(PyUnicode_AsUTF8, 1);
    SYM(PyLong_AsLongLong, 1);
    SYM(Py_DecRef, 1);
    SYM(PyErr_Occurred, 1);
    SYM(PyErr_Fetch, 1);
    SYM(PyErr_Clear, 1);
    SYM(Py_SetPythonHome, 0);
    SYM(Py_DecodeLocale, 0);
#undef SYM
    return 0;
}

/* Python's API in this process: the host's (already loaded), else the configured libpython */
static int start_python(bp_instance *inst, const python_config *cfg) {
    const char *library;
    void *handle;
    if (api_ready) return 0;
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized")) {
        if (resolve(RTLD_DEFAULT, inst)) return -1;
    } else {
        library = getenv("BISO_COSIM_LIBPYTHON");
        if (!library || !*library) library = cfg->libpython;
        if (!*library) {
            bp_message(inst, BP_ERROR,
                       "instantiation: this FMU runs on Python and the host has none loaded; the Python that built "
                       "it has no shared library (built without --enable-shared), so a native host cannot load one: "
                       "load the FMU from that Python (e.g. FMPy), or build it with a Python that has "
                       "libpython3.X.so (or set BISO_COSIM_LIBPYTHON to one of the same version)");
            return -1;
        }
        handle = dlopen(library, RTLD_NOW | RTLD_GLOBAL); /* global: extension modules link against it */
        if (!handle) {
            messagef(inst, BP_ERROR, "instantiation: cannot load the Python library %s (%s); set BISO_COSIM_LIBPYTHON "
                     "to the libpython of Python %s", library, dlerror(), cfg->version[0] ? cfg->version : "3.X");
            return -1;
        }
        if (resolve(handle, inst)) return -1;
    }
    if (!api.Py_IsInitialized()) {
        if (cfg->home[0] && !getenv("PYTHONHOME") && api.Py_SetPythonHome && api.Py_DecodeLocale) {
            python_home = api.Py_DecodeLocale(cfg->home, NULL);
            if (python_home) api.Py_SetPythonHome(python_home);
        }
        api.Py_InitializeEx(0); /* no signal handlers: the host owns them */
        if (!api.Py_IsInitialized()) {
            bp_message(inst, BP_ERROR, "instantiation: Python did not start");
            return -1;
        }
        api.PyEval_SaveThread(); /* release the GIL for good; each call takes it (never finalised) */
    }
    api_ready = 1;
    return 0;
}

/* the pending Python error as text (cleared); GIL held */
static void python_error(bp_instance *inst, const char *where) {
    PyObject *type = NULL, *value = NULL, *tb = NULL, *text;
    const char *utf8 = NULL;
    api.PyErr_Fetch(&type, &value, &tb);
    text = value ? api.PyObject_Str(value) : (type ? api.PyObject_Str(type) : NULL);
    if (text) utf8 = api.PyUnicode_AsUTF8(text);
    messagef(inst, BP_ERROR, "%s: %s", where, utf8 ? utf8 : "a Python error without a message");
    if (text) api.Py_DecRef(text);
    if (type) api.Py_DecRef(type);
    if (value) api.Py_DecRef(value);
    if (tb) api.Py_DecRef(tb);
    api.PyErr_Clear();
}

static PyObject *call_object(PyObject *callable, const char *format, va_list ap) {
    PyObject *args = api.Py_VaBuildValue(format, ap), *result;
    if (!args) return NULL;
    result = api.PyObject_CallObject(callable, args);
    api.Py_DecRef(args);
    return result;
}

static PyObject *call_attr(PyObject *object, const char *name, const char *format, ...) {
    PyObject *callable = api.PyObject_GetAttrString(object, name), *result;
    va_list ap;
    if (!callable) return NULL;
    va_start(ap, format);
    result = call_object(callable, format, ap);
    va_end(ap);
    api.Py_DecRef(callable);
    return result;
}

static const char *EMBEDDED = "biso_cosim.fmu._embedded";

/* import the bridge module; when the host's path lacks biso_cosim, add the build's
 * site-packages (site.addsitedir: their .pth files too) and try again. GIL held. */
static PyObject *import_bridge(bp_instance *inst, const python_config *cfg) {
    PyObject *module = api.PyImport_ImportModule(EMBEDDED), *site;
    int i;
    if (module || cfg->n_paths == 0) return module;
    api.PyErr_Clear();
    site = api.PyImport_ImportModule("site");
    if (!site) return NULL;
    for (i = 0; i < cfg->n_paths; i++) {
        PyObject *r = call_attr(site, "addsitedir", "(s)", cfg->paths[i]);
        if (!r) {
            api.Py_DecRef(site);
            return NULL;
        }
        api.Py_DecRef(r);
    }
    api.Py_DecRef(site);
    (void)inst;
    return api.PyImport_ImportModule(EMBEDDED);
}

int bp_instantiate(bp_instance *inst, const char *fmu, const char *resources, const char *resource_dir,
                   int fmi_version, int logging_on) {
    python_config cfg;
    PyGILState_STATE gil;
    PyObject *module, *bridge = NULL;
    read_config(resource_dir, &cfg);
    pthread_mutex_lock(&start_lock);
    if (start_python(inst, &cfg)) {
        pthread_mutex_unlock(&start_lock);
        return -1;
    }
    pthread_mutex_unlock(&start_lock);
    if (cfg.version[0] && strncmp(api.Py_GetVersion(), cfg.version, strlen(cfg.version)) != 0) {
        messagef(inst, BP_ERROR, "instantiation: this FMU was built for Python %s; the Python in this process is %.20s",
                 cfg.version, api.Py_GetVersion());
        return -1;
    }
    gil = api.PyGILState_Ensure();
    module = import_bridge(inst, &cfg);
    if (!module) {
        python_error(inst, "instantiation: cannot import biso_cosim (the Python in this process must have it, or "
                           "the site-packages named in resources/python.txt)");
    } else {
        bridge = call_attr(module, "instantiate", "(sssiKKi)", fmu, inst->name, resources ? resources : "",
                           fmi_version, (unsigned long long)(uintptr_t)&bp_log_trampoline,
                           (unsigned long long)(uintptr_t)inst, logging_on);
        if (!bridge) python_error(inst, "instantiation");
        api.Py_DecRef(module);
    }
    api.PyGILState_Release(gil);
    inst->bridge = bridge;
    return bridge ? 0 : -1;
}

long long bp_call(bp_instance *inst, const char *method, const char *format, ...) {
    PyGILState_STATE gil;
    PyObject *callable, *result = NULL;
    long long value = -1;
    va_list ap;
    if (!inst->bridge) return -1;
    gil = api.PyGILState_Ensure();
    callable = api.PyObject_GetAttrString(inst->bridge, method);
    if (callable) {
        va_start(ap, format);
        result = call_object(callable, format, ap);
        va_end(ap);
        api.Py_DecRef(callable);
    }
    if (result) {
        value = api.PyLong_AsLongLong(result);
        api.Py_DecRef(result);
        if (value == -1 && api.PyErr_Occurred()) python_error(inst, method);
    } else {
        python_error(inst, method);
        value = -1;
    }
    api.PyGILState_Release(gil);
    return value;
}

int bp_status(long long result) { return result < 0 || result > BP_FATAL ? BP_ERROR : (int)result; }

void bp_free(bp_instance *inst) {
    PyGILState_STATE gil;
    if (!inst->bridge) return;
    bp_call(inst, "free", "()");
    gil = api.PyGILState_Ensure();
    api.Py_DecRef(inst->bridge);
    api.PyGILState_Release(gil);
    inst->bridge = NULL;
}
