/*
 * rotor_core.h -- FMI-independent core of the calib aeroelastic rotor model.
 *
 * The core holds everything physical: blade-element aerodynamics on tabulated polars
 * with the additive correction field of calib.corrections, the per-element BEM
 * (Ning 2014) quasi-steady induction, Oye dynamic inflow, azimuth-resolved inflow
 * (power-law shear, yaw, potential-flow tower shadow), stall delay, and a modal
 * flap/edge model of every blade.  The FMI 2.0 / 3.0 wrappers (variant_a, variant_b)
 * only translate value references, units and calling conventions.
 *
 * There is no global mutable state: every instance owns a RotorCore.  All state that
 * evolves in time lives in fixed-size members of RotorCore (no pointers), so an FMU
 * state is a plain copy of core->dyn (see core_copy_dynamic).
 *
 * Variables are addressed by a CoreVar id and an element index (node, blade or output
 * station).  Angles are degrees and rotor speed rpm at this interface; all other
 * quantities are SI.
 */
#ifndef ROTOR_CORE_H
#define ROTOR_CORE_H

#include <stddef.h>

#define CORE_MAX_BLADES 3
#define CORE_MAX_STATIONS 96
#define CORE_MAX_NODES 512       /* lift nodes (= drag nodes) of the correction grid */
#define CORE_MAX_AXIS_NODES 64   /* nodes along alpha or eta */
#define CORE_MAX_OUT_STATIONS 16
/* Internal sub-steps allowed in one core_do_step: a longer communication step is refused
 * (bounded run time per call; at the default 0.02 s internal step, 200 s of simulation). */
#define CORE_MAX_SUBSTEPS 10000

/* Variable ids of the core.  The build script (calib/fmu/build.py) parses this enum:
 * keep one id per line, spelled CV_<NAME>. */
typedef enum {
    /* inputs */
    CV_WIND_SPEED = 0,          /* hub-height free-stream wind speed [m/s] */
    CV_ROTOR_SPEED_RPM,         /* rotor speed [rpm] */
    CV_PITCH_DEG,               /* collective pitch [deg], positive toward feather */
    CV_AIR_DENSITY,             /* [kg/m^3] */
    CV_YAW_DEG,                 /* yaw misalignment [deg] */
    /* tunable parameters */
    CV_DCL,                     /* lift correction node value [-], index = lift node */
    CV_DCD,                     /* drag correction node value [-], index = drag node */
    CV_PITCH_OFFSET_DEG,        /* per-blade pitch offset [deg], index = blade */
    CV_STALL_DELAY_STRENGTH,    /* multiplier of the stall-delay increment [-] */
    /* fixed parameters */
    CV_TIP_LOSS,                /* switch 0/1: Prandtl tip loss */
    CV_HUB_LOSS,                /* switch 0/1: Prandtl hub loss */
    CV_TOWER_SHADOW,            /* switch 0/1: potential-flow tower shadow */
    CV_SHEAR,                   /* switch 0/1: power-law shear */
    CV_SHEAR_EXPONENT,          /* power-law exponent [-] */
    CV_YAW_EFFECTS,             /* switch 0/1: yaw misalignment acts (else yaw input ignored) */
    CV_SKEWED_WAKE,             /* switch 0/1: Glauert/Pitt-Peters skewed-wake correction */
    CV_DYNAMIC_INFLOW,          /* switch 0/1: Oye dynamic inflow (0: quasi-steady) */
    CV_STALL_DELAY_MODEL,       /* 0 off, 1 Snel, 2 Du & Selig */
    CV_FLEXIBLE,                /* switch 0/1: modal blade flexibility */
    CV_GRAVITY,                 /* switch 0/1: blade weight in the edgewise loads */
    CV_FLAP_FREQUENCY_HZ,       /* first flap natural frequency [Hz] */
    CV_EDGE_FREQUENCY_HZ,       /* first edge natural frequency [Hz] */
    CV_FLAP_DAMPING_RATIO,      /* structural damping ratio [-] */
    CV_EDGE_DAMPING_RATIO,      /* structural damping ratio [-] */
    CV_BLADE_MASS,              /* blade mass [kg] */
    CV_TOWER_HEIGHT,            /* tower-top height [m] */
    CV_TOWER_BASE_DIAMETER,     /* [m] */
    CV_TOWER_TOP_DIAMETER,      /* [m] */
    CV_TOWER_CLEARANCE,         /* rotor-plane to tower-axis distance at hub height [m] */
    CV_SHAFT_TILT_DEG,          /* shaft tilt [deg] */
    CV_N_BLADES,                /* 2 or 3 */
    CV_MAX_STEP,                /* largest internal step [s] */
    CV_MAX_AZIMUTH_STEP_DEG,    /* largest azimuth increment per internal step [deg] */
    CV_INITIAL_AZIMUTH_DEG,     /* azimuth of blade 1 at the start time [deg] */
    CV_DEBUG_FAULT,             /* TEST ONLY: fault injected by doStep: 0 none, 1 error, 2 abort, 3 hang */
    CV_DEBUG_FAULT_WIND_SPEED,  /* TEST ONLY: the fault fires only while wind speed > this [m/s] */
    /* outputs */
    CV_POWER,                   /* aerodynamic power [W] */
    CV_TORQUE,                  /* aerodynamic torque [N m] */
    CV_THRUST,                  /* rotor thrust [N] */
    CV_AZIMUTH_DEG,             /* blade-1 azimuth [deg], 0 = up, in [0, 360) */
    CV_ROOT_FLAP_MOMENT,        /* per blade [N m], positive downwind */
    CV_ROOT_EDGE_MOMENT,        /* per blade [N m], positive in the rotation direction */
    CV_TIP_FLAP_DEFLECTION,     /* per blade [m] */
    CV_TIP_EDGE_DEFLECTION,     /* per blade [m] */
    CV_NORMAL_FORCE,            /* blade-1 normal force per length at output station k [N/m] */
    CV_ANGLE_OF_ATTACK,         /* blade-1 angle of attack at output station k [deg] */
    CV_OUT_STATION_RADIUS,      /* radius of output station k [m] */
    CV_TIP_RADIUS,              /* rotor (tip) radius of the rotor data [m] */
    CV_AERO_FAILURES,           /* element solves without a bracketed root so far [-] */
    CV_COUNT
} CoreVar;

