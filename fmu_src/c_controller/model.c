/* The strain-feedback law (see model.h); the C twin of controller/strain_feedback.py. */
#include "model.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* controller/strain_feedback.py SWITCH_TIME_RTOL: a time accumulated in floating point that
 * lands a few ulp below switch_on_time still counts as "switched on". */
#define SWITCH_TIME_RTOL 1e-12

static const char *const CHANNEL_NAMES[N_CHANNELS] = {"site1_C", "site1_E", "site2_C", "site2_E"};

/* controller/params.py _check_real: low <= x (< or <=) high, NaN rejected. */
static int check_real(const char *name, double x, double high, int high_open, char *msg,
                      size_t size)
{
    const char *right = high_open ? "<" : "<=";
    if (isnan(x)) {
        snprintf(msg, size, "%s = nan is not allowed; allowed: 0 <= %s %s %g", name, name,
                 right, high);
        return 1;
    }
    if (x < 0.0 || (high_open ? x >= high : x > high)) {
        snprintf(msg, size, "%s = %.17g is out of range; allowed: 0 <= %s %s %g", name, x, name,
                 right, high);
        return 1;
    }
    return 0;
}

int law_check_params(const LawParams *p, char *msg, size_t size)
{
    if (check_real("gain", p->gain, INFINITY, 1, msg, size) ||
        check_real("force_limit", p->force_limit, INFINITY, 0, msg, size) ||
        check_real("symmetric_force_limit", p->symmetric_force_limit, INFINITY, 0, msg, size) ||
        check_real("switch_on_time", p->switch_on_time, INFINITY, 1, msg, size) ||
        check_real("lag_time_constant", p->lag_time_constant, INFINITY, 1, msg, size)) {
        return 1;
    }
    if (p->mode != 0 && p->mode != 1) {
        snprintf(msg, size, "mode = %d is not allowed; allowed: 0 (unrestricted) or 1 "
                 "(compressive_only)", p->mode);
        return 1;
    }
    return 0;
}

void law_reset(LawState *s)
{
    for (int i = 0; i < N_CHANNELS; i++) {
        s->force[i] = 0.0;
    }
    law_params_changed(s);
}

void law_params_changed(LawState *s)
{
    s->decay_dt = NAN;
    s->decay = 0.0;
}

/* StrainController.is_active */
static int is_active(const LawParams *p, double t)
{
    if (!p->enabled) {
        return 0;
    }
    const double t_on = p->switch_on_time;
    const double scale = fabs(t_on) > 1.0 ? fabs(t_on) : 1.0;
    return t >= t_on - SWITCH_TIME_RTOL * scale;
}

int law_step(LawState *s, const LawParams *p, double t, double dt,
             const double strain[N_CHANNELS], char *msg, size_t size)
{
    if (!(isfinite(t) && isfinite(dt) && dt >= 0.0)) {
        snprintf(msg, size, "need finite t and finite dt >= 0, got t = %.17g, dt = %.17g", t, dt);
        return 1;
    }
    for (int i = 0; i < N_CHANNELS; i++) {
        if (!isfinite(strain[i])) {
            snprintf(msg, size, "non-finite strain in channel %s: %.17g", CHANNEL_NAMES[i],
                     strain[i]);
            return 1;
        }
    }
    /* StrainController.command: numpy's clip is max-then-min with these comparisons */
    double u[N_CHANNELS] = {0.0, 0.0, 0.0, 0.0};
    if (is_active(p, t)) {
        const double lower = p->mode == 1 ? 0.0 : -p->symmetric_force_limit;
        const double upper = p->mode == 1 ? p->force_limit : p->symmetric_force_limit;
        for (int i = 0; i < N_CHANNELS; i++) {
            double v = p->gain * strain[i];
            v = v < lower ? lower : v;
            u[i] = v > upper ? upper : v;
        }
    }
    /* StrainController.step: the exact lag solution with u held over the step */
    const double tau = p->lag_time_constant;
    if (tau == 0.0) {
        memcpy(s->force, u, sizeof u);
    } else {
        if (dt != s->decay_dt) {
            s->decay = exp(-dt / tau);
            s->decay_dt = dt;
        }
        for (int i = 0; i < N_CHANNELS; i++) {
            s->force[i] = u[i] + (s->force[i] - u[i]) * s->decay;
        }
    }
    return 0;
}
