/* The tightly coupled filter's numeric hot path in C: the block covariance prediction, the
 * pseudorange innovations with their Jacobian, and the stacked Kalman update with the range
 * rates (model.py's formulas; equal to the numpy forms to rounding, tested in tests/test_tight.py).
 *
 * State layout (model.py): p 0-2, v 3-5, a 6-8, d 9-11, clocks 12-17, drift 18, heading offset 19,
 * yaw-rate bias 20, and (once a barometer was seen) the baro offset 21: the state size N (21 or 22) is
 * the given covariance's. Arrays are float64, C order. Compiled with -ffp-contract=off (no fused
 * multiply-add), as the estimator's core.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>
#define NPY_NO_DEPRECATED_API NPY_1_22_API_VERSION
#include <numpy/arrayobject.h>
#include "../estimator/held.h" /* the held-time noise, shared with the loose core */

#define N_BASE 21 /* the state without the baro offset */
#define I_BARO 21
#define NMAX 22 /* with it */
#define NC 6
#define I_CLK 12
#define I_DRIFT 18
#define I_HEAD 19
#define I_YAWB 20
#define MAXM 160 /* measurement rows in one update (pseudoranges + range rates) */

static const double C_M_S = 299792458.0;
static const double W_C = 7.2921151467e-5 / 299792458.0; /* ω_e / c */

static PyArrayObject *in_array(PyObject *obj, int nd) {
    if (PyArray_CheckExact(obj)) { /* already a C-ordered, aligned float64 array of nd dimensions (the usual
                                    * case): itself, without numpy's conversion machinery (~2 k instructions) */
        PyArrayObject *a = (PyArrayObject *)obj;
        if (PyArray_NDIM(a) == nd && PyArray_TYPE(a) == NPY_DOUBLE && PyArray_ISNOTSWAPPED(a)
            && PyArray_IS_C_CONTIGUOUS(a) && PyArray_ISALIGNED(a)) {
            Py_INCREF(obj);
            return a;
        }
    }
    return (PyArrayObject *)PyArray_FROMANY(obj, NPY_DOUBLE, nd, nd, NPY_ARRAY_IN_ARRAY);
}

static PyObject *new_array(int nd, npy_intp d0, npy_intp d1, const double *src) {
    npy_intp dims[2] = {d0, d1};
    PyObject *out = PyArray_SimpleNew(nd, dims, NPY_DOUBLE);
    if (out && src) memcpy(PyArray_DATA((PyArrayObject *)out), src, sizeof(double) * (size_t)(d0 * (nd == 2 ? d1 : 1)));
    return out;
}

/* ---------------------------------------------------------------- prediction */
/* the integrals a (a tuple of HELD_INTS floats, or any such sequence) into v: t and the held-time
 * moments (held.h; the rest left 0) */
static int read_held(PyObject *o, double *v) {
    PyObject *seq = PySequence_Fast(o, "integrals");
    if (!seq) return -1;
    if (PySequence_Fast_GET_SIZE(seq) != HELD_INTS) {
        Py_DECREF(seq);
        PyErr_Format(PyExc_ValueError, "integrals: expected %d numbers", HELD_INTS);
        return -1;
    }
    PyObject **it = PySequence_Fast_ITEMS(seq);
    memset(v, 0, sizeof(double) * HELD_INTS);
    v[0] = PyFloat_AsDouble(it[0]);
    for (int k = HELD_AT; k < HELD_INTS; k++) v[k] = PyFloat_AsDouble(it[k]);
    Py_DECREF(seq);
    return PyErr_Occurred() ? -1 : 0;
}

/* held_noise(a, b, q_white (3: per axis), q_rw, q_coast) -> (pp, pv, vv) of each axis (9) or None:
 * held.h's held_noise between the integrals a and b (None: no held time nor coast, or densities 0) */
static PyObject *py_held_noise(PyObject *self, PyObject *args) {
    PyObject *oa, *ob;
    double qw[3], qj, qc, a[HELD_INTS], b[HELD_INTS], hq[9];
    if (!PyArg_ParseTuple(args, "OO(ddd)dd", &oa, &ob, &qw[0], &qw[1], &qw[2], &qj, &qc)) return NULL;
    if (read_held(oa, a) < 0 || read_held(ob, b) < 0) return NULL;
    if (!held_noise(a, b, qw, qj, qc, hq)) Py_RETURN_NONE;
    return Py_BuildValue("(ddddddddd)", hq[0], hq[1], hq[2], hq[3], hq[4], hq[5], hq[6], hq[7], hq[8]);
}

/* predict_cov(P, T, nA, nB, live, q_acc_ne, q_acc_d, q_rw, q_ned, q_clock, q_isb, q_drift, q_heading,
 *             q_yaw_bias, heading_live[, a, b, q_hold_ne, q_hold_d, q_hold_rw, q_coast]) -> F P F^T + Q
 * (model.transition, model.process_noise); with the block's integrals a and b, its held-time noise
 * (held.h: the held sample's white density q_hold_ne horizontally and q_hold_d vertically, the random
 * walk q_hold_rw, a coast's dropped acceleration scaled by q_coast) on p, v */
static inline __attribute__((always_inline)) PyObject *predict_cov_n(PyObject *args, const int N) {
    PyObject *oP, *onA, *onB, *olive, *oa = NULL, *ob = NULL;
    double T, qne, qd, w, e, qc, qi, qdr, qh, qb, qw[3] = {0.0, 0.0, 0.0}, hrw = 0.0, hc = 0.0, qbaro = 0.0;
    int hlive;
    if (!PyArg_ParseTuple(args, "OdOOOdddddddddp|OOddddd", &oP, &T, &onA, &onB, &olive, &qne, &qd, &w, &e, &qc,
                          &qi, &qdr, &qh, &qb, &hlive, &oa, &ob, &qw[0], &qw[2], &hrw, &hc, &qbaro))
        return NULL;
    qw[1] = qw[0];
    /* held time: hq[3 i ..] = (pp, pv, vv) of axis i, when the block holds any */
    double hq[9];
    int held = 0;
    if (oa && ob && (qw[0] != 0.0 || qw[2] != 0.0 || hrw != 0.0 || hc != 0.0)) {
        double a[HELD_INTS], b[HELD_INTS];
        if (read_held(oa, a) < 0 || read_held(ob, b) < 0) return NULL;
        held = held_noise(a, b, qw, hrw, hc, hq);
    }
    PyArrayObject *aP = in_array(oP, 2), *anA = in_array(onA, 1), *anB = in_array(onB, 1), *alive = in_array(olive, 1);
    if (!aP || !anA || !anB || !alive) goto fail;
    if (PyArray_DIM(aP, 0) != N || PyArray_DIM(aP, 1) != N || PyArray_DIM(anA, 0) != 9
        || PyArray_DIM(anB, 0) != 9 || PyArray_DIM(alive, 0) != NC) {
        PyErr_SetString(PyExc_ValueError, "predict_cov: shapes");
        goto fail;
    }
    const double *P = PyArray_DATA(aP), *nA = PyArray_DATA(anA), *nB = PyArray_DATA(anB), *live = PyArray_DATA(alive);
    double F[NMAX * NMAX], FP[NMAX * NMAX], out[NMAX * NMAX];
    memset(F, 0, sizeof(double) * (size_t)(N * N));
    for (int i = 0; i < N; i++) F[i * N + i] = 1.0;
    double h = -0.5 * T * T;
    for (int i = 0; i < 3; i++) {
        F[i * N + 3 + i] = T;
        F[i * N + 9 + i] = h;
        F[(3 + i) * N + 9 + i] = -T;
        for (int j = 0; j < 3; j++) {
            F[i * N + 6 + j] = nB[i * 3 + j];
            F[(3 + i) * N + 6 + j] = nA[i * 3 + j];
        }
    }
    for (int j = 0; j < NC; j++) F[(I_CLK + j) * N + I_DRIFT] = T * live[j];
    F[I_HEAD * N + I_YAWB] = -T;
    /* F P and (F P) F^T over each row's non-zero entries of F (a few per row), in increasing column order:
     * the same sums, term by term, as the dense products that skip F's zeros */
    int nz[NMAX * NMAX], nnz[NMAX];
    for (int i = 0; i < N; i++) {
        nnz[i] = 0;
        for (int j = 0; j < N; j++)
            if (F[i * N + j] != 0.0) nz[i * N + nnz[i]++] = j;
    }
    for (int i = 0; i < N; i++)
        for (int k = 0; k < N; k++) {
            double s = 0.0;
            for (int t = 0; t < nnz[i]; t++) {
                int j = nz[i * N + t];
                s += F[i * N + j] * P[j * N + k];
            }
            FP[i * N + k] = s;
        }
    for (int i = 0; i < N; i++)
        for (int k = 0; k < N; k++) {
            double s = 0.0;
            for (int t = 0; t < nnz[k]; t++) {
                int j = nz[k * N + t];
                s += FP[i * N + j] * F[k * N + j];
            }
            out[i * N + k] = s;
        }
    for (int i = 0; held && i < 3; i++) { /* held time (held.h), before the model's Q as the loose core adds it */
        const double *h3 = hq + 3 * i;
        out[i * N + i] += h3[0];
        out[i * N + 3 + i] += h3[1];
        out[(3 + i) * N + i] += h3[1];
        out[(3 + i) * N + 3 + i] += h3[2];
    }
    /* Q (model.process_noise) */
    double T2 = T * T, T3 = T2 * T, T4 = T2 * T2, T5 = T4 * T;
    double pp = (w + e) * T5 / 20.0, pv = (w + e) * T4 / 8.0, vv = (w + e) * T3 / 3.0;
    double pd = -e * T3 / 6.0, vd = -e * T2 / 2.0;
    for (int i = 0; i < 3; i++) {
        double q = i == 2 ? qd : qne;
        out[i * N + i] += q * T3 / 3.0 + pp;
        out[i * N + 3 + i] += q * T2 / 2.0 + pv;
        out[(3 + i) * N + i] += q * T2 / 2.0 + pv;
        out[(3 + i) * N + 3 + i] += q * T + vv;
        out[(6 + i) * N + 6 + i] += w * T;
        out[(9 + i) * N + 9 + i] += e * T;
        out[i * N + 9 + i] += pd;
        out[(9 + i) * N + i] += pd;
        out[(3 + i) * N + 9 + i] += vd;
        out[(9 + i) * N + 3 + i] += vd;
    }
    if (w > 0.0) {
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) {
                double Rm = T > 0.0 ? -nA[i * 3 + j] / T : (i == j ? 1.0 : 0.0);
                double pa = (-w * T3 / 6.0) * Rm, va = (-w * T2 / 2.0) * Rm;
                out[i * N + 6 + j] += pa;
                out[(6 + j) * N + i] += pa;
                out[(3 + i) * N + 6 + j] += va;
                out[(6 + j) * N + 3 + i] += va;
            }
    }
    double c = qc * T + qdr * T3 / 3.0;
    for (int i = 0; i < NC; i++) {
        for (int j = 0; j < NC; j++) out[(I_CLK + i) * N + I_CLK + j] += live[i] * live[j] * c;
        out[(I_CLK + i) * N + I_CLK + i] += live[i] * (qi * T);
        out[(I_CLK + i) * N + I_DRIFT] += live[i] * (qdr * T2 / 2.0);
        out[I_DRIFT * N + I_CLK + i] += live[i] * (qdr * T2 / 2.0);
    }
    out[I_DRIFT * N + I_DRIFT] += qdr * T;
    if (hlive) {
        out[I_HEAD * N + I_HEAD] += qh * T + qb * T3 / 3.0;
        out[I_HEAD * N + I_YAWB] += -qb * T2 / 2.0;
        out[I_YAWB * N + I_HEAD] += -qb * T2 / 2.0;
        out[I_YAWB * N + I_YAWB] += qb * T;
    }
    if (N > I_BARO) out[I_BARO * N + I_BARO] += qbaro * T; /* the baro offset's random walk */
    Py_DECREF(aP); Py_DECREF(anA); Py_DECREF(anB); Py_DECREF(alive);
    return new_array(2, N, N, out);
