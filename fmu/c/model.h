/* The boat as one FMI-agnostic model: the interface both FMI wrappers translate onto.
 *
 * Values live in one array indexed by value reference (boat_config.h, generated from
 * fmu/variables.py); the dynamics are CasADi's C of controller.model.plant_step_function().
 * Everything a wrapper needs to know about the boat is here; nothing here knows about FMI.
 */
#ifndef BOAT_MODEL_H
#define BOAT_MODEL_H

#include <stddef.h>

#include "boat_config.h"

typedef enum { BOAT_OK = 0, BOAT_WARNING = 1, BOAT_ERROR = 3 } BoatStatus;

typedef enum {
    PHASE_INSTANTIATED = 1,
    PHASE_INITIALIZATION = 2,
    PHASE_STEP = 4,
    PHASE_TERMINATED = 8
} BoatPhase;

#define PHASE_ANY (PHASE_INSTANTIATED | PHASE_INITIALIZATION | PHASE_STEP | PHASE_TERMINATED)

/* Log categories, one bit each (the order of LogCategories in the modelDescription). */
#define BOAT_LOG_ERROR 1u
#define BOAT_LOG_WARNING 2u
#define BOAT_LOG_CALLS 4u
#define BOAT_LOG_ALL 7u

/* The complete FMU state: plain data, copied by get/set FMU state and serialized as bytes. */
typedef struct {
    double time;
    double start_time;
    double stop_time;
    int stop_time_defined;
    int phase;
    double values[BOAT_NUMBER_OF_VARIABLES];
} BoatState;

/* Delivers one formatted message to the FMI tool (the wrapper adds what its version needs). */
typedef void (*BoatLogFn)(void *wrapper, BoatStatus status, const char *category,
                          const char *message);

typedef struct {
    BoatState s;
    int logging_on;
    unsigned categories;
    BoatLogFn log;
    void *wrapper;
    /* CasADi workspace, allocated once per instance: doStep allocates nothing */
    const double **arg;
    double **res;
    long long *iw;
    double *w;
} BoatModel;

BoatModel *boat_new(BoatLogFn log, void *wrapper, int logging_on);
void boat_free(BoatModel *m);
void boat_reset(BoatModel *m);

void boat_log(BoatModel *m, BoatStatus status, unsigned category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;
BoatStatus boat_set_debug_logging(BoatModel *m, int on, size_t n, const char *const names[]);

/* 0 if `phase` is one of `allowed`, else logs "<function> not allowed in <phase>". */
int boat_phase_ok(BoatModel *m, unsigned allowed, const char *function);

BoatStatus boat_set(BoatModel *m, const unsigned vr[], size_t n, const double value[]);
BoatStatus boat_get(BoatModel *m, const unsigned vr[], size_t n, double value[]);
BoatStatus boat_no_such_type(BoatModel *m, const char *type, const unsigned vr[], size_t n);

BoatStatus boat_enter_initialization(BoatModel *m, double start_time, int stop_time_defined,
                                     double stop_time);
BoatStatus boat_exit_initialization(BoatModel *m);
BoatStatus boat_do_step(BoatModel *m, double current_time, double step_size);
BoatStatus boat_terminate(BoatModel *m);

/* FMU state snapshots and their byte form. */
BoatState *boat_state_new(const BoatModel *m);
BoatStatus boat_state_restore(BoatModel *m, const BoatState *state);
size_t boat_serialized_size(void);
void boat_serialize(const BoatState *state, unsigned char *bytes);
BoatStatus boat_deserialize(BoatModel *m, const unsigned char *bytes, size_t size,
                            BoatState *state);

#endif
