/*
 * rotor_data.c -- read the rotor resource file written by calib.fmu.resources.
 *
 * Format (whitespace separated, '#' starts a comment line):
 *   calib_rotor_resource 1
 *   name <str>  n_blades <int>  hub_radius <m>  tip_radius <m>  precone_deg <deg>
 *   tilt_deg <deg>  hub_height <m>
 *   n_stations <int>   stations: n_stations rows
 *       "r chord twist_deg alpha0_deg x_az y_az z_az cone_rad ds w_thrust w_torque w_root"
 *   n_polar <int> alpha_start_deg <deg> alpha_step_deg <deg>
 *   cl: n_stations x n_polar values    cd: n_stations x n_polar values
 *   alpha_nodes <n> <values...>   eta_nodes <n> <values...>
 *   out_stations <n> <0-based station indices...>
 *   end
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core_internal.h"

/* Read the next non-comment token into buf. Returns 0 on success. */
static int next_token(FILE *f, char *buf, size_t n)
{
    for (;;) {
        if (fscanf(f, "%63s", buf) != 1) return -1;
        if (buf[0] == '#') {              /* skip rest of the comment line */
            int c;
            while ((c = fgetc(f)) != EOF && c != '\n') {}
            continue;
        }
        (void)n;
        return 0;
    }
}

static int expect_key(FILE *f, const char *key, const RotorCore *core, const char *path)
{
    char tok[64] = "";
    if (next_token(f, tok, sizeof tok) != 0 || strcmp(tok, key) != 0) {
        core_logf(core, 2, "%s: expected keyword '%s', found '%s'", path, key,
                  tok[0] ? tok : "<end of file>");
        return -1;
    }
    return 0;
}

static int read_double(FILE *f, double *x, const char *what, const RotorCore *core, const char *path)
{
    char tok[64];
    char *end;
    if (next_token(f, tok, sizeof tok) != 0) {
        core_logf(core, 2, "%s: unexpected end of file reading %s", path, what);
        return -1;
    }
    *x = strtod(tok, &end);
    if (*end != '\0' || !isfinite(*x)) {
        core_logf(core, 2, "%s: %s: expected a finite number, found '%s'", path, what, tok);
        return -1;
    }
    return 0;
}

static int read_int(FILE *f, int *k, int lo, int hi, const char *what, const RotorCore *core,
                    const char *path)
{
    double x;
    if (read_double(f, &x, what, core, path) != 0) return -1;
    if (x != floor(x) || x < lo || x > hi) {
        core_logf(core, 2, "%s: %s must be an integer in [%d, %d], got %g", path, what, lo, hi, x);
        return -1;
    }
    *k = (int)x;
    return 0;
}

static int key_double(FILE *f, const char *key, double *x, const RotorCore *core, const char *path)
{
    return expect_key(f, key, core, path) || read_double(f, x, key, core, path);
}

static int read_axis(FILE *f, const char *key, int *n, double *nodes, const RotorCore *core,
                     const char *path)
{
    int i;
    if (expect_key(f, key, core, path) || read_int(f, n, 2, CORE_MAX_AXIS_NODES, key, core, path))
        return -1;
    for (i = 0; i < *n; i++) {
        if (read_double(f, &nodes[i], key, core, path)) return -1;
        if (i > 0 && nodes[i] <= nodes[i - 1]) {
            core_logf(core, 2, "%s: %s must be strictly increasing", path, key);
            return -1;
        }
    }
    return 0;
}

/* Hat-function weights on a node grid (same rule as calib.corrections.hat_weights):
 * inside the grid linear interpolation, outside it the end hat ramps to zero over one spacing. */
void core_hat_weights(double x, const double *nodes, int n, int *k, double w[2])
{
    if (x < nodes[0]) {
        double t = (nodes[0] - x) / (nodes[1] - nodes[0]);
        *k = 0; w[0] = t < 1.0 ? 1.0 - t : 0.0; w[1] = 0.0;
    } else if (x > nodes[n - 1]) {
        double t = (x - nodes[n - 1]) / (nodes[n - 1] - nodes[n - 2]);
        *k = n - 2; w[0] = 0.0; w[1] = t < 1.0 ? 1.0 - t : 0.0;
    } else {
        int j = 0;
        double t;
        while (j < n - 2 && nodes[j + 1] <= x) j++;
        t = (x - nodes[j]) / (nodes[j + 1] - nodes[j]);
        *k = j; w[0] = 1.0 - t; w[1] = t;
    }
}