fail:
    Py_XDECREF(aP); Py_XDECREF(anA); Py_XDECREF(anB); Py_XDECREF(alive);
    return NULL;
}

/* ---------------------------------------------------------------- measurements */
/* the receiver position r = r0 + C p (ECEF) and velocity C v */
static void receiver(const double *x, const double *r0, const double *C, double *r, double *ve) {
    for (int i = 0; i < 3; i++) {
        r[i] = r0[i] + C[i * 3] * x[0] + C[i * 3 + 1] * x[1] + C[i * 3 + 2] * x[2];
        ve[i] = C[i * 3] * x[3] + C[i * 3 + 1] * x[4] + C[i * 3 + 2] * x[5];
    }
}

/* innovations(x, P, r0, C, sat_pos (m, 3), slot (m) float, z (m)) -> (y (m), H (m, N), HP (m, N), s0 (m),
 * min |y| per clock slot (NC, inf where none)): model.pseudorange and the β-independent innovation
 * variances (H P H^T)_ii */
static inline __attribute__((always_inline)) PyObject *innovations_n(PyObject *args, const int N) {
    PyObject *ox, *oP, *or0, *oC, *os, *osl, *oz;
    if (!PyArg_ParseTuple(args, "OOOOOOO", &ox, &oP, &or0, &oC, &os, &osl, &oz)) return NULL;
    PyArrayObject *ax = in_array(ox, 1), *aP = in_array(oP, 2), *ar0 = in_array(or0, 1), *aC = in_array(oC, 2),
                  *as = in_array(os, 2), *asl = in_array(osl, 1), *az = in_array(oz, 1);
    PyObject *oy = NULL, *oH = NULL, *oHP = NULL, *os0 = NULL, *omin = NULL;
    if (!ax || !aP || !ar0 || !aC || !as || !asl || !az) goto fail;
    npy_intp m = PyArray_DIM(as, 0);
    if (PyArray_DIM(aP, 0) != N || PyArray_DIM(ax, 0) != N || PyArray_DIM(aP, 1) != N
        || PyArray_DIM(as, 1) != 3 || PyArray_DIM(asl, 0) != m || PyArray_DIM(az, 0) != m) {
        PyErr_SetString(PyExc_ValueError, "innovations: shapes");
        goto fail;
    }
    const double *x = PyArray_DATA(ax), *P = PyArray_DATA(aP), *r0 = PyArray_DATA(ar0), *C = PyArray_DATA(aC),
                 *S = PyArray_DATA(as), *sl = PyArray_DATA(asl), *z = PyArray_DATA(az);
    oy = new_array(1, m, 0, NULL); oH = new_array(2, m, N, NULL); oHP = new_array(2, m, N, NULL);
    os0 = new_array(1, m, 0, NULL);
    omin = new_array(1, NC, 0, NULL);
    if (!oy || !oH || !oHP || !os0 || !omin) goto fail;
    double *mins = PyArray_DATA((PyArrayObject *)omin);
    for (int j = 0; j < NC; j++) mins[j] = INFINITY;
    double *y = PyArray_DATA((PyArrayObject *)oy), *H = PyArray_DATA((PyArrayObject *)oH),
           *HP = PyArray_DATA((PyArrayObject *)oHP), *s0 = PyArray_DATA((PyArrayObject *)os0);
    double r[3], ve[3];
    receiver(x, r0, C, r, ve);
    memset(H, 0, sizeof(double) * (size_t)(m * N));
    for (npy_intp i = 0; i < m; i++) {
        const double *s = S + 3 * i;
        double d0 = s[0] - r[0], d1 = s[1] - r[1], d2 = s[2] - r[2];
        double rng = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
        int j = (int)sl[i];
        double pred = rng + W_C * (s[0] * r[1] - s[1] * r[0]) + x[I_CLK + j];
        y[i] = z[i] - pred;
        if (j >= 0 && j < NC && fabs(y[i]) < mins[j]) mins[j] = fabs(y[i]);
        double dr0 = -d0 / rng - W_C * s[1], dr1 = -d1 / rng + W_C * s[0], dr2 = -d2 / rng;
        double *h = H + i * N;
        for (int k = 0; k < 3; k++) h[k] = dr0 * C[k] + dr1 * C[3 + k] + dr2 * C[6 + k];
        h[I_CLK + j] = 1.0;
        double *hp = HP + i * N, q = 0.0;
        for (int k = 0; k < N; k++) {
            double v = h[0] * P[k] + h[1] * P[N + k] + h[2] * P[2 * N + k] + P[(I_CLK + j) * N + k];
            hp[k] = v;
        }
        q = hp[0] * h[0] + hp[1] * h[1] + hp[2] * h[2] + hp[I_CLK + j];
        s0[i] = q;
    }
    Py_DECREF(ax); Py_DECREF(aP); Py_DECREF(ar0); Py_DECREF(aC); Py_DECREF(as); Py_DECREF(asl); Py_DECREF(az);
    return Py_BuildValue("(NNNNN)", oy, oH, oHP, os0, omin);
fail:
    Py_XDECREF(ax); Py_XDECREF(aP); Py_XDECREF(ar0); Py_XDECREF(aC); Py_XDECREF(as); Py_XDECREF(asl);
    Py_XDECREF(az); Py_XDECREF(oy); Py_XDECREF(oH); Py_XDECREF(oHP); Py_XDECREF(os0); Py_XDECREF(omin);
    return NULL;
}

