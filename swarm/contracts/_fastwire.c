/* The wire's hot path in C: sensor frames encoded (world) and decoded (agents), and the
 * nearest contact chosen (agents). Optional: swarm/contracts/fastpath.py loads it where it was
 * built (pip install on a machine with a C compiler) and falls back to the pure-Python
 * functions of swarm/contracts/wire.py and swarm/agents/selection.py otherwise. Those stay
 * the reference: tests/pure/test_fastwire.py checks that both give the same bytes and the same
 * objects, bit for bit.
 *
 * The layouts (little-endian, packed) are wire.SENSE_HEAD "<BBBBiqddddI" (52 bytes) and
 * wire.CONTACT "<idddh" (30 bytes): see docs/reference/protocol.md.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

/* fastpath.py uses this module only when its API is the one it expects: a module built from
 * an older checkout (pip install -e, then a pull) is not used. Raise it with every change of
 * a function's signature or meaning. */
#define FASTWIRE_API 3

#define HEAD_SIZE 52
#define CONTACT_SIZE 30

/* -- little-endian packing (memcpy: no alignment assumed) ------------------------------ */
#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "swarm._fastwire: little-endian machines only (the pure-Python path serves the others)"
#endif

static inline void put_i32(char *p, int32_t v) { memcpy(p, &v, 4); }
static inline void put_i64(char *p, int64_t v) { memcpy(p, &v, 8); }
static inline void put_u32(char *p, uint32_t v) { memcpy(p, &v, 4); }
static inline void put_i16(char *p, int16_t v) { memcpy(p, &v, 2); }
static inline void put_f64(char *p, double v) { memcpy(p, &v, 8); }
static inline int32_t get_i32(const char *p) { int32_t v; memcpy(&v, p, 4); return v; }
static inline int16_t get_i16(const char *p) { int16_t v; memcpy(&v, p, 2); return v; }
static inline double get_f64(const char *p) { double v; memcpy(&v, p, 8); return v; }

/* math.nan's bits (struct.pack("<d", math.nan)) */
static double quiet_nan(void) {
    uint64_t bits = 0x7ff8000000000000ULL;
    double d;
    memcpy(&d, &bits, 8);
    return d;
}

static void put_head(char *p, int has_target, int32_t agent, int64_t tick, double time, double heading,
                     double tx, double ty, uint32_t n) {
    p[0] = 1; /* wire.KIND_SENSE */
    p[1] = 1; /* wire.VERSION */
    p[2] = (char)(has_target ? 1 : 0);
    p[3] = 0;
    put_i32(p + 4, agent);
    put_i64(p + 8, tick);
    put_f64(p + 16, time);
    put_f64(p + 24, heading);
    put_f64(p + 32, tx);
    put_f64(p + 40, ty);
    put_u32(p + 48, n);
}

/* A Python int that must fit `lo`..`hi` (struct.pack's range check, as struct.error would). */
static int int_in(PyObject *o, long long lo, long long hi, long long *out, const char *what) {
    long long v = PyLong_AsLongLong(o);
    if (v == -1 && PyErr_Occurred()) return -1;
    if (v < lo || v > hi) {
        PyErr_Format(PyExc_OverflowError, "%s %lld out of range", what, v);
        return -1;
    }
    *out = v;
    return 0;
}

static int as_double(PyObject *o, double *out) {
    double v = PyFloat_AsDouble(o);
    if (v == -1.0 && PyErr_Occurred()) return -1;
    *out = v;
    return 0;
}

/* The arguments every encoder starts with: nargs == want, then tick (int64) and time (float);
 * -1 with an exception set otherwise. */
static int tick_time(PyObject *const *args, Py_ssize_t nargs, Py_ssize_t want, const char *name, long long *tick,
                     double *time) {
    if (nargs != want) {
        PyErr_Format(PyExc_TypeError, "%s takes %zd arguments", name, want);
        return -1;
    }
    if (int_in(args[0], INT64_MIN, INT64_MAX, tick, "tick") < 0) return -1;
    return as_double(args[1], time);
}

/* encode_sense_tuples(tick, time, agent, heading, target, contacts) -> bytes
 * target: None or (dx, dy); contacts: a sequence of (id, bearing, heading, range, hops). */
