/* The estimator's numeric core in C: the IMU history with prefix integrals (history.py), the
 * block mean and covariance of the 15-state model (model.py) and the Kalman update.
 *
 * Pure numerics, no state beyond the IMU history's arrays. Every formula is the one documented
 * in history.py and model.py, written with the same operations in the same order where a
 * Python float expression existed before (so those give the same bits; compiled with
 * -ffp-contract=off, no fused multiply-add); the matrix products sum the non-zero terms of
 * F P F^T and K (H P) in their own order (equal to numpy's to rounding). Tested against the
 * numpy reference forms of model.py and a pure-Python history kept in the tests.
 *
 * State x = [p, v, b (NED), a (FRD), d (NED)] (15), covariance P 15x15 (C order, float64).
 * Integrals = (t_s, S1 (3), S2 (3), M1 (9), M2 (9), W (3), J (3), C (9)) (40 floats, history.py): W and J
 * the moments (∫ n, ∫ n s, ∫ n s^2) of the held-time noise densities, C those of a coast's dropped
 * acceleration per axis (history.py, "Held time"; held.h).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <math.h>
#include <string.h>
#define NPY_NO_DEPRECATED_API NPY_1_22_API_VERSION
#include <numpy/arrayobject.h>
#include "held.h"

#define NS 15
#define NN (NS * NS)
#define ROW 57
#define NINT HELD_INTS  /* held.h: the integrals' length */
#define RING 8  /* recent sample intervals: their median is the IMU's period */


/* ------------------------------------------------------------------ helpers */
/* a float64 array of the given shape, aligned and in native byte order: read it directly */
static int plain_doubles(PyObject *obj, int nd, npy_intp d0, npy_intp d1) {
    if (!PyArray_Check(obj)) return 0;
    PyArrayObject *a = (PyArrayObject *)obj;
    return PyArray_TYPE(a) == NPY_DOUBLE && PyArray_NDIM(a) == nd && PyArray_DIM(a, 0) == d0
           && (nd == 1 || PyArray_DIM(a, 1) == d1) && PyArray_ISALIGNED(a) && PyArray_ISNOTSWAPPED(a);
}

/* n floats from a 1-D float64 array, a tuple, a list or any sequence of numbers */
static int read_doubles(PyObject *obj, double *out, Py_ssize_t n, const char *what) {
    if (plain_doubles(obj, 1, n, 0)) {
        PyArrayObject *a = (PyArrayObject *)obj;
        const char *p = PyArray_BYTES(a);
        npy_intp st = PyArray_STRIDE(a, 0);
        for (Py_ssize_t i = 0; i < n; i++) out[i] = *(const double *)(p + i * st);
        return 0;
    }
    PyObject *seq = PySequence_Fast(obj, what);  /* tuples and lists as they are */
    if (!seq) return -1;
    if (PySequence_Fast_GET_SIZE(seq) != n) {
        Py_DECREF(seq);
        PyErr_Format(PyExc_ValueError, "%s: expected %zd numbers", what, n);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(seq);
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *it = items[i];
        out[i] = PyFloat_CheckExact(it) ? PyFloat_AS_DOUBLE(it) : PyFloat_AsDouble(it);
    }
    Py_DECREF(seq);
    return PyErr_Occurred() ? -1 : 0;
}

/* a new tuple (or list) of n floats */
static PyObject *floats_of(const double *v, Py_ssize_t n, int as_list) {
    PyObject *t = as_list ? PyList_New(n) : PyTuple_New(n);
    if (!t) return NULL;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *f = PyFloat_FromDouble(v[i]);
        if (!f) { Py_DECREF(t); return NULL; }
        if (as_list) PyList_SET_ITEM(t, i, f); else PyTuple_SET_ITEM(t, i, f);
    }
    return t;
}

static PyObject *tuple_of(const double *v, Py_ssize_t n) { return floats_of(v, n, 0); }
static PyObject *list_of(const double *v, Py_ssize_t n) { return floats_of(v, n, 1); }

/* P (15x15 float64) into out[225], any layout numpy accepts. */
static int read_cov(PyObject *obj, double *out) {
    PyArrayObject *a;
    if (plain_doubles(obj, 2, NS, NS)) {
        a = (PyArrayObject *)Py_NewRef(obj);
    } else {  /* anything else (nested lists, other dtypes): through numpy */
        a = (PyArrayObject *)PyArray_FROMANY(obj, NPY_DOUBLE, 2, 2, NPY_ARRAY_ALIGNED | NPY_ARRAY_NOTSWAPPED);
        if (!a) return -1;
        if (PyArray_DIM(a, 0) != NS || PyArray_DIM(a, 1) != NS) {
            Py_DECREF(a);
            PyErr_SetString(PyExc_ValueError, "covariance: expected 15x15");
            return -1;
        }
    }
    const char *p = PyArray_BYTES(a);
    npy_intp s0 = PyArray_STRIDE(a, 0), s1 = PyArray_STRIDE(a, 1);
    if (s1 == 8 && s0 == 8 * NS) {
        memcpy(out, p, sizeof(double) * NN);
    } else {
        for (int i = 0; i < NS; i++)
            for (int j = 0; j < NS; j++) out[i * NS + j] = *(const double *)(p + i * s0 + j * s1);
    }
    Py_DECREF(a);
    return 0;
}

/* A new float64 ndarray of shape (d0,) or (d0, d1) holding its numbers from c. */
static PyObject *new_array(int nd, npy_intp d0, npy_intp d1, const double *c) {
    npy_intp dims[2] = {d0, d1};
    PyObject *arr = PyArray_SimpleNew(nd, dims, NPY_DOUBLE);
    if (!arr) return NULL;
    memcpy(PyArray_DATA((PyArrayObject *)arr), c, sizeof(double) * (size_t)(nd == 1 ? d0 : d0 * d1));
    return arr;
}

static PyObject *new_cov(const double *c) { return new_array(2, NS, NS, c); }

/* ---------------------------------------------------------- rotation blocks and the mean */
/* (-A, -B) row-major between integrals a and b (history.rotation_blocks). */
static void rot_blocks(const double *a, const double *b, double *nA, double *nB) {
    double tb = b[0];
    for (int k = 0; k < 9; k++) {
        double d = a[7 + k] - b[7 + k];
        nA[k] = d;
        nB[k] = tb * d + (b[16 + k] - a[16 + k]);
    }
}

/* history.mean_between: x carried between the times of integrals a and b. */
static void mean_between_c(const double *x, const double *a, const double *b, double alpha, double *out,
                           double *nA, double *nB) {
    rot_blocks(a, b, nA, nB);
    double ta = a[0], tb = b[0];
    double T = tb - ta;
    double h = 0.5 * T * T;
    double d[3] = {b[1] - a[1], b[2] - a[2], b[3] - a[3]};
    double ux = x[9], uy = x[10], uz = x[11];
    for (int i = 0; i < 3; i++) {
        const double *Bi = nB + 3 * i, *Ai = nA + 3 * i;
        out[i] = x[i] + x[3 + i] * T + (tb * d[i] - (b[4 + i] - a[4 + i])) + (Bi[0] * ux + Bi[1] * uy + Bi[2] * uz)
                 - x[12 + i] * h;
        out[3 + i] = x[3 + i] + d[i] + (Ai[0] * ux + Ai[1] * uy + Ai[2] * uz) - x[12 + i] * T;
        out[6 + i] = alpha * x[6 + i];
    }
    for (int i = 9; i < NS; i++) out[i] = x[i];
}

static int read_x_ints(PyObject *x_o, PyObject *a_o, PyObject *b_o, double *x, double *a, double *b) {
    if (read_doubles(x_o, x, NS, "state") < 0) return -1;
    if (read_doubles(a_o, a, NINT, "integrals") < 0) return -1;
    return read_doubles(b_o, b, NINT, "integrals");
}

static PyObject *py_mean_between(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) { PyErr_SetString(PyExc_TypeError, "mean_between(x, a, b, alpha)"); return NULL; }
    double x[NS], a[NINT], b[NINT], out[NS], nA[9], nB[9];
    if (read_x_ints(args[0], args[1], args[2], x, a, b) < 0) return NULL;
    double alpha = PyFloat_AsDouble(args[3]);
    if (alpha == -1.0 && PyErr_Occurred()) return NULL;
    mean_between_c(x, a, b, alpha, out, nA, nB);
    PyObject *xo = tuple_of(out, NS), *ao = list_of(nA, 9), *bo = list_of(nB, 9);
    if (!xo || !ao || !bo) { Py_XDECREF(xo); Py_XDECREF(ao); Py_XDECREF(bo); return NULL; }
    return Py_BuildValue("(NNN)", xo, ao, bo);
}

static PyObject *py_rotation_blocks(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) { PyErr_SetString(PyExc_TypeError, "rotation_blocks(a, b)"); return NULL; }
    double a[NINT], b[NINT], nA[9], nB[9];
    if (read_doubles(args[0], a, NINT, "integrals") < 0 || read_doubles(args[1], b, NINT, "integrals") < 0)
        return NULL;
    rot_blocks(a, b, nA, nB);
    PyObject *ao = list_of(nA, 9), *bo = list_of(nB, 9);
    if (!ao || !bo) { Py_XDECREF(ao); Py_XDECREF(bo); return NULL; }
    return Py_BuildValue("(NN)", ao, bo);
}

/* the integrals at the newest sample of a History (defined below); 0 if o is not one */
static int newest_integrals(PyObject *o, double *out);

/* ------------------------------------------------------------------ the model */
typedef struct {
    PyObject_HEAD
    double q_acc, q_rw, q_ned;
    double q_hold_white, q_hold_rw;  /* the densities the held-time moments W and J are scaled by */
    double q_coast;  /* the scale of the coast's dropped-acceleration moments C (1: on, 0: off) */
} Propagator;

/* The held-time process noise of a block between integrals a and b (held.h's held_noise with the
 * propagator's densities, the white one the same on each axis): hq[3 i ..] = (pp, pv, vv) on axis i's
 * p, v; 0 when there is none. */
static int held_q(const Propagator *pr, const double *a, const double *b, double *hq) {
    const double qw[3] = {pr->q_hold_white, pr->q_hold_white, pr->q_hold_white};
    return held_noise(a, b, qw, pr->q_hold_rw, pr->q_coast, hq);
}

/* out = F P F^T + Q for a block (model.BlockPropagator.predict); F's non-zero structure:
 * p_i row: 1 at p_i, T at v_i, -B_i (nB row i) on a, h = -T^2/2 at d_i;
 * v_i row: 1 at v_i, -A_i (nA row i) on a, -T at d_i;  b_i row: alpha at b_i;  a, d rows: 1. */
static void apply_f_rows(const double *M, double *out, double T, const double *nA, const double *nB, double alpha) {
    double h = -0.5 * T * T, m = -T;
    for (int i = 0; i < 3; i++) {
        const double *Bi = nB + 3 * i, *Ai = nA + 3 * i;
        const double *mp = M + i * NS, *mv = M + (3 + i) * NS, *md = M + (12 + i) * NS;
        const double *m9 = M + 9 * NS, *m10 = M + 10 * NS, *m11 = M + 11 * NS;
        double *op = out + i * NS, *ov = out + (3 + i) * NS, *ob = out + (6 + i) * NS;
        const double *mb = M + (6 + i) * NS;
        for (int j = 0; j < NS; j++) {
            double ua = Bi[0] * m9[j] + Bi[1] * m10[j] + Bi[2] * m11[j];
            double va = Ai[0] * m9[j] + Ai[1] * m10[j] + Ai[2] * m11[j];
            op[j] = mp[j] + T * mv[j] + ua + h * md[j];
            ov[j] = mv[j] + va + m * md[j];
            ob[j] = alpha * mb[j];
        }
    }
    memcpy(out + 9 * NS, M + 9 * NS, sizeof(double) * 6 * NS);
}

static void transpose(const double *M, double *out) {
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < NS; j++) out[j * NS + i] = M[i * NS + j];
}