/* model.range_rate for one satellite: prediction and H row */
static double range_rate_row(const double *x, const double *r0, const double *C, const double *rs,
                             const double *us, double *h, int N) {
    double r[3], ve[3];
    receiver(x, r0, C, r, ve);
    double d[3] = {rs[0] - r[0], rs[1] - r[1], rs[2] - r[2]};
    double rng = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    double l[3] = {d[0] / rng, d[1] / rng, d[2] / rng};
    double dv[3] = {us[0] - ve[0], us[1] - ve[1], us[2] - ve[2]};
    double g = l[0] * dv[0] + l[1] * dv[1] + l[2] * dv[2];
    double sv = l[0] * us[0] + l[1] * us[1] + l[2] * us[2];
    double f = 1.0 - sv / C_M_S;
    double sag = W_C * (us[0] * r[1] + rs[0] * ve[1] - us[1] * r[0] - rs[1] * ve[0]);
    double dm_dr[3], dm_dv[3];
    for (int k = 0; k < 3; k++) {
        double dg = -(dv[k] - g * l[k]) / rng, ds = -(us[k] - sv * l[k]) / rng;
        dm_dr[k] = dg * f - (g / C_M_S) * ds;
        dm_dv[k] = -l[k] * f;
    }
    dm_dr[0] -= W_C * us[1];
    dm_dr[1] += W_C * us[0];
    dm_dv[0] -= W_C * rs[1];
    dm_dv[1] += W_C * rs[0];
    memset(h, 0, sizeof(double) * N);
    for (int k = 0; k < 3; k++) {
        h[k] = dm_dr[0] * C[k] + dm_dr[1] * C[3 + k] + dm_dr[2] * C[6 + k];
        h[3 + k] = dm_dv[0] * C[k] + dm_dv[1] * C[3 + k] + dm_dv[2] * C[6 + k];
    }
    h[I_DRIFT] = 1.0;
    return g * f + sag + x[I_DRIFT];
}

/* update(x, P, H (m, N), HP (m, N), y (m), r (m), used (m) float 0/1, r0, C, sat_pos, sat_vel, z_rate (m, NaN: none),
 *        r_rate (m), gate2) -> (x+, P+, NIS, range rates used): the used pseudoranges and, for each used
 * satellite with a range rate that passes its own gate (y² ≤ gate2 (s0 + r)), that range rate, in one
 * Kalman update (Cholesky of S) */
/* Cholesky factor A = L Lᵀ of the symmetric A (k×k, row-major; L in its lower triangle, in place);
 * 0 if A is not positive definite */
static int chol_factor(double *A, int k) {
    for (int j = 0; j < k; j++) {
        double s = A[j * k + j];
        for (int c = 0; c < j; c++) s -= A[j * k + c] * A[j * k + c];
        if (!(s > 0.0)) return 0;
        double d = sqrt(s);
        A[j * k + j] = d;
        for (int i = j + 1; i < k; i++) {
            double t = A[i * k + j];
            for (int c = 0; c < j; c++) t -= A[i * k + c] * A[j * k + c];
            A[i * k + j] = t / d;
        }
    }
    return 1;
}

/* Sums Σ_c a[c] b[c] taken over the nonzero b[c] alone are the full sums, bit for bit, when every a[c] is
 * finite: a left-out term is ±0, and an accumulator that starts at +0 never becomes −0 (round to nearest),
 * so adding ±0 never changes it. nonzero_index: the columns of b's nonzero entries (all n when a_finite is 0:
 * the full sum) */
static int nonzero_index(const double *b, int n, int a_finite, int *idx) {
    int m = 0;
    for (int c = 0; c < n; c++)
        if (!a_finite || b[c] != 0.0) idx[m++] = c;
    return m;
}

static int all_finite(const double *a, int n) {
    for (int i = 0; i < n; i++)
        if (!isfinite(a[i])) return 0;
    return 1;
}

static inline __attribute__((always_inline)) PyObject *update_n(PyObject *args, const int N) {
    PyObject *ox, *oP, *oH, *oHP, *oy, *or, *ou, *or0, *oC, *os, *ov, *ozr, *orr;
    double gate2;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOOOd", &ox, &oP, &oH, &oHP, &oy, &or, &ou, &or0, &oC, &os, &ov, &ozr,
                          &orr, &gate2))
        return NULL;
    PyObject *objs[13] = {ox, oP, oH, oHP, oy, or, ou, or0, oC, os, ov, ozr, orr};
    int nds[13] = {1, 2, 2, 2, 1, 1, 1, 1, 2, 2, 2, 1, 1};
    PyArrayObject *a[13] = {0};
    double *Hs = NULL, *HPs = NULL, *W = NULL, *Sm = NULL;
    int *Hnz = NULL;
    PyObject *result = NULL;
    for (int i = 0; i < 13; i++) {
        a[i] = in_array(objs[i], nds[i]);
        if (!a[i]) goto done;
    }
    npy_intp m = PyArray_DIM(a[4], 0);
    if (PyArray_DIM(a[1], 0) != N || PyArray_DIM(a[0], 0) != N || PyArray_DIM(a[1], 1) != N
        || PyArray_DIM(a[2], 1) != N || PyArray_DIM(a[3], 1) != N || PyArray_DIM(a[2], 0) != m
        || PyArray_DIM(a[3], 0) != m) {
        PyErr_SetString(PyExc_ValueError, "update: shapes");
        goto done;
    }
    const double *x = PyArray_DATA(a[0]), *P = PyArray_DATA(a[1]), *H = PyArray_DATA(a[2]), *HP = PyArray_DATA(a[3]),
                 *y = PyArray_DATA(a[4]), *r = PyArray_DATA(a[5]), *used = PyArray_DATA(a[6]),
                 *r0 = PyArray_DATA(a[7]), *C = PyArray_DATA(a[8]), *sp = PyArray_DATA(a[9]),
                 *sv = PyArray_DATA(a[10]), *zr = PyArray_DATA(a[11]), *rr = PyArray_DATA(a[12]);
    Hs = malloc(sizeof(double) * MAXM * N);
    HPs = malloc(sizeof(double) * MAXM * N);
    double ys[MAXM], rs[MAXM];
    int k = 0, n_rate = 0, P_finite = all_finite(P, N * N);
    for (npy_intp i = 0; i < m && k < MAXM; i++) {
        if (used[i] == 0.0) continue;
        memcpy(Hs + k * N, H + i * N, sizeof(double) * N);
        memcpy(HPs + k * N, HP + i * N, sizeof(double) * N);
        ys[k] = y[i];
        rs[k] = r[i];
        k++;
    }
    for (npy_intp i = 0; i < m && k < MAXM; i++) {
        if (used[i] == 0.0 || !isfinite(zr[i]) || !isfinite(sv[3 * i])) continue;
        double *h = Hs + k * N, *hp = HPs + k * N;
        double pred = range_rate_row(x, r0, C, sp + 3 * i, sv + 3 * i, h, N);
        double yr = zr[i] - pred, s0 = 0.0;
        int nz[NMAX], nnz = nonzero_index(h, N, P_finite, nz); /* h: p, v and the drift */
        for (int c = 0; c < N; c++) {
            double v = 0.0;
            for (int t = 0; t < nnz; t++) v += h[nz[t]] * P[nz[t] * N + c];
            hp[c] = v;
        }
        for (int c = 0; c < N; c++) s0 += hp[c] * h[c];
        if (yr * yr <= gate2 * (s0 + rr[i])) {
            ys[k] = yr;
            rs[k] = rr[i];
            k++;
            n_rate++;
        }
    }
    double xo[NMAX], Po[NMAX * NMAX], nis = NAN;
    memcpy(xo, x, sizeof(double) * (size_t)N);
    memcpy(Po, P, sizeof(double) * (size_t)(N * N));
    if (k > 0) {
        Sm = malloc(sizeof(double) * k * k);
        W = malloc(sizeof(double) * k * (N + 1));
        Hnz = malloc(sizeof(int) * k * N);
        int HP_finite = all_finite(HPs, k * N), n_nz[MAXM];
        for (int j = 0; j < k; j++) n_nz[j] = nonzero_index(Hs + j * N, N, HP_finite, Hnz + j * N);
        for (int i = 0; i < k; i++)
            for (int j = 0; j <= i; j++) { /* over H_j's nonzero columns: a pseudorange's 4, a range rate's 7 */
                const int *cj = Hnz + j * N;
                double s = 0.0;
                for (int t = 0; t < n_nz[j]; t++) s += HPs[i * N + cj[t]] * Hs[j * N + cj[t]];
                Sm[i * k + j] = Sm[j * k + i] = s + (i == j ? rs[i] : 0.0);
            }
        if (!chol_factor(Sm, k)) { /* S = L L^T (lower, in place) */
            PyErr_SetString(PyExc_ArithmeticError, "update: innovation covariance not positive definite");
            goto done;
        }
        /* V = L^-1 [y, HP] (k x (N+1)), forward substitution: then K y = HP^T S^-1 y = V_HP^T V_y and
         * K H P = V_HP^T V_HP (symmetric), NIS = |V_y|^2 */
        for (int i = 0; i < k; i++) {
            W[i * (N + 1)] = ys[i];
            memcpy(W + i * (N + 1) + 1, HPs + i * N, sizeof(double) * N);
        }
        for (int i = 0; i < k; i++) {
            double *restrict wi = W + i * (N + 1); /* rows i and j < i: apart (restrict: the loop vectorises) */
            for (int j = 0; j < i; j++) {
                double l = Sm[i * k + j];
                const double *restrict wj = W + j * (N + 1);
                for (int c = 0; c <= N; c++) wi[c] -= l * wj[c];
            }
            double d = Sm[i * k + i];
            for (int c = 0; c <= N; c++) wi[c] /= d;
        }
        nis = 0.0;
        for (int i = 0; i < k; i++) nis += W[i * (N + 1)] * W[i * (N + 1)];
        /* the sums over the rows i, every column's at once (each in the order i = 0 … k − 1: the loops over c
         * vectorise) */
        double acc[NMAX];
        for (int c = 0; c < N; c++) acc[c] = 0.0;
        for (int i = 0; i < k; i++) {
            const double *restrict wi = W + i * (N + 1);
            for (int c = 0; c < N; c++) acc[c] += wi[1 + c] * wi[0];
        }
        for (int c = 0; c < N; c++) xo[c] += acc[c];
        for (int r1 = 0; r1 < N; r1++) {
            for (int c = r1; c < N; c++) acc[c] = 0.0;
            for (int i = 0; i < k; i++) {
                const double *restrict wi = W + i * (N + 1) + 1;
                double w = wi[r1];
                for (int c = r1; c < N; c++) acc[c] += w * wi[c];
            }
            for (int c = r1; c < N; c++) {
                Po[r1 * N + c] -= acc[c];
                if (c != r1) Po[c * N + r1] -= acc[c];
            }
        }
        for (int r1 = 0; r1 < N; r1++) /* P was symmetric: keep it exactly so */
            for (int c = r1 + 1; c < N; c++) {
                double s = 0.5 * (Po[r1 * N + c] + Po[c * N + r1]);
                Po[r1 * N + c] = Po[c * N + r1] = s;
            }
    }
    result = Py_BuildValue("(NNdi)", new_array(1, N, 0, xo), new_array(2, N, N, Po), nis, n_rate);
