/* fmu_slave.c -- the FMI-version-independent half of both wrappers (see fmu_slave.h). */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core_internal.h"
#include "fmu_slave.h"

void fmu_slave_logf(const FmuSlave *s, int level, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    core_vlog(s->log, s->log_env, level, fmt, ap);
    va_end(ap);
}

/* ---- logging categories (also listed in the model descriptions, calib/fmu/model_description.py):
 * index = message level */
static const char *const LOG_CATEGORY[FMU_LOG_LEVELS] = {"logEvents", "logStatusWarning", "logStatusError"};

int fmu_slave_set_logging(FmuSlave *s, int on, size_t n_categories, const char *const categories[])
{
    int enable[FMU_LOG_LEVELS], level;
    size_t i;
    for (level = 0; level < FMU_LOG_LEVELS; level++)
        enable[level] = n_categories == 0 ? on : s->log_on[level];
    for (i = 0; i < n_categories; i++) {
        for (level = 0; level < FMU_LOG_LEVELS; level++)
            if (categories && categories[i] && strcmp(categories[i], LOG_CATEGORY[level]) == 0) break;
        if (level == FMU_LOG_LEVELS) {
            fmu_slave_logf(s, 2, "unknown log category '%s'; valid: %s, %s, %s",
                           categories && categories[i] ? categories[i] : "(null)", LOG_CATEGORY[0],
                           LOG_CATEGORY[1], LOG_CATEGORY[2]);
            return -1;
        }
        enable[level] = on;
    }
    memcpy(s->log_on, enable, sizeof enable);
    return 0;
}

const char *fmu_slave_log_category(const FmuSlave *s, int level)
{
    if (level < 0) level = 0;
    if (level >= FMU_LOG_LEVELS) level = FMU_LOG_LEVELS - 1;
    return s->log_on[level] ? LOG_CATEGORY[level] : NULL;
}

int fmu_slave_create(FmuSlave *s, const char *given_token, const char *resource_dir,
                     const FmuVar *vars, int n_vars, const char *token, CoreLogger log,
                     void *log_env)
{
    memset(s, 0, sizeof *s);
    s->vars = vars;
    s->n_vars = n_vars;
    s->token = token;
    s->log = log;
    s->log_env = log_env;
    s->log_on[0] = 0;                 /* logEvents: fmi*SetDebugLogging or loggingOn */
    s->log_on[1] = s->log_on[2] = 1;  /* warnings and errors unless switched off */
    if (!given_token || strcmp(given_token, token) != 0) {
        fmu_slave_logf(s, 2, "GUID / instantiation token mismatch: got '%s', the binary was built "
                       "for %s", given_token ? given_token : "(null)", token);
        return -1;
    }
    if (!resource_dir || !resource_dir[0]) {
        fmu_slave_logf(s, 2, "no resource location given; the FMU needs resources/rotor.dat");
        return -1;
    }
    s->core = core_create(resource_dir, log, log_env);
    if (!s->core || fmu_check_table(s->core, vars, n_vars) != 0 ||
        fmu_apply_starts(s->core, vars, n_vars) != 0) {
        fmu_slave_logf(s, 2, "instantiation failed (see the messages above)");
        core_free(s->core);
        s->core = NULL;
        return -1;
    }
    s->mode = FMU_MODE_INSTANTIATED;
    return 0;
}

void fmu_slave_destroy(FmuSlave *s)
{
    core_free(s->core);
    s->core = NULL;
}

/* ---- life cycle -------------------------------------------------------------------- */
int fmu_slave_set_start_time(FmuSlave *s, double start_time)
{
    if (s->mode != FMU_MODE_INSTANTIATED) {
        fmu_slave_logf(s, 2, "the start time can only be set after instantiation");
        return -1;
    }
    if (!isfinite(start_time)) {
        fmu_slave_logf(s, 2, "start time must be finite, got %g", start_time);
        return -1;
    }
    s->start_time = start_time;
    return 0;
}