static PyObject *encode_sense_tuples(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    long long tick, agent;
    double time, heading, tx, ty;
    if (tick_time(args, nargs, 6, "encode_sense_tuples", &tick, &time) < 0) return NULL;
    if (int_in(args[2], INT32_MIN, INT32_MAX, &agent, "agent") < 0) return NULL;
    if (as_double(args[3], &heading) < 0) return NULL;
    int has_target = args[4] != Py_None;
    if (has_target) {
        /* a tuple (copied from any other sequence): a __float__ cannot change it meanwhile */
        PyObject *t = PySequence_Tuple(args[4]);
        if (t == NULL) return NULL;
        if (PyTuple_GET_SIZE(t) != 2) {
            Py_DECREF(t);
            PyErr_SetString(PyExc_ValueError, "target must be a pair");
            return NULL;
        }
        int bad = as_double(PyTuple_GET_ITEM(t, 0), &tx) < 0 || as_double(PyTuple_GET_ITEM(t, 1), &ty) < 0;
        Py_DECREF(t);
        if (bad) return NULL;
    } else {
        tx = ty = quiet_nan();
    }
    PyObject *cs = PySequence_Tuple(args[5]); /* as the target: a tuple, copied from a list */
    if (cs == NULL) return NULL;
    Py_ssize_t n = PyTuple_GET_SIZE(cs);
    if (n > (PY_SSIZE_T_MAX - HEAD_SIZE) / CONTACT_SIZE || (uint64_t)n > UINT32_MAX) {
        Py_DECREF(cs);
        PyErr_SetString(PyExc_OverflowError, "too many contacts");
        return NULL;
    }
    PyObject *out = PyBytes_FromStringAndSize(NULL, HEAD_SIZE + n * CONTACT_SIZE);
    if (out == NULL) {
        Py_DECREF(cs);
        return NULL;
    }
    char *p = PyBytes_AS_STRING(out);
    put_head(p, has_target, (int32_t)agent, (int64_t)tick, time, heading, tx, ty, (uint32_t)n);
    p += HEAD_SIZE;
    for (Py_ssize_t k = 0; k < n; k++, p += CONTACT_SIZE) {
        PyObject *c = PyTuple_GET_ITEM(cs, k);
        if (!PyTuple_Check(c) || PyTuple_GET_SIZE(c) != 5) {
            PyErr_SetString(PyExc_TypeError, "a contact is a 5-tuple (id, bearing, heading, range, hops)");
            goto fail;
        }
        long long id, hops;
        double b, h, r;
        if (int_in(PyTuple_GET_ITEM(c, 0), INT32_MIN, INT32_MAX, &id, "contact id") < 0 ||
            as_double(PyTuple_GET_ITEM(c, 1), &b) < 0 || as_double(PyTuple_GET_ITEM(c, 2), &h) < 0 ||
            as_double(PyTuple_GET_ITEM(c, 3), &r) < 0 ||
            int_in(PyTuple_GET_ITEM(c, 4), INT16_MIN, INT16_MAX, &hops, "contact hops") < 0)
            goto fail;
        put_i32(p, (int32_t)id);
        put_f64(p + 4, b);
        put_f64(p + 12, h);
        put_f64(p + 20, r);
        put_i16(p + 28, (int16_t)hops);
    }
    Py_DECREF(cs);
    return out;
fail:
    Py_DECREF(cs);
    Py_DECREF(out);
    return NULL;
}

/* -- numpy columns through the buffer protocol (no numpy headers needed) --------------- */
typedef struct {
    Py_buffer view;
    int held;
} Col;

/* A C-contiguous buffer of `count` items of `itemsize` bytes (the caller passed arrays of
 * the right dtype: wire.py's _columns makes sure of it). */
static int col_get(PyObject *o, Col *c, Py_ssize_t count, Py_ssize_t itemsize, const char *what) {
    if (PyObject_GetBuffer(o, &c->view, PyBUF_C_CONTIGUOUS) < 0) return -1;
    c->held = 1;
    if (c->view.len != count * itemsize) {
        PyErr_Format(PyExc_ValueError, "%s: %zd bytes, expected %zd", what, c->view.len, count * itemsize);
        return -1;
    }
    return 0;
}

static void col_release(Col *c) {
    if (c->held) PyBuffer_Release(&c->view);
    c->held = 0;
}

/* What both array encoders take about the agents: the rows to encode (int64 (R,)) and, per
 * agent, ids (int64), heading, target_dx, target_dy (float64), is_leader (uint8, bool) and
 * the hops it advertises (int64), each (N,). */
typedef struct {
    Col rows, ids, head, dx, dy, lead, hops;
    Py_ssize_t n, nr;
} Agents;