done:
    for (int i = 0; i < 13; i++) Py_XDECREF(a[i]);
    free(Hs); free(HPs); free(W); free(Sm); free(Hnz);
    return result;
}

/* belief_step(theta, h_fast, h_slow, y, s0, r_nominal, theta_prior, eta, lambda_reg, alpha_fast, alpha_slow,
 *             omega_fast, nu, k, kappa, theta_min, theta_max, gate2, first_order, epoch_scale, early)
 * -> (theta, h_fast, h_slow, beta, r, used): belief.grad_theta, the second-order (or first-order) step,
 * the clamp, β = σ(θ), R(β) = R_nom k^(1-β) and the innovation gate y² <= gate2 (s0 + R), per satellite;
 * epoch_scale: the gradient's S scaled by belief.epoch_scale (the epoch's median y²/S over χ²(1)'s, ≥ 1);
 * early: the consistency (median and gradient) sees an early innovation (y < 0) times this
 * (belief.consistency_innovation); the gate sees y as it is */
#define CHI2_1_MEDIAN 0.454936
#define MAX_SORT 256
static PyObject *py_belief_step(PyObject *self, PyObject *args) {
    PyObject *o[7];
    double eta, lam, af, as_, wf, nu, kk, kappa, tmin, tmax, gate2, early;
    int first, epoch_scale;
    if (!PyArg_ParseTuple(args, "OOOOOOOdddddddddddppd", &o[0], &o[1], &o[2], &o[3], &o[4], &o[5], &o[6], &eta,
                          &lam, &af, &as_, &wf, &nu, &kk, &kappa, &tmin, &tmax, &gate2, &first, &epoch_scale,
                          &early))
        return NULL;
    PyArrayObject *a[7] = {0};
    PyObject *out[6] = {0};
    for (int i = 0; i < 7; i++) {
        a[i] = in_array(o[i], 1);
        if (!a[i]) goto fail;
    }
    npy_intp m = PyArray_DIM(a[0], 0);
    for (int i = 1; i < 7; i++)
        if (PyArray_DIM(a[i], 0) != m) {
            PyErr_SetString(PyExc_ValueError, "belief_step: shapes");
            goto fail;
        }
    for (int i = 0; i < 6; i++) {
        out[i] = new_array(1, m, 0, NULL);
        if (!out[i]) goto fail;
    }
    const double *th0 = PyArray_DATA(a[0]), *hf0 = PyArray_DATA(a[1]), *hs0 = PyArray_DATA(a[2]),
                 *y = PyArray_DATA(a[3]), *s0 = PyArray_DATA(a[4]), *rn = PyArray_DATA(a[5]),
                 *pr = PyArray_DATA(a[6]);
    double *th = PyArray_DATA((PyArrayObject *)out[0]), *hf = PyArray_DATA((PyArrayObject *)out[1]),
           *hs = PyArray_DATA((PyArrayObject *)out[2]), *be = PyArray_DATA((PyArrayObject *)out[3]),
           *r = PyArray_DATA((PyArrayObject *)out[4]), *used = PyArray_DATA((PyArrayObject *)out[5]);
    double lnk = log(kk);
    double scale = 1.0;
    if (epoch_scale && m >= 4 && m <= MAX_SORT) {  /* the median of y²/(s0 + R(β)) before the step */
        double q[MAX_SORT];
        for (npy_intp i = 0; i < m; i++) {
            double b = 1.0 / (1.0 + exp(-th0[i]));
            double ye = y[i] < 0.0 ? early * y[i] : y[i];
            double v = ye * ye / (s0[i] + rn[i] * pow(kk, 1.0 - b)), w;
            npy_intp j = i;
            for (; j > 0 && (w = q[j - 1]) > v; j--) q[j] = w;  /* insertion sort */
            q[j] = v;
        }
        double med = (m % 2) ? q[m / 2] : 0.5 * (q[m / 2 - 1] + q[m / 2]);
        scale = med / CHI2_1_MEDIAN > 1.0 ? med / CHI2_1_MEDIAN : 1.0;
    }
    for (npy_intp i = 0; i < m; i++) {
        double t = th0[i];
        double b = 1.0 / (1.0 + exp(-t));
        double rr = rn[i] * pow(kk, 1.0 - b);
        double ye = y[i] < 0.0 ? early * y[i] : y[i];
        double S = scale * (s0[i] + rr), y2 = ye * ye;
        double dl = 0.5 / S - 0.5 * (nu + 1.0) * y2 / (S * (nu * S + y2));
        double g = dl * (-lnk) * scale * rr * b * (1.0 - b) + kappa * (t - pr[i]);
        double f = hf0[i], sl = hs0[i];
        if (first) {
            t = t - eta * g;
        } else {
            f = af * f + g * g;
            sl = as_ * sl + g * g;
            double h = wf * f + (1.0 - wf) * sl;
            t = t - eta * g / (h + lam);
        }
        t = t < tmin ? tmin : (t > tmax ? tmax : t);
        b = 1.0 / (1.0 + exp(-t));
        rr = rn[i] * pow(kk, 1.0 - b);
        th[i] = t; hf[i] = f; hs[i] = sl; be[i] = b; r[i] = rr;
        used[i] = y[i] * y[i] <= gate2 * (s0[i] + rr) ? 1.0 : 0.0;
    }
    for (int i = 0; i < 7; i++) Py_DECREF(a[i]);
    return Py_BuildValue("(NNNNNN)", out[0], out[1], out[2], out[3], out[4], out[5]);
fail:
    for (int i = 0; i < 7; i++) Py_XDECREF(a[i]);
    for (int i = 0; i < 6; i++) Py_XDECREF(out[i]);
    return NULL;
}

/* ------------------------------------------------------------- epoch snapshot */
/* Cholesky solve of the symmetric positive definite A (k×k, row-major, overwritten by its factor) for
 * nr right-hand sides B (k×nr, row-major, overwritten by the solutions); 0 if A is not positive definite */