int fmu_slave_enter_init(FmuSlave *s)
{
    if (s->mode != FMU_MODE_INSTANTIATED) {
        fmu_slave_logf(s, 2, "initialization mode can only be entered after instantiation or reset");
        return -1;
    }
    s->mode = FMU_MODE_INIT;
    return 0;
}

int fmu_slave_exit_init(FmuSlave *s)
{
    if (s->mode != FMU_MODE_INIT) {
        fmu_slave_logf(s, 2, "exit initialization mode: the instance is not in initialization mode");
        return -1;
    }
    if (core_initialize(s->core, s->start_time) != 0) {
        s->mode = FMU_MODE_ERROR;
        fmu_slave_logf(s, 2, "initialization failed (see the messages above)");
        return -1;
    }
    s->mode = FMU_MODE_STEP;
    fmu_slave_logf(s, 0, "initialized at t = %g s", s->start_time);
    return 0;
}

int fmu_slave_terminate(FmuSlave *s)
{
    s->mode = FMU_MODE_TERMINATED;
    return 0;
}

int fmu_slave_reset(FmuSlave *s)
{
    memset(&s->core->dyn, 0, sizeof s->core->dyn);
    if (fmu_apply_starts(s->core, s->vars, s->n_vars) != 0) {
        fmu_slave_logf(s, 2, "reset failed (see the messages above)");
        s->mode = FMU_MODE_ERROR;
        return -1;
    }
    s->mode = FMU_MODE_INSTANTIATED;
    s->start_time = 0.0;
    return 0;
}

/* ---- get / set ------------------------------------------------------------------------ */
static const FmuVar *lookup(const FmuSlave *s, unsigned int vr, int type)
{
    const FmuVar *v = fmu_find(s->vars, s->n_vars, vr);
    if (!v) {
        fmu_slave_logf(s, 2, "unknown value reference %u", vr);
        return NULL;
    }
    if (v->type != type) {
        fmu_slave_logf(s, 2, "variable '%s' has another type than the one requested", v->name);
        return NULL;
    }
    return v;
}

int fmu_slave_get(FmuSlave *s, const unsigned int vr[], size_t nvr, int type, double values[],
                  size_t n_values)
{
    size_t i, j = 0;
    int k;
    if (nvr > 0 && (!vr || !values)) {
        fmu_slave_logf(s, 2, "null value-reference or value array");
        return -1;
    }
    for (i = 0; i < nvr; i++) {
        const FmuVar *v = lookup(s, vr[i], type);
        if (!v) return -1;
        if ((size_t)v->count > n_values - j) {
            fmu_slave_logf(s, 2, "value array too short for '%s' (%zu values given)", v->name, n_values);
            return -1;
        }
        for (k = 0; k < v->count; k++, j++)
            if (fmu_get(s->core, v, k, &values[j]) != 0) return -1;
    }
    if (j != n_values) {
        fmu_slave_logf(s, 2, "%zu values given for variables with %zu elements", n_values, j);
        return -1;
    }
    return 0;
}

/* May v be set in the current mode? */
static int settable_now(const FmuSlave *s, const FmuVar *v)
{
    if (v->kind == FK_OUTPUT || v->kind == FK_INDEPENDENT) {
        fmu_slave_logf(s, 2, "variable '%s' is an output and cannot be set", v->name);
        return 0;
    }
    if (s->mode == FMU_MODE_TERMINATED || s->mode == FMU_MODE_ERROR) {
        fmu_slave_logf(s, 2, "cannot set '%s': the instance is terminated or in error", v->name);
        return 0;
    }
    if (v->kind == FK_FIXED && s->mode != FMU_MODE_INSTANTIATED && s->mode != FMU_MODE_INIT) {
        fmu_slave_logf(s, 2, "fixed parameter '%s' can only be set before initialization ends", v->name);
        return 0;
    }
    return 1;
}

