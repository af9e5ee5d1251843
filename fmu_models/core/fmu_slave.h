/*
 * fmu_slave.h -- the FMI-version-independent half of a co-simulation instance.
 *
 * Both wrappers (variant_a/fmi2_wrapper.c, variant_b/fmi3_wrapper.c) keep only what
 * differs between FMI 2.0 and 3.0 (function names and signatures, callback types,
 * Integer/Boolean C types); everything else lives here once: the life cycle (modes),
 * range-checked and atomic get/set through the value-reference table, the step with its
 * time check, and the FMU state.
 *
 * Every function returns 0 on success and -1 on error after logging the reason through
 * the logger given at creation (level 0 info, 1 warning, 2 error); a rejected call
 * changes nothing, except that a step that fails part-way puts the instance in
 * FMU_MODE_ERROR (only reset, a state restore, getters and free are allowed then).
 */
#ifndef FMU_SLAVE_H
#define FMU_SLAVE_H

#include <stddef.h>

#include "fmu_common.h"

typedef enum {
    FMU_MODE_INSTANTIATED = 0,
    FMU_MODE_INIT,
    FMU_MODE_STEP,
    FMU_MODE_TERMINATED,
    FMU_MODE_ERROR
} FmuMode;

/* doStep: the caller's currentCommunicationPoint must equal the FMU's time within
 * FMU_TIME_RTOL * max(1 s, |time|). */
#define FMU_TIME_RTOL 1e-9

#define FMU_LOG_LEVELS 3   /* 0 logEvents, 1 logStatusWarning, 2 logStatusError */

typedef struct {
    RotorCore *core;
    const FmuVar *vars;      /* the generated table (fmu_variables.h) */
    int n_vars;
    const char *token;       /* GUID (FMI 2) / instantiationToken (FMI 3) of this build */
    FmuMode mode;
    double start_time;
    CoreLogger log;
    void *log_env;
    int log_on[FMU_LOG_LEVELS];   /* per category; see fmu_slave_set_logging */
} FmuSlave;

/* Check the token given by the importer against this build's, read the resources and apply
 * the start values. On error nothing is left to free. */
int fmu_slave_create(FmuSlave *s, const char *given_token, const char *resource_dir,
                     const FmuVar *vars, int n_vars, const char *token, CoreLogger log,
                     void *log_env);
void fmu_slave_destroy(FmuSlave *s);

void fmu_slave_logf(const FmuSlave *s, int level, const char *fmt, ...);

/* fmi*SetDebugLogging: no categories -> all categories on/off; else the named ones
 * (logEvents, logStatusWarning, logStatusError); an unknown name is an error. */
int fmu_slave_set_logging(FmuSlave *s, int on, size_t n_categories, const char *const categories[]);

/* The category of a message of this level, or NULL if that category is off. */
const char *fmu_slave_log_category(const FmuSlave *s, int level);

int fmu_slave_set_start_time(FmuSlave *s, double start_time);   /* before initialization */
int fmu_slave_enter_init(FmuSlave *s);
int fmu_slave_exit_init(FmuSlave *s);
int fmu_slave_terminate(FmuSlave *s);
int fmu_slave_reset(FmuSlave *s);

/* Values of the variables vr[0..nvr) of FmuType type, all elements in order (n_values in
 * total), in FMU units. */
int fmu_slave_get(FmuSlave *s, const unsigned int vr[], size_t nvr, int type, double values[],
                  size_t n_values);

/* Set them: atomic -- every reference, type, mode rule, count and range is checked before
 * the first value is written, so a refused call leaves every variable unchanged. */
int fmu_slave_set(FmuSlave *s, const unsigned int vr[], size_t nvr, int type,
                  const double values[], size_t n_values);

/* Advance from current_time (must be the FMU's time, see FMU_TIME_RTOL) by h. */
int fmu_slave_do_step(FmuSlave *s, double current_time, double h);

/* ---- FMU state --------------------------------------------------------------------- */
/* Save into *state (allocated if *state is NULL, else overwritten). */
int fmu_slave_get_state(FmuSlave *s, void **state);
int fmu_slave_set_state(FmuSlave *s, const void *state);
void fmu_slave_free_state(void **state);
size_t fmu_slave_state_size(void);
int fmu_slave_serialize_state(FmuSlave *s, const void *state, unsigned char *bytes, size_t size);
int fmu_slave_deserialize_state(FmuSlave *s, const unsigned char *bytes, size_t size, void **state);

/* Saturating conversion of a variable's value to a C int (Integer getters). */
int fmu_to_int(double x);

#endif
