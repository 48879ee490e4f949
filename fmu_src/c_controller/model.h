/* The strain-feedback law of controller/strain_feedback.py in C99 (no FMI code here).
 *
 * Per channel (site 1/2 x gauge C/E):
 *
 *     u = clip(gain * strain, lower, upper)   while enabled and t >= switch_on_time,
 *     u = 0                                   otherwise,
 *     F(t + dt) = u + (F(t) - u) * exp(-dt / T)   (first-order lag, u held over the step),
 *     F(t + dt) = u                               for T = 0,
 *
 * with [lower, upper] = [-symmetric_force_limit, symmetric_force_limit] in mode 0
 * (unrestricted) and [0, force_limit] in mode 1 (compressive_only). Every operation is the
 * one the Python law performs, in the same order, so the two agree bit for bit.
 */
#ifndef DCS_MODEL_H
#define DCS_MODEL_H

#include <stddef.h>

#include "config.h"

/* Parameters of the law (controller/params.py ControllerParams). */
typedef struct {
    double gain;                  /* [N per unit strain], 0 <= gain < inf */
    double force_limit;           /* [N], 0 <= force_limit <= inf (mode 1) */
    double symmetric_force_limit; /* [N], 0 <= value <= inf (mode 0) */
    double switch_on_time;        /* [s], 0 <= value < inf */
    double lag_time_constant;     /* [s], 0 <= value < inf; 0 = no lag */
    int mode;                     /* 0 = unrestricted, 1 = compressive_only */
    int enabled;                  /* 0 = zero output at all times */
} LawParams;

/* State of the law: the actuator forces (the lag state) and the cached lag decay. */
typedef struct {
    double force[N_CHANNELS]; /* [N] */
    double decay_dt;          /* [s] step the cached decay belongs to (NaN: none) */
    double decay;             /* exp(-decay_dt / lag_time_constant) */
} LawState;

/* 0 if every parameter is in range; else nonzero and a one-line message (name, value,
 * allowed range) in msg. */
int law_check_params(const LawParams *p, char *msg, size_t size);

/* Zero forces, no cached decay. */
void law_reset(LawState *s);

/* Forget the cached decay (parameters changed). */
void law_params_changed(LawState *s);

/* Advance over [t, t + dt] with the strains [1] held; forces [N] at t + dt in s->force.
 * Returns 0, or nonzero (state unchanged, message in msg) for a non-finite t, dt < 0 or a
 * non-finite strain. */
int law_step(LawState *s, const LawParams *p, double t, double dt,
             const double strain[N_CHANNELS], char *msg, size_t size);

#endif /* DCS_MODEL_H */