static void predict_c(const Propagator *pr, const double *P, double T, const double *nA, const double *nB,
                      double alpha, double q_b, const double *hq, double *out) {
    double FP[NN], FPt[NN], G[NN];
    apply_f_rows(P, FP, T, nA, nB, alpha);   /* F P */
    transpose(FP, FPt);                      /* (F P)^T = P F^T */
    apply_f_rows(FPt, G, T, nA, nB, alpha);  /* F (F P)^T = F P F^T (symmetric P) */
    transpose(G, out);                       /* (F P F^T)^T: as F @ P @ F.T is laid out */
    /* Q (BlockPropagator._q_diag and the random-walk terms with the block's mean rotation) */
    double T2 = T * T;
    double q = pr->q_acc, w = pr->q_rw, e = pr->q_ned;
    double we = w + e;
    double pp = q * T2 * T / 3.0 + we * T2 * T2 * T / 20.0, pv = q * T2 / 2.0 + we * T2 * T2 / 8.0;
    double vv = q * T + we * T2 * T / 3.0, aa = w * T, dd = e * T, pd = -e * T2 * T / 6.0, vd = -e * T2 / 2.0;
    double kp = pr->q_rw * T * T / 6.0, kv = pr->q_rw * T / 2.0;
    for (int i = 0; hq && i < 3; i++) {  /* held time (held_q) */
        out[i * NS + i] += hq[3 * i];
        out[i * NS + 3 + i] += hq[3 * i + 1];
        out[(3 + i) * NS + i] += hq[3 * i + 1];
        out[(3 + i) * NS + 3 + i] += hq[3 * i + 2];
    }
    for (int i = 0; i < 3; i++) {
        out[i * NS + i] += pp;
        out[i * NS + 3 + i] += pv;
        out[(3 + i) * NS + i] += pv;
        out[(3 + i) * NS + 3 + i] += vv;
        out[(6 + i) * NS + 6 + i] += q_b;
        out[(9 + i) * NS + 9 + i] += aa;
        out[(12 + i) * NS + 12 + i] += dd;
        out[i * NS + 12 + i] += pd;
        out[(12 + i) * NS + i] += pd;
        out[(3 + i) * NS + 12 + i] += vd;
        out[(12 + i) * NS + 3 + i] += vd;
        for (int c = 0; c < 3; c++) {
            double pa = kp * nA[3 * i + c], va = kv * nA[3 * i + c];
            out[i * NS + 9 + c] += pa;
            out[(9 + c) * NS + i] += pa;
            out[(3 + i) * NS + 9 + c] += va;
            out[(9 + c) * NS + 3 + i] += va;
        }
    }
}

/* The variances of p, v, b of predict_c, alone (BlockPropagator.variances). */
static void variances_c(const Propagator *pr, const double *P, double T, const double *nA, const double *nB,
                        double alpha, double q_b, const double *hq, double *var) {
    double h = -0.5 * T * T, m = -T;
    for (int i = 0; i < 3; i++) {
        int ip[6] = {i, 3 + i, 9, 10, 11, 12 + i};
        double cp[6] = {1.0, T, nB[3 * i], nB[3 * i + 1], nB[3 * i + 2], h};
        int iv[5] = {3 + i, 9, 10, 11, 12 + i};
        double cv[5] = {1.0, nA[3 * i], nA[3 * i + 1], nA[3 * i + 2], m};
        double sp = 0.0, sv = 0.0;
        for (int r = 0; r < 6; r++) {
            double s = 0.0;
            for (int c = 0; c < 6; c++) s += P[ip[r] * NS + ip[c]] * cp[c];
            sp += cp[r] * s;
        }
        for (int r = 0; r < 5; r++) {
            double s = 0.0;
            for (int c = 0; c < 5; c++) s += P[iv[r] * NS + iv[c]] * cv[c];
            sv += cv[r] * s;
        }
        var[i] = sp;
        var[3 + i] = sv;
        var[6 + i] = P[(6 + i) * NS + 6 + i];
    }
    double T2 = T * T;
    double we = pr->q_rw + pr->q_ned;
    double pp = pr->q_acc * T2 * T / 3.0 + we * T2 * T2 * T / 20.0;
    double vv = pr->q_acc * T + we * T2 * T / 3.0;
    double a2 = alpha * alpha;
    for (int i = 0; hq && i < 3; i++) {  /* held time (held_q), as predict_c adds it */
        var[i] = var[i] + hq[3 * i];
        var[3 + i] = var[3 + i] + hq[3 * i + 2];
    }
    for (int i = 0; i < 3; i++) {
        var[i] = var[i] + pp;
        var[3 + i] = var[3 + i] + vv;
        var[6 + i] = a2 * var[6 + i] + q_b;
    }
}

/* model.inv3: row-major inverse of a symmetric 3x3 given by its upper triangle. */
static void inv3_c(double a, double b, double c, double d, double e, double f, double *out) {
    double c0 = d * f - e * e, c1 = c * e - b * f, c2 = b * e - c * d;
    double u = 1.0 / (a * c0 + b * c1 + c * c2);
    double i11 = (a * f - c * c) * u, i12 = (b * c - a * e) * u, i22 = (a * d - b * b) * u;
    out[0] = c0 * u; out[1] = c1 * u; out[2] = c2 * u;
    out[3] = c1 * u; out[4] = i11; out[5] = i12;
    out[6] = c2 * u; out[7] = i12; out[8] = i22;
}

/* H P H^T (3x3, full) and P H^T (15x3) for H = [I 0 I 0 0]. */
static void pht_of(const double *P, double *PHt, double *hph) {
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < 3; j++) PHt[i * 3 + j] = P[i * NS + j] + P[i * NS + 6 + j];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) hph[i * 3 + j] = PHt[i * 3 + j] + PHt[(6 + i) * 3 + j];
}

/* out = (A + A^T) / 2, exactly symmetric */
static void symmetrise(const double *A, double *out) {
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < NS; j++) out[i * NS + j] = (A[i * NS + j] + A[j * NS + i]) * 0.5;
}

/* model.update_fast: x+, P+ (symmetrised), NIS for z = p + b + nu, nu ~ N(0, diag r). */
static double update_c(const double *x, const double *P, const double *y, const double *r, double *xo, double *Po) {
    double PHt[NS * 3], hph[9], Si[9];
    pht_of(P, PHt, hph);
    inv3_c(hph[0] + r[0], hph[1], hph[2], hph[4] + r[1], hph[5], hph[8] + r[2], Si);
    double g0 = Si[0] * y[0] + Si[1] * y[1] + Si[2] * y[2], g1 = Si[3] * y[0] + Si[4] * y[1] + Si[5] * y[2],
           g2 = Si[6] * y[0] + Si[7] * y[1] + Si[8] * y[2];
    double K[NS * 3];
    for (int i = 0; i < NS; i++) {
        const double *h = PHt + 3 * i;
        K[3 * i] = h[0] * Si[0] + h[1] * Si[3] + h[2] * Si[6];
        K[3 * i + 1] = h[0] * Si[1] + h[1] * Si[4] + h[2] * Si[7];
        K[3 * i + 2] = h[0] * Si[2] + h[1] * Si[5] + h[2] * Si[8];
        xo[i] = x[i] + (h[0] * g0 + h[1] * g1 + h[2] * g2);
    }
    double A[NN];
    for (int i = 0; i < NS; i++)
        for (int j = 0; j < NS; j++)
            A[i * NS + j] = P[i * NS + j] - (K[3 * i] * PHt[3 * j] + K[3 * i + 1] * PHt[3 * j + 1]
                                             + K[3 * i + 2] * PHt[3 * j + 2]);
    /* K S K^T is symmetric but its rounding is not: symmetrise (model.update_fast) */
    symmetrise(A, Po);
    return y[0] * g0 + y[1] * g1 + y[2] * g2;
}

static int prop_init(Propagator *self, PyObject *args, PyObject *kw) {
    self->q_hold_white = self->q_hold_rw = self->q_coast = 0.0;
    if (!PyArg_ParseTuple(args, "ddd|ddd", &self->q_acc, &self->q_rw, &self->q_ned, &self->q_hold_white,
                          &self->q_hold_rw, &self->q_coast))
        return -1;
    return 0;
}

static int parse_block(PyObject *const *args, double *T, double *nA, double *nB, double *alpha, double *q_b) {
    *T = PyFloat_AsDouble(args[0]);
    if (read_doubles(args[1], nA, 9, "-A") < 0 || read_doubles(args[2], nB, 9, "-B") < 0) return -1;
    *alpha = PyFloat_AsDouble(args[3]);
    *q_b = PyFloat_AsDouble(args[4]);
    return PyErr_Occurred() ? -1 : 0;
}

/* predict(P, T, nA, nB, alpha, q_b) -> F P F^T + Q (a new array) */
static PyObject *prop_predict(Propagator *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 6) { PyErr_SetString(PyExc_TypeError, "predict(P, T, nA, nB, alpha, q_b)"); return NULL; }
    double P[NN], out[NN], T, nA[9], nB[9], alpha, q_b;
    if (read_cov(args[0], P) < 0 || parse_block(args + 1, &T, nA, nB, &alpha, &q_b) < 0) return NULL;
    predict_c(self, P, T, nA, nB, alpha, q_b, NULL, out);
    return new_cov(out);
}

/* variances(P, T, nA, nB, alpha, q_b[, unused]) -> the 9 variances of p, v, b of predict */
static PyObject *prop_variances(Propagator *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 6 && nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "variances(P, T, nA, nB, alpha, q_b)");
        return NULL;
    }
    double P[NN], var[9], T, nA[9], nB[9], alpha, q_b;
    if (read_cov(args[0], P) < 0 || parse_block(args + 1, &T, nA, nB, &alpha, &q_b) < 0) return NULL;
    variances_c(self, P, T, nA, nB, alpha, q_b, NULL, var);
    return list_of(var, 9);
}

/* predict_from(x, P, a, b, T, alpha, q_b) -> (x-, P-, hph (3x3 nested tuples), pht_p (3)):
 * the engine's prediction of an entry to a fix (mean from the integrals a, b; covariance;
 * the innovation terms H P- H^T and the position diagonal of P- H^T). */
static PyObject *prop_predict_from(Propagator *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 7) { PyErr_SetString(PyExc_TypeError, "predict_from(x, P, a, b, T, alpha, q_b)"); return NULL; }
    double x[NS], a[NINT], b[NINT], P[NN], xo[NS], nA[9], nB[9], out[NN], PHt[NS * 3], hph[9];
    if (read_x_ints(args[0], args[2], args[3], x, a, b) < 0 || read_cov(args[1], P) < 0) return NULL;
    double T = PyFloat_AsDouble(args[4]), alpha = PyFloat_AsDouble(args[5]), q_b = PyFloat_AsDouble(args[6]);
    if (PyErr_Occurred()) return NULL;
    mean_between_c(x, a, b, alpha, xo, nA, nB);
    double hq[9];
    predict_c(self, P, T, nA, nB, alpha, q_b, held_q(self, a, b, hq) ? hq : NULL, out);
    pht_of(out, PHt, hph);
    double pp[3] = {PHt[0], PHt[4], PHt[8]};
    return Py_BuildValue("(NN((ddd)(ddd)(ddd))N)", tuple_of(xo, NS), new_cov(out), hph[0], hph[1], hph[2], hph[3],
                         hph[4], hph[5], hph[6], hph[7], hph[8], tuple_of(pp, 3));
}

/* output_from(x, P, a, b, T, alpha, q_b) -> (x at b, [p, v, b, their 9 variances] (ndarray (18,))):
 * the engine's snapshot; b may be the History itself (its newest sample) */
static PyObject *prop_output_from(Propagator *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 7) { PyErr_SetString(PyExc_TypeError, "output_from(x, P, a, b, T, alpha, q_b)"); return NULL; }
    double x[NS], a[NINT], b[NINT], P[NN], xo[NS], nA[9], nB[9], out[18];
    int newest = newest_integrals(args[3], b);
    if (newest < 0) return NULL;
    if (read_doubles(args[0], x, NS, "state") < 0 || read_doubles(args[2], a, NINT, "integrals") < 0
        || (!newest && read_doubles(args[3], b, NINT, "integrals") < 0) || read_cov(args[1], P) < 0)
        return NULL;
    double T = PyFloat_AsDouble(args[4]), alpha = PyFloat_AsDouble(args[5]), q_b = PyFloat_AsDouble(args[6]);
    if (PyErr_Occurred()) return NULL;
    mean_between_c(x, a, b, alpha, xo, nA, nB);
    memcpy(out, xo, sizeof(double) * 9);
    double hq[9];
    variances_c(self, P, T, nA, nB, alpha, q_b, held_q(self, a, b, hq) ? hq : NULL, out + 9);
    return Py_BuildValue("(NN)", tuple_of(xo, NS), new_array(1, 18, 0, out));
}