int fmu_slave_set(FmuSlave *s, const unsigned int vr[], size_t nvr, int type,
                  const double values[], size_t n_values)
{
    size_t i, j = 0;
    int k;
    if (nvr > 0 && (!vr || !values)) {
        fmu_slave_logf(s, 2, "null value-reference or value array");
        return -1;
    }
    for (i = 0; i < nvr; i++) {             /* 1. validate everything */
        const FmuVar *v = lookup(s, vr[i], type);
        if (!v || !settable_now(s, v)) return -1;
        if ((size_t)v->count > n_values - j) {
            fmu_slave_logf(s, 2, "value array too short for '%s' (%zu values given)", v->name, n_values);
            return -1;
        }
        for (k = 0; k < v->count; k++, j++)
            if (fmu_check_range(s->core, v, k, values[j]) != 0) return -1;
    }
    if (j != n_values) {
        fmu_slave_logf(s, 2, "%zu values given for variables with %zu elements; nothing set", n_values, j);
        return -1;
    }
    for (i = 0, j = 0; i < nvr; i++) {      /* 2. write */
        const FmuVar *v = fmu_find(s->vars, s->n_vars, vr[i]);
        for (k = 0; k < v->count; k++, j++)
            if (fmu_set(s->core, v, k, values[j]) != 0) return -1;
    }
    return 0;
}

/* ---- stepping ---------------------------------------------------------------------------- */
int fmu_slave_do_step(FmuSlave *s, double current_time, double h)
{
    double now = s->core->dyn.time;
    int rc;
    if (s->mode != FMU_MODE_STEP) {
        fmu_slave_logf(s, 2, "doStep: the instance is not initialized (or terminated or in error)");
        return -1;
    }
    if (!(fabs(current_time - now) <= FMU_TIME_RTOL * fmax(1.0, fabs(now)))) {
        fmu_slave_logf(s, 2, "doStep: currentCommunicationPoint %.17g s is not the FMU's time "
                       "%.17g s (tolerance %g relative); steps must continue where the last one "
                       "ended (restore a saved FMU state to go back)", current_time, now,
                       FMU_TIME_RTOL);
        return -1;
    }
    s->core->dyn.time = current_time;
    rc = core_do_step(s->core, h);
    if (rc == CORE_STEP_FAILED) {
        s->mode = FMU_MODE_ERROR;
        fmu_slave_logf(s, 2, "step failed part-way (see the messages above); reset or restore a state");
    }
    return rc == 0 ? 0 : -1;
}

/* ---- FMU state ----------------------------------------------------------------------------
 * In memory and serialized alike: a header that identifies the build, then the payload.
 *   magic "calib-rotor-state" | format | header and payload sizes | FNV-1a 64 checksum of the
 *   payload | the build's GUID / instantiation token
 * Restoring checks all of it, then every number of the payload (core_check_dynamic) and
 * every settable variable against its range; a state of another build, a truncated or
 * edited one, is refused with a message. The payload is a plain copy of the core's
 * dynamic part (native byte order: a state moves between instances of one build on one
 * platform, not between platforms). */
#define STATE_MAGIC "calib-rotor-state"
#define STATE_FORMAT 1u
#define STATE_TOKEN_BYTES 64

typedef struct {
    char magic[24];
    uint32_t format;
    uint32_t header_bytes;
    uint64_t payload_bytes;
    uint64_t checksum;
    char token[STATE_TOKEN_BYTES];
} StateHeader;

typedef struct {
    CoreDynamic dyn;
    int32_t mode;
    int32_t reserved;
    double start_time;
} StatePayload;

typedef struct {
    StateHeader head;
    StatePayload body;
} Snapshot;

static uint64_t fnv1a64(const unsigned char *p, size_t n)
{
    uint64_t h = 14695981039346656037ull;
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= p[i];
        h *= 1099511628211ull;
    }
    return h;
}

