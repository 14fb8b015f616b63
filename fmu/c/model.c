/* The boat model behind both FMI wrappers: values, checks, the fixed-step RK4 doStep.
 *
 * One communication step [t, t + H] is cut into n = ceil(H / internal_step) equal steps; each
 * is one call of the generated plant step (actuator rate limit, then RK4 with the actuators
 * held). Outputs after doStep are the values at t + H: the state, the actuators in effect over
 * the last internal step, and the body-frame accelerations f(x(t + H), actuators).
 */
#include "model.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "boat_dynamics.h"

#define NX 6
#define NU 2

static const char *const CATEGORY_NAMES[] = {"logStatusError", "logStatusWarning", "logCalls"};
#define N_CATEGORIES 3

static const char SERIAL_MAGIC[8] = {'c', 'a', 'n', 'a', 'l', 'b', 't', '1'};

static const char *phase_name(int phase) {
    switch (phase) {
        case PHASE_INSTANTIATED: return "the instantiated state";
        case PHASE_INITIALIZATION: return "initialization mode";
        case PHASE_STEP: return "step mode";
        case PHASE_TERMINATED: return "the terminated state";
        default: return "an unknown state";
    }
}

BoatModel *boat_new(BoatLogFn log, void *wrapper, int logging_on) {
    casadi_int sz_arg, sz_res, sz_iw, sz_w;
    BoatModel *m = (BoatModel *)calloc(1, sizeof(BoatModel));
    if (!m) return NULL;
    m->log = log;
    m->wrapper = wrapper;
    m->logging_on = logging_on;
    m->categories = BOAT_LOG_ALL;
    plant_step_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
    m->arg = (const double **)calloc((size_t)sz_arg, sizeof(double *));
    m->res = (double **)calloc((size_t)sz_res, sizeof(double *));
    m->iw = (long long *)calloc((size_t)(sz_iw > 0 ? sz_iw : 1), sizeof(long long));
    m->w = (double *)calloc((size_t)(sz_w > 0 ? sz_w : 1), sizeof(double));
    if (!m->arg || !m->res || !m->iw || !m->w) {
        boat_free(m);
        return NULL;
    }
    boat_reset(m);
    return m;
}

void boat_free(BoatModel *m) {
    if (!m) return;
    free((void *)m->arg);
    free(m->res);
    free(m->iw);
    free(m->w);
    free(m);
}

void boat_reset(BoatModel *m) {
    memset(&m->s, 0, sizeof m->s);
    memcpy(m->s.values, BOAT_START, sizeof m->s.values);
    m->s.phase = PHASE_INSTANTIATED;
}

void boat_log(BoatModel *m, BoatStatus status, unsigned category, const char *fmt, ...) {
    char message[1024];
    va_list args;
    int idx = category == BOAT_LOG_ERROR ? 0 : category == BOAT_LOG_WARNING ? 1 : 2;
    if (!m || !m->log) return;
    /* Errors always reach the tool, so an error status never comes unexplained; everything
       else only with logging on and its category enabled. */
    if (status != BOAT_ERROR && !(m->logging_on && (m->categories & category))) return;
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    m->log(m->wrapper, status, CATEGORY_NAMES[idx], message);
}

BoatStatus boat_set_debug_logging(BoatModel *m, int on, size_t n, const char *const names[]) {
    unsigned mask = 0;
    size_t i;
    int k;
    for (i = 0; i < n; i++) {
        int found = 0;
        for (k = 0; k < N_CATEGORIES; k++) {
            if (names[i] && strcmp(names[i], CATEGORY_NAMES[k]) == 0) {
                mask |= 1u << k;
                found = 1;
            }
        }
        if (!found) {
            boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "unknown log category '%s'",
                     names[i] ? names[i] : "(null)");
            return BOAT_ERROR;
        }
    }
    m->logging_on = on;
    m->categories = n == 0 ? BOAT_LOG_ALL : mask;
    return BOAT_OK;
}

int boat_phase_ok(BoatModel *m, unsigned allowed, const char *function) {
    if ((unsigned)m->s.phase & allowed) return 1;
    boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "%s is not allowed in %s", function,
             phase_name(m->s.phase));
    return 0;
}

