/* fmu_common.c -- value-reference table helpers shared by the FMI wrappers. */
#include <math.h>

#include "core_internal.h"
#include "fmu_common.h"

const FmuVar *fmu_find(const FmuVar *vars, int n, unsigned int vr)
{
    int lo = 0, hi = n - 1;
    while (lo <= hi) {
        int mid = (lo + hi) / 2;
        if (vars[mid].vr == vr) return &vars[mid];
        if (vars[mid].vr < vr) lo = mid + 1;
        else hi = mid - 1;
    }
    return NULL;
}

int fmu_get(const RotorCore *core, const FmuVar *v, int k, double *value)
{
    double x;
    if (v->kind == FK_INDEPENDENT) {
        *value = core->dyn.time;
        return 0;
    }
    if (core_get(core, (CoreVar)v->var, v->index + k, &x) != 0) return -1;
    x = v->scale * x + v->offset;
    if (v->wrap360) {
        x = fmod(x, 360.0);
        if (x < 0.0) x += 360.0;
    }
    *value = x;
    return 0;
}

int fmu_check_range(const RotorCore *core, const FmuVar *v, int k, double value)
{
    if (value >= v->min && value <= v->max) return 0;   /* false for NaN */
    if (v->count > 1)
        core_logf(core, 2, "variable '%s'[%d] = %g is outside its range [%g, %g]%s%s; value refused",
                  v->name, k, value, v->min, v->max, v->unit[0] ? " " : "", v->unit);
    else
        core_logf(core, 2, "variable '%s' = %g is outside its range [%g, %g]%s%s; value refused",
                  v->name, value, v->min, v->max, v->unit[0] ? " " : "", v->unit);
    return -1;
}

int fmu_set(RotorCore *core, const FmuVar *v, int k, double value)
{
    if (v->kind == FK_OUTPUT || v->kind == FK_INDEPENDENT) {
        core_logf(core, 2, "variable '%s' (vr %u) is not settable", v->name, v->vr);
        return -1;
    }
    if (fmu_check_range(core, v, k, value) != 0) return -1;
    return core_set(core, (CoreVar)v->var, v->index + k, (value - v->offset) / v->scale);
}

int fmu_apply_starts(RotorCore *core, const FmuVar *vars, int n)
{
    int i, k;
    for (i = 0; i < n; i++) {
        if (vars[i].kind == FK_OUTPUT || vars[i].kind == FK_INDEPENDENT) continue;
        for (k = 0; k < vars[i].count; k++)
            if (fmu_set(core, &vars[i], k, vars[i].start) != 0) return -1;
    }
    return 0;
}

int fmu_check_table(const RotorCore *core, const FmuVar *vars, int n)
{
    int i;
    for (i = 0; i < n; i++) {
        const FmuVar *v = &vars[i];
        if (v->kind == FK_INDEPENDENT) continue;
        if (v->index < 0 || v->index + v->count > core_var_size(core, (CoreVar)v->var)) {
            core_logf(core, 2, "variable '%s' addresses elements %d..%d but the rotor data give "
                      "%d; the FMU resources do not match its model description",
                      v->name, v->index, v->index + v->count - 1,
                      core_var_size(core, (CoreVar)v->var));
            return -1;
        }
        if (v->scale == 0.0) {
            core_logf(core, 2, "variable '%s' has a zero unit scale", v->name);
            return -1;
        }
    }
    return 0;
}