static PyMethodDef prop_methods[] = {
    {"predict", (PyCFunction)(void (*)(void))prop_predict, METH_FASTCALL, "F P F^T + Q over a block"},
    {"variances", (PyCFunction)(void (*)(void))prop_variances, METH_FASTCALL, "the 9 variances of predict"},
    {"predict_from", (PyCFunction)(void (*)(void))prop_predict_from, METH_FASTCALL, "mean, covariance, gain terms"},
    {"output_from", (PyCFunction)(void (*)(void))prop_output_from, METH_FASTCALL, "mean and 9 variances"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject PropagatorType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "companion.estimator._core.Propagator",
    .tp_basicsize = sizeof(Propagator),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE,
    .tp_doc = "Propagator(q_acc_m2_s3, q_rw_m2_s5, q_ned_m2_s5, q_hold_white_m2_s3=0, q_hold_rw_m2_s5=0, q_coast=0): "
              "the 15-state block prediction",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)prop_init,
    .tp_methods = prop_methods,
};

/* the arguments (x, P, a 3-vector, R) of the measurement functions below; -1 on error */
static int read_measurement(PyObject *const *args, Py_ssize_t nargs, const char *usage, const char *what,
                            double *x, double *P, double *v, double *r) {
    if (nargs != 4) { PyErr_SetString(PyExc_TypeError, usage); return -1; }
    if (read_doubles(args[0], x, NS, "state") < 0 || read_cov(args[1], P) < 0
        || read_doubles(args[2], v, 3, what) < 0 || read_doubles(args[3], r, 3, "R") < 0)
        return -1;
    return 0;
}

/* update(x, P, y, r) -> (x+, P+, NIS) */
static PyObject *py_update(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    double x[NS], P[NN], y[3], r[3], xo[NS], Po[NN];
    if (read_measurement(args, nargs, "update(x, P, y, r)", "innovation", x, P, y, r) < 0) return NULL;
    double nis = update_c(x, P, y, r, xo, Po);
    return Py_BuildValue("(NNd)", tuple_of(xo, NS), new_cov(Po), nis);
}

/* The receiver's velocity: z_v = v + nu, nu ~ N(0, diag r); a component whose z_v or r is not finite
 * (or r <= 0) is not reported. */
static int vel_component(const double *zv, const double *r, int i) {
    return isfinite(zv[i]) && isfinite(r[i]) && r[i] > 0.0;
}

/* (horizontal NIS, vertical NIS) of z_v against the prior (x, P): y = z_v - v, S = P_vv + diag r; the
 * horizontal NIS over the north-east block (2 dof; 1 dof when one of them is missing, 0 when both). */
static void vel_nis_c(const double *x, const double *P, const double *zv, const double *r, double *nis) {
    int n = vel_component(zv, r, 0), e = vel_component(zv, r, 1), d = vel_component(zv, r, 2);
    double yn = n ? zv[0] - x[3] : 0.0, ye = e ? zv[1] - x[4] : 0.0;
    double snn = P[3 * NS + 3] + (n ? r[0] : 0.0), see = P[4 * NS + 4] + (e ? r[1] : 0.0), sne = P[3 * NS + 4];
    if (n && e)
        nis[0] = (see * yn * yn - 2.0 * sne * yn * ye + snn * ye * ye) / (snn * see - sne * sne);
    else
        nis[0] = n ? yn * yn / snn : (e ? ye * ye / see : 0.0);
    nis[1] = 0.0;
    if (d) {
        double yd = zv[2] - x[5];
        nis[1] = yd * yd / (P[5 * NS + 5] + r[2]);
    }
}

/* vel_nis(x, P, z_v, r) -> (horizontal NIS, vertical NIS) */
static PyObject *py_vel_nis(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    double x[NS], P[NN], zv[3], r[3], nis[2];
    if (read_measurement(args, nargs, "vel_nis(x, P, z_v, r)", "velocity", x, P, zv, r) < 0) return NULL;
    vel_nis_c(x, P, zv, r, nis);
    return Py_BuildValue("(dd)", nis[0], nis[1]);
}

/* update_vel(x, P, z_v, r) -> (x+, P+): the reported components fused one at a time (for a diagonal R
 * equal to the joint update), each with the innovation of the state updated so far; P+ symmetrised. */
static PyObject *py_update_vel(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    double x[NS], P[NN], zv[3], r[3], col[NS], A[NN];
    if (read_measurement(args, nargs, "update_vel(x, P, z_v, r)", "velocity", x, P, zv, r) < 0) return NULL;
    for (int c = 0; c < 3; c++) {
        if (!vel_component(zv, r, c)) continue;
        int j = 3 + c;
        double s = P[j * NS + j] + r[c], y = zv[c] - x[j];
        for (int i = 0; i < NS; i++) col[i] = P[i * NS + j];
        for (int i = 0; i < NS; i++) {
            double k = col[i] / s;
            x[i] += k * y;
            for (int m = 0; m < NS; m++) P[i * NS + m] -= k * col[m];
        }
    }
    symmetrise(P, A);
    return Py_BuildValue("(NN)", tuple_of(x, NS), new_cov(A));
}

/* engine._centre_step: the factor a log-domain running centre moves by for a sample ratio x its value */
static double centre_step(double ratio, double k, double ek) {
    if (ratio >= M_E) return ek;
    if (ratio <= 1.0 / M_E) return 1.0 / ek;
    return pow(ratio, k);
}

/* receiver_spread(a, b, z, pz, pu, pd, tp, T, yd, scales, k, ek, kn, ekn) -> (scales', u, dv): the engine's
 * running centres of the receiver (engine.Fusion.scale_*_m, noise_*_m) after a fix at the time of the
 * integrals b, the previous fix pz (None: none) at those of a. scales = (scale_h, scale_v, noise_h,
 * noise_v); yd the innovation decided on; u = (z - pz - D_imu) / T (None without pz), dv the IMU's
 * velocity change over the block; pu, pd, tp the previous entry's u (None: none), dv and block length;
 * (k, e^k) the innovation spread's rate, (kn, e^kn) the noise's.
 * The formulas of FusionEngine._fuse (docs there). */
static PyObject *py_receiver_spread(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 14) {
        PyErr_SetString(PyExc_TypeError, "receiver_spread(a, b, z, pz, pu, pd, tp, T, yd, scales, k, ek, kn, ekn)");
        return NULL;
    }
    double a[NINT], b[NINT], z[3], pz[3], pu[3], pd[3], yd[3], sc[4];
    int have_pz = args[3] != Py_None, have_pu = args[4] != Py_None;
    if (read_doubles(args[0], a, NINT, "integrals") < 0 || read_doubles(args[1], b, NINT, "integrals") < 0
        || read_doubles(args[2], z, 3, "fix") < 0 || (have_pz && read_doubles(args[3], pz, 3, "fix") < 0)
        || (have_pu && read_doubles(args[4], pu, 3, "u") < 0) || read_doubles(args[5], pd, 3, "dv") < 0
        || read_doubles(args[8], yd, 3, "innovation") < 0 || read_doubles(args[9], sc, 4, "scales") < 0)
        return NULL;
    double tp = PyFloat_AsDouble(args[6]), T = PyFloat_AsDouble(args[7]), k = PyFloat_AsDouble(args[10]),
           ek = PyFloat_AsDouble(args[11]), kn = PyFloat_AsDouble(args[12]), ekn = PyFloat_AsDouble(args[13]);
    if (PyErr_Occurred()) return NULL;
    double dv[3] = {0.0, 0.0, 0.0}, u[3];
    int have_u = 0;
    if (T > 0.0) {
        sc[0] *= centre_step(hypot(yd[0], yd[1]) / sc[0], k, ek);
        sc[1] *= centre_step(fabs(yd[2]) / sc[1], k, ek);
        double tb = b[0];
        for (int i = 0; i < 3; i++) dv[i] = b[1 + i] - a[1 + i];
        if (have_pz) {
            for (int i = 0; i < 3; i++) u[i] = (z[i] - pz[i] - (tb * dv[i] - (b[4 + i] - a[4 + i]))) / T;
            have_u = 1;
            if (have_pu && tp > 0.0) {
                double c = 1.0 / sqrt(1.0 / (T * T) + (1.0 / T + 1.0 / tp) * (1.0 / T + 1.0 / tp) + 1.0 / (tp * tp));
                double e0 = (u[0] - pu[0] - pd[0]) * c, e1 = (u[1] - pu[1] - pd[1]) * c,
                       e2 = (u[2] - pu[2] - pd[2]) * c;
                sc[2] *= centre_step(hypot(e0, e1) / sc[2], kn, ekn);
                sc[3] *= centre_step(fabs(e2) / sc[3], kn, ekn);
            }
        }
    }
    PyObject *uo = have_u ? tuple_of(u, 3) : Py_NewRef(Py_None);
    PyObject *dvo = tuple_of(dv, 3);
    if (!uo || !dvo) { Py_XDECREF(uo); Py_XDECREF(dvo); return NULL; }
    return Py_BuildValue("(ddddNN)", sc[0], sc[1], sc[2], sc[3], uo, dvo);
}

/* inv3(s) -> row-major inverse (9-tuple) of a symmetric 3x3 (nested sequences, upper triangle read) */
static PyObject *py_inv3(PyObject *self, PyObject *s) {
    double m[9];
    PyObject *rows = PySequence_Fast(s, "inv3: a 3x3");
    if (!rows) return NULL;
    if (PySequence_Fast_GET_SIZE(rows) != 3) { Py_DECREF(rows); PyErr_SetString(PyExc_ValueError, "inv3: 3x3"); return NULL; }
    for (int i = 0; i < 3; i++)
        if (read_doubles(PySequence_Fast_GET_ITEM(rows, i), m + 3 * i, 3, "inv3 row") < 0) { Py_DECREF(rows); return NULL; }
    Py_DECREF(rows);
    double out[9];
    inv3_c(m[0], m[1], m[2], m[4], m[5], m[8], out);
    return tuple_of(out, 9);
}

/* R_ned_frd row-major of the quaternion q = (w, x, y, z) (navigator.rotation_scaled with s = 2 / |q|^2);
 * 0 (r untouched) when |q|^2 is not finite or <= 1e-12 */
static int rotation_of(const double *q, double *r) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    double n2 = w * w + x * x + y * y + z * z;
    if (!(isfinite(n2) && n2 > 1e-12)) return 0;
    double s = 2.0 / n2;
    double xs = x * s, ys = y * s, zs = z * s;
    double wx = w * xs, wy = w * ys, wz = w * zs;
    double xx = x * xs, xy = x * ys, xz = x * zs;
    double yy = y * ys, yz = y * zs, zz = z * zs;
    r[0] = 1.0 - (yy + zz); r[1] = xy - wz; r[2] = xz + wy;
    r[3] = xy + wz; r[4] = 1.0 - (xx + zz); r[5] = yz - wx;
    r[6] = xz - wy; r[7] = yz + wx; r[8] = 1.0 - (xx + yy);
    return 1;
}

/* rotation_q(q) -> R_ned_frd row-major (9-tuple) of the quaternion (w, x, y, z), or None when
 * |q|^2 is not finite or <= 1e-12 (rotation_of). */
static PyObject *py_rotation_q(PyObject *self, PyObject *q_o) {
    double q[4], r[9];
    if (read_doubles(q_o, q, 4, "quaternion") < 0) return NULL;
    if (!rotation_of(q, r)) Py_RETURN_NONE;
    return tuple_of(r, 9);
}