/* -- values -------------------------------------------------------------------------- */

/* The shortest of %.15g, %.16g, %.17g that reads back as the same double: messages show
   what the user typed (-1e-09, not -1.0000000000000001e-09). */
typedef struct { char text[32]; } Number;

static Number number(double value) {
    Number n;
    int digits;
    for (digits = 15; digits <= 17; digits++) {
        snprintf(n.text, sizeof n.text, "%.*g", digits, value);
        if (!isfinite(value) || strtod(n.text, NULL) == value) break;
    }
    return n;
}

static BoatStatus check_value(BoatModel *m, unsigned vr, double value) {
    const char *name = BOAT_NAMES[vr];
    if (BOAT_SETTABLE[vr] == BOAT_SET_NEVER) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "variable %s (value reference %u) cannot be set: it is computed by the FMU",
                 name, vr);
        return BOAT_ERROR;
    }
    if (BOAT_SETTABLE[vr] == BOAT_SET_BEFORE_STEP &&
        !(m->s.phase & (PHASE_INSTANTIATED | PHASE_INITIALIZATION))) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "variable %s is a fixed parameter: it can be set only before initialization "
                 "ends (got %s in %s)", name, number(value).text, phase_name(m->s.phase));
        return BOAT_ERROR;
    }
    if (!isfinite(value)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "variable %s: value %g is not a finite number",
                 name, value);
        return BOAT_ERROR;
    }
    if (BOAT_SIGN[vr] == 1 && !(value > 0.0)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "variable %s: value %s must be positive",
                 name, number(value).text);
        return BOAT_ERROR;
    }
    if (BOAT_SIGN[vr] == 2 && value < 0.0) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "variable %s: value %s must be zero (off) or positive", name,
                 number(value).text);
        return BOAT_ERROR;
    }
    return BOAT_OK;
}

BoatStatus boat_set(BoatModel *m, const unsigned vr[], size_t n, const double value[]) {
    size_t i;
    if (n > 0 && (!vr || !value)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "set: null value reference or value array");
        return BOAT_ERROR;
    }
    for (i = 0; i < n; i++) {
        if (vr[i] >= BOAT_NUMBER_OF_VARIABLES) {
            boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "set: unknown value reference %u", vr[i]);
            return BOAT_ERROR;
        }
        if (check_value(m, vr[i], value[i]) != BOAT_OK) return BOAT_ERROR;
        m->s.values[vr[i]] = value[i];
        boat_log(m, BOAT_OK, BOAT_LOG_CALLS, "set %s = %s", BOAT_NAMES[vr[i]],
                 number(value[i]).text);
    }
    return BOAT_OK;
}

/* One generated plant step: x, act at the start -> x_next, act_next, xdot (f at the start). */
static void plant(BoatModel *m, const double *x, const double *act, const double *cmd,
                  double h, double *x_next, double *act_next, double *xdot) {
    const double *v = m->s.values;
    m->arg[0] = x;
    m->arg[1] = act;
    m->arg[2] = cmd;
    m->arg[3] = v + BOAT_GROUP_P;
    m->arg[4] = v + BOAT_GROUP_CURRENT;
    m->arg[5] = v + BOAT_GROUP_RATE;
    m->arg[6] = &h;
    m->res[0] = x_next;
    m->res[1] = act_next;
    m->res[2] = xdot;
    plant_step(m->arg, m->res, m->iw, m->w, 0);
}

/* f(x, act): the accelerations with the actuators held (a plant step of length 0). */
static void accelerations(BoatModel *m, const double *x, const double *act, double *xdot) {
    double x_same[NX], act_same[NU];
    plant(m, x, act, act, 0.0, x_same, act_same, xdot);
}

static int all_finite(const double *a, int n) {
    int i;
    for (i = 0; i < n; i++)
        if (!isfinite(a[i])) return 0;
    return 1;
}