static int chol_solve(double *A, int k, double *B, int nr) {
    if (!chol_factor(A, k)) return 0;
    for (int c = 0; c < nr; c++) {
        for (int i = 0; i < k; i++) { /* L z = b */
            double v = B[i * nr + c];
            for (int l = 0; l < i; l++) v -= A[i * k + l] * B[l * nr + c];
            B[i * nr + c] = v / A[i * k + i];
        }
        for (int i = k - 1; i >= 0; i--) { /* Lᵀ x = z */
            double v = B[i * nr + c];
            for (int l = i + 1; l < k; l++) v -= A[l * k + i] * B[l * nr + c];
            B[i * nr + c] = v / A[i * k + i];
        }
    }
    return 1;
}

/* snapshot(H, y, r, used, p_pred, sat_pos, sat_vel, rate, r_rate, r0, C) -> (p (3), var (3), v (3), b (3))
 * or None: snapshot.epoch_fix's position (p_pred + the weighted least-squares correction of position and one
 * clock per slot present among the used rows, weights 1/r, one redundant satellite required) and its
 * variances, snapshot.epoch_velocity's velocity at it (NaN with fewer than 5 finite rates among the used
 * rows), and the same correction for every used row late by its own σ = √r (snapshot.delay_bias: the
 * one-signed delays' bias); None without a redundant satellite or with a singular geometry */
static PyObject *py_snapshot(PyObject *self, PyObject *args) {
    PyObject *objs[11];
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOO", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4], &objs[5],
                          &objs[6], &objs[7], &objs[8], &objs[9], &objs[10]))
        return NULL;
    int nds[11] = {2, 1, 1, 1, 1, 2, 2, 1, 1, 1, 2};
    PyArrayObject *a[11] = {0};
    PyObject *result = NULL;
    for (int i = 0; i < 11; i++) {
        a[i] = in_array(objs[i], nds[i]);
        if (!a[i]) goto done;
    }
    npy_intp m = PyArray_DIM(a[1], 0);
    const int N = (int)PyArray_DIM(a[0], 1);
    if (PyArray_DIM(a[0], 0) != m || (N != N_BASE && N != N_BASE + 1) || PyArray_DIM(a[2], 0) != m
        || PyArray_DIM(a[3], 0) != m || PyArray_DIM(a[4], 0) != 3 || PyArray_DIM(a[5], 0) != m
        || PyArray_DIM(a[6], 0) != m || PyArray_DIM(a[7], 0) != m || PyArray_DIM(a[8], 0) != m
        || PyArray_DIM(a[9], 0) != 3) {
        PyErr_SetString(PyExc_ValueError, "snapshot: shapes");
        goto done;
    }
    const double *H = PyArray_DATA(a[0]), *y = PyArray_DATA(a[1]), *r = PyArray_DATA(a[2]),
                 *used = PyArray_DATA(a[3]), *pp = PyArray_DATA(a[4]), *sp = PyArray_DATA(a[5]),
                 *sv = PyArray_DATA(a[6]), *zr = PyArray_DATA(a[7]), *rr = PyArray_DATA(a[8]),
                 *r0 = PyArray_DATA(a[9]), *C = PyArray_DATA(a[10]);
    /* the clock columns present among the used rows */
    int col[3 + NC], k = 3, n_used = 0;
    for (int j = 0; j < 3; j++) col[j] = j;
    for (int j = 0; j < NC; j++) {
        for (npy_intp i = 0; i < m; i++)
            if (used[i] != 0.0 && H[i * N + I_CLK + j] != 0.0) {
                col[k++] = I_CLK + j;
                break;
            }
    }
    for (npy_intp i = 0; i < m; i++) n_used += used[i] != 0.0;
    if (n_used <= k) {
        result = Py_None;
        Py_INCREF(result);
        goto done;
    }
    double A[(3 + NC) * (3 + NC)] = {0}, B[(3 + NC) * 5] = {0};
    for (npy_intp i = 0; i < m; i++) {
        if (used[i] == 0.0) continue;
        const double *h = H + i * N;
        double w = 1.0 / r[i], sd = sqrt(r[i]);
        for (int p = 0; p < k; p++) {
            double gp = h[col[p]] * w;
            if (gp == 0.0) continue;
            for (int q = 0; q < k; q++) A[p * k + q] += gp * h[col[q]];
            B[p * 5] += gp * y[i];
            B[p * 5 + 4] += gp * sd;
        }
    }
    for (int j = 0; j < 3; j++) B[j * 5 + 1 + j] = 1.0;
    if (!chol_solve(A, k, B, 5)) {
        result = Py_None;
        Py_INCREF(result);
        goto done;
    }
    double out[12];
    for (int j = 0; j < 3; j++) {
        out[j] = pp[j] + B[j * 5];
        out[3 + j] = B[j * 5 + 1 + j];
        out[9 + j] = B[j * 5 + 4];
        if (!isfinite(out[j]) || !(out[3 + j] > 0.0) || !isfinite(out[3 + j])) {
            result = Py_None;
            Py_INCREF(result);
            goto done;
        }
    }
    /* the velocity from the used rows' finite rates at the snapshot's position */
    double re[3];
    for (int i = 0; i < 3; i++) re[i] = r0[i] + C[i * 3] * out[0] + C[i * 3 + 1] * out[1] + C[i * 3 + 2] * out[2];
    double Av[16] = {0}, Bv[4] = {0};
    int n_rate = 0;
    for (npy_intp i = 0; i < m; i++) {
        if (used[i] == 0.0 || !isfinite(zr[i])) continue;
        const double *s = sp + 3 * i, *u = sv + 3 * i;
        double d0 = s[0] - re[0], d1 = s[1] - re[1], d2 = s[2] - re[2];
        double rng = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
        double l0 = d0 / rng, l1 = d1 / rng, l2 = d2 / rng;
        double g[4];
        for (int c = 0; c < 3; c++) g[c] = -(l0 * C[c] + l1 * C[3 + c] + l2 * C[6 + c]);
        g[3] = 1.0;
        double yv = zr[i] - (l0 * u[0] + l1 * u[1] + l2 * u[2]), w = 1.0 / rr[i];
        for (int p = 0; p < 4; p++) {
            for (int q = 0; q < 4; q++) Av[p * 4 + q] += g[p] * w * g[q];
            Bv[p] += g[p] * w * yv;
        }
        n_rate++;
    }
    for (int j = 0; j < 3; j++) out[6 + j] = NAN;
    if (n_rate >= 5 && chol_solve(Av, 4, Bv, 1) && isfinite(Bv[0]) && isfinite(Bv[1]) && isfinite(Bv[2])
        && isfinite(Bv[3]))
        for (int j = 0; j < 3; j++) out[6 + j] = Bv[j];
    result = new_array(1, 12, 0, out);
done:
    for (int i = 0; i < 11; i++) Py_XDECREF(a[i]);
    return result;
}

/* The state size of the covariance (or H) at args[i] (dimension dim): 22 with the baro offset, else 21.
 * Each entry point below is compiled twice, for 21 and 22 (the loops' bounds constants, as before). */
/* ------------------------------------------------------------- satellite states */
/* carry_states(rows (n, 12): each anchor's pos, vel, acc, clock, drift, valid; dt (n,) s from the anchor)
 * -> (pos (n, 3), vel (n, 3), clock (n,), drift (n,), anchored (n,) bool: valid == 1): satcache's
 * second-order step p + v dt + ½ a dt², v + a dt, clock + drift dt, in numpy's order of operations */
/* one satellite's anchor row r (pos, vel, acc, clock, drift, valid) carried by t: p + v t + ½ a t², v + a t,
 * clock + drift t, drift (numpy's operations in its order); returns the row's validity (valid == 1) */
static inline int carry_row(const double *r, double t, double *p, double *v, double *c, double *d) {
    for (int k = 0; k < 3; k++) {
        p[k] = (r[k] + r[3 + k] * t) + 0.5 * r[6 + k] * t * t;
        v[k] = r[3 + k] + r[6 + k] * t;
    }
    *c = r[9] + r[10] * t;
    *d = r[10];
    return r[11] == 1.0;
}

/* transmit_anchor(t_rx_s, pseudorange (n,), period) -> (t0 = t_rx − P/c (n,), the anchor round(t0 / period)
 * as an int) or (t0, None) when the satellites' anchors differ or one is not finite (satcache: the general
 * path) or n == 0 */