/* ------------------------------------------------------------------ the IMU history */
typedef struct {
    PyObject_HEAD
    double hold_max_s;
    long long hold_us;
    double hold_periods;  /* the hold limit follows the IMU's period: max(hold_max_s, this x period); 0: off */
    double max_force;  /* push_frd: a specific force beyond this per axis (m/s^2) is not used (counted) */
    long long t0;
    int started;
    long long *t;     /* sample times (us) */
    double *rows;     /* ROW doubles per sample: t_s, a (3), S1 (3), S2 (3), R (9), M1 (9), M2 (9), the
                       * held-time densities (w, j) of the interval ending here, W (3), J (3), the coast's
                       * densities c (3, per axis) of that interval, C (3 x 3: per axis) */
    Py_ssize_t start, n, cap;
    Py_ssize_t trim_len;  /* push returns 1 once the history is longer (the engine trims) */
    long long n_used, n_gaps, n_nonfinite, n_backwards, n_out_of_range;  /* samples pushed, by outcome */
    long long ring[RING];  /* the last sample intervals (us), for the period (held_period) */
    int ring_n, ring_i;
} History;

static int hist_init(History *self, PyObject *args, PyObject *kw) {
    static char *kwlist[] = {"hold_max_s", "hold_periods", "max_force_m_s2", NULL};
    double hold, periods = 0.0, max_force = INFINITY;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "d|dd", kwlist, &hold, &periods, &max_force)) return -1;
    self->hold_max_s = hold;
    self->hold_periods = periods;
    self->max_force = max_force;
    self->hold_us = (long long)nearbyint(hold * 1e6);  /* round half to even, as Python's round */
    self->started = 0;
    self->start = self->n = 0;
    self->trim_len = PY_SSIZE_T_MAX;
    self->n_used = self->n_gaps = self->n_nonfinite = self->n_backwards = self->n_out_of_range = 0;
    self->ring_n = self->ring_i = 0;
    if (!self->t) {
        self->cap = 1024;
        self->t = PyMem_Malloc(sizeof(long long) * self->cap);
        self->rows = PyMem_Malloc(sizeof(double) * ROW * self->cap);
        if (!self->t || !self->rows) { PyErr_NoMemory(); return -1; }
    }
    return 0;
}

static void hist_dealloc(History *self) {
    PyMem_Free(self->t);
    PyMem_Free(self->rows);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int hist_reserve(History *h) {
    if (h->start + h->n < h->cap) return 0;
    if (h->start > h->cap / 2) {  /* room at the front (trimmed): move down */
        memmove(h->t, h->t + h->start, sizeof(long long) * h->n);
        memmove(h->rows, h->rows + h->start * ROW, sizeof(double) * ROW * h->n);
        h->start = 0;
        return 0;
    }
    Py_ssize_t cap = h->cap * 2;
    long long *t = PyMem_Realloc(h->t, sizeof(long long) * cap);
    if (!t) { PyErr_NoMemory(); return -1; }
    h->t = t;
    double *rows = PyMem_Realloc(h->rows, sizeof(double) * ROW * cap);
    if (!rows) { PyErr_NoMemory(); return -1; }
    h->rows = rows;
    h->cap = cap;
    return 0;
}

static PyTypeObject HistoryType;

#define HROW(h, k) ((h)->rows + ((h)->start + (k)) * ROW)
#define HT(h, k) ((h)->t[(h)->start + (k)])

/* (∫ s, ∫ s^2) over [tp, t] */
static void moments(double tp, double t, double *dm, double *d3) {
    double dt = t - tp;
    *dm = dt * (tp + t) * 0.5;
    *d3 = dt * (tp * tp + tp * t + t * t) / 3.0;
}

/* the row after r at time t (s) holding a (3) and R (9), with the held-time densities (w, j) and the
 * coast's densities c (3; NULL: none) of the interval [r's time, t]: history._next_row */
static void next_row(const double *r, double t, double ax, double ay, double az, const double *rot, double w,
                     double j, const double *c, double *o) {
    double tp = r[0];
    double dt = t - tp, dm, d3;
    moments(tp, t, &dm, &d3);
    o[37] = w; o[38] = j;
    if (w != 0.0 || j != 0.0) {
        o[39] = r[39] + w * dt; o[40] = r[40] + w * dm; o[41] = r[41] + w * d3;
        o[42] = r[42] + j * dt; o[43] = r[43] + j * dm; o[44] = r[44] + j * d3;
    } else {
        memcpy(o + 39, r + 39, sizeof(double) * 6);
    }
    if (c) {
        for (int i = 0; i < 3; i++) {
            o[45 + i] = c[i];
            o[48 + 3 * i] = r[48 + 3 * i] + c[i] * dt;
            o[49 + 3 * i] = r[49 + 3 * i] + c[i] * dm;
            o[50 + 3 * i] = r[50 + 3 * i] + c[i] * d3;
        }
    } else {
        o[45] = o[46] = o[47] = 0.0;
        memcpy(o + 48, r + 48, sizeof(double) * 9);
    }
    o[0] = t; o[1] = ax; o[2] = ay; o[3] = az;
    for (int i = 0; i < 3; i++) {
        o[4 + i] = r[4 + i] + r[1 + i] * dt;
        o[7 + i] = r[7 + i] + r[1 + i] * dm;
    }
    for (int i = 0; i < 9; i++) {
        o[10 + i] = rot[i];
        o[19 + i] = r[19 + i] + r[10 + i] * dt;
        o[28 + i] = r[28 + i] + r[10 + i] * dm;
    }
}

/* The IMU's period (us): the median (the lower one of an even count) of the last RING sample intervals;
 * 0 before the first interval. */
static long long ring_period(const History *h) {
    long long s[RING];
    int n = h->ring_n;
    if (!n) return 0;
    memcpy(s, h->ring, sizeof(long long) * (size_t)n);
    for (int i = 1; i < n; i++)  /* insertion sort of at most RING numbers */
        for (int k = i; k > 0 && s[k - 1] > s[k]; k--) {
            long long x = s[k]; s[k] = s[k - 1]; s[k - 1] = x;
        }
    return s[(n - 1) / 2];
}

/* The IMU's period (ring_period) when the interval dt_us is longer than 1.5 periods (a sample is
 * missing: the interval would be two periods or more), else 0 (also before the first interval). An
 * interval no longer than 1.5 times the shortest of them is not (no sort). */
static long long held_period(const History *h, long long dt_us) {
    int n = h->ring_n, longer = 0;
    for (int i = 0; i < n; i++) longer |= 2 * dt_us > 3 * h->ring[i];
    if (!longer) return 0;
    long long p = ring_period(h);
    return 2 * dt_us > 3 * p ? p : 0;
}

/* The hold limit (us) of an interval dt_us: hold_us, or hold_periods x the period (ring_period, before
 * this interval) when that is longer (only looked at for an interval longer than hold_us). */
static long long hold_limit(const History *h, long long dt_us) {
    if (h->hold_periods <= 0.0 || dt_us <= h->hold_us) return h->hold_us;
    long long kp = (long long)nearbyint(h->hold_periods * (double)ring_period(h));
    return kp > h->hold_us ? kp : h->hold_us;
}

/* The held-time densities (w, j) of an input held over [tp, t] (s) against the period p_us (held_period;
 * 0: not held, (0, 0)): w = (L - p) / p and j = L^2 / 3 over the L = t - tp the input is held
 * (history.py, "Held time"). */
static void held_densities(long long p_us, double tp, double t, double *w, double *j) {
    *w = *j = 0.0;
    if (p_us <= 0) return;
    double L = t - tp, p = (double)p_us * 1e-6;
    if (L <= p) return;
    *w = (L - p) / p;
    *j = L * L / 3.0;
}

/* append (the caller gates time order and finiteness): 1 on a gap, 0 otherwise, -1 on error */
static int hist_append_c(History *h, long long t_us, double ax, double ay, double az, const double *rot) {
    if (hist_reserve(h) < 0) return -1;
    if (h->n == 0 && !h->started) {
        h->t0 = t_us;
        h->started = 1;
        double *o = HROW(h, 0);
        memset(o, 0, sizeof(double) * ROW);
        o[1] = ax; o[2] = ay; o[3] = az;
        memcpy(o + 10, rot, sizeof(double) * 9);
        HT(h, 0) = t_us;
        h->n = 1;
        return 0;
    }
    double *r = HROW(h, h->n - 1);
    double t = (double)(t_us - h->t0) * 1e-6;
    long long dt_us = t_us - HT(h, h->n - 1), p_us = held_period(h, dt_us), lim_us = hold_limit(h, dt_us);
    h->ring[h->ring_i] = dt_us;
    h->ring_i = (h->ring_i + 1) % RING;
    if (h->ring_n < RING) h->ring_n++;
    double w, j;
    /* the fixed limit compared as before (in s since t0), an extended one alike */
    int gap = t - r[0] > (lim_us == h->hold_us ? h->hold_max_s : (double)lim_us * 1e-6);
    /* the held-time densities of the whole interval (a gap's j: its hold and its coast alike) */
    held_densities(p_us, r[0], t, &w, &j);
    if (gap) {  /* held up to the limit (held time), then coasting (the acceleration's change, and the
                 * acceleration dropped); the held sample's white noise only where it is held */
        long long tv = HT(h, h->n - 1) + lim_us;
        double tvs = (double)(tv - h->t0) * 1e-6, jh;
        held_densities(p_us, r[0], tvs, &w, &jh);
        double *o = HROW(h, h->n);
        next_row(r, tvs, 0.0, 0.0, 0.0, r + 10, w, j, NULL, o);
        HT(h, h->n) = tv;
        h->n++;
        if (hist_reserve(h) < 0) return -1;
        r = HROW(h, h->n - 1);  /* the virtual sample; the held one is the row before */
        const double *held = HROW(h, h->n - 2);
        double C = t - tvs, c[3];
        for (int i = 0; i < 3; i++) c[i] = held[1 + i] * held[1 + i] * C;
        next_row(r, t, ax, ay, az, rot, 0.0, j, c, HROW(h, h->n));
    } else {
        next_row(r, t, ax, ay, az, rot, w, j, NULL, HROW(h, h->n));
    }
    HT(h, h->n) = t_us;
    h->n++;
    return gap;
}

static const double IDENT9[9] = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};

/* append(t_us, ax, ay, az, rot=identity) -> gap (bool) */
static PyObject *hist_append(History *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4 && nargs != 5) { PyErr_SetString(PyExc_TypeError, "append(t_us, ax, ay, az, rot)"); return NULL; }
    long long t = PyLong_AsLongLong(args[0]);
    double ax = PyFloat_AsDouble(args[1]), ay = PyFloat_AsDouble(args[2]), az = PyFloat_AsDouble(args[3]);
    double rot[9];
    if (nargs == 5) {
        if (read_doubles(args[4], rot, 9, "rotation") < 0) return NULL;
    } else {
        memcpy(rot, IDENT9, sizeof rot);
    }
    if (PyErr_Occurred()) return NULL;
    int g = hist_append_c(self, t, ax, ay, az, rot);
    if (g < 0) return NULL;
    return PyBool_FromLong(g);
}

/* the engine's per-sample path with its gates, counted (``counts``): not finite, not later
 * than the last sample, used (after a gap); returns True when the history is longer than
 * ``trim_len`` (time to trim), else False */
static PyObject *push_checked(History *self, long long t, double ax, double ay, double az, const double *rot) {
    if (!(isfinite(ax) && isfinite(ay) && isfinite(az))) {
        self->n_nonfinite++;
        Py_RETURN_FALSE;
    }
    if (self->n && t <= HT(self, self->n - 1)) {
        self->n_backwards++;
        Py_RETURN_FALSE;
    }
    int g = hist_append_c(self, t, ax, ay, az, rot);
    if (g < 0) return NULL;
    self->n_used++;
    self->n_gaps += g;
    return PyBool_FromLong(self->n > self->trim_len);
}

/* push(t_us, ax, ay, az, rot) -> time to trim (push_checked) */
static PyObject *hist_push(History *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) { PyErr_SetString(PyExc_TypeError, "push(t_us, ax, ay, az, rot)"); return NULL; }
    long long t = PyLong_AsLongLong(args[0]);
    double ax = PyFloat_AsDouble(args[1]), ay = PyFloat_AsDouble(args[2]), az = PyFloat_AsDouble(args[3]);
    double rot[9];
    if (read_doubles(args[4], rot, 9, "rotation") < 0) return NULL;
    if (PyErr_Occurred()) return NULL;
    return push_checked(self, t, ax, ay, az, rot);
}

