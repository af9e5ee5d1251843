/*
 * core_internal.h -- declarations shared by the core translation units
 * (rotor_data.c, aero.c, inflow.c, structure.c, rotor_core.c). Not part of the
 * interface seen by the FMI wrappers.
 */
#ifndef CORE_INTERNAL_H
#define CORE_INTERNAL_H

#include <stdarg.h>

#include "rotor_core.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif
#define DEG2RAD (M_PI / 180.0)
#define RAD2DEG (180.0 / M_PI)

void core_logf(const RotorCore *core, int level, const char *fmt, ...);
/* Format and pass a message to log (if any): the one formatter of core and wrappers. */
void core_vlog(CoreLogger log, void *env, int level, const char *fmt, va_list ap);

/* ---- rotor_data.c ---------------------------------------------------------- */
int rotor_data_read(RotorData *data, const char *path, const RotorCore *core);
void rotor_data_free(RotorData *data);
void core_hat_weights(double x, const double *nodes, int n, int *k, double w[2]);

/* ---- aero.c ------------------------------------------------------------------ */
/* Local flow and geometry of one blade element. */
typedef struct {
    const RotorCore *core;
    int station;             /* station index */
    double r;                /* radius along the blade [m] */
    double chord;            /* [m] */
    double theta;            /* twist + pitch + pitch offset [rad] */
    double sigma_p;          /* local solidity B c / (2 pi r) [-] */
    double vx, vy;           /* axial and tangential velocity seen by the element [m/s] */
    double lambda_rotor;     /* Omega R / sqrt(V^2 + (Omega R)^2) (Du & Selig) [-] */
} Element;

/* Lift and drag coefficient with stall delay and correction field at alpha [rad]. */
void aero_coefficients(const Element *e, double alpha, double *cl, double *cd);

/* Quasi-steady BEM solution of one element (Ning 2014). Returns 0 when a bracketed
 * root was found, -1 otherwise (a = ap = 0 then). */
int aero_solve_element(const Element *e, double *phi, double *a, double *ap);

/* ---- inflow.c ---------------------------------------------------------------- */
/* Free-stream velocity components at station st of a blade at azimuth psi [rad]:
 * axial vx (normal to the coned blade) and in-plane tangential vy_wind (the
 * rotational parts are added by the caller). */
void inflow_wind(const RotorCore *core, double psi, int st, double *vx, double *vy_wind);

/* One Oye dynamic-inflow update of the axial induced velocity [m/s] over dt [s]. */
void inflow_oye_update(double *w, double *w_int, double w_qs, double w_qs_prev,
                       double dt, double radius_ratio, double rotor_radius, double wind_speed,
                       double axial_velocity);

/* Skewed-wake factor (>= 0) multiplying the axial induction in yaw. */
double inflow_skew_factor(const RotorCore *core, double psi, double r, double mean_induction);

/* ---- structure.c ------------------------------------------------------------- */
void structure_setup(RotorCore *core);
double structure_mass_per_length(const RotorCore *core, double r);
/* Modal accelerations from the generalized forces [N] of one blade. */
void structure_accelerations(const RotorCore *core, int blade, double force_flap,
                             double force_edge, double *qdd_flap, double *qdd_edge);
void structure_advance(RotorCore *core, double dt);
double structure_gravity(void);   /* [m/s^2] */

#endif
