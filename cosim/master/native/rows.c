/*
 * Recorded rows as CSV text, for the recorder's writer thread (cosim/master/recorder.py): the
 * text Python's "%.17g" % value gives (glibc's correctly rounded printf; NaN as "nan" whatever
 * its sign bit), values separated by ',' and rows ended by '\n'. Called through ctypes, which
 * releases the GIL: the text is made while the run steps on.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

/* 25 bytes hold any "%.17g" of a double ("-1.2345678901234567e-308") and its separator. */
#define DCS_VALUE_BYTES 25

/* Write the n x ncols row-major values as CSV lines into out (cap bytes); the length written,
 * or -1 if it does not fit (cap >= n * (ncols * DCS_VALUE_BYTES + 1) always does). */
__attribute__((visibility("default"))) int64_t dcs_format_rows(const double *rows, int64_t n,
                                                              int32_t ncols, char *out,
                                                              int64_t cap)
{
    int64_t len = 0, i;
    int32_t j;
    for (i = 0; i < n; i++) {
        for (j = 0; j < ncols; j++) {
            double v = rows[i * ncols + j];
            int k;
            if (cap - len < DCS_VALUE_BYTES + 1)
                return -1;
            if (isnan(v)) {
                memcpy(out + len, "nan", 3);
                k = 3;
            } else {
                k = snprintf(out + len, DCS_VALUE_BYTES, "%.17g", v);
                if (k < 0 || k >= DCS_VALUE_BYTES)
                    return -1;
            }
            len += k;
            out[len++] = j + 1 < ncols ? ',' : '\n';
        }
    }
    return len;
}