int rotor_data_read(RotorData *d, const char *path, const RotorCore *core)
{
    FILE *f = fopen(path, "r");
    char tok[64];
    double version, x;
    int i, j, n;

    memset(d, 0, sizeof *d);
    if (!f) {
        core_logf(core, 2, "cannot open rotor resource file '%s'", path);
        return -1;
    }
    if (expect_key(f, "calib_rotor_resource", core, path) ||
        read_double(f, &version, "version", core, path)) goto fail;
    if (version != 1.0) {
        core_logf(core, 2, "%s: unsupported resource version %g (expected 1)", path, version);
        goto fail;
    }
    if (expect_key(f, "name", core, path) || next_token(f, tok, sizeof tok)) goto fail;
    strncpy(d->name, tok, sizeof d->name - 1);
    if (expect_key(f, "n_blades", core, path) ||
        read_int(f, &d->n_blades_data, 1, 100, "n_blades", core, path)) goto fail;
    if (key_double(f, "hub_radius", &d->hub_radius, core, path) ||
        key_double(f, "tip_radius", &d->tip_radius, core, path) ||
        key_double(f, "precone_deg", &d->precone_deg, core, path) ||
        key_double(f, "tilt_deg", &d->tilt_deg, core, path) ||
        key_double(f, "hub_height", &d->hub_height, core, path)) goto fail;
    if (!(d->hub_radius > 0.0 && d->tip_radius > d->hub_radius)) {
        core_logf(core, 2, "%s: need 0 < hub_radius < tip_radius", path);
        goto fail;
    }
    if (expect_key(f, "n_stations", core, path) ||
        read_int(f, &d->n_stations, 2, CORE_MAX_STATIONS, "n_stations", core, path)) goto fail;
    for (i = 0; i < d->n_stations; i++) {
        if (read_double(f, &d->r[i], "station r", core, path) ||
            read_double(f, &d->chord[i], "station chord", core, path) ||
            read_double(f, &d->twist_deg[i], "station twist_deg", core, path) ||
            read_double(f, &d->alpha0_deg[i], "station alpha0_deg", core, path) ||
            read_double(f, &d->x_az[i], "station x_az", core, path) ||
            read_double(f, &d->y_az[i], "station y_az", core, path) ||
            read_double(f, &d->z_az[i], "station z_az", core, path) ||
            read_double(f, &d->cone[i], "station cone", core, path) ||
            read_double(f, &d->ds[i], "station ds", core, path) ||
            read_double(f, &d->w_thrust[i], "station w_thrust", core, path) ||
            read_double(f, &d->w_torque[i], "station w_torque", core, path) ||
            read_double(f, &d->w_root[i], "station w_root", core, path)) goto fail;
        if (d->r[i] < d->hub_radius || d->r[i] > d->tip_radius || d->chord[i] <= 0.0 ||
            (i > 0 && d->r[i] <= d->r[i - 1])) {
            core_logf(core, 2, "%s: station %d: r must increase inside [hub, tip] and chord > 0",
                      path, i);
            goto fail;
        }
    }
    if (expect_key(f, "n_polar", core, path) ||
        read_int(f, &d->n_polar, 4, 1000000, "n_polar", core, path) ||
        key_double(f, "alpha_start_deg", &d->alpha_start_deg, core, path) ||
        key_double(f, "alpha_step_deg", &d->alpha_step_deg, core, path)) goto fail;
    if (!(d->alpha_step_deg > 0.0) || d->alpha_start_deg > -180.0 + 1e-9 ||
        d->alpha_start_deg + (d->n_polar - 1) * d->alpha_step_deg < 180.0 - 1e-9) {
        core_logf(core, 2, "%s: the polar grid must be uniform and cover -180..180 deg", path);
        goto fail;
    }
    n = d->n_stations * d->n_polar;
    d->cl = (double *)malloc(sizeof(double) * (size_t)n);
    d->cd = (double *)malloc(sizeof(double) * (size_t)n);
    if (!d->cl || !d->cd) {
        core_logf(core, 2, "out of memory reading polars (%d values)", n);
        goto fail;
    }
    if (expect_key(f, "cl", core, path)) goto fail;
    for (i = 0; i < n; i++)
        if (read_double(f, &d->cl[i], "cl", core, path)) goto fail;
    if (expect_key(f, "cd", core, path)) goto fail;
    for (i = 0; i < n; i++)
        if (read_double(f, &d->cd[i], "cd", core, path)) goto fail;
    if (read_axis(f, "alpha_nodes", &d->n_alpha_nodes, d->alpha_nodes_deg, core, path) ||
        read_axis(f, "eta_nodes", &d->n_eta_nodes, d->eta_nodes, core, path)) goto fail;
    if (d->n_alpha_nodes * d->n_eta_nodes > CORE_MAX_NODES) {
        core_logf(core, 2, "%s: %d x %d correction nodes exceed the limit of %d", path,
                  d->n_alpha_nodes, d->n_eta_nodes, CORE_MAX_NODES);
        goto fail;
    }
    if (expect_key(f, "out_stations", core, path) ||
        read_int(f, &d->n_out, 1, CORE_MAX_OUT_STATIONS, "out_stations", core, path)) goto fail;
    for (i = 0; i < d->n_out; i++)
        if (read_int(f, &d->out_station[i], 0, d->n_stations - 1, "out_stations", core, path))
            goto fail;
    if (expect_key(f, "end", core, path)) goto fail;
    fclose(f);
    for (j = 0; j < d->n_stations; j++) {
        x = d->r[j] / d->tip_radius;
        core_hat_weights(x, d->eta_nodes, d->n_eta_nodes, &d->eta_index[j], d->eta_weight[j]);
    }
    return 0;
fail:
    fclose(f);
    rotor_data_free(d);
    return -1;
}

void rotor_data_free(RotorData *d)
{
    free(d->cl);
    free(d->cd);
    d->cl = d->cd = NULL;
}
