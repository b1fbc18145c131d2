/* A compiled per-sample step called from Python in one C call (optional module).

   Why C: a per-sample call through the compiler's dispatcher, or through ctypes, costs more
   than a whole per-sample update of the detectors we are compared with (docs/llr.md,
   "Streaming call"). This file holds no algorithm, only the call:

   - ``StepOwner``, a base class whose instances hold the address of a compiled step
     ``int64 step(double *fs, int64 n_fs, int64 *ints, int64 n_ints, double t, double w,
     double f)`` (core/llr_cstep.py) and the two state arrays it runs on (their buffers
     and references held while armed): ``_step_arm(address, fs, ints)``,
     ``_step_disarm()``, ``_step_armed()``.
   - ``CompiledUpdate(python_update, on_flags_name)``, a class attribute that behaves as
     the method ``python_update`` (same signature through ``__wrapped__``, same doc). Called
     on an armed StepOwner with exactly three positional Python floats it calls the step:
     0 flags -> a new empty list; flags > 0 -> ``self.<on_flags_name>(flags)``; flags < 0
     (the step raised) -> ArithmeticError. Any other call is ``python_update(self, ...)``.
*/
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include "structmember.h"

typedef int64_t (*step_fn)(double *, int64_t, int64_t *, int64_t, double, double, double);

typedef struct {
    PyObject_HEAD
    step_fn step;
    Py_buffer fs;
    Py_buffer ints;
} StepOwner;

typedef struct {
    PyObject_HEAD
    PyObject *python;     /* the Python method it stands for */
    PyObject *on_flags;   /* name of the method called with non-zero flags */
    vectorcallfunc vectorcall;
} CompiledUpdate;

static PyTypeObject StepOwnerType;

/* -- StepOwner ----------------------------------------------------------------------- */

static void
disarm(StepOwner *self)
{
    if (self->step != NULL) {
        self->step = NULL;
        PyBuffer_Release(&self->fs);
        PyBuffer_Release(&self->ints);
    }
}

static int
get_buffer(PyObject *array, Py_buffer *view, int floats)
{
    if (PyObject_GetBuffer(array, view, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE | PyBUF_FORMAT))
        return -1;
    const char *format = view->format == NULL ? "B" : view->format;
    if (view->itemsize != 8 || view->ndim != 1
            || strchr(floats ? "d" : "qlQL", format[0]) == NULL || format[1] != '\0') {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_TypeError, "%s: a writable 1-d contiguous array of 8-byte %s "
                     "expected", floats ? "fs" : "ints", floats ? "floats" : "integers");
        return -1;
    }
    return 0;
}

static PyObject *
step_arm(StepOwner *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer fs, ints;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "_step_arm(address, fs, ints)");
        return NULL;
    }
    void *address = PyLong_AsVoidPtr(args[0]);
    if (address == NULL) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "_step_arm: null address");
        return NULL;
    }
    if (get_buffer(args[1], &fs, 1))
        return NULL;
    if (get_buffer(args[2], &ints, 0)) {
        PyBuffer_Release(&fs);
        return NULL;
    }
    disarm(self);
    self->fs = fs;
    self->ints = ints;
    self->step = (step_fn)address;
    Py_RETURN_NONE;
}

static PyObject *
step_disarm(StepOwner *self, PyObject *Py_UNUSED(ignored))
{
    disarm(self);
    Py_RETURN_NONE;
}

static PyObject *
step_armed(StepOwner *self, PyObject *Py_UNUSED(ignored))
{
    return PyBool_FromLong(self->step != NULL);
}

static int
owner_traverse(StepOwner *self, visitproc visit, void *arg)
{
    if (self->step != NULL) {
        Py_VISIT(self->fs.obj);
        Py_VISIT(self->ints.obj);
    }
    return 0;
}

static int
owner_clear(StepOwner *self)
{
    disarm(self);
    return 0;
}