/* Agents from the arguments rows, ids, heading, target_dx, target_dy, is_leader (`cols`, in
 * that order) and hops; 0, or -1 with an exception set (agents_release either way). */
static int agents_get(PyObject *const *cols, PyObject *hops, Agents *a) {
    if (PyObject_GetBuffer(cols[1], &a->ids.view, PyBUF_C_CONTIGUOUS) < 0) return -1;
    a->ids.held = 1;
    if (PyObject_GetBuffer(cols[0], &a->rows.view, PyBUF_C_CONTIGUOUS) < 0) return -1;
    a->rows.held = 1;
    a->n = a->ids.view.len / 8;
    a->nr = a->rows.view.len / 8;
    if (a->ids.view.len != a->n * 8 || a->rows.view.len != a->nr * 8) {
        PyErr_SetString(PyExc_ValueError, "ids and rows: int64");
        return -1;
    }
    Py_ssize_t n = a->n;
    if (col_get(cols[2], &a->head, n, 8, "heading") < 0 || col_get(cols[3], &a->dx, n, 8, "target_dx") < 0 ||
        col_get(cols[4], &a->dy, n, 8, "target_dy") < 0 || col_get(cols[5], &a->lead, n, 1, "is_leader") < 0 ||
        col_get(hops, &a->hops, n, 8, "hops") < 0)
        return -1;
    return 0;
}

static void agents_release(Agents *a) {
    col_release(&a->rows);
    col_release(&a->ids);
    col_release(&a->head);
    col_release(&a->dx);
    col_release(&a->dy);
    col_release(&a->lead);
    col_release(&a->hops);
}

/* The frame of agent index k with room for `count` contacts, its head written; *p: where its
 * contacts go. NULL with an exception set (k out of range, an id past int32). */
static PyObject *row_frame(const Agents *a, int64_t k, long long tick, double time, Py_ssize_t count, char **p) {
    const int64_t *idv = a->ids.view.buf;
    if (k < 0 || k >= a->n) {
        PyErr_Format(PyExc_IndexError, "row %lld out of range", (long long)k);
        return NULL;
    }
    if (idv[k] < INT32_MIN || idv[k] > INT32_MAX) {
        PyErr_Format(PyExc_OverflowError, "agent id %lld out of range", (long long)idv[k]);
        return NULL;
    }
    PyObject *frame = PyBytes_FromStringAndSize(NULL, HEAD_SIZE + count * CONTACT_SIZE);
    if (frame == NULL) return NULL;
    const double *hd = a->head.view.buf, *dxv = a->dx.view.buf, *dyv = a->dy.view.buf;
    int l = ((const unsigned char *)a->lead.view.buf)[k] != 0;
    double nan = quiet_nan();
    *p = PyBytes_AS_STRING(frame);
    put_head(*p, l, (int32_t)idv[k], (int64_t)tick, time, hd[k], l ? dxv[k] : nan, l ? dyv[k] : nan,
             (uint32_t)count);
    *p += HEAD_SIZE;
    return frame;
}

/* The contact record of agent index j, sensed at `bearing` and `range`. */
static inline void put_contact(char *p, const Agents *a, int64_t j, double bearing, double range) {
    put_i32(p, (int32_t)((const int64_t *)a->ids.view.buf)[j]); /* numpy's astype("<i4"): wraps, as the C cast */
    put_f64(p + 4, bearing);
    put_f64(p + 12, ((const double *)a->head.view.buf)[j]);
    put_f64(p + 20, range);
    put_i16(p + 28, (int16_t)((const int64_t *)a->hops.view.buf)[j]);
}

/* encode_sense_rows(tick, time, rows, ids, heading, target_dx, target_dy, is_leader, sensed,
 *                   bearing, ranges, hops) -> list of bytes
 * The agents' arrays as in `Agents`; sensed uint8 (bool), bearing, ranges float64 (N, N). The
 * bytes of wire.encode_sense_rows_py: row k's frame holds, for every j with sensed[k, j], in
 * order of j, the contact record of j at bearing[k, j], ranges[k, j]. */