/* Logging callback: level 0 info, 1 warning, 2 error. */
typedef void (*CoreLogger)(void *env, int level, const char *message);

/* Immutable rotor data read from resources/rotor.dat. */
typedef struct {
    char name[64];
    int n_blades_data;
    double hub_radius, tip_radius, precone_deg, tilt_deg, hub_height;
    int n_stations;
    double r[CORE_MAX_STATIONS], chord[CORE_MAX_STATIONS], twist_deg[CORE_MAX_STATIONS];
    double alpha0_deg[CORE_MAX_STATIONS];   /* zero-lift angle (stall delay) [deg] */
    /* blade axis in the azimuthal frame (CCBlade conventions, precone/precurve/presweep) */
    double x_az[CORE_MAX_STATIONS], y_az[CORE_MAX_STATIONS], z_az[CORE_MAX_STATIONS];
    double cone[CORE_MAX_STATIONS];         /* local cone angle [rad] */
    /* trapezoid weights along the blade path, zero load at hub and tip (as the native BEM):
     * per-blade thrust = sum w_thrust N', torque = sum w_torque T', root moments
     * = sum w_root N' (T'), generalized forces = sum ds phi N' (T') */
    double ds[CORE_MAX_STATIONS], w_thrust[CORE_MAX_STATIONS], w_torque[CORE_MAX_STATIONS];
    double w_root[CORE_MAX_STATIONS];
    int n_polar;                            /* points of the uniform polar grid */
    double alpha_start_deg, alpha_step_deg;
    double *cl, *cd;                        /* n_stations x n_polar, row-major (owned) */
    int n_alpha_nodes, n_eta_nodes;
    double alpha_nodes_deg[CORE_MAX_AXIS_NODES], eta_nodes[CORE_MAX_AXIS_NODES];
    int n_out;                              /* output stations */
    int out_station[CORE_MAX_OUT_STATIONS];
    /* spanwise correction weights per station (eta is fixed per station) */
    int eta_index[CORE_MAX_STATIONS];
    double eta_weight[CORE_MAX_STATIONS][2];
} RotorData;

/* Parameters (set before or, for tunables, during the simulation). */
typedef struct {
    double dcl[CORE_MAX_NODES], dcd[CORE_MAX_NODES];
    double pitch_offset_deg[CORE_MAX_BLADES];
    double stall_strength;
    double tip_loss, hub_loss, tower_shadow, shear, shear_exponent, yaw_effects, skewed_wake;
    double dynamic_inflow, stall_model, flexible, gravity;
    double flap_freq_hz, edge_freq_hz, flap_damping, edge_damping, blade_mass;
    double tower_height, tower_base_d, tower_top_d, tower_clearance, shaft_tilt_deg;
    double n_blades, max_step, max_azimuth_step_deg, initial_azimuth_deg;
    double debug_fault, debug_fault_wind_speed;   /* test-only fault injection (see CV_DEBUG_FAULT) */
} CoreParams;