/* push_checked of the NED acceleration R f + [0, 0, g] of the body specific force f; a finite specific
 * force beyond max_force on an axis (beyond any IMU's full scale: damage) is counted, not used */
static PyObject *push_frd_c(History *self, long long t, const double *f, const double *r, double g) {
    double fx = f[0], fy = f[1], fz = f[2], m = self->max_force;
    if (!(fabs(fx) <= m && fabs(fy) <= m && fabs(fz) <= m) && isfinite(fx) && isfinite(fy) && isfinite(fz)) {
        self->n_out_of_range++;
        Py_RETURN_FALSE;
    }
    return push_checked(self, t, r[0] * fx + r[1] * fy + r[2] * fz, r[3] * fx + r[4] * fy + r[5] * fz,
                        r[6] * fx + r[7] * fy + r[8] * fz + g, r);
}

/* push_frd(t_us, f_frd, rot, g) -> push_frd_c */
static PyObject *hist_push_frd(History *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) { PyErr_SetString(PyExc_TypeError, "push_frd(t_us, f_frd, rot, g)"); return NULL; }
    long long t = PyLong_AsLongLong(args[0]);
    if (t == -1 && PyErr_Occurred()) return NULL;
    double f[3], r[9];
    if (read_doubles(args[1], f, 3, "specific force") < 0 || read_doubles(args[2], r, 9, "rotation") < 0) return NULL;
    double g = PyFloat_AsDouble(args[3]);
    if (g == -1.0 && PyErr_Occurred()) return NULL;
    return push_frd_c(self, t, f, r, g);
}

/* append_batch(t_us int64 (n,), a_ned float64 (n, 3), rot float64 (n, 9) or None): append one by
 * one (the caller gates order, gaps and finiteness); counted as used */
static PyObject *hist_append_batch(History *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) { PyErr_SetString(PyExc_TypeError, "append_batch(t_us, a_ned, rot)"); return NULL; }
    int have_rot = args[2] != Py_None;
    PyArrayObject *t = (PyArrayObject *)PyArray_FROMANY(args[0], NPY_INT64, 1, 1, NPY_ARRAY_CARRAY_RO);
    PyArrayObject *a = (PyArrayObject *)PyArray_FROMANY(args[1], NPY_DOUBLE, 2, 2, NPY_ARRAY_CARRAY_RO);
    PyArrayObject *r = have_rot ? (PyArrayObject *)PyArray_FROMANY(args[2], NPY_DOUBLE, 2, 2, NPY_ARRAY_CARRAY_RO)
                                : NULL;
    PyObject *res = NULL;
    if (!t || !a || (have_rot && !r)) goto done;
    npy_intp n = PyArray_DIM(t, 0);
    if (PyArray_DIM(a, 0) != n || PyArray_DIM(a, 1) != 3
        || (have_rot && (PyArray_DIM(r, 0) != n || PyArray_DIM(r, 1) != 9))) {
        PyErr_SetString(PyExc_ValueError, "append_batch: int64 (n,), float64 (n, 3), float64 (n, 9)");
        goto done;
    }
    const npy_int64 *tv = (const npy_int64 *)PyArray_DATA(t);
    const double *av = (const double *)PyArray_DATA(a), *rv = have_rot ? (const double *)PyArray_DATA(r) : NULL;
    npy_intp k;
    for (k = 0; k < n; k++)
        if (hist_append_c(self, tv[k], av[3 * k], av[3 * k + 1], av[3 * k + 2], have_rot ? rv + 9 * k : IDENT9) < 0)
            break;
    if (k == n) {
        self->n_used += n;
        res = Py_NewRef(Py_None);
    }
done:
    Py_XDECREF(t);
    Py_XDECREF(a);
    Py_XDECREF(r);
    return res;
}

/* index of the last sample at or before t (bisect_right - 1); -1 if none */
static Py_ssize_t hist_find(const History *h, long long t) {
    Py_ssize_t lo = 0, hi = h->n;
    const long long *ts = h->t + h->start;
    while (lo < hi) {
        Py_ssize_t mid = (lo + hi) / 2;
        if (t < ts[mid]) hi = mid; else lo = mid + 1;
    }
    return lo - 1;
}

static int hist_integrals_c(const History *h, long long t_us, double *o) {
    Py_ssize_t k = hist_find(h, t_us);
    if (k < 0) {
        PyErr_SetString(PyExc_ValueError, "integrals: time before the IMU history");
        return -1;
    }
    const double *r = HROW(h, k);
    double t = (double)(t_us - h->t0) * 1e-6;
    double tau = t - r[0];
    o[0] = t;
    memcpy(o + 25, r + 39, sizeof(double) * 6);
    memcpy(o + 31, r + 48, sizeof(double) * 9);
    if (tau == 0.0) {
        memcpy(o + 1, r + 4, sizeof(double) * 6);
        memcpy(o + 7, r + 19, sizeof(double) * 18);
        return 0;
    }
    /* the held-time densities of the interval from r on are in the next row (none yet past the last) */
    const double *nx = k + 1 < h->n ? HROW(h, k + 1) : NULL;
    int held = nx && (nx[37] != 0.0 || nx[38] != 0.0);
    int coast = nx && (nx[45] != 0.0 || nx[46] != 0.0 || nx[47] != 0.0);  /* inside a coast */
    double dm2 = 0.0, d3 = 0.0;
    if (held || coast) moments(r[0], t, &dm2, &d3);
    if (held) {
        o[25] += nx[37] * tau; o[26] += nx[37] * dm2; o[27] += nx[37] * d3;
        o[28] += nx[38] * tau; o[29] += nx[38] * dm2; o[30] += nx[38] * d3;
    }
    if (coast) {
        for (int i = 0; i < 3; i++) {
            o[31 + 3 * i] += nx[45 + i] * tau; o[32 + 3 * i] += nx[45 + i] * dm2; o[33 + 3 * i] += nx[45 + i] * d3;
        }
    }
    double dm = tau * (r[0] + t) * 0.5;
    for (int i = 0; i < 3; i++) {
        o[1 + i] = r[4 + i] + r[1 + i] * tau;
        o[4 + i] = r[7 + i] + r[1 + i] * dm;
    }
    for (int i = 0; i < 9; i++) {
        o[7 + i] = r[19 + i] + r[10 + i] * tau;
        o[16 + i] = r[28 + i] + r[10 + i] * dm;
    }
    return 0;
}

static PyObject *hist_integrals(History *self, PyObject *arg) {
    long long t = PyLong_AsLongLong(arg);
    if (t == -1 && PyErr_Occurred()) return NULL;
    double o[NINT];
    if (hist_integrals_c(self, t, o) < 0) return NULL;
    return tuple_of(o, NINT);
}

static int newest_integrals(PyObject *o, double *out) {
    if (!PyObject_TypeCheck(o, &HistoryType)) return 0;
    History *h = (History *)o;
    if (!h->n) { PyErr_SetString(PyExc_IndexError, "empty IMU history"); return -1; }
    const double *r = HROW(h, h->n - 1);
    out[0] = r[0];
    memcpy(out + 1, r + 4, sizeof(double) * 6);
    memcpy(out + 7, r + 19, sizeof(double) * 18);
    memcpy(out + 25, r + 39, sizeof(double) * 6);
    memcpy(out + 31, r + 48, sizeof(double) * 9);
    return 1;
}

static PyObject *hist_last_integrals(History *self, PyObject *unused) {
    double o[NINT];
    if (newest_integrals((PyObject *)self, o) < 0) return NULL;
    return tuple_of(o, NINT);
}

static PyObject *hist_trim_before(History *self, PyObject *arg) {
    long long t = PyLong_AsLongLong(arg);
    if (t == -1 && PyErr_Occurred()) return NULL;
    Py_ssize_t k = hist_find(self, t);
    if (k > 0) {
        self->start += k;
        self->n -= k;
    }
    Py_RETURN_NONE;
}

static PyObject *hist_get_rows(History *self, void *c) {
    PyObject *l = PyList_New(self->n);
    if (!l) return NULL;
    for (Py_ssize_t k = 0; k < self->n; k++) {
        PyObject *r = tuple_of(HROW(self, k), ROW);
        if (!r) { Py_DECREF(l); return NULL; }
        PyList_SET_ITEM(l, k, r);
    }
    return l;
}

static PyObject *hist_get_t_us(History *self, void *c) {
    PyObject *l = PyList_New(self->n);
    if (!l) return NULL;
    for (Py_ssize_t k = 0; k < self->n; k++) {
        PyObject *v = PyLong_FromLongLong(HT(self, k));
        if (!v) { Py_DECREF(l); return NULL; }
        PyList_SET_ITEM(l, k, v);
    }
    return l;
}

static PyObject *hist_get_first(History *self, void *c) {
    if (!self->n) { PyErr_SetString(PyExc_IndexError, "empty IMU history"); return NULL; }
    return PyLong_FromLongLong(HT(self, 0));
}

static PyObject *hist_get_last(History *self, void *c) {
    if (!self->n) { PyErr_SetString(PyExc_IndexError, "empty IMU history"); return NULL; }
    return PyLong_FromLongLong(HT(self, self->n - 1));
}

static PyObject *hist_get_t0(History *self, void *c) {
    if (!self->started) Py_RETURN_NONE;
    return PyLong_FromLongLong(self->t0);
}

static PyObject *hist_get_hold(History *self, void *c) { return PyFloat_FromDouble(self->hold_max_s); }
static PyObject *hist_get_hold_periods(History *self, void *c) { return PyFloat_FromDouble(self->hold_periods); }

static Py_ssize_t hist_len(History *self) { return self->n; }

static PyObject *hist_get_counts(History *self, void *c) {
    return Py_BuildValue("(LLLLL)", self->n_used, self->n_gaps, self->n_nonfinite, self->n_backwards,
                         self->n_out_of_range);
}

static PyMemberDef hist_members[] = {
    {"trim_len", T_PYSSIZET, offsetof(History, trim_len), 0, "push returns True above this many samples"},
    {NULL, 0, 0, 0, NULL},
};