static PyObject *encode_sense_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    long long tick;
    double time;
    if (tick_time(args, nargs, 12, "encode_sense_rows", &tick, &time) < 0) return NULL;
    Agents a = {0};
    Col sensed = {0}, bear = {0}, rng = {0};
    PyObject *out = NULL;
    if (agents_get(args + 2, args[11], &a) < 0) goto done;
    Py_ssize_t n = a.n;
    if (col_get(args[8], &sensed, n * n, 1, "sensed") < 0 || col_get(args[9], &bear, n * n, 8, "bearing") < 0 ||
        col_get(args[10], &rng, n * n, 8, "ranges") < 0)
        goto done;
    const int64_t *rw = a.rows.view.buf;
    const double *bv = bear.view.buf, *rv = rng.view.buf;
    const unsigned char *sv = sensed.view.buf;
    out = PyList_New(a.nr);
    if (out == NULL) goto done;
    for (Py_ssize_t q = 0; q < a.nr; q++) {
        int64_t k = rw[q];
        Py_ssize_t count = 0;
        if (k >= 0 && k < n)
            for (Py_ssize_t j = 0; j < n; j++) count += sv[k * n + j] != 0;
        char *p;
        PyObject *frame = row_frame(&a, k, tick, time, count, &p);
        if (frame == NULL) {
            Py_CLEAR(out);
            goto done;
        }
        for (Py_ssize_t j = 0; j < n; j++) {
            if (!sv[k * n + j]) continue;
            put_contact(p, &a, j, bv[k * n + j], rv[k * n + j]);
            p += CONTACT_SIZE;
        }
        PyList_SET_ITEM(out, q, frame);
    }
done:
    agents_release(&a);
    col_release(&sensed);
    col_release(&bear);
    col_release(&rng);
    return out;
}

/* encode_sense_pairs(tick, time, rows, ids, heading, target_dx, target_dy, is_leader, i, j,
 *                    bearing, ranges, hops) -> list of bytes
 * The agents' arrays as in `Agents`; i, j int64, bearing, ranges float64 (P,): the sensed
 * pairs, sorted by i, then j. The bytes of wire.encode_sense_pairs_py: row k's frame holds,
 * in order, the contact records of the pairs whose i is k. */
static PyObject *encode_sense_pairs(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    long long tick;
    double time;
    if (tick_time(args, nargs, 13, "encode_sense_pairs", &tick, &time) < 0) return NULL;
    Agents a = {0};
    Col pi = {0}, pj = {0}, bear = {0}, rng = {0};
    PyObject *out = NULL;
    Py_ssize_t *start = NULL;
    if (agents_get(args + 2, args[12], &a) < 0) goto done;
    Py_ssize_t n = a.n;
    if (PyObject_GetBuffer(args[8], &pi.view, PyBUF_C_CONTIGUOUS) < 0) goto done;
    pi.held = 1;
    Py_ssize_t np_ = pi.view.len / 8;
    if (pi.view.len != np_ * 8) {
        PyErr_SetString(PyExc_ValueError, "i: int64");
        goto done;
    }
    if (col_get(args[9], &pj, np_, 8, "j") < 0 || col_get(args[10], &bear, np_, 8, "bearing") < 0 ||
        col_get(args[11], &rng, np_, 8, "ranges") < 0)
        goto done;
    const int64_t *rw = a.rows.view.buf, *iv = pi.view.buf, *jv = pj.view.buf;
    const double *bv = bear.view.buf, *rv = rng.view.buf;
    /* start[a] .. start[a + 1]: the pairs of agent a (sorted by i: a check, not an assumption) */
    start = PyMem_Calloc((size_t)n + 1, sizeof(Py_ssize_t));
    if (start == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t e = 0; e < np_; e++) {
        if (iv[e] < 0 || iv[e] >= n || jv[e] < 0 || jv[e] >= n || (e && iv[e] < iv[e - 1])) {
            PyErr_SetString(PyExc_ValueError, "pairs: i and j must be indices, sorted by i");
            goto done;
        }
        start[iv[e] + 1]++;
    }
    for (Py_ssize_t m = 0; m < n; m++) start[m + 1] += start[m];
    out = PyList_New(a.nr);
    if (out == NULL) goto done;
    for (Py_ssize_t q = 0; q < a.nr; q++) {
        int64_t k = rw[q];
        Py_ssize_t first = 0, last = 0;
        if (k >= 0 && k < n) first = start[k], last = start[k + 1];
        char *p;
        PyObject *frame = row_frame(&a, k, tick, time, last - first, &p);
        if (frame == NULL) {
            Py_CLEAR(out);
            goto done;
        }
        for (Py_ssize_t e = first; e < last; e++, p += CONTACT_SIZE) put_contact(p, &a, jv[e], bv[e], rv[e]);
        PyList_SET_ITEM(out, q, frame);
    }
done:
    PyMem_Free(start);
    agents_release(&a);
    col_release(&pi);
    col_release(&pj);
    col_release(&bear);
    col_release(&rng);
    return out;
}

