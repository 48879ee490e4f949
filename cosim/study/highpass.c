/*
 * Cascaded second-order sections in transposed direct form II, zero initial state: the loop of
 * scipy.signal.sosfilt (scipy/signal/_sosfilt.pyx) for one float64 signal, operation for
 * operation (compiled with -ffp-contract=off), so both give the same numbers bit for bit.
 * sos: n_sections rows of (b0, b1, b2, a0 = 1, a1, a2); x: n samples in, y: n samples out.
 */
#include <stdint.h>

__attribute__((visibility("default"))) void dcs_sosfilt(const double *sos, int32_t n_sections,
                                                        const double *x, double *y, int64_t n,
                                                        double *zi)
{
    int64_t k;
    int32_t s;
    for (s = 0; s < 2 * n_sections; s++)
        zi[s] = 0.0;
    for (k = 0; k < n; k++) {
        double x_cur = x[k];
        for (s = 0; s < n_sections; s++) {
            const double *c = sos + 6 * s;
            double *z = zi + 2 * s;
            double x_new = c[0] * x_cur + z[0];
            z[0] = c[1] * x_cur - c[4] * x_new + z[1];
            z[1] = c[2] * x_cur - c[5] * x_new;
            x_cur = x_new;
        }
        y[k] = x_cur;
    }
}