static void
owner_dealloc(StepOwner *self)
{
    PyObject_GC_UnTrack(self);
    disarm(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyMethodDef owner_methods[] = {
    {"_step_arm", (PyCFunction)(void (*)(void))step_arm, METH_FASTCALL,
     "_step_arm(address, fs, ints): call the step at address on these arrays from now on."},
    {"_step_disarm", (PyCFunction)step_disarm, METH_NOARGS,
     "Stop calling the compiled step: every update takes the Python path."},
    {"_step_armed", (PyCFunction)step_armed, METH_NOARGS,
     "Return True while a compiled step is armed."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject StepOwnerType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "rwa_monitor.core._stepcall.StepOwner",
    .tp_doc = "Base class holding an armed compiled per-sample step and its state arrays.",
    .tp_basicsize = sizeof(StepOwner),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE | Py_TPFLAGS_HAVE_GC,
    .tp_new = PyType_GenericNew,
    .tp_traverse = (traverseproc)owner_traverse,
    .tp_clear = (inquiry)owner_clear,
    .tp_dealloc = (destructor)owner_dealloc,
    .tp_methods = owner_methods,
};

/* -- CompiledUpdate ------------------------------------------------------------------ */

static PyObject *
compiled_call(CompiledUpdate *self, PyObject *const *args, size_t nargsf, PyObject *kwnames)
{
    Py_ssize_t nargs = PyVectorcall_NARGS(nargsf);
    if (nargs == 4 && kwnames == NULL && PyObject_TypeCheck(args[0], &StepOwnerType)) {
        StepOwner *owner = (StepOwner *)args[0];
        if (owner->step != NULL && PyFloat_Check(args[1]) && PyFloat_Check(args[2])
                && PyFloat_Check(args[3])) {
            int64_t flags = owner->step(
                (double *)owner->fs.buf, owner->fs.shape[0],
                (int64_t *)owner->ints.buf, owner->ints.shape[0],
                PyFloat_AS_DOUBLE(args[1]), PyFloat_AS_DOUBLE(args[2]),
                PyFloat_AS_DOUBLE(args[3]));
            if (flags == 0)
                return PyList_New(0);
            if (flags < 0) {
                PyErr_SetString(PyExc_ArithmeticError,
                                "the compiled step raised (a division by zero) at this sample");
                return NULL;
            }
            PyObject *value = PyLong_FromLongLong(flags);
            if (value == NULL)
                return NULL;
            PyObject *out = PyObject_CallMethodOneArg(args[0], self->on_flags, value);
            Py_DECREF(value);
            return out;
        }
    }
    return PyObject_Vectorcall(self->python, args, nargsf, kwnames);
}

static PyObject *
compiled_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    PyObject *python, *on_flags;
    if (kwargs != NULL && PyDict_GET_SIZE(kwargs)) {
        PyErr_SetString(PyExc_TypeError, "CompiledUpdate(python_update, on_flags_name)");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "OU:CompiledUpdate", &python, &on_flags))
        return NULL;
    if (!PyCallable_Check(python)) {
        PyErr_SetString(PyExc_TypeError, "CompiledUpdate: python_update must be callable");
        return NULL;
    }
    CompiledUpdate *self = (CompiledUpdate *)type->tp_alloc(type, 0);
    if (self == NULL)
        return NULL;
    Py_INCREF(python);
    self->python = python;
    Py_INCREF(on_flags);
    PyUnicode_InternInPlace(&on_flags);
    self->on_flags = on_flags;
    self->vectorcall = (vectorcallfunc)compiled_call;
    return (PyObject *)self;
}

static PyObject *
compiled_get(PyObject *self, PyObject *obj, PyObject *Py_UNUSED(type))
{
    if (obj == NULL || obj == Py_None) {
        Py_INCREF(self);
        return self;
    }
    return PyMethod_New(self, obj);
}

static PyObject *
compiled_getattro(CompiledUpdate *self, PyObject *name)
{
    /* __name__, __qualname__, __annotations__ ... of the Python method (__doc__, __module__:
       getset below, as the type has its own). */
    PyObject *out = PyObject_GenericGetAttr((PyObject *)self, name);
    if (out != NULL || !PyErr_ExceptionMatches(PyExc_AttributeError))
        return out;
    PyErr_Clear();
    return PyObject_GetAttr(self->python, name);
}

static int
compiled_traverse(CompiledUpdate *self, visitproc visit, void *arg)
{
    Py_VISIT(self->python);
    return 0;
}

static int
compiled_clear(CompiledUpdate *self)
{
    Py_CLEAR(self->python);
    return 0;
}

static void
compiled_dealloc(CompiledUpdate *self)
{
    PyObject_GC_UnTrack(self);
    Py_CLEAR(self->python);
    Py_CLEAR(self->on_flags);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *
compiled_wrapped_attr(CompiledUpdate *self, void *name)
{
    return PyObject_GetAttrString(self->python, (const char *)name);
}

static PyMemberDef compiled_members[] = {
    {"__wrapped__", T_OBJECT, offsetof(CompiledUpdate, python), READONLY,
     "The Python method this one stands for."},
    {NULL, 0, 0, 0, NULL},
};

static PyGetSetDef compiled_getset[] = {
    {"__doc__", (getter)compiled_wrapped_attr, NULL, NULL, "__doc__"},
    {"__module__", (getter)compiled_wrapped_attr, NULL, NULL, "__module__"},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject CompiledUpdateType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "rwa_monitor.core._stepcall.CompiledUpdate",
    .tp_basicsize = sizeof(CompiledUpdate),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC | Py_TPFLAGS_HAVE_VECTORCALL
        | Py_TPFLAGS_METHOD_DESCRIPTOR,
    .tp_new = compiled_new,
    .tp_call = PyVectorcall_Call,
    .tp_vectorcall_offset = offsetof(CompiledUpdate, vectorcall),
    .tp_descr_get = compiled_get,
    .tp_getattro = (getattrofunc)compiled_getattro,
    .tp_traverse = (traverseproc)compiled_traverse,
    .tp_clear = (inquiry)compiled_clear,
    .tp_dealloc = (destructor)compiled_dealloc,
    .tp_members = compiled_members,
    .tp_getset = compiled_getset,
};

/* -- module -------------------------------------------------------------------------- */

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_stepcall",
    "A compiled per-sample step called from Python in one C call (core/_stepcall.c).",
    -1, NULL,
};

PyMODINIT_FUNC
PyInit__stepcall(void)
{
    if (PyType_Ready(&StepOwnerType) < 0 || PyType_Ready(&CompiledUpdateType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddObjectRef(m, "StepOwner", (PyObject *)&StepOwnerType) < 0
            || PyModule_AddObjectRef(m, "CompiledUpdate", (PyObject *)&CompiledUpdateType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