/* Outputs before the first step: the initial state and actuators, f at them. */
static BoatStatus initial_outputs(BoatModel *m) {
    double *v = m->s.values;
    double act[NU], xdot[NX];
    int i;
    for (i = 0; i < NU; i++) act[i] = fmin(fmax(v[BOAT_GROUP_ACT0 + i], -100.0), 100.0);
    accelerations(m, v + BOAT_GROUP_X0, act, xdot);
    if (!all_finite(xdot, NX)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "the initial accelerations are not finite (check the parameters)");
        return BOAT_ERROR;
    }
    memcpy(v + BOAT_GROUP_X, v + BOAT_GROUP_X0, NX * sizeof(double));
    memcpy(v + BOAT_GROUP_ACT, act, NU * sizeof(double));
    memcpy(v + BOAT_GROUP_ACCEL, xdot + 3, 3 * sizeof(double));
    return BOAT_OK;
}

BoatStatus boat_get(BoatModel *m, const unsigned vr[], size_t n, double value[]) {
    size_t i;
    if (n > 0 && (!vr || !value)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "get: null value reference or value array");
        return BOAT_ERROR;
    }
    if (m->s.phase & (PHASE_INSTANTIATED | PHASE_INITIALIZATION)) {
        /* outputs follow the parameters and inputs until initialization ends */
        if (initial_outputs(m) != BOAT_OK) return BOAT_ERROR;
    }
    for (i = 0; i < n; i++) {
        if (vr[i] >= BOAT_NUMBER_OF_VARIABLES) {
            boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "get: unknown value reference %u", vr[i]);
            return BOAT_ERROR;
        }
        value[i] = vr[i] == VR_time ? m->s.time : m->s.values[vr[i]];
    }
    return BOAT_OK;
}

BoatStatus boat_no_such_type(BoatModel *m, const char *type, const unsigned vr[], size_t n) {
    if (n == 0) return BOAT_OK;
    boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
             "value reference %u: this FMU has no variables of type %s (all are 64-bit reals)",
             vr ? vr[0] : 0u, type);
    return BOAT_ERROR;
}

/* -- lifecycle ----------------------------------------------------------------------- */

BoatStatus boat_enter_initialization(BoatModel *m, double start_time, int stop_time_defined,
                                     double stop_time) {
    if (!boat_phase_ok(m, PHASE_INSTANTIATED, "entering initialization mode")) return BOAT_ERROR;
    if (!isfinite(start_time)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "start time %g is not finite", start_time);
        return BOAT_ERROR;
    }
    if (stop_time_defined && !(stop_time >= start_time)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "stop time %s is before the start time %s",
                 number(stop_time).text, number(start_time).text);
        return BOAT_ERROR;
    }
    m->s.time = m->s.start_time = start_time;
    m->s.stop_time_defined = stop_time_defined;
    m->s.stop_time = stop_time;
    m->s.phase = PHASE_INITIALIZATION;
    return BOAT_OK;
}

BoatStatus boat_exit_initialization(BoatModel *m) {
    if (!boat_phase_ok(m, PHASE_INITIALIZATION, "exiting initialization mode")) return BOAT_ERROR;
    if (initial_outputs(m) != BOAT_OK) return BOAT_ERROR;
    m->s.phase = PHASE_STEP;
    return BOAT_OK;
}

BoatStatus boat_terminate(BoatModel *m) {
    if (!boat_phase_ok(m, PHASE_INITIALIZATION | PHASE_STEP, "terminate")) return BOAT_ERROR;
    m->s.phase = PHASE_TERMINATED;
    return BOAT_OK;
}

