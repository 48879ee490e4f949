/*
 * The master's stepping loop in C: runs base steps [tick, stop) of a system whose components
 * all have C entry points, with the algorithm, exchange and recording of the Python loop
 * (cosim/master/algorithms.py, delays.py, recorder.py) operation for operation, so both give
 * the same numbers bit for bit. Python sets the plan up once (cosim/master/native/runner.py)
 * and calls dcs_run_steps between the events it handles itself (progress, manipulators,
 * recording flush, errors).
 *
 * A component is either an FMI 2.0 co-simulation instance (fmi2SetReal, fmi2DoStep,
 * fmi2GetReal through the library's function pointers) or a compiled step
 * int step(void *context, double t, double h) with the arrays it reads and writes.
 *
 * The loop stops at the first event Python must handle and says which (DcsSteps.event):
 *   DCS_DONE         stop reached
 *   DCS_FAILED       an FMI call returned a status > fmi2Warning (slave, call, status, tick of
 *                    the time the Python loop reports); nothing after it was called
 *   DCS_STEP_FAILED  a compiled step returned a non-zero code (slave, code, tick); Python
 *                    settles that step (slave.native_step_failed) and, if it went well, calls
 *                    again with `resume` = that slave: the tick goes on after its step
 *   DCS_NON_FINITE   an exchanged output is not finite (the step's divergence check; the tick
 *                    is not completed)
 *   DCS_LIMIT        a limited output exceeds its bound after the step to `tick` (completed,
 *                    its row not recorded: Python runs that tick's observers itself)
 *   DCS_FULL         the recording buffer is full (tick completed and recorded up to here)
 * Floating point: no contraction (-ffp-contract=off), the Python expressions in their order.
 *
 * Telemetry: the wall time of every component call is added to the component's `timing`
 * record (cosim/master/algorithms.py, _Algorithm.timing): its steps' total, longest and count,
 * and the total of its exchange calls (set inputs, get outputs), on a monotonic clock.
 */
#if !defined(_WIN32) && !defined(_POSIX_C_SOURCE)
#define _POSIX_C_SOURCE 199309L
#endif
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#ifdef _WIN32
#include <windows.h>
#else
#include <time.h>
#endif

typedef int (*dcs_set_real)(void *, const unsigned int *, size_t, const double *);
typedef int (*dcs_do_step)(void *, double, double, int);
typedef int (*dcs_get_real)(void *, const unsigned int *, size_t, double *);
typedef int (*dcs_step)(void *, double, double);

enum { DCS_FMI = 0, DCS_COMPILED = 1 };
enum { DCS_JACOBI = 0, DCS_GAUSS_SEIDEL = 1 };
enum { DCS_DONE = 0, DCS_FAILED = 1, DCS_STEP_FAILED = 2, DCS_NON_FINITE = 3, DCS_LIMIT = 4,
       DCS_FULL = 5 };
enum { DCS_SET = 0, DCS_DO_STEP = 1, DCS_GET = 2 };

/* One transport-delay ring buffer (cosim/master/delays.py DelayLine). */
typedef struct {
    int32_t n, depth, pos, linear;
    double f;
    double *buf;
} DcsLine;

/* One component (libcosim's simulator_info): its calls, period and exchange plan. */
typedef struct {
    int32_t kind, period;
    double h;
    /* DCS_FMI */
    void *component;
    dcs_set_real set_real;
    dcs_do_step do_step;
    dcs_get_real get_real;
    const unsigned int *in_vr, *out_vr;
    /* DCS_COMPILED: inputs go to step_in[in_slot[i]], outputs come from step_out[out_slot[i]] */
    dcs_step step;
    void *context;
    double *step_in;
    const double *step_out;
    const int32_t *in_slot, *out_slot;
    int32_t n_in, n_out;
    double *u;                /* the master's input buffer of the component (n_in) */
    double *y;                /* its outputs in the master's output buffer (n_out) */
    int32_t n_plain, n_delayed, n_push;
    const int32_t *plain;     /* (input position, output index) pairs */
    const int32_t *delayed;   /* (input position, line, first horizon, source period) */
    const int32_t *push;      /* (output index, line) pairs */
    double *timing;           /* [step total, step max, exchange total, steps] [s, s, s, 1] */
} DcsSlave;