/* The n contact records at p as a tuple of `ct` (a tuple subclass); *finite &= every float
 * of every record is finite. NULL with an exception set on failure. */
static PyObject *contacts_at(const char *p, Py_ssize_t n, PyTypeObject *ct, int *finite) {
    PyObject *contacts = PyTuple_New(n);
    if (contacts == NULL) return NULL;
    for (Py_ssize_t k = 0; k < n; k++, p += CONTACT_SIZE) {
        int32_t id = get_i32(p);
        double b = get_f64(p + 4), h = get_f64(p + 12), r = get_f64(p + 20);
        int16_t hops = get_i16(p + 28);
        *finite &= isfinite(b) && isfinite(h) && isfinite(r);
        PyObject *c = ct->tp_alloc(ct, 5);
        if (c == NULL) goto fail;
#if PY_VERSION_HEX >= 0x030E0000
        ((PyTupleObject *)c)->ob_hash = -1; /* 3.14 caches a tuple's hash: not computed yet */
#endif
        PyObject *v0 = PyLong_FromLong(id), *v1 = PyFloat_FromDouble(b), *v2 = PyFloat_FromDouble(h),
                 *v3 = PyFloat_FromDouble(r), *v4 = PyLong_FromLong(hops);
        PyTuple_SET_ITEM(c, 0, v0);
        PyTuple_SET_ITEM(c, 1, v1);
        PyTuple_SET_ITEM(c, 2, v2);
        PyTuple_SET_ITEM(c, 3, v3);
        PyTuple_SET_ITEM(c, 4, v4);
        PyTuple_SET_ITEM(contacts, k, c);
        if (!v0 || !v1 || !v2 || !v3 || !v4) goto fail;
    }
    return contacts;
fail:
    Py_DECREF(contacts);
    return NULL;
}

static int is_tuple_type(PyObject *t, const char *what) {
    if (!PyType_Check(t) || !PyType_IsSubtype((PyTypeObject *)t, &PyTuple_Type)) {
        PyErr_Format(PyExc_TypeError, "%s must be a tuple subclass", what);
        return 0;
    }
    return 1;
}

/* decode_sense(buf, kind, version, max_agents, contact_type, frame_type) -> frame or None
 * A whole sensor frame (wire.SENSE_HEAD, then its contacts) as `frame_type` (a tuple subclass:
 * swarm.contracts.frames.SensorFrame): (tick, time, agent, heading, contacts, target or None).
 * None for anything wire.decode_sense_py refuses (a header of another kind or version, more
 * than max_agents contacts, a length not that of its contacts, a non-finite number, a negative
 * tick): the caller then decodes it in Python, which says why. */
static PyObject *decode_sense(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "decode_sense takes 6 arguments");
        return NULL;
    }
    if (!is_tuple_type(args[4], "contact_type") || !is_tuple_type(args[5], "frame_type")) return NULL;
    long kind = PyLong_AsLong(args[1]), version = PyLong_AsLong(args[2]);
    long long max_agents = PyLong_AsLongLong(args[3]);
    if (PyErr_Occurred()) return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(args[0], &view, PyBUF_SIMPLE) < 0) return NULL;
    const unsigned char *b = (const unsigned char *)view.buf;
    const char *p = (const char *)view.buf;
    PyObject *frame = NULL, *contacts = NULL, *target = NULL;
    if (view.len < HEAD_SIZE || b[0] != kind || b[1] != version) goto refused;
    int has_t = b[2] != 0;
    int32_t agent = get_i32(p + 4);
    int64_t tick;
    memcpy(&tick, p + 8, 8);
    double time = get_f64(p + 16), heading = get_f64(p + 24), tx = get_f64(p + 32), ty = get_f64(p + 40);
    uint32_t n;
    memcpy(&n, p + 48, 4);
    if ((long long)n > max_agents || view.len != HEAD_SIZE + (Py_ssize_t)n * CONTACT_SIZE) goto refused;
    int finite = isfinite(time) && isfinite(heading) && (!has_t || (isfinite(tx) && isfinite(ty)));
    if (!finite || tick < 0) goto refused;
    contacts = contacts_at(p + HEAD_SIZE, (Py_ssize_t)n, (PyTypeObject *)args[4], &finite);
    if (contacts == NULL) goto done;
    if (!finite) goto refused;
    if (has_t) {
        target = Py_BuildValue("(dd)", tx, ty);
        if (target == NULL) goto done;
    } else {
        target = Py_NewRef(Py_None);
    }
    PyTypeObject *ft = (PyTypeObject *)args[5];
    frame = ft->tp_alloc(ft, 6);
    if (frame == NULL) goto done;