static void fill_snapshot(const FmuSlave *s, Snapshot *snap)
{
    memset(snap, 0, sizeof *snap);
    memcpy(snap->head.magic, STATE_MAGIC, sizeof STATE_MAGIC);
    snap->head.format = STATE_FORMAT;
    snap->head.header_bytes = (uint32_t)sizeof(StateHeader);
    snap->head.payload_bytes = (uint64_t)sizeof(StatePayload);
    snprintf(snap->head.token, sizeof snap->head.token, "%s", s->token);
    memcpy(&snap->body.dyn, &s->core->dyn, sizeof snap->body.dyn);
    snap->body.mode = (int32_t)s->mode;
    snap->body.start_time = s->start_time;
    snap->head.checksum = fnv1a64((const unsigned char *)&snap->body, sizeof snap->body);
}

/* Every settable variable of the snapshot inside its range, Integer/Boolean integral. */
static int check_ranges(const FmuSlave *s, const CoreDynamic *dyn)
{
    RotorCore *view = (RotorCore *)malloc(sizeof(RotorCore));
    int i, k, rc = 0;
    if (!view) {
        fmu_slave_logf(s, 2, "out of memory checking the FMU state");
        return -1;
    }
    memcpy(view, s->core, sizeof *view);            /* shares the rotor data; never freed */
    memcpy(&view->dyn, dyn, sizeof view->dyn);
    for (i = 0; i < s->n_vars && rc == 0; i++) {
        const FmuVar *v = &s->vars[i];
        if (v->kind == FK_OUTPUT || v->kind == FK_INDEPENDENT) continue;
        for (k = 0; k < v->count && rc == 0; k++) {
            double x;
            if (fmu_get(view, v, k, &x) != 0 || fmu_check_range(view, v, k, x) != 0) rc = -1;
            else if (v->type != FT_REAL && x != floor(x)) {
                fmu_slave_logf(s, 2, "variable '%s' = %g is not an integer", v->name, x);
                rc = -1;
            }
        }
    }
    free(view);
    return rc;
}

/* Is snap a state this build could have written? 0 if so, else -1 (logged). */
static int check_snapshot(const FmuSlave *s, const Snapshot *snap, const char *what)
{
    const StateHeader *h = &snap->head;
    char token[STATE_TOKEN_BYTES];
    if (memcmp(h->magic, STATE_MAGIC, sizeof STATE_MAGIC) != 0) {
        fmu_slave_logf(s, 2, "%s: not a state of this rotor FMU (no header)", what);
        return -1;
    }
    if (h->format != STATE_FORMAT || h->header_bytes != sizeof(StateHeader) ||
        h->payload_bytes != sizeof(StatePayload)) {
        fmu_slave_logf(s, 2, "%s: state format %u with %u + %llu bytes, this build writes format %u "
                       "with %zu + %zu bytes", what, h->format, h->header_bytes,
                       (unsigned long long)h->payload_bytes, STATE_FORMAT, sizeof(StateHeader),
                       sizeof(StatePayload));
        return -1;
    }
    memset(token, 0, sizeof token);
    snprintf(token, sizeof token, "%s", s->token);
    if (memcmp(h->token, token, sizeof token) != 0) {       /* NUL padding included */
        fmu_slave_logf(s, 2, "%s: the state comes from another build (token %.*s), this FMU is %s",
                       what, STATE_TOKEN_BYTES, h->token, s->token);
        return -1;
    }
    if (h->checksum != fnv1a64((const unsigned char *)&snap->body, sizeof snap->body)) {
        fmu_slave_logf(s, 2, "%s: checksum mismatch: the state was altered or truncated", what);
        return -1;
    }
    if (snap->body.mode < FMU_MODE_INSTANTIATED || snap->body.mode > FMU_MODE_ERROR ||
        !isfinite(snap->body.start_time)) {
        fmu_slave_logf(s, 2, "%s: invalid mode %d or start time", what, (int)snap->body.mode);
        return -1;
    }
    if ((snap->body.mode == FMU_MODE_STEP && !snap->body.dyn.initialized) ||
        ((snap->body.mode == FMU_MODE_INSTANTIATED || snap->body.mode == FMU_MODE_INIT) &&
         snap->body.dyn.initialized)) {
        fmu_slave_logf(s, 2, "%s: mode and initialization flag disagree", what);
        return -1;
    }
    if (core_check_dynamic(s->core, &snap->body.dyn) != 0 || check_ranges(s, &snap->body.dyn) != 0) {
        fmu_slave_logf(s, 2, "%s: the state holds invalid values (see above)", what);
        return -1;
    }
    return 0;
}