static PyMethodDef hist_methods[] = {
    {"append", (PyCFunction)(void (*)(void))hist_append, METH_FASTCALL,
     "append(t_us, ax, ay, az, rot=identity) -> gap: add a sample (the caller gates)"},
    {"push", (PyCFunction)(void (*)(void))hist_push, METH_FASTCALL,
     "push(t_us, ax, ay, az, rot) -> time to trim: a gated, counted sample"},
    {"push_frd", (PyCFunction)(void (*)(void))hist_push_frd, METH_FASTCALL,
     "push_frd(t_us, f_frd, rot, g): push with the NED acceleration R f + [0, 0, g]"},
    {"append_batch", (PyCFunction)(void (*)(void))hist_append_batch, METH_FASTCALL,
     "append_batch(t_us, a_ned, rot): append row by row"},
    {"integrals", (PyCFunction)hist_integrals, METH_O, "(t_s, S1, S2, M1, M2) at a time inside the history"},
    {"last_integrals", (PyCFunction)hist_last_integrals, METH_NOARGS, "integrals at the newest sample"},
    {"trim_before", (PyCFunction)hist_trim_before, METH_O, "drop samples not needed from t_us on"},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef hist_getset[] = {
    {"rows", (getter)hist_get_rows, NULL, "the rows as tuples (a copy)", NULL},
    {"t_us", (getter)hist_get_t_us, NULL, "the sample times (a copy)", NULL},
    {"first_t_us", (getter)hist_get_first, NULL, "oldest sample time", NULL},
    {"last_t_us", (getter)hist_get_last, NULL, "newest sample time", NULL},
    {"t0_us", (getter)hist_get_t0, NULL, "time of the first sample ever (None before)", NULL},
    {"hold_max_s", (getter)hist_get_hold, NULL, "longest hold of an input", NULL},
    {"hold_periods", (getter)hist_get_hold_periods, NULL, "the hold limit in IMU periods (0: hold_max_s only)", NULL},
    {"counts", (getter)hist_get_counts, NULL, "samples pushed: (used, gaps, not finite, time not increasing)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PySequenceMethods hist_seq = {.sq_length = (lenfunc)hist_len};

static PyTypeObject HistoryType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "companion.estimator._core.History",
    .tp_basicsize = sizeof(History),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE,
    .tp_doc = "History(hold_max_s, hold_periods=0, max_force_m_s2=inf): held IMU inputs with prefix integrals",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)hist_init,
    .tp_dealloc = (destructor)hist_dealloc,
    .tp_methods = hist_methods,
    .tp_getset = hist_getset,
    .tp_members = hist_members,
    .tp_as_sequence = &hist_seq,
};

/* ------------------------------------------------------------------ the navigator's per-sample front */
/* Front(history, g_m_s2, imu_type, attitude_type, other, pushed, waiting): a navigator's push(sample)
 * (navigator.Navigator.push; docs in its class): an attitude sample's rotation kept (rotation_of; counted
 * in attitude_used or attitude_rejected_nonfinite), an IMU sample pushed with the latest rotation
 * (History.push_frd; counted in imu_rejected_no_attitude before any) and ``pushed()`` called when that
 * returns True or ``waiting`` (a list) is not empty; any other sample handed to ``other(sample)``. */
enum { F_HIST, F_IMU_TYPE, F_ATT_TYPE, F_OTHER, F_PUSHED, F_WAITING, F_NREF };

typedef struct {
    PyObject_HEAD
    vectorcallfunc vectorcall;
    PyObject *ref[F_NREF];  /* the objects held (F_*: the history, the two sample types, other, pushed, waiting) */
    double g;
    double rot[9];
    int has_rot;
    long long n_used, n_nonfinite, n_no_attitude;  /* the samples counted (the navigator's counters) */
} Front;

static PyObject *s_t_us, *s_acc, *s_q;

/* n floats from the attribute ``name`` of ``o`` (read_doubles) */
static int attr_doubles(PyObject *o, PyObject *name, double *out, Py_ssize_t n, const char *what) {
    PyObject *v = PyObject_GetAttr(o, name);
    if (!v) return -1;
    int rc = read_doubles(v, out, n, what);
    Py_DECREF(v);
    return rc;
}

static PyObject *front_push(Front *self, PyObject *sample) {
    PyTypeObject *kind = Py_TYPE(sample);
    if ((PyObject *)kind == self->ref[F_IMU_TYPE]) {
        if (!self->has_rot) {
            self->n_no_attitude++;
            Py_RETURN_NONE;
        }
        PyObject *t_o = PyObject_GetAttr(sample, s_t_us);
        if (!t_o) return NULL;
        long long t = PyLong_AsLongLong(t_o);
        Py_DECREF(t_o);
        if (t == -1 && PyErr_Occurred()) return NULL;
        double f[3];
        if (attr_doubles(sample, s_acc, f, 3, "specific force") < 0) return NULL;
        PyObject *due = push_frd_c((History *)self->ref[F_HIST], t, f, self->rot, self->g);
        if (!due) return NULL;
        int is_due = due == Py_True;
        Py_DECREF(due);
        if (is_due || PyList_GET_SIZE(self->ref[F_WAITING]) > 0) return PyObject_CallNoArgs(self->ref[F_PUSHED]);
        Py_RETURN_NONE;
    }
    if ((PyObject *)kind == self->ref[F_ATT_TYPE]) {
        double q[4];
        if (attr_doubles(sample, s_q, q, 4, "quaternion") < 0) return NULL;
        if (!rotation_of(q, self->rot)) {
            self->n_nonfinite++;
            Py_RETURN_NONE;
        }
        self->has_rot = 1;
        self->n_used++;
        Py_RETURN_NONE;
    }
    return PyObject_CallOneArg(self->ref[F_OTHER], sample);
}

static PyObject *front_vectorcall(PyObject *self, PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    if (PyVectorcall_NARGS(nargsf) != 1 || (kwnames && PyTuple_GET_SIZE(kwnames))) {
        PyErr_SetString(PyExc_TypeError, "push(sample): one sample");
        return NULL;
    }
    return front_push((Front *)self, args[0]);
}

static int front_init(Front *self, PyObject *args, PyObject *kw) {
    PyObject *hist, *imu_type, *att_type, *other, *pushed, *waiting;
    double g;
    if (!PyArg_ParseTuple(args, "O!dOOOOO!", &HistoryType, &hist, &g, &imu_type, &att_type, &other, &pushed,
                          &PyList_Type, &waiting))
        return -1;
    PyObject *held[F_NREF] = {hist, imu_type, att_type, other, pushed, waiting};
    for (int i = 0; i < F_NREF; i++) Py_XSETREF(self->ref[i], Py_NewRef(held[i]));
    self->g = g;
    self->has_rot = 0;
    self->vectorcall = front_vectorcall;
    return 0;
}

static int front_traverse(Front *self, visitproc visit, void *arg) {
    for (int i = 0; i < F_NREF; i++) Py_VISIT(self->ref[i]);
    return 0;
}

static int front_clear(Front *self) {
    for (int i = 0; i < F_NREF; i++) Py_CLEAR(self->ref[i]);
    return 0;
}

static void front_dealloc(Front *self) {
    PyObject_GC_UnTrack(self);
    front_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* rot: the latest attitude's R_ned_frd (9-tuple; None before one); settable (a batch of samples sets it) */
static PyObject *front_get_rot(Front *self, void *c) {
    if (!self->has_rot) Py_RETURN_NONE;
    return tuple_of(self->rot, 9);
}

static int front_set_rot(Front *self, PyObject *v, void *c) {
    if (!v || v == Py_None) { self->has_rot = 0; return 0; }
    double r[9];
    if (read_doubles(v, r, 9, "rotation") < 0) return -1;
    memcpy(self->rot, r, sizeof r);
    self->has_rot = 1;
    return 0;
}

static PyGetSetDef front_getset[] = {
    {"rot", (getter)front_get_rot, (setter)front_set_rot, "the latest R_ned_frd (row-major) or None", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMemberDef front_members[] = {
    {"attitude_used", T_LONGLONG, offsetof(Front, n_used), 0, "attitude samples used"},
    {"attitude_rejected_nonfinite", T_LONGLONG, offsetof(Front, n_nonfinite), 0,
     "attitude samples whose quaternion is not finite or about 0"},
    {"imu_rejected_no_attitude", T_LONGLONG, offsetof(Front, n_no_attitude), 0, "IMU samples before any attitude"},
    {NULL, 0, 0, 0, NULL},
};

static PyTypeObject FrontType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "companion.estimator._core.Front",
    .tp_basicsize = sizeof(Front),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC | Py_TPFLAGS_HAVE_VECTORCALL,
    .tp_doc = "Front(history, g_m_s2, imu_type, attitude_type, other, pushed, waiting): a navigator's push(sample)",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)front_init,
    .tp_traverse = (traverseproc)front_traverse,
    .tp_clear = (inquiry)front_clear,
    .tp_dealloc = (destructor)front_dealloc,
    .tp_call = PyVectorcall_Call,
    .tp_vectorcall_offset = offsetof(Front, vectorcall),
    .tp_getset = front_getset,
    .tp_members = front_members,
};

/* ------------------------------------------------------------------ the belief's loss */
/* loss_grad(beta, terms, params) -> (loss, d loss / d beta, NIS): belief.loss_grad, operation for operation
 * (belief.s_of_beta, belief._terms, the Student-t or Gaussian fit, belief.bias_level), for an
 * InnovationTerms ``terms`` (y, s0, q_bias_unit, r_nominal, pht_p, bias_scale, bias_m2) and ``params`` =
 * belief.loss_params(cfg): (sigma_bias_max_m, sigma_bias_floor_m, r_inflation_max, lambda_smooth_1_m,
 * student (1) or gaussian (0), student_dof, lambda_bias_level). */
/* NULL with the exception Python's float arithmetic raises (belief.loss_grad's out of its domain) */
static PyObject *py_error(PyObject *type, const char *what) {
    PyErr_SetString(type, what);
    return NULL;
}

/* -1 with the exception Python's float arithmetic raises */
static int fail(PyObject *type, const char *what) {
    PyErr_SetString(type, what);
    return -1;
}

static int loss_grad_c(double beta, PyObject *t, PyObject *params, double *out) {
    if (!PyTuple_Check(t) || PyTuple_GET_SIZE(t) != 7) {
        PyErr_SetString(PyExc_TypeError, "loss_grad: terms, an InnovationTerms (7)");
        return -1;
    }
    double y[3], s0[3], rn[3], p[3], bm[3], c[7];
    double qbu = PyFloat_AsDouble(PyTuple_GET_ITEM(t, 2)), f = PyFloat_AsDouble(PyTuple_GET_ITEM(t, 5));
    if (PyErr_Occurred() || read_doubles(PyTuple_GET_ITEM(t, 0), y, 3, "y") < 0
        || read_doubles(PyTuple_GET_ITEM(t, 1), s0, 3, "s0") < 0
        || read_doubles(PyTuple_GET_ITEM(t, 3), rn, 3, "r_nominal") < 0
        || read_doubles(PyTuple_GET_ITEM(t, 4), p, 3, "pht_p") < 0
        || read_doubles(PyTuple_GET_ITEM(t, 6), bm, 3, "bias_m2") < 0 || read_doubles(params, c, 7, "params") < 0)
        return -1;
    double smax = c[0], floor_m = c[1], rmax = c[2], lam = c[3], nu = c[5], wb = c[6];
    /* s_of_beta */
    double sb = (smax * (1.0 - beta) + floor_m) * f;
    double e = 1.0 - beta, r = pow(rmax, e);
    if (isinf(r) && isfinite(rmax) && isfinite(e)) {  /* Python's ** overflowing */
        PyErr_SetString(PyExc_OverflowError, "(34, 'Numerical result out of range')");
        return -1;
    }
    double q = qbu * sb * sb;
    double dq = -2.0 * qbu * sb * smax * f;
    double dr = -log(rmax) * r;
    double S[3], dS[3], w[3];
    for (int i = 0; i < 3; i++) {
        S[i] = (s0[i] + q) + r * rn[i];
        dS[i] = dq + dr * rn[i];
        w[i] = y[i] / S[i];
    }
    /* _terms: sums over the axes from 0.0, left to right */
    double logdet = 0.0, d_logdet = 0.0, nis = 0.0, d_nis = 0.0, dp2 = 0.0, d_dp2 = 0.0;
    for (int i = 0; i < 3; i++)  /* Python's y / S, then math.log(S): their exceptions, in that order */
        if (S[i] == 0.0) return fail(PyExc_ZeroDivisionError, "float division by zero");
    for (int i = 0; i < 3; i++) {
        if (S[i] < 0.0) return fail(PyExc_ValueError, "math domain error");
        logdet += log(S[i]);
        d_logdet += dS[i] / S[i];
        nis += y[i] * w[i];
        d_nis -= w[i] * w[i] * dS[i];
        double j = p[i] * w[i];
        dp2 += j * j;
        d_dp2 += 2.0 * j * (-p[i] * w[i] * dS[i] / S[i]);
    }
    double n = sqrt(dp2), smooth = 0.0, d_smooth = 0.0;
    if (n > 0.0) {
        smooth = lam * n;
        d_smooth = 0.5 * lam * d_dp2 / n;
    }
    double fit, d_fit;
    if (c[4] != 0.0) {
        if (nis / nu <= -1.0) return fail(PyExc_ValueError, "math domain error");  /* math.log1p's */
        fit = 0.5 * (nu + 3.0) * log1p(nis / nu);
        d_fit = 0.5 * (nu + 3.0) * d_nis / (nu + nis);
    } else {
        fit = 0.5 * nis;
        d_fit = 0.5 * d_nis;
    }
    double level = 0.0, d_level = 0.0;  /* bias_level */
    if (wb != 0.0) {
        double sigma = (smax * (1.0 - beta) + floor_m) * f;
        if (sigma * sigma == 0.0) return fail(PyExc_ZeroDivisionError, "float division by zero");
        if (sigma < 0.0) return fail(PyExc_ValueError, "math domain error");
        double m = bm[0] + bm[1] + bm[2];
        double inv2 = 1.0 / (sigma * sigma);
        level = wb * (3.0 * log(sigma) + 0.5 * m * inv2);
        d_level = wb * (3.0 - m * inv2) / sigma * (-smax * f);
    }
    out[0] = 0.5 * logdet + fit + smooth + level;
    out[1] = 0.5 * d_logdet + d_fit + d_smooth + d_level;
    out[2] = nis;
    return 0;
}

static PyObject *py_loss_grad(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) { PyErr_SetString(PyExc_TypeError, "loss_grad(beta, terms, params)"); return NULL; }
    double beta = PyFloat_AsDouble(args[0]), out[3];
    if ((beta == -1.0 && PyErr_Occurred()) || loss_grad_c(beta, args[1], args[2], out) < 0) return NULL;
    return Py_BuildValue("(ddd)", out[0], out[1], out[2]);
}

static PyObject *same_type(PyObject *like, PyObject *items);

/* belief_update(state, terms, loss_params, step) -> methods._Belief.update of the first-order (step = (1, eta_1,
 * theta_min, theta_max)) or second-order (step = (2, eta, theta_min, theta_max, alpha_fast, alpha_slow,
 * omega_fast, lambda_reg)) belief, operation for operation: g = loss_grad's derivative x beta (1 - beta), the
 * step, theta clamped (min(theta_max, max(theta_min, theta)) as Python's builtins), beta = 1 / (1 + e^-theta);
 * a BeliefState (the type of ``state``: theta, h_fast, h_slow, beta) */
static PyObject *py_belief_update(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4 || !PyTuple_Check(args[0]) || PyTuple_GET_SIZE(args[0]) != 4 || !PyTuple_Check(args[3])) {
        PyErr_SetString(PyExc_TypeError, "belief_update(state (4), terms, loss_params, step)");
        return NULL;
    }
    double st[4], k[8], lg[3];
    Py_ssize_t n = PyTuple_GET_SIZE(args[3]);
    if (read_doubles(args[0], st, 4, "state") < 0 || (n != 4 && n != 8)
        || read_doubles(args[3], k, n, "step") < 0)
        return PyErr_Occurred() ? NULL : py_error(PyExc_ValueError, "belief_update: step of 4 or 8 numbers");
    double beta = st[3];
    if (loss_grad_c(beta, args[1], args[2], lg) < 0) return NULL;
    double g = lg[1] * beta * (1.0 - beta), theta, h_fast = st[1], h_slow = st[2];
    if (k[0] == 1.0 && n == 4) {
        theta = st[0] - k[1] * g;
    } else if (k[0] == 2.0 && n == 8) {
        h_fast = k[4] * st[1] + g * g;
        h_slow = k[5] * st[2] + g * g;
        double h = k[6] * h_fast + (1.0 - k[6]) * h_slow;
        theta = st[0] - k[1] * g / (h + k[7]);
    } else {
        return py_error(PyExc_ValueError, "belief_update: step kind 1 (4 numbers) or 2 (8 numbers)");
    }
    if (!(theta > k[2])) theta = k[2];  /* max(theta_min, theta): theta only when greater */
    if (!(theta < k[3])) theta = k[3];  /* min(theta_max, theta): theta only when less */
    double e = exp(-theta);
    if (isinf(e) && isfinite(theta)) return py_error(PyExc_OverflowError, "math range error");
    return same_type(args[0], Py_BuildValue("(dddd)", theta, h_fast, h_slow, 1.0 / (1.0 + e)));
}