BoatStatus boat_do_step(BoatModel *m, double t, double H) {
    double *v = m->s.values;
    double x[NX], act[NU], x_next[NX], act_next[NU], xdot[NX];
    double tolerance, t_end, n_steps, dt, internal_step = v[VR_internal_step];
    long k, n;

    if (!boat_phase_ok(m, PHASE_STEP, "doStep")) return BOAT_ERROR;
    if (!isfinite(t) || !isfinite(H) || !(H > 0.0)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "doStep: communication step size %g at t = %g must be positive and finite",
                 H, t);
        return BOAT_ERROR;
    }
    tolerance = 1e-9 * fmax(1.0, fabs(m->s.time));
    if (fabs(t - m->s.time) > tolerance) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "doStep: communication point %s does not match the FMU time %s",
                 number(t).text, number(m->s.time).text);
        return BOAT_ERROR;
    }
    t_end = t + H;
    if (m->s.stop_time_defined &&
        t_end > m->s.stop_time + 1e-9 * fmax(1.0, fabs(m->s.stop_time))) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "doStep: a step of %s s from t = %s goes past the stop time %s",
                 number(H).text, number(t).text, number(m->s.stop_time).text);
        return BOAT_ERROR;
    }
    n_steps = ceil(H / internal_step - 1e-9);
    if (n_steps < 1.0) n_steps = 1.0;
    if (n_steps > 1e8) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "doStep: step size %g needs %g internal steps of internal_step = %g", H,
                 n_steps, internal_step);
        return BOAT_ERROR;
    }
    n = (long)n_steps;
    dt = H / (double)n;

    memcpy(x, v + BOAT_GROUP_X, sizeof x);
    memcpy(act, v + BOAT_GROUP_ACT, sizeof act);
    for (k = 0; k < n; k++) {
        plant(m, x, act, v + BOAT_GROUP_CMD, dt, x_next, act_next, xdot);
        if (!all_finite(x_next, NX)) {
            boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                     "doStep: the state became non-finite at t = %s (internal step %g s); "
                     "the FMU stays at t = %s", number(t + (double)k * dt).text, dt,
                     number(t).text);
            return BOAT_ERROR;
        }
        memcpy(x, x_next, sizeof x);
        memcpy(act, act_next, sizeof act);
    }
    accelerations(m, x, act, xdot);
    if (!all_finite(xdot, NX)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "doStep: the accelerations at t = %s are not finite",
                 number(t_end).text);
        return BOAT_ERROR;
    }
    memcpy(v + BOAT_GROUP_X, x, sizeof x);
    memcpy(v + BOAT_GROUP_ACT, act, sizeof act);
    memcpy(v + BOAT_GROUP_ACCEL, xdot + 3, 3 * sizeof(double));
    /* the master's t + H, not a running sum: no drift of the communication point */
    m->s.time = t_end;
    boat_log(m, BOAT_OK, BOAT_LOG_CALLS, "doStep t = %s, H = %s: %ld internal steps",
             number(t).text, number(H).text, n);
    return BOAT_OK;
}

/* -- FMU state ----------------------------------------------------------------------- */

BoatState *boat_state_new(const BoatModel *m) {
    BoatState *state = (BoatState *)malloc(sizeof(BoatState));
    if (state) memcpy(state, &m->s, sizeof *state);
    return state;
}

BoatStatus boat_state_restore(BoatModel *m, const BoatState *state) {
    if (!state) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "set FMU state: the state is null");
        return BOAT_ERROR;
    }
    memcpy(&m->s, state, sizeof m->s);
    return BOAT_OK;
}

size_t boat_serialized_size(void) { return sizeof SERIAL_MAGIC + sizeof(BoatState); }

void boat_serialize(const BoatState *state, unsigned char *bytes) {
    memcpy(bytes, SERIAL_MAGIC, sizeof SERIAL_MAGIC);
    memcpy(bytes + sizeof SERIAL_MAGIC, state, sizeof *state);
}

BoatStatus boat_deserialize(BoatModel *m, const unsigned char *bytes, size_t size,
                            BoatState *state) {
    BoatState candidate;
    if (!bytes || size != boat_serialized_size() ||
        memcmp(bytes, SERIAL_MAGIC, sizeof SERIAL_MAGIC) != 0) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR,
                 "deserialize FMU state: %lu bytes are not a state of this FMU (expected %lu)",
                 (unsigned long)size, (unsigned long)boat_serialized_size());
        return BOAT_ERROR;
    }
    memcpy(&candidate, bytes + sizeof SERIAL_MAGIC, sizeof candidate);
    if (!(candidate.phase & PHASE_ANY)) {
        boat_log(m, BOAT_ERROR, BOAT_LOG_ERROR, "deserialize FMU state: corrupt phase %d",
                 candidate.phase);
        return BOAT_ERROR;
    }
    memcpy(state, &candidate, sizeof candidate);
    return BOAT_OK;
}