int fmu_slave_get_state(FmuSlave *s, void **state)
{
    Snapshot *snap;
    if (!state) {
        fmu_slave_logf(s, 2, "get FMU state: null state pointer");
        return -1;
    }
    snap = (Snapshot *)(*state ? *state : malloc(sizeof(Snapshot)));
    if (!snap) {
        fmu_slave_logf(s, 2, "out of memory saving the FMU state");
        return -1;
    }
    fill_snapshot(s, snap);
    *state = snap;
    return 0;
}

int fmu_slave_set_state(FmuSlave *s, const void *state)
{
    const Snapshot *snap = (const Snapshot *)state;
    if (!snap) {
        fmu_slave_logf(s, 2, "set FMU state: null state");
        return -1;
    }
    if (check_snapshot(s, snap, "set FMU state") != 0) return -1;
    core_restore_dynamic(s->core, &snap->body.dyn);
    s->mode = (FmuMode)snap->body.mode;
    s->start_time = snap->body.start_time;
    return 0;
}

void fmu_slave_free_state(void **state)
{
    if (state) {
        free(*state);
        *state = NULL;
    }
}

size_t fmu_slave_state_size(void) { return sizeof(Snapshot); }

int fmu_slave_serialize_state(FmuSlave *s, const void *state, unsigned char *bytes, size_t size)
{
    if (!state || !bytes) {
        fmu_slave_logf(s, 2, "serialize FMU state: null state or buffer");
        return -1;
    }
    if (size < sizeof(Snapshot)) {
        fmu_slave_logf(s, 2, "serialization buffer too small (%zu < %zu bytes)", size, sizeof(Snapshot));
        return -1;
    }
    memcpy(bytes, state, sizeof(Snapshot));
    return 0;
}

int fmu_slave_deserialize_state(FmuSlave *s, const unsigned char *bytes, size_t size, void **state)
{
    Snapshot *snap;
    if (!bytes || !state) {
        fmu_slave_logf(s, 2, "deserialize FMU state: null bytes or state pointer");
        return -1;
    }
    if (size != sizeof(Snapshot)) {
        fmu_slave_logf(s, 2, "deserialize FMU state: %zu bytes, a state of this build has %zu", size,
                       sizeof(Snapshot));
        return -1;
    }
    snap = (Snapshot *)malloc(sizeof(Snapshot));
    if (!snap) {
        fmu_slave_logf(s, 2, "out of memory restoring the FMU state");
        return -1;
    }
    memcpy(snap, bytes, sizeof(Snapshot));
    if (check_snapshot(s, snap, "deserialize FMU state") != 0) {
        free(snap);
        return -1;
    }
    if (*state) {                      /* reuse the importer's state object */
        memcpy(*state, snap, sizeof(Snapshot));
        free(snap);
    } else {
        *state = snap;
    }
    return 0;
}

int fmu_to_int(double x)
{
    if (!(x == x)) return 0;
    if (x >= 2147483647.0) return 2147483647;
    if (x <= -2147483648.0) return -2147483647 - 1;
    return (int)x;
}
