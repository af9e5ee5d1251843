/*
 * fmu_common.h -- the value-reference table shared by the FMI wrappers.
 *
 * Each variant's table (fmu_variables.h, generated at build time by
 * calib/fmu/build.py from fmu_models/<variant>/variables.toml) lists every FMI
 * variable: value reference, the core variable and element it maps to, its FMI type
 * and kind, and the affine unit map  fmu_value = scale * core_value + offset
 * (optionally wrapped into [0, 360) for angles).  The wrappers stay thin: they only
 * look variables up here and call the core.
 */
#ifndef FMU_COMMON_H
#define FMU_COMMON_H

#include "rotor_core.h"

typedef enum { FT_REAL = 0, FT_INTEGER = 1, FT_BOOLEAN = 2 } FmuType;
typedef enum { FK_INPUT = 0, FK_TUNABLE, FK_FIXED, FK_OUTPUT, FK_INDEPENDENT } FmuKind;

typedef struct {
    unsigned int vr;        /* value reference */
    int var;                /* CoreVar id */
    int index;              /* first core element */
    int count;              /* number of elements (> 1 for FMI 3 arrays) */
    int type;               /* FmuType */
    int kind;               /* FmuKind */
    double scale, offset;   /* fmu = scale * core + offset */
    int wrap360;            /* wrap the FMU value into [0, 360) */
    double start;           /* start value in FMU units (inputs and parameters) */
    double min, max;        /* accepted range in FMU units (variables.toml min/max; outputs: none) */
    const char *name;
    const char *unit;       /* FMU unit ("" if none), for messages */
} FmuVar;

/* Binary search of a table sorted by value reference; NULL if absent. */
const FmuVar *fmu_find(const FmuVar *vars, int n, unsigned int vr);

/* Element k of variable v, in FMU units. 0 on success. */
int fmu_get(const RotorCore *core, const FmuVar *v, int k, double *value);

/* Is value (FMU units) inside the variable's range [min, max] (and finite)? If not, log an
 * error naming the variable, the value and the range, and return -1. */
int fmu_check_range(const RotorCore *core, const FmuVar *v, int k, double value);

/* Set element k of v (range-checked). 0 on success. */
int fmu_set(RotorCore *core, const FmuVar *v, int k, double value);

/* Apply every start value of the table. 0 on success. */
int fmu_apply_starts(RotorCore *core, const FmuVar *vars, int n);

/* Check that the table fits the rotor data (array sizes). 0 on success (else logged). */
int fmu_check_table(const RotorCore *core, const FmuVar *vars, int n);

#endif