typedef struct {
    int32_t algorithm, n_slaves, n_lines, n_y;
    DcsSlave *slaves;
    DcsLine *lines;
    const double *horizons;
    double *y;                /* all exchanged outputs */
    int64_t *newest;          /* per component: tick of its newest outputs */
    double start;             /* time of tick k: start + (k * num) / den, as Python's ints */
    int64_t num, den;
    /* recording: a row (time, y[rec_index[...]]) at every tick multiple of rec_every */
    int64_t rec_every, rec_capacity, rec_rows;
    int32_t n_rec, n_limit;
    const int32_t *rec_index;
    double *rec;
    /* limits: stop when !(|y[limit_index[i]]| <= limit[i]) after a step */
    const int32_t *limit_index;
    const double *limit;
    /* where the run is, and the event that stopped it */
    int64_t tick, event_tick;
    int32_t event, event_slave, event_call, event_status;
    int32_t resume;           /* >= 0: the first tick goes on after this slave's step */
} DcsSteps;

/* Seconds on a monotonic clock. */
static double now(void)
{
#ifdef _WIN32
    LARGE_INTEGER c, f;
    QueryPerformanceCounter(&c);
    QueryPerformanceFrequency(&f);
    return (double)c.QuadPart / (double)f.QuadPart;
#else
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#endif
}

static void timed_step(DcsSlave *s, double t0)
{
    double dt = now() - t0;
    s->timing[0] += dt;
    if (dt > s->timing[1])
        s->timing[1] = dt;
    s->timing[3] += 1.0;
}

static double time_of(const DcsSteps *r, int64_t k)
{
    return r->start + (double)(k * r->num) / (double)r->den;
}

static double line_delayed(const DcsLine *ln, int32_t back)
{
    int32_t i = ln->pos - ln->n - back;
    int32_t j = i < 0 ? i + ln->depth : i;
    int32_t j1;
    if (ln->f == 0.0)
        return ln->buf[j];
    j1 = i - 1 < 0 ? i - 1 + ln->depth : i - 1;
    return (1.0 - ln->f) * ln->buf[j] + ln->f * ln->buf[j1];
}

static double line_value(const DcsLine *ln, double horizon)
{
    double v0 = line_delayed(ln, 0);
    if (!ln->linear)
        return v0;
    return v0 + (v0 - line_delayed(ln, 1)) * horizon;
}

static void line_push(DcsLine *ln, double value)
{
    int32_t pos = ln->pos + 1;
    if (pos == ln->depth)
        pos = 0;
    ln->buf[pos] = value;
    ln->pos = pos;
}

static int fail(DcsSteps *r, int32_t event, int32_t slave, int32_t call, int32_t status,
                int64_t tick)
{
    r->event = event;
    r->event_slave = slave;
    r->event_call = call;
    r->event_status = status;
    r->event_tick = tick;
    return 1;
}

/* The inputs of slave i for its step from `tick` (held, delayed, extrapolated), then set. */
static int apply_inputs(DcsSteps *r, int32_t i, int64_t tick, int64_t time_tick)
{
    DcsSlave *s = &r->slaves[i];
    int32_t j;
    for (j = 0; j < s->n_plain; j++)
        s->u[s->plain[2 * j]] = r->y[s->plain[2 * j + 1]];
    for (j = 0; j < s->n_delayed; j++) {
        const int32_t *d = &s->delayed[4 * j];
        s->u[d[0]] = line_value(&r->lines[d[1]], r->horizons[d[2] + tick % d[3]]);
    }
    if (s->n_in == 0)
        return 0;
    if (s->kind == DCS_COMPILED) {
        for (j = 0; j < s->n_in; j++)
            s->step_in[s->in_slot[j]] = s->u[j];
        return 0;
    }
    {
        double t0 = now();
        j = s->set_real(s->component, s->in_vr, (size_t)s->n_in, s->u);
        s->timing[2] += now() - t0;
    }
    return j > 1 ? fail(r, DCS_FAILED, i, DCS_SET, j, time_tick) : 0;
}

static int step_slave(DcsSteps *r, int32_t i, int64_t tick)
{
    DcsSlave *s = &r->slaves[i];
    double t = time_of(r, tick);
    double t0 = now();
    int st;
    if (s->kind == DCS_COMPILED) {
        st = s->step(s->context, t, s->h);
        timed_step(s, t0);
        return st != 0 ? fail(r, DCS_STEP_FAILED, i, DCS_DO_STEP, st, tick) : 0;
    }
    st = s->do_step(s->component, t, s->h, 0);
    timed_step(s, t0);
    return st > 1 ? fail(r, DCS_FAILED, i, DCS_DO_STEP, st, tick) : 0;
}

