/* The packet walk and gather of telemetry/ccsds_scan.py in C (optional module).

   Why C: following the length fields of a packet file is a sequential loop, a few
   instructions per packet. The compiler used elsewhere (numba) runs it as fast, but a
   process pays about 2 s to import it and prepare its first call, more than `rwa-monitor
   detect` spends on a 3 h CSV file; this module loads in a millisecond. Same arguments,
   results and checks as the plain version in ccsds_scan.py (test/test_ccsds_scan.py proves
   them equal); ccsds_scan uses the plain version when this module is not built.

   - ``walk(buf, start, end, wanted, counts, offsets, lengths, words) -> (n, pos)``
   - ``gather(buf, offsets, length, out) -> None``
   Buffers: ``buf`` uint8, ``wanted`` bool (2048), ``counts`` int64 (2049), ``offsets``,
   ``lengths``, ``words`` int64, ``out`` uint8 (n * length), all C-contiguous; checked.
*/
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#define APIDS 2048

static int
get(PyObject *obj, Py_buffer *view, Py_ssize_t itemsize, int writable, const char *what)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT
                           | (writable ? PyBUF_WRITABLE : 0)) < 0)
        return -1;
    if (view->itemsize != itemsize) {
        PyErr_Format(PyExc_TypeError, "%s: items of %zd bytes expected", what, itemsize);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static PyObject *
walk(PyObject *self, PyObject *args)
{
    PyObject *objs[6];
    Py_ssize_t start, end;
    Py_buffer buf, wanted, counts, offsets, lengths, words;
    if (!PyArg_ParseTuple(args, "OnnOOOOO", &objs[0], &start, &end, &objs[1], &objs[2],
                          &objs[3], &objs[4], &objs[5]))
        return NULL;
    if (get(objs[0], &buf, 1, 0, "buf") < 0)
        return NULL;
    if (get(objs[1], &wanted, 1, 0, "wanted") < 0)
        goto release_buf;
    if (get(objs[2], &counts, 8, 1, "counts") < 0)
        goto release_wanted;
    if (get(objs[3], &offsets, 8, 1, "offsets") < 0)
        goto release_counts;
    if (get(objs[4], &lengths, 8, 1, "lengths") < 0)
        goto release_offsets;
    if (get(objs[5], &words, 8, 1, "words") < 0)
        goto release_lengths;
    if (start < 0 || end < start || end > buf.len || wanted.len < APIDS
            || counts.len < 8 * (APIDS + 1) || lengths.len < offsets.len
            || words.len < offsets.len) {
        PyErr_SetString(PyExc_ValueError, "walk: bad bounds or buffer sizes");
        goto release_all;
    }
    const uint8_t *b = (const uint8_t *)buf.buf;
    const uint8_t *want = (const uint8_t *)wanted.buf;
    int64_t *count = (int64_t *)counts.buf;
    int64_t *off = (int64_t *)offsets.buf, *len = (int64_t *)lengths.buf;
    int64_t *word = (int64_t *)words.buf;
    Py_ssize_t capacity = offsets.len / 8, n = 0, pos = start;
    Py_BEGIN_ALLOW_THREADS
    while (pos + 6 <= end && n < capacity) {
        Py_ssize_t length = ((Py_ssize_t)b[pos + 4] << 8 | b[pos + 5]) + 7;
        if (pos + length > end)
            break;
        if (b[pos] >> 5) {
            count[APIDS] += 1;
        } else {
            int apid = (b[pos] & 7) << 8 | b[pos + 1];
            count[apid] += 1;
            if (want[apid]) {
                off[n] = pos;
                len[n] = length;
                word[n] = (int64_t)b[pos] << 24 | (int64_t)b[pos + 1] << 16
                    | (int64_t)b[pos + 2] << 8 | b[pos + 3];
                n++;
            }
        }
        pos += length;
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&words);
    PyBuffer_Release(&lengths);
    PyBuffer_Release(&offsets);
    PyBuffer_Release(&counts);
    PyBuffer_Release(&wanted);
    PyBuffer_Release(&buf);
    return Py_BuildValue("nn", n, pos);
release_all:
    PyBuffer_Release(&words);
release_lengths:
    PyBuffer_Release(&lengths);
release_offsets:
    PyBuffer_Release(&offsets);
release_counts:
    PyBuffer_Release(&counts);
release_wanted:
    PyBuffer_Release(&wanted);
release_buf:
    PyBuffer_Release(&buf);
    return NULL;
}

static PyObject *
gather(PyObject *self, PyObject *args)
{
    PyObject *objs[3];
    Py_ssize_t length;
    Py_buffer buf, offsets, out;
    if (!PyArg_ParseTuple(args, "OOnO", &objs[0], &objs[1], &length, &objs[2]))
        return NULL;
    if (get(objs[0], &buf, 1, 0, "buf") < 0)
        return NULL;
    if (get(objs[1], &offsets, 8, 0, "offsets") < 0) {
        PyBuffer_Release(&buf);
        return NULL;
    }
    if (get(objs[2], &out, 1, 1, "out") < 0) {
        PyBuffer_Release(&offsets);
        PyBuffer_Release(&buf);
        return NULL;
    }
    Py_ssize_t n = offsets.len / 8;
    const int64_t *off = (const int64_t *)offsets.buf;
    int ok = length >= 0 && out.len == n * length;
    for (Py_ssize_t i = 0; ok && i < n; i++)
        ok = off[i] >= 0 && off[i] + length <= buf.len;
    if (ok) {
        const uint8_t *b = (const uint8_t *)buf.buf;
        uint8_t *o = (uint8_t *)out.buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t i = 0; i < n; i++)
            memcpy(o + i * length, b + off[i], (size_t)length);
        Py_END_ALLOW_THREADS
    }
    PyBuffer_Release(&out);
    PyBuffer_Release(&offsets);
    PyBuffer_Release(&buf);
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "gather: an offset or the output is out of bounds");
        return NULL;
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"walk", walk, METH_VARARGS, "Follow packets; see the module comment."},
    {"gather", gather, METH_VARARGS, "Copy packets into rows; see the module comment."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_packetwalk",
    "The packet walk and gather of telemetry/ccsds_scan.py in C (telemetry/_packetwalk.c).",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__packetwalk(void)
{
    return PyModule_Create(&module);
}