static PyObject *py_transmit_anchor(PyObject *self, PyObject *args) {
    PyObject *opr;
    double t_rx, period;
    if (!PyArg_ParseTuple(args, "dOd", &t_rx, &opr, &period)) return NULL;
    PyArrayObject *pr = in_array(opr, 1);
    if (!pr) return NULL;
    npy_intp n = PyArray_DIM(pr, 0);
    PyObject *t0 = new_array(1, n, 0, NULL);
    if (!t0) {
        Py_DECREF(pr);
        return NULL;
    }
    const double *pv = PyArray_DATA(pr);
    double *tv = PyArray_DATA((PyArrayObject *)t0), k0 = NAN;
    int common = n > 0;
    for (npy_intp i = 0; i < n; i++) {
        tv[i] = t_rx - pv[i] / C_M_S;
        const double k = rint(tv[i] / period); /* numpy's rint: the current (nearest-even) rounding */
        if (i == 0) k0 = k;
        common = common && isfinite(k) && k == k0;
    }
    Py_DECREF(pr);
    if (common && fabs(k0) < 9.0e15) return Py_BuildValue("(NL)", t0, (long long)k0);
    return Py_BuildValue("(NO)", t0, Py_None);
}

/* transmit_states(table (m, 12), rows (n, intp), t0 (n,), t_anchor) -> (pos, vel, clock, drift, valid,
 * t_tx): the anchor rows carried to t0 (carry_row, dt = t0 − t_anchor), then moved back by the satellite
 * clock offset dt_sv (0 where not valid): pos − vel dt_sv, clock − drift dt_sv, t0 − dt_sv
 * (ephemeris.transmission_states's numpy, element by element) */
static PyObject *py_transmit_states(PyObject *self, PyObject *args) {
    PyObject *otab, *orows, *ot0;
    double t_anchor;
    if (!PyArg_ParseTuple(args, "OOOd", &otab, &orows, &ot0, &t_anchor)) return NULL;
    PyArrayObject *tab = in_array(otab, 2), *t0a = in_array(ot0, 1);
    PyArrayObject *rw = (PyArrayObject *)PyArray_FROMANY(orows, NPY_INTP, 1, 1, NPY_ARRAY_IN_ARRAY);
    PyObject *pos = NULL, *vel = NULL, *clk = NULL, *drift = NULL, *ok = NULL, *ttx = NULL;
    if (!tab || !t0a || !rw) goto fail;
    npy_intp n = PyArray_DIM(rw, 0), m = PyArray_DIM(tab, 0);
    if (PyArray_DIM(tab, 1) != 12 || PyArray_DIM(t0a, 0) != n) {
        PyErr_SetString(PyExc_ValueError, "transmit_states: shapes");
        goto fail;
    }
    const npy_intp *ri = PyArray_DATA(rw);
    for (npy_intp i = 0; i < n; i++)
        if (ri[i] < 0 || ri[i] >= m) {
            PyErr_SetString(PyExc_IndexError, "transmit_states: a row outside the table");
            goto fail;
        }
    pos = new_array(2, n, 3, NULL); vel = new_array(2, n, 3, NULL);
    clk = new_array(1, n, 0, NULL); drift = new_array(1, n, 0, NULL); ttx = new_array(1, n, 0, NULL);
    ok = PyArray_SimpleNew(1, &n, NPY_BOOL);
    if (!pos || !vel || !clk || !drift || !ok || !ttx) goto fail;
    const double *o = PyArray_DATA(tab), *t0 = PyArray_DATA(t0a);
    double *p = PyArray_DATA((PyArrayObject *)pos), *v = PyArray_DATA((PyArrayObject *)vel),
           *c = PyArray_DATA((PyArrayObject *)clk), *d = PyArray_DATA((PyArrayObject *)drift),
           *tt = PyArray_DATA((PyArrayObject *)ttx);
    npy_bool *a = PyArray_DATA((PyArrayObject *)ok);
    for (npy_intp i = 0; i < n; i++) {
        double cc;
        a[i] = carry_row(o + 12 * ri[i], t0[i] - t_anchor, p + 3 * i, v + 3 * i, &cc, d + i);
        const double dt = a[i] ? cc : 0.0;
        for (int k = 0; k < 3; k++) p[3 * i + k] = p[3 * i + k] - v[3 * i + k] * dt;
        c[i] = cc - d[i] * dt;
        tt[i] = t0[i] - dt;
    }
    Py_DECREF(tab); Py_DECREF(t0a); Py_DECREF(rw);
    return Py_BuildValue("(NNNNNN)", pos, vel, clk, drift, ok, ttx);
fail:
    Py_XDECREF(tab); Py_XDECREF(t0a); Py_XDECREF(rw); Py_XDECREF(pos); Py_XDECREF(vel); Py_XDECREF(clk);
    Py_XDECREF(drift); Py_XDECREF(ok); Py_XDECREF(ttx);
    return NULL;
}

/* anchors(t (n,), period) -> [round(t / period) as ints] (NaN and infinite times: 0), satcache.AtmosphereCache's;
 * None when one is beyond ±9e15 (the caller's numpy) */
static PyObject *py_anchors(PyObject *self, PyObject *args) {
    PyObject *ot;
    double period;
    if (!PyArg_ParseTuple(args, "Od", &ot, &period)) return NULL;
    PyArrayObject *ta = in_array(ot, 1);
    if (!ta) return NULL;
    npy_intp n = PyArray_DIM(ta, 0);
    const double *t = PyArray_DATA(ta);
    PyObject *out = PyList_New(n);
    for (npy_intp i = 0; out && i < n; i++) {
        const double k = rint((isfinite(t[i]) ? t[i] : 0.0) / period);
        if (!(isfinite(k) && fabs(k) < 9.0e15)) {
            Py_CLEAR(out);
            Py_DECREF(ta);
            Py_RETURN_NONE;
        }
        PyObject *v = PyLong_FromLongLong((long long)k);
        if (!v) {
            Py_CLEAR(out);
            break;
        }
        PyList_SET_ITEM(out, i, v);
    }
    Py_DECREF(ta);
    return out;
}

static PyObject *py_carry_states(PyObject *self, PyObject *args) {
    PyObject *orows, *odt;
    if (!PyArg_ParseTuple(args, "OO", &orows, &odt)) return NULL;
    PyArrayObject *ar = in_array(orows, 2), *adt = in_array(odt, 1);
    PyObject *pos = NULL, *vel = NULL, *clk = NULL, *drift = NULL, *ok = NULL;
    if (!ar || !adt) goto fail;
    npy_intp n = PyArray_DIM(ar, 0);
    if (PyArray_DIM(ar, 1) != 12 || PyArray_DIM(adt, 0) != n) {
        PyErr_SetString(PyExc_ValueError, "carry_states: shapes");
        goto fail;
    }
    pos = new_array(2, n, 3, NULL); vel = new_array(2, n, 3, NULL);
    clk = new_array(1, n, 0, NULL); drift = new_array(1, n, 0, NULL);
    ok = PyArray_SimpleNew(1, &n, NPY_BOOL);
    if (!pos || !vel || !clk || !drift || !ok) goto fail;
    const double *o = PyArray_DATA(ar), *dt = PyArray_DATA(adt);
    double *p = PyArray_DATA((PyArrayObject *)pos), *v = PyArray_DATA((PyArrayObject *)vel),
           *c = PyArray_DATA((PyArrayObject *)clk), *d = PyArray_DATA((PyArrayObject *)drift);
    npy_bool *a = PyArray_DATA((PyArrayObject *)ok);
    for (npy_intp i = 0; i < n; i++) a[i] = carry_row(o + 12 * i, dt[i], p + 3 * i, v + 3 * i, c + i, d + i);
    Py_DECREF(ar); Py_DECREF(adt);
    return Py_BuildValue("(NNNNN)", pos, vel, clk, drift, ok);
fail:
    Py_XDECREF(ar); Py_XDECREF(adt); Py_XDECREF(pos); Py_XDECREF(vel); Py_XDECREF(clk); Py_XDECREF(drift);
    Py_XDECREF(ok);
    return NULL;
}

/* ---------------------------------------------------------------- epoch preparation */
/* prepare(sat_pos (n,3), r0, C, pseudorange, sat_clock, atmosphere, rate, drift, cn0, glo (n: the σ² factor),
 * sat_vel (n,3), params) -> (z, r_model, r_los, theta_prior, el_deg, az, rate (NaN where it or the
 * satellite's velocity is not finite), r_rate (n each), every rate and velocity finite) or
 * None (an observation dropped by the mask, or n == 0: the numpy path selects): engine.prepare_epoch's
 * arithmetic for a receiver's raw epoch with satellite states and atmospheric delays known, element by
 * element. params: (sin of the elevation mask, C/N0 ref, σ_floor², σ_zenith², σ_los_cn0², the range rate's
 * σ² over the model's at the zenith, the prior's C/N0 midpoint, per dB, per degree, elevation midpoint). */