/* ------------------------------------------------------------------ the reported accuracy's sums */
/* x ** 2 as Python's float power computes it (libm's pow; OverflowError where it overflows) */
static int py_square(double x, double *out) {
    double r = pow(x, 2.0);
    if (isinf(r) && isfinite(x)) {
        PyErr_SetString(PyExc_OverflowError, "(34, 'Numerical result out of range')");
        return -1;
    }
    *out = r;
    return 0;
}

/* the weight exp(-dt / window_s) of the older sums, dt = (t_us - t0) * 1e-6 (math.exp: OverflowError where
 * it overflows); -1 on error */
static int decay_of(PyObject *t_o, long long t0, double window_s, double *dt, double *a) {
    long long t = PyLong_AsLongLong(t_o);
    if (t == -1 && PyErr_Occurred()) return -1;
    *dt = (double)(t - t0) * 1e-6;
    double e = -*dt / window_s;
    *a = exp(e);
    if (isinf(*a) && isfinite(e)) {
        PyErr_SetString(PyExc_OverflowError, "math range error");
        return -1;
    }
    return 0;
}

/* a NamedTuple of the type of ``like`` holding ``items`` (stolen; NULL: an error already set) */
static PyObject *same_type(PyObject *like, PyObject *items) {
    if (!items) return NULL;
    PyObject *args = PyTuple_Pack(1, items);
    Py_DECREF(items);
    if (!args) return NULL;
    PyObject *o = PyTuple_Type.tp_new(Py_TYPE(like), args, NULL);
    Py_DECREF(args);
    return o;
}

/* the fields of a Scatter or Scatter1 (12), their t_us; -1 on error */
static int scatter_fields(PyObject *s, PyObject ***f, long long *t0) {
    if (!PyTuple_Check(s) || PyTuple_GET_SIZE(s) != 12) {
        PyErr_SetString(PyExc_TypeError, "scatter_add: not a Scatter");
        return -1;
    }
    *f = &PyTuple_GET_ITEM(s, 0);
    *t0 = PyLong_AsLongLong((*f)[0]);
    return (*t0 == -1 && PyErr_Occurred()) ? -1 : 0;
}

/* scatter_add(s, t_us, z, v, window_s) -> consistency.Scatter.add of a Scatter ``s`` holding a fix (t_us >= 0),
 * operation for operation (z, v: (N, E) 2-tuples, kept as given) */
static PyObject *py_scatter_add(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) { PyErr_SetString(PyExc_TypeError, "scatter_add(s, t_us, z, v, window_s)"); return NULL; }
    PyObject **f;
    long long t0;
    if (scatter_fields(args[0], &f, &t0) < 0) return NULL;
    double z[2], v[2], z0[2], v0[2], q[2], qp[2], s[2], s2[2], dt, a;
    double w = PyFloat_AsDouble(f[5]), w2 = PyFloat_AsDouble(f[6]), d1 = PyFloat_AsDouble(f[9]),
           d2 = PyFloat_AsDouble(f[10]), dw = PyFloat_AsDouble(f[11]), window_s = PyFloat_AsDouble(args[4]);
    int has_prev = f[4] != Py_None;
    if (PyErr_Occurred() || read_doubles(args[2], z, 2, "z") < 0 || read_doubles(args[3], v, 2, "v") < 0
        || read_doubles(f[1], z0, 2, "z") < 0 || read_doubles(f[2], v0, 2, "v") < 0
        || read_doubles(f[3], q, 2, "q") < 0 || (has_prev && read_doubles(f[4], qp, 2, "q_prev") < 0)
        || read_doubles(f[7], s, 2, "q_sum") < 0 || read_doubles(f[8], s2, 2, "q2_sum") < 0
        || decay_of(args[1], t0, window_s, &dt, &a) < 0)
        return NULL;
    double h = 0.5 * dt;
    double q0 = q[0] + (z[0] - z0[0]) - h * (v[0] + v0[0]);
    double q1 = q[1] + (z[1] - z0[1]) - h * (v[1] + v0[1]);
    d1 = a * d1;
    d2 = a * d2;
    dw = a * dw;
    if (has_prev) {
        double e0, e1, e2, e3;
        if (py_square(q0 - q[0], &e0) < 0 || py_square(q1 - q[1], &e1) < 0 || py_square(q0 - qp[0], &e2) < 0
            || py_square(q1 - qp[1], &e3) < 0)
            return NULL;
        d1 += e0 + e1;
        d2 += e2 + e3;
        dw += 1.0;
    }
    return same_type(args[0], Py_BuildValue("(OOO(dd)Odd(dd)(dd)ddd)", args[1], args[2], args[3], q0, q1, f[3],
                                            a * w + 1.0, a * a * w2 + 1.0, a * s[0] + q0, a * s[1] + q1,
                                            a * s2[0] + q0 * q0, a * s2[1] + q1 * q1, d1, d2, dw));
}

/* scatter1_add(s, t_us, z, v, window_s) -> consistency.Scatter1.add of a Scatter1 ``s`` holding a fix, operation
 * for operation (z, v: floats) */
static PyObject *py_scatter1_add(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) { PyErr_SetString(PyExc_TypeError, "scatter1_add(s, t_us, z, v, window_s)"); return NULL; }
    PyObject **f;
    long long t0;
    if (scatter_fields(args[0], &f, &t0) < 0) return NULL;
    double z = PyFloat_AsDouble(args[2]), v = PyFloat_AsDouble(args[3]), window_s = PyFloat_AsDouble(args[4]);
    double z0 = PyFloat_AsDouble(f[1]), v0 = PyFloat_AsDouble(f[2]), q0 = PyFloat_AsDouble(f[3]);
    double w = PyFloat_AsDouble(f[5]), w2 = PyFloat_AsDouble(f[6]), s = PyFloat_AsDouble(f[7]),
           s2 = PyFloat_AsDouble(f[8]), d1 = PyFloat_AsDouble(f[9]), d2 = PyFloat_AsDouble(f[10]),
           dw = PyFloat_AsDouble(f[11]);
    int has_prev = f[4] != Py_None;
    double qp = has_prev ? PyFloat_AsDouble(f[4]) : 0.0, dt, a;
    if (PyErr_Occurred() || decay_of(args[1], t0, window_s, &dt, &a) < 0) return NULL;
    double q = q0 + (z - z0) - (0.5 * dt) * (v + v0);
    d1 = a * d1;
    d2 = a * d2;
    dw = a * dw;
    if (has_prev) {
        double e1, e2;
        if (py_square(q - q0, &e1) < 0 || py_square(q - qp, &e2) < 0) return NULL;
        d1 += e1 + e1;
        d2 += e2 + e2;
        dw += 1.0;
    }
    return same_type(args[0], Py_BuildValue("(OOOdOddddddd)", args[1], args[2], args[3], q, f[3], a * w + 1.0,
                                            a * a * w2 + 1.0, a * s + q, a * s2 + q * q, d1, d2, dw));
}

/* decay_add3(nu_sum, w2_sum, a, nu0, nu1, nu2) -> (a nu_sum + nu, a^2 w2_sum + 1) as new arrays (3,):
 * consistency.fit_add3's sums */
static PyObject *py_decay_add3(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 6) { PyErr_SetString(PyExc_TypeError, "decay_add3(nu_sum, w2_sum, a, nu0, nu1, nu2)"); return NULL; }
    double n[3], w[3], nu[3], a = PyFloat_AsDouble(args[2]);
    for (int i = 0; i < 3; i++) nu[i] = PyFloat_AsDouble(args[3 + i]);
    if (PyErr_Occurred() || read_doubles(args[0], n, 3, "nu_sum") < 0 || read_doubles(args[1], w, 3, "w2_sum") < 0)
        return NULL;
    double aa = a * a, no[3], wo[3];
    for (int i = 0; i < 3; i++) {
        no[i] = a * n[i] + nu[i];
        wo[i] = aa * w[i] + 1.0;
    }
    return Py_BuildValue("(NN)", new_array(1, 3, 0, no), new_array(1, 3, 0, wo));
}

/* consistency.floored_axis: max(k p, min(c k p, s2)) for one axis's variance p (k p when c <= 1) */
static double floored_axis_c(double p, double k, double c, double s2) {
    double kp = p * k;
    if (c <= 1.0) return kp;
    double f = kp * c;
    f = f < s2 ? f : s2;
    return f > kp ? f : kp;
}

/* reported(out, k, floor) -> (p, v, b, var): a snapshot's ``out`` (18,: p, v, b, their variances) as the
 * navigator reports it, four new arrays (3, 3, 3, 9): the position variances x k (the consistency factor,
 * 1: none), and with ``floor`` = (c, s2, c_v, s2_v) (None: none) each horizontal one floored_axis(P, k, c,
 * s2) when c > 1, the vertical one with (c_v, s2_v) when c_v > 1 */
