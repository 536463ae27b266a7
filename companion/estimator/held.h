/* The held-time process noise of a block, shared by the loose core (_core.c) and the tight filter's
 * (companion/tight/_tight.c): history.py, "Held time".
 *
 * The IMU history's integrals (HELD_INTS floats: t_s at 0, ..., then from HELD_AT the prefix moments
 * W = (∫ w, ∫ w s, ∫ w s^2) and J alike of the held-time densities w and j, and C (three per axis) of
 * a coast's dropped acceleration c_i). Between the integrals a and b of a block ending at t_b, with
 * the held sample's white density q_white[i] of axis i (m^2/s^3), the acceleration's random-walk
 * density q_rw (m^2/s^5) and the coast's scale q_coast (1: on, 0: off), the white acceleration
 * density n_i(s) = q_white[i] w(s) + q_rw j(s) + q_coast c_i(s) adds to axis i's p, v
 *
 *   hq[3 i ..] = (pp, pv, vv) = (∫ n_i (t_b - s)^2, ∫ n_i (t_b - s), ∫ n_i)
 *
 * held_noise returns 0 (hq left alone) when the block holds no held time or coast, or the densities
 * are 0: then nothing is to be added, and a prediction stays bit-identical to one without.
 */
#ifndef BELIEFNAV_HELD_H
#define BELIEFNAV_HELD_H

#define HELD_AT 25   /* W (3), J (3), C (9) in the integrals, from here */
#define HELD_INTS 40 /* the integrals' length */

static inline int held_noise(const double *a, const double *b, const double *q_white, double q_rw,
                             double q_coast, double *hq) {
    const double *wa = a + HELD_AT, *wb = b + HELD_AT;
    double w0 = wb[0] - wa[0], j0 = wb[3] - wa[3];
    int white = q_white[0] != 0.0 || q_white[1] != 0.0 || q_white[2] != 0.0;
    int held = !((w0 == 0.0 || !white) && (j0 == 0.0 || q_rw == 0.0));
    int coast = q_coast != 0.0 && (wb[6] != wa[6] || wb[9] != wa[9] || wb[12] != wa[12]);
    if (!held && !coast) return 0;
    double tb = b[0];
    for (int i = 0; i < 3; i++) {
        double e0 = 0.0, e1 = 0.0, e2 = 0.0;
        if (held) {
            e0 = q_white[i] * w0 + q_rw * j0;
            e1 = q_white[i] * (wb[1] - wa[1]) + q_rw * (wb[4] - wa[4]);
            e2 = q_white[i] * (wb[2] - wa[2]) + q_rw * (wb[5] - wa[5]);
        }
        if (coast) {
            const double *ca = wa + 6 + 3 * i, *cb = wb + 6 + 3 * i;
            e0 += q_coast * (cb[0] - ca[0]);
            e1 += q_coast * (cb[1] - ca[1]);
            e2 += q_coast * (cb[2] - ca[2]);
        }
        hq[3 * i] = tb * tb * e0 - 2.0 * tb * e1 + e2;
        hq[3 * i + 1] = tb * e0 - e1;
        hq[3 * i + 2] = e0;
    }
    return 1;
}

#endif