static PyObject *py_prepare(PyObject *self, PyObject *args) {
    PyObject *o[11];
    double sin_mask, cn0_ref, a2, sz2, slos2, rate_scale, mid, per_db, per_deg, el_mid;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOO(dddddddddd)", &o[0], &o[1], &o[2], &o[3], &o[4], &o[5], &o[6],
                          &o[7], &o[8], &o[9], &o[10], &sin_mask, &cn0_ref, &a2, &sz2, &slos2, &rate_scale, &mid,
                          &per_db, &per_deg, &el_mid))
        return NULL;
    static const int nd[11] = {2, 1, 2, 1, 1, 1, 1, 1, 1, 1, 2};
    PyArrayObject *a[11] = {NULL};
    PyObject *out[8] = {NULL}, *res = NULL;
    for (int k = 0; k < 11; k++)
        if (!(a[k] = in_array(o[k], nd[k]))) goto done;
    npy_intp n = PyArray_DIM(a[0], 0);
    int shapes = PyArray_DIM(a[0], 1) == 3 && PyArray_DIM(a[1], 0) == 3 && PyArray_DIM(a[2], 0) == 3
                 && PyArray_DIM(a[2], 1) == 3;
    for (int k = 3; k < 11; k++) shapes = shapes && PyArray_DIM(a[k], 0) == n;
    shapes = shapes && PyArray_DIM(a[10], 1) == 3;
    if (!shapes) {
        PyErr_SetString(PyExc_ValueError, "prepare: shapes");
        goto done;
    }
    const double *sp = PyArray_DATA(a[0]), *r0 = PyArray_DATA(a[1]), *C = PyArray_DATA(a[2]),
                 *pr = PyArray_DATA(a[3]), *clk = PyArray_DATA(a[4]), *atm = PyArray_DATA(a[5]),
                 *rate = PyArray_DATA(a[6]), *drift = PyArray_DATA(a[7]), *cn0 = PyArray_DATA(a[8]),
                 *glo = PyArray_DATA(a[9]), *vel = PyArray_DATA(a[10]);
    for (npy_intp i = 0; i < n; i++) { /* the mask first: any observation dropped, the numpy path */
        const double d0 = sp[3 * i] - r0[0], d1 = sp[3 * i + 1] - r0[1], d2 = sp[3 * i + 2] - r0[2];
        const double se = -(d0 * C[2] + d1 * C[5] + d2 * C[8]) / sqrt(d0 * d0 + d1 * d1 + d2 * d2);
        if (!(isfinite(pr[i]) && isfinite(se) && se >= sin_mask && isfinite(clk[i]))) {
            res = Py_None;
            Py_INCREF(res);
            goto done;
        }
    }
    if (n == 0) {
        res = Py_None;
        Py_INCREF(res);
        goto done;
    }
    double *w[8];
    for (int k = 0; k < 8; k++) {
        if (!(out[k] = new_array(1, n, 0, NULL))) goto done;
        w[k] = PyArray_DATA((PyArrayObject *)out[k]);
    }
    const double two_pi = 2.0 * 3.141592653589793, to_deg = 180.0 / 3.141592653589793;
    int vel_all = 1;
    for (npy_intp i = 0; i < n; i++) {
        const double d0 = sp[3 * i] - r0[0], d1 = sp[3 * i + 1] - r0[1], d2 = sp[3 * i + 2] - r0[2];
        const double se = -(d0 * C[2] + d1 * C[5] + d2 * C[8]) / sqrt(d0 * d0 + d1 * d1 + d2 * d2);
        const double el = asin(se < -1.0 ? -1.0 : (se > 1.0 ? 1.0 : se));
        w[0][i] = pr[i] + C_M_S * clk[i] - atm[i];
        double az = fmod(atan2(d0 * C[1] + d1 * C[4] + d2 * C[7], d0 * C[0] + d1 * C[3] + d2 * C[6]), two_pi);
        if (az != 0.0) {
            if (az < 0.0) az += two_pi; /* numpy's remainder: the divisor's sign */
        } else {
            az = 0.0;
        }
        w[5][i] = az;
        const double c = isfinite(cn0[i]) ? cn0[i] : cn0_ref;
        const double weak = pow(10.0, (cn0_ref - c) / 10.0);
        const double s = se > 0.05 ? se : 0.05;
        w[1][i] = (a2 + sz2 * weak / (s * s)) * glo[i];
        w[2][i] = (a2 + slos2 * weak) * glo[i];
        w[7][i] = w[1][i] * rate_scale;
        w[4][i] = el * to_deg;
        w[3][i] = per_db * ((isfinite(cn0[i]) ? cn0[i] : mid) - mid) + per_deg * (w[4][i] - el_mid);
        const double rr = rate[i] + C_M_S * (isfinite(drift[i]) ? drift[i] : 0.0);
        const int ok = isfinite(rr) && isfinite(vel[3 * i]) && isfinite(vel[3 * i + 1]) && isfinite(vel[3 * i + 2]);
        w[6][i] = ok ? rr : NAN;
        vel_all = vel_all && ok;
    }
    res = PyTuple_New(9);
    if (!res) goto done;
    for (int k = 0; k < 8; k++) {
        PyTuple_SET_ITEM(res, k, out[k]);
        out[k] = NULL;
    }
    PyTuple_SET_ITEM(res, 8, PyBool_FromLong(vel_all));
done:
    for (int k = 0; k < 11; k++) Py_XDECREF(a[k]);
    for (int k = 0; k < 8; k++) Py_XDECREF(out[k]);
    return res;
}

/* ---------------------------------------------------------------- C/N0 calibration (cn0cal) */
/* cn0_add(hist (bins,), edges (bins + 1,), cn0 (n,), lo, hi, bin) -> the number counted: each finite value
 * clipped to [lo, hi] counted in its bin (int((c − edges[0]) / bin), the last bin at most), in place: numpy's
 * bincount added to the histogram, as whole numbers (exact) */
static PyObject *py_cn0_add(PyObject *self, PyObject *args) {
    PyObject *oh, *oe, *oc;
    double lo, hi, bin;
    if (!PyArg_ParseTuple(args, "OOOddd", &oh, &oe, &oc, &lo, &hi, &bin)) return NULL;
    if (!PyArray_Check(oh) || PyArray_TYPE((PyArrayObject *)oh) != NPY_DOUBLE || PyArray_NDIM((PyArrayObject *)oh) != 1
        || !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)oh) || !PyArray_ISWRITEABLE((PyArrayObject *)oh)) {
        PyErr_SetString(PyExc_TypeError, "cn0_add: the histogram must be a writeable float64 vector");
        return NULL;
    }
    PyArrayObject *h = (PyArrayObject *)oh, *e = in_array(oe, 1), *c = in_array(oc, 1);
    if (!e || !c) {
        Py_XDECREF(e); Py_XDECREF(c);
        return NULL;
    }
    npy_intp bins = PyArray_DIM(h, 0), n = PyArray_DIM(c, 0), counted = 0;
    if (PyArray_DIM(e, 0) != bins + 1 || bins < 1) {
        Py_DECREF(e); Py_DECREF(c);
        PyErr_SetString(PyExc_ValueError, "cn0_add: shapes");
        return NULL;
    }
    double *hv = PyArray_DATA(h);
    const double *ev = PyArray_DATA(e), *cv = PyArray_DATA(c);
    for (npy_intp i = 0; i < n; i++) {
        if (!isfinite(cv[i])) continue;
        double v = cv[i] > lo ? cv[i] : lo;
        v = v < hi ? v : hi;
        npy_intp k = (npy_intp)((v - ev[0]) / bin);
        hv[k < bins - 1 ? k : bins - 1] += 1.0;
        counted++;
    }
    Py_DECREF(e); Py_DECREF(c);
    return PyLong_FromSsize_t(counted);
}

/* cn0_level(hist, edges, target, bin) -> the histogram's value at the count ``target`` (> 0), linear within its
 * bin (cn0cal.level_dbhz: numpy's cumsum and searchsorted, side "left") */