static PyObject *py_reported(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) { PyErr_SetString(PyExc_TypeError, "reported(out, k, floor)"); return NULL; }
    double o[18], fl[4], k = PyFloat_AsDouble(args[1]);
    if ((k == -1.0 && PyErr_Occurred()) || read_doubles(args[0], o, 18, "out") < 0
        || (args[2] != Py_None && read_doubles(args[2], fl, 4, "floor") < 0))
        return NULL;
    double var[9];
    for (int i = 0; i < 9; i++) var[i] = i < 3 ? o[9 + i] * k : o[9 + i];
    if (args[2] != Py_None) {
        if (fl[0] > 1.0) {
            var[0] = floored_axis_c(o[9], k, fl[0], fl[1]);
            var[1] = floored_axis_c(o[10], k, fl[0], fl[1]);
        }
        if (fl[2] > 1.0) var[2] = floored_axis_c(o[11], k, fl[2], fl[3]);
    }
    return Py_BuildValue("(NNNN)", new_array(1, 3, 0, o), new_array(1, 3, 0, o + 3), new_array(1, 3, 0, o + 6),
                         new_array(1, 9, 0, var));
}

/* geodetic_ned(consts, lat_deg, lon_deg, alt_m) -> (N, E, D) (m): navigator.NedConverter, pymap3d's
 * geodetic2ecef written out operation for operation (math.radians' product, libm's cos, sin and hypot:
 * numpy's float64 functions where they are libm's) less the home's ECEF position, rotated into its NED;
 * consts = (A, A^2, B, (B/A)^2, the home's ECEF x, y, z, R_ned_ecef row-major (9)) */
static PyObject *py_geodetic_ned(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) { PyErr_SetString(PyExc_TypeError, "geodetic_ned(consts, lat_deg, lon_deg, alt_m)"); return NULL; }
    double c[16];
    double lat_deg = PyFloat_AsDouble(args[1]), lon_deg = PyFloat_AsDouble(args[2]), alt = PyFloat_AsDouble(args[3]);
    if (PyErr_Occurred() || read_doubles(args[0], c, 16, "consts") < 0) return NULL;
    const double deg = Py_MATH_PI / 180.0;  /* math.radians */
    double lat = lat_deg * deg, lon = lon_deg * deg;
    double cos_lat = cos(lat), sin_lat = sin(lat);
    double n = c[1] / hypot(c[0] * cos_lat, c[2] * sin_lat);
    double x = (n + alt) * cos_lat * cos(lon), y = (n + alt) * cos_lat * sin(lon), z = (n * c[3] + alt) * sin_lat;
    double dx = x - c[4], dy = y - c[5], dz = z - c[6];
    const double *r = c + 7;
    return Py_BuildValue("(ddd)", r[0] * dx + r[1] * dy + r[2] * dz, r[3] * dx + r[4] * dy + r[5] * dz,
                         r[6] * dx + r[7] * dy + r[8] * dz);
}

/* slots_new(cls, descriptors, *values) -> object.__new__(cls) with each descriptor's __set__(obj, value) in
 * turn: a frozen dataclass with slots built from all its fields (samples.new_nav_estimate's steps, without
 * its Python call: the navigator's per-estimate NavEstimate) */
static PyObject *py_slots_new(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs < 2 || !PyType_Check(args[0]) || !PyTuple_Check(args[1]) || PyTuple_GET_SIZE(args[1]) != nargs - 2) {
        PyErr_SetString(PyExc_TypeError, "slots_new(cls, descriptors, *values): one value per descriptor");
        return NULL;
    }
    PyObject *empty = PyTuple_New(0);
    if (!empty) return NULL;
    PyObject *o = PyBaseObject_Type.tp_new((PyTypeObject *)args[0], empty, NULL);
    Py_DECREF(empty);
    if (!o) return NULL;
    for (Py_ssize_t i = 0; i < nargs - 2; i++) {
        PyObject *d = PyTuple_GET_ITEM(args[1], i);
        descrsetfunc set = Py_TYPE(d)->tp_descr_set;
        if (!set) { Py_DECREF(o); PyErr_SetString(PyExc_TypeError, "slots_new: not a data descriptor"); return NULL; }
        if (set(d, o, args[2 + i]) < 0) { Py_DECREF(o); return NULL; }
    }
    return o;
}

/* consistency._correlation: c in [1, C_MAX] from the squared changes' sums */
#define C_MAX 100.0
#define SCATTER_MAX 2.0
static double correlation_c(double dw, double d1, double d2) {
    if (dw < 1.5 || d1 <= 0.0) return 1.0;
    double r = d2 / d1;
    if (r <= 1.0) return 1.0;
    if (r >= 2.0 * C_MAX / (C_MAX + 1.0)) return C_MAX;
    return r / (2.0 - r);
}

/* consistency.fix_floor(scatter, r) of a Scatter (N and E: q_sum a 2-tuple) or a Scatter1 (the axis given
 * twice), operation for operation (_statistics, _correlation): out = (c, s2); -1 on error */
static int fix_floor_c(PyObject *sc, PyObject *r_o, double *out) {
    if (!PyTuple_Check(sc) || PyTuple_GET_SIZE(sc) != 12) {
        PyErr_SetString(PyExc_TypeError, "fix_floors: not a Scatter");
        return -1;
    }
    PyObject **f = &PyTuple_GET_ITEM(sc, 0);
    double s[2], s2[2];
    if (PyTuple_Check(f[7])) {
        if (read_doubles(f[7], s, 2, "q_sum") < 0 || read_doubles(f[8], s2, 2, "q2_sum") < 0) return -1;
    } else {
        s[0] = s[1] = PyFloat_AsDouble(f[7]);
        s2[0] = s2[1] = PyFloat_AsDouble(f[8]);
    }
    double w = PyFloat_AsDouble(f[5]), w2 = PyFloat_AsDouble(f[6]), d1 = PyFloat_AsDouble(f[9]),
           d2 = PyFloat_AsDouble(f[10]), dw = PyFloat_AsDouble(f[11]), r = PyFloat_AsDouble(r_o);
    if (PyErr_Occurred()) return -1;
    double c = correlation_c(dw, d1, d2), v = 0.0;
    if (!(dw <= 0.0 || w * w <= w2 * 1.000001)) {
        if (w == 0.0 || w * w == 0.0) return fail(PyExc_ZeroDivisionError, "float division by zero");
        double m0 = s[0] / w, m1 = s[1] / w;
        double var = 0.5 * ((s2[0] / w - m0 * m0) + (s2[1] / w - m1 * m1));
        double share = c * w2 / (w * w);
        double fa = share < 1.0 - 1.0 / SCATTER_MAX ? 1.0 / (1.0 - share) : SCATTER_MAX;
        v = var * fa;
        v = v > 0.0 ? v : 0.0;
    }
    if (r > v && isfinite(r)) v = r;
    out[0] = c;
    out[1] = v;
    return 0;
}

/* fix_floors(scatter, scatter_v, r_h, r_v) -> (c, s2, c_v, s2_v), consistency.fix_floor of the horizontal and
 * the vertical scatter (the navigator's floor), or None when neither c is above 1 */
static PyObject *py_fix_floors(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) { PyErr_SetString(PyExc_TypeError, "fix_floors(scatter, scatter_v, r_h, r_v)"); return NULL; }
    double h[2], v[2];
    if (fix_floor_c(args[0], args[2], h) < 0 || fix_floor_c(args[1], args[3], v) < 0) return NULL;
    if (!(h[0] > 1.0 || v[0] > 1.0)) Py_RETURN_NONE;
    return Py_BuildValue("(dddd)", h[0], h[1], v[0], v[1]);
}

/* inflation3(nu_sum, w2_sum) -> consistency.fit_inflation3 of a three-axis Fit's sums (1 when the weights'
 * sum is not > 0, at least 1) */
static PyObject *py_inflation3(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) { PyErr_SetString(PyExc_TypeError, "inflation3(nu_sum, w2_sum)"); return NULL; }
    double n[3], w[3];
    if (read_doubles(args[0], n, 3, "nu_sum") < 0 || read_doubles(args[1], w, 3, "w2_sum") < 0) return NULL;
    double den = w[0] + w[1] + w[2];
    if (!(den > 0.0)) return PyFloat_FromDouble(1.0);
    double k = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) / den;
    return PyFloat_FromDouble(k > 1.0 ? k : 1.0);
}

/* a module function of the METH_FASTCALL convention, py_NAME */
#define FASTCALL(name, doc) {#name, (PyCFunction)(void (*)(void))py_##name, METH_FASTCALL, doc}

static PyMethodDef module_methods[] = {
    FASTCALL(mean_between, "mean_between(x, a, b, alpha) -> (x at b, -A, -B)"),
    FASTCALL(rotation_blocks, "rotation_blocks(a, b) -> (-A, -B) row-major"),
    FASTCALL(update, "update(x, P, y, r) -> (x+, P+, NIS)"),
    FASTCALL(receiver_spread,
             "receiver_spread(a, b, z, pz, pu, pd, tp, T, yd, scales, k, ek, kn, ekn) -> (4 centres, u, dv)"),
    FASTCALL(vel_nis, "vel_nis(x, P, z_v, r) -> (horizontal NIS, vertical NIS) of a velocity measurement"),
    FASTCALL(update_vel, "update_vel(x, P, z_v, r) -> (x+, P+): the reported velocity components fused"),
    {"inv3", (PyCFunction)py_inv3, METH_O, "inverse of a symmetric 3x3, row-major"},
    {"rotation_q", (PyCFunction)py_rotation_q, METH_O, "R_ned_frd of a quaternion, or None"},
    FASTCALL(scatter_add, "scatter_add(s, t_us, z, v, window_s) -> consistency.Scatter.add (s holding a fix)"),
    FASTCALL(scatter1_add, "scatter1_add(s, t_us, z, v, window_s) -> consistency.Scatter1.add (s holding a fix)"),
    FASTCALL(decay_add3, "decay_add3(nu_sum, w2_sum, a, nu0, nu1, nu2) -> (a nu_sum + nu, a^2 w2_sum + 1)"),
    FASTCALL(fix_floors,
             "fix_floors(scatter, scatter_v, r_h, r_v) -> (c, s2, c_v, s2_v) or None: consistency.fix_floor of both"),
    FASTCALL(inflation3, "inflation3(nu_sum, w2_sum) -> consistency.fit_inflation3 of a three-axis Fit"),
    FASTCALL(slots_new, "slots_new(cls, descriptors, *values) -> a slots dataclass set through its descriptors"),
    FASTCALL(geodetic_ned, "geodetic_ned(consts, lat_deg, lon_deg, alt_m) -> (N, E, D): navigator.NedConverter"),
    FASTCALL(reported, "reported(out, k, floor) -> (p, v, b, var): a snapshot as the navigator reports it"),
    FASTCALL(belief_update,
             "belief_update(state, terms, loss_params, step) -> BeliefState: a first/second-order _Belief.update"),
    FASTCALL(loss_grad, "loss_grad(beta, terms, params) -> (loss, its beta-derivative, NIS): belief.loss_grad"),
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef core_module = {
    PyModuleDef_HEAD_INIT, "_core", "The estimator's numeric core (history, block prediction, update).", -1,
    module_methods,
};

PyMODINIT_FUNC PyInit__core(void) {
    import_array();
    if (PyType_Ready(&HistoryType) < 0 || PyType_Ready(&PropagatorType) < 0 || PyType_Ready(&FrontType) < 0)
        return NULL;
    if (!(s_t_us = PyUnicode_InternFromString("t_us")) || !(s_acc = PyUnicode_InternFromString("acc_frd_m_s2"))
        || !(s_q = PyUnicode_InternFromString("q_ned_frd")))
        return NULL;
    PyObject *m = PyModule_Create(&core_module);
    if (!m) return NULL;
    if (PyModule_AddObjectRef(m, "History", (PyObject *)&HistoryType) < 0
        || PyModule_AddObjectRef(m, "Propagator", (PyObject *)&PropagatorType) < 0
        || PyModule_AddObjectRef(m, "Front", (PyObject *)&FrontType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