#if PY_VERSION_HEX >= 0x030E0000
    ((PyTupleObject *)frame)->ob_hash = -1;
#endif
    PyObject *v0 = PyLong_FromLongLong(tick), *v1 = PyFloat_FromDouble(time), *v2 = PyLong_FromLong(agent),
             *v3 = PyFloat_FromDouble(heading);
    PyTuple_SET_ITEM(frame, 0, v0);
    PyTuple_SET_ITEM(frame, 1, v1);
    PyTuple_SET_ITEM(frame, 2, v2);
    PyTuple_SET_ITEM(frame, 3, v3);
    PyTuple_SET_ITEM(frame, 4, contacts);
    PyTuple_SET_ITEM(frame, 5, target);
    contacts = target = NULL; /* owned by the frame now */
    if (!v0 || !v1 || !v2 || !v3) Py_CLEAR(frame);
    goto done;
refused:
    frame = Py_NewRef(Py_None);
done:
    Py_XDECREF(contacts);
    Py_XDECREF(target);
    PyBuffer_Release(&view);
    return frame;
}

/* nearest(contacts) -> the contact with the smallest (range, id), the first of equals, or
 * None for none; NotImplemented when a contact is not a tuple whose range (item 3) is a
 * float and whose id (item 0) is an int (the caller then uses its own rule). */
static PyObject *nearest(PyObject *self, PyObject *contacts) {
    if (!PyTuple_Check(contacts)) Py_RETURN_NOTIMPLEMENTED;
    Py_ssize_t n = PyTuple_GET_SIZE(contacts);
    PyObject *best = NULL;
    double best_r = 0.0;
    long long best_id = 0;
    for (Py_ssize_t k = 0; k < n; k++) {
        PyObject *c = PyTuple_GET_ITEM(contacts, k);
        if (!PyTuple_Check(c) || PyTuple_GET_SIZE(c) < 4) Py_RETURN_NOTIMPLEMENTED;
        PyObject *ro = PyTuple_GET_ITEM(c, 3), *io = PyTuple_GET_ITEM(c, 0);
        if (!PyFloat_CheckExact(ro) || !PyLong_CheckExact(io)) Py_RETURN_NOTIMPLEMENTED;
        double r = PyFloat_AS_DOUBLE(ro);
        if (isnan(r)) Py_RETURN_NOTIMPLEMENTED; /* tuple comparison with NaN: leave it to Python */
        int overflow;
        long long id = PyLong_AsLongLongAndOverflow(io, &overflow);
        if (overflow) Py_RETURN_NOTIMPLEMENTED;
        if (best == NULL || r < best_r || (r == best_r && id < best_id)) {
            best = c;
            best_r = r;
            best_id = id;
        }
    }
    if (best == NULL) Py_RETURN_NONE;
    Py_INCREF(best);
    return best;
}

static PyMethodDef methods[] = {
    {"encode_sense_tuples", (PyCFunction)(void (*)(void))encode_sense_tuples, METH_FASTCALL,
     "wire.encode_sense_tuples in C: the same bytes."},
    {"encode_sense_rows", (PyCFunction)(void (*)(void))encode_sense_rows, METH_FASTCALL,
     "wire.encode_sense_rows in C, from arrays of fixed dtypes (see wire.py): the same bytes."},
    {"encode_sense_pairs", (PyCFunction)(void (*)(void))encode_sense_pairs, METH_FASTCALL,
     "wire.encode_sense_pairs in C, from arrays of fixed dtypes (see wire.py): the same bytes."},
    {"decode_sense", (PyCFunction)(void (*)(void))decode_sense, METH_FASTCALL,
     "wire.decode_sense_py in C for a valid frame: the same frame; None for any it refuses."},
    {"nearest", nearest, METH_O, "selection.nearest in C: the contact with the smallest (range, id)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_fastwire",
                                    "The wire's hot path in C (see swarm/contracts/fastpath.py).", -1, methods};

PyMODINIT_FUNC PyInit__fastwire(void) {
    PyObject *m = PyModule_Create(&module);
    if (m != NULL && PyModule_AddIntConstant(m, "API", FASTWIRE_API) < 0) Py_CLEAR(m);
    return m;
}