static PyObject *py_cn0_level(PyObject *self, PyObject *args) {
    PyObject *oh, *oe;
    double target, bin;
    if (!PyArg_ParseTuple(args, "OOdd", &oh, &oe, &target, &bin)) return NULL;
    PyArrayObject *h = in_array(oh, 1), *e = in_array(oe, 1);
    if (!h || !e || PyArray_DIM(e, 0) != PyArray_DIM(h, 0) + 1 || PyArray_DIM(h, 0) < 1) {
        if (h && e) PyErr_SetString(PyExc_ValueError, "cn0_level: shapes");
        Py_XDECREF(h); Py_XDECREF(e);
        return NULL;
    }
    npy_intp bins = PyArray_DIM(h, 0), i = 0;
    const double *hv = PyArray_DATA(h), *ev = PyArray_DATA(e);
    double cum = 0.0, below = 0.0; /* below: the cumulative count before bin i */
    for (i = 0; i < bins; i++) {
        below = cum;
        cum += hv[i];
        if (cum >= target) break;
    }
    if (i == bins) i = bins - 1; /* past the end: the last bin (below is the count before it) */
    const double frac = hv[i] > 0.0 ? (target - below) / hv[i] : 0.5;
    const double level = ev[i] + frac * bin;
    Py_DECREF(h); Py_DECREF(e);
    return PyFloat_FromDouble(level);
}

/* ---------------------------------------------------------------- the reported accuracy (navigator.estimate) */
/* a SnapshotFloor (white, slow, slow_rate, cap) into f; 0 for None */
static int read_floor(PyObject *o, double *f) {
    if (o == Py_None) return 0;
    if (!PyTuple_Check(o) || PyTuple_GET_SIZE(o) != 4) {
        PyErr_SetString(PyExc_TypeError, "report_cov: a floor is (white, slow, slow_rate, cap) or None");
        return -1;
    }
    for (int k = 0; k < 4; k++) f[k] = PyFloat_AsDouble(PyTuple_GET_ITEM(o, k));
    return PyErr_Occurred() ? -1 : 1;
}

/* consistency.snapshot_axis(p, k, f, delay) */
static double snapshot_axis(double p, double k, int have, const double *f, double delay) {
    double v = p * k;
    if (have) {
        const double slow = p * f[2];
        double s = p * f[0] + (slow < f[1] ? slow : f[1]);
        s = s < f[3] ? s : f[3];
        v = v > s ? v : s;
    }
    return v > delay ? v : delay;
}

/* report_cov(out (18,), k, floor_h, floor_v, d_n, d_e, d_d) -> (9,): snapshot_axis of the position's variances
 * out[9:12] (N and E with floor_h, D with floor_v, each with its delay bias²), then out[12:18] as they are */
static PyObject *py_report_cov(PyObject *self, PyObject *args) {
    PyObject *oo, *ofh, *ofv;
    double k, d[3], fh[4], fv[4];
    if (!PyArg_ParseTuple(args, "OdOOddd", &oo, &k, &ofh, &ofv, &d[0], &d[1], &d[2])) return NULL;
    const int hh = read_floor(ofh, fh), hv = hh < 0 ? -1 : read_floor(ofv, fv);
    if (hh < 0 || hv < 0) return NULL;
    PyArrayObject *a = in_array(oo, 1);
    if (!a) return NULL;
    if (PyArray_DIM(a, 0) != 18) {
        Py_DECREF(a);
        PyErr_SetString(PyExc_ValueError, "report_cov: out must have 18 elements");
        return NULL;
    }
    const double *o = PyArray_DATA(a);
    PyObject *cov = new_array(1, 9, 0, NULL);
    if (cov) {
        double *c = PyArray_DATA((PyArrayObject *)cov);
        c[0] = snapshot_axis(o[9], k, hh, fh, d[0]);
        c[1] = snapshot_axis(o[10], k, hh, fh, d[1]);
        c[2] = snapshot_axis(o[11], k, hv, fv, d[2]);
        for (int i = 3; i < 9; i++) c[i] = o[9 + i];
    }
    Py_DECREF(a);
    return cov;
}

/* predict_mean(x (N,), m15 (15 numbers: the loose block's p, v, b, a, d at the new time), T, live (NC
 * numbers)) -> x at the new time: p, v from m15[0:6], a, d from m15[9:15], each live clock + T · drift · live
 * (engine._predict's numpy: (T x_drift) live added to the clocks), the rest as it was */
static PyObject *py_predict_mean(PyObject *self, PyObject *args) {
    PyObject *ox, *om, *ol;
    double T;
    if (!PyArg_ParseTuple(args, "OOdO", &ox, &om, &T, &ol)) return NULL;
    double m[15], live[NC];
    PyObject *seqs[2] = {om, ol};
    double *dst[2] = {m, live};
    const Py_ssize_t len[2] = {15, NC};
    for (int s = 0; s < 2; s++) {
        PyObject *q = PySequence_Fast(seqs[s], "predict_mean: a sequence");
        if (!q) return NULL;
        if (PySequence_Fast_GET_SIZE(q) != len[s]) {
            Py_DECREF(q);
            PyErr_SetString(PyExc_ValueError, "predict_mean: 15 means and one liveness per clock");
            return NULL;
        }
        for (Py_ssize_t i = 0; i < len[s]; i++) dst[s][i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(q, i));
        Py_DECREF(q);
        if (PyErr_Occurred()) return NULL;
    }
    PyArrayObject *xa = in_array(ox, 1);
    if (!xa) return NULL;
    const npy_intp n = PyArray_DIM(xa, 0);
    if (n < I_DRIFT + 1) {
        Py_DECREF(xa);
        PyErr_SetString(PyExc_ValueError, "predict_mean: the state is too short");
        return NULL;
    }
    PyObject *out = new_array(1, n, 0, PyArray_DATA(xa));
    Py_DECREF(xa);
    if (!out) return NULL;
    double *x = PyArray_DATA((PyArrayObject *)out);
    for (int i = 0; i < 6; i++) x[i] = m[i];
    for (int i = 6; i < 12; i++) x[i] = m[i + 3];
    const double td = T * x[I_DRIFT];
    for (int j = 0; j < NC; j++) x[I_CLK + j] = x[I_CLK + j] + td * live[j];
    return out;
}

static int state_size(PyObject *args, int i, int dim) {
    PyObject *o = PyTuple_Check(args) && PyTuple_GET_SIZE(args) > i ? PyTuple_GET_ITEM(args, i) : NULL;
    return o && PyArray_Check(o) && PyArray_NDIM((PyArrayObject *)o) > dim
           && PyArray_DIM((PyArrayObject *)o, dim) == NMAX ? NMAX : N_BASE;
}

static PyObject *py_predict_cov(PyObject *self, PyObject *args) {
    return state_size(args, 0, 0) == NMAX ? predict_cov_n(args, NMAX) : predict_cov_n(args, N_BASE);
}

static PyObject *py_innovations(PyObject *self, PyObject *args) {
    return state_size(args, 1, 0) == NMAX ? innovations_n(args, NMAX) : innovations_n(args, N_BASE);
}

static PyObject *py_update(PyObject *self, PyObject *args) {
    return state_size(args, 1, 0) == NMAX ? update_n(args, NMAX) : update_n(args, N_BASE);
}

static PyMethodDef methods[] = {
    {"prepare", py_prepare, METH_VARARGS, "an epoch's state-independent rows (engine.prepare_epoch's arithmetic)"},
    {"cn0_add", py_cn0_add, METH_VARARGS, "an epoch's C/N0 counted in the calibration's histogram (cn0cal)"},
    {"cn0_level", py_cn0_level, METH_VARARGS, "the histogram's quantile (cn0cal.level_dbhz)"},
    {"transmit_anchor", py_transmit_anchor, METH_VARARGS, "the transmission time t_rx - P/c and its common anchor"},
    {"transmit_states", py_transmit_states, METH_VARARGS, "satellite states at transmission from one anchor's rows"},
    {"anchors", py_anchors, METH_VARARGS, "the anchor of each time (the atmosphere cache's)"},
    {"report_cov", py_report_cov, METH_VARARGS, "the reported variances with the snapshots' floors (navigator.estimate)"},
    {"predict_mean", py_predict_mean, METH_VARARGS, "the state's mean predicted (engine._predict's numpy)"},
    {"carry_states", py_carry_states, METH_VARARGS, "satellite states carried from their anchors (satcache)"},
    {"snapshot", py_snapshot, METH_VARARGS, "the epoch's own weighted least-squares position, its variances, its Doppler velocity"},
    {"belief_step", py_belief_step, METH_VARARGS, "the per-satellite belief's step, R(β) and gate"},
    {"predict_cov", py_predict_cov, METH_VARARGS, "F P F^T + Q over a block (model.transition, model.process_noise)"},
    {"held_noise", py_held_noise, METH_VARARGS, "the held-time noise (pp, pv, vv) between two integrals, or None"},
    {"innovations", py_innovations, METH_VARARGS, "pseudorange innovations, H, H P, (H P H^T)_ii"},
    {"update", py_update, METH_VARARGS, "the stacked Kalman update with the range rates"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_tight", "the tight filter's C hot path", -1, methods};

PyMODINIT_FUNC PyInit__tight(void) {
    import_array();
    return PyModule_Create(&module);
}