typedef struct {
    double wind_speed, rotor_speed_rpm, pitch_deg, air_density, yaw_deg;
} CoreInputs;

/* Everything that evolves: a plain value type (copyable with memcpy). */
typedef struct {
    CoreParams par;
    CoreInputs in;
    int initialized;
    double time;
    double azimuth;                                     /* blade 1 [rad] */
    /* Oye filter states per blade and element: induced axial velocity [m/s] */
    double w[CORE_MAX_BLADES][CORE_MAX_STATIONS];
    double w_int[CORE_MAX_BLADES][CORE_MAX_STATIONS];
    double w_qs_prev[CORE_MAX_BLADES][CORE_MAX_STATIONS];
    /* modal coordinates (0 flap, 1 edge) [m] and rates [m/s] */
    double q[CORE_MAX_BLADES][2], qd[CORE_MAX_BLADES][2];
    /* results of the last evaluation at the current state */
    double w_qs[CORE_MAX_BLADES][CORE_MAX_STATIONS];
    double fn[CORE_MAX_BLADES][CORE_MAX_STATIONS];      /* normal force [N/m] */
    double ft[CORE_MAX_BLADES][CORE_MAX_STATIONS];      /* tangential force [N/m] */
    double aoa[CORE_MAX_BLADES][CORE_MAX_STATIONS];     /* [rad] */
    double qdd[CORE_MAX_BLADES][2];
    double power, torque, thrust;
    double flap_moment[CORE_MAX_BLADES], edge_moment[CORE_MAX_BLADES];
    double aero_failures;
} CoreDynamic;

/* Derived structural constants (recomputed at initialization). */
typedef struct {
    double gen_mass;          /* int m phi^2 dr [kg] */
    double mass_phi;          /* int m phi dr [kg] */
    double mass_phi_arm;      /* int m phi (r - Rh) dr [kg m] */
    double mass_arm;          /* int m (r - Rh) dr [kg m] */
    double phi[CORE_MAX_STATIONS];
} CoreStructure;

typedef struct {
    RotorData data;
    CoreDynamic dyn;
    CoreStructure st;
    CoreLogger log;
    void *log_env;
} RotorCore;

/* Create an instance from a resources directory (ending with or without '/').
 * Returns NULL and logs the reason on failure. Parameters are zero: the wrapper
 * applies the start values of its model description. */
RotorCore *core_create(const char *resource_dir, CoreLogger log, void *log_env);
void core_free(RotorCore *core);

/* Back to the state after core_create (parameters kept as they are). */
void core_reset_state(RotorCore *core);

/* Number of elements of a variable (1, blades, nodes or output stations). */
int core_var_size(const RotorCore *core, CoreVar var);

/* 0 on success, -1 on bad id/index (logged). */
int core_get(const RotorCore *core, CoreVar var, int index, double *value);
int core_set(RotorCore *core, CoreVar var, int index, double value);

/* Exit initialization: check parameters, compute derived constants and start in
 * quasi-steady equilibrium at start_time. 0 on success, -1 on error (logged). */
int core_initialize(RotorCore *core, double start_time);

/* Advance by h [s] with at most CORE_MAX_SUBSTEPS internal sub-steps. Returns 0 on
 * success, CORE_STEP_REFUSED (nothing changed: bad h, inputs, too many sub-steps) or
 * CORE_STEP_FAILED (non-finite loads part-way: the state is unusable); logged. */
#define CORE_STEP_REFUSED (-1)
#define CORE_STEP_FAILED (-2)
int core_do_step(RotorCore *core, double h);

/* Could dyn (e.g. from a serialized FMU state) have been produced by this core? Every
 * number finite, flags and counts valid, the number of blades 2 or 3, and, once
 * initialized, the parameter and input checks of core_initialize. 0 if so, else -1
 * (logged). The wrapper checks the variables' ranges (fmu_slave.c). */
int core_check_dynamic(const RotorCore *core, const CoreDynamic *dyn);

/* Replace the dynamic part by dyn (checked) and recompute what derives from it. */
void core_restore_dynamic(RotorCore *core, const CoreDynamic *dyn);

#endif