/* Read slave i's outputs (newest at `newest`), push them into its delay lines. */
static int read_outputs(DcsSteps *r, int32_t i, int64_t newest)
{
    DcsSlave *s = &r->slaves[i];
    int32_t j;
    if (s->n_out > 0) {
        if (s->kind == DCS_COMPILED) {
            for (j = 0; j < s->n_out; j++)
                s->y[j] = s->step_out[s->out_slot[j]];
        } else {
            double t0 = now();
            int st = s->get_real(s->component, s->out_vr, (size_t)s->n_out, s->y);
            s->timing[2] += now() - t0;
            if (st > 1)
                return fail(r, DCS_FAILED, i, DCS_GET, st, newest);
        }
    }
    r->newest[i] = newest;
    for (j = 0; j < s->n_push; j++)
        line_push(&r->lines[s->push[2 * j + 1]], r->y[s->push[2 * j]]);
    return 0;
}

static int finite(const DcsSteps *r)
{
    int32_t j;
    for (j = 0; j < r->n_y; j++)
        if (!isfinite(r->y[j]))
            return 0;
    return 1;
}

/* The step from `tick`; slaves up to `after` (-1: none) have stepped already. */
static int jacobi_step(DcsSteps *r, int64_t tick, int32_t after)
{
    int64_t k1 = tick + 1;
    int32_t i;
    for (i = after + 1; i < r->n_slaves; i++)
        if (tick % r->slaves[i].period == 0 && step_slave(r, i, tick))
            return 1;
    for (i = 0; i < r->n_slaves; i++)
        if (k1 % r->slaves[i].period == 0 && read_outputs(r, i, k1))
            return 1;
    if (!finite(r))
        return fail(r, DCS_NON_FINITE, -1, -1, 0, tick);
    for (i = 0; i < r->n_slaves; i++)
        if (k1 % r->slaves[i].period == 0 && apply_inputs(r, i, k1, k1))
            return 1;
    return 0;
}

/* The step from `tick`; slave `after` (-1: none) has stepped already, those before it are done. */
static int gauss_seidel_step(DcsSteps *r, int64_t tick, int32_t after)
{
    int32_t i;
    for (i = after < 0 ? 0 : after; i < r->n_slaves; i++) {
        int32_t p = r->slaves[i].period;
        if (tick % p)
            continue;
        if (i != after && (apply_inputs(r, i, tick, tick) || step_slave(r, i, tick)))
            return 1;
        if (read_outputs(r, i, tick + p))
            return 1;
    }
    if (!finite(r))
        return fail(r, DCS_NON_FINITE, -1, -1, 0, tick);
    return 0;
}

/* After the step to k1: stop on a limit, else record its row. */
static int observe(DcsSteps *r, int64_t k1)
{
    int32_t j;
    double *row;
    for (j = 0; j < r->n_limit; j++)
        if (!(fabs(r->y[r->limit_index[j]]) <= r->limit[j]))
            return fail(r, DCS_LIMIT, -1, -1, 0, k1);
    if (r->rec_every <= 0 || k1 % r->rec_every)
        return 0;
    row = r->rec + r->rec_rows * (1 + r->n_rec);
    row[0] = time_of(r, k1);
    for (j = 0; j < r->n_rec; j++)
        row[1 + j] = r->y[r->rec_index[j]];
    r->rec_rows++;
    return r->rec_rows == r->rec_capacity ? fail(r, DCS_FULL, -1, -1, 0, k1) : 0;
}

__attribute__((visibility("default"))) int dcs_run_steps(DcsSteps *r, int64_t stop)
{
    int32_t after = r->resume;
    r->resume = -1;
    r->event = DCS_DONE;
    while (r->tick < stop) {
        int stopped = r->algorithm == DCS_JACOBI ? jacobi_step(r, r->tick, after)
                                                 : gauss_seidel_step(r, r->tick, after);
        after = -1;
        if (stopped)
            return r->event;
        r->tick++;
        if (observe(r, r->tick))
            return r->event;
    }
    return r->event;
}
