/* An emulated drive's power stage, as servo drives run it (docs/runs.md "Safety behaviour"): the
 * CiA 402 states in which it is energised, its holding brake under automatic brake control, and
 * its own ramp to standstill (quick stop, fault reaction). Both emulated drives (sim_drive.c, the
 * arm protocol's; sim_canopen_node.c, the CiA 402 slave's) keep one per joint; the loop asks it,
 * once a period, for the torque it applies and the holding torque its brake has engaged.
 *
 * - Automatic brake control: the brake is engaged at power-on. On entering operation enabled the
 *   drive releases it and it opens after its release delay (meanwhile it holds and the drive
 *   already applies its target torque). When the drive leaves an energised state (operation
 *   enabled, quick stop active, fault reaction active) for one that is not, the brake is told to
 *   close and the power stage stays on for the closing delay, the drive holding standstill with
 *   its velocity loop; only then is the power stage off and the new state reported.
 * - Quick stop (0x605A): 0 the power stage off at once (the brake closes unpowered); 1 and 5 the
 *   slow-down ramp, 2 to 4 and 6 to 8 the quick stop ramp. In cyclic synchronous torque the drive
 *   ramps its VELOCITY to zero at the ramp's deceleration (0x6084, 0x6085) with its own velocity
 *   loop (proportional and integral), whose integrator starts at the torque the drive was applying
 *   (a loaded joint is not dropped while the loop takes over); the master's target torque is no
 *   longer applied (a master that has gone cannot leave a wrong one in force). At standstill, 1 to
 *   4 close the brake and end in switch on disabled, 5 to 8 stay in quick stop active, holding,
 *   until the master disables.
 * - Fault (0x605E): fault reaction active; 0 the power stage off at once, 1 the slow-down ramp,
 *   2 to 4 the quick stop ramp; then the brake closes and the drive reports fault.
 * - Power lost: the power stage is off at once; the brake is spring-applied and closes on its
 *   own after its closing delay.
 *
 * The velocity loop is tuned for the joint's inertia at the start pose (what a drive's autotune
 * measures): proportional 2 pi 25 Hz times it, integral corner 5 Hz. A joint without a brake
 * (holding torque 0) is free once its power stage is off. */
#ifndef ARM_SIM_POWER_STAGE_H
#define ARM_SIM_POWER_STAGE_H

#include <stdint.h>

/* CiA 402 statuswords of the power states the emulated drives have. */
typedef enum {
    SIM_PS_SWITCH_ON_DISABLED = 0x0250,
    SIM_PS_READY_TO_SWITCH_ON = 0x0231,
    SIM_PS_SWITCHED_ON = 0x0233,
    SIM_PS_OPERATION_ENABLED = 0x0237,
    SIM_PS_QUICK_STOP_ACTIVE = 0x0217,
    SIM_PS_FAULT_REACTION = 0x021F, /* fault reaction active: still energised */
    SIM_PS_FAULT = 0x0218,
} sim_power_t;

typedef struct {
    double holding_nm; /* the brake's holding torque at the joint; 0: no brake */
    double close_s;    /* brake closing delay (the power stage holds the joint meanwhile) */
    double release_s;  /* brake release delay */
} sim_brake_config_t;

typedef enum {
    SIM_BRAKE_ENGAGED = 0,
    SIM_BRAKE_RELEASING, /* told to open: still holding for the release delay */
    SIM_BRAKE_RELEASED,
    SIM_BRAKE_CLOSING,   /* told to close: still open for the closing delay */
} sim_brake_state_t;

typedef enum {
    SIM_STAGE_OFF = 0, /* no torque */
    SIM_STAGE_FOLLOW,  /* the target torque (operation enabled) */
    SIM_STAGE_RAMP,    /* the drive's own velocity loop, its reference ramping to zero, then holding */
} sim_stage_mode_t;

/* 0x605A quick stop and 0x605E fault reaction codes the emulated drive honours. */
#define SIM_QS_DISABLE 0
#define SIM_QS_SLOW_DOWN 1
#define SIM_QS_QUICK 2
#define SIM_FR_DISABLE 0
#define SIM_FR_SLOW_DOWN 1
#define SIM_FR_QUICK 2

typedef struct {
    sim_brake_config_t brake;
    double torque_limit;   /* N m: the drive's own torque never exceeds it */
    double kv, ki;         /* the velocity loop: N m s/rad, and 1/s of its integrator */
    sim_brake_state_t brake_state;
    double brake_timer_s;  /* left of the release or closing delay */
    sim_stage_mode_t mode;
    int powered_close;     /* closing with the power stage on (not a power loss or a disable at once) */
    sim_power_t after_close; /* the state the drive reports once the brake has closed */
    int stay_after_ramp;   /* quick stop 5..8: hold in quick stop active at standstill */
    int ramp_done;         /* the velocity reference reached zero and the joint stood still */
    int v_ref_pending;     /* the loop takes over next period: 1 ramping from its velocity, 2 at standstill */
    double v_ref;          /* rad/s */
    double decel;          /* rad/s^2 */
    double integ;          /* N m */
    double settle_s;       /* time at a zero reference */
    double last_nm;        /* the torque applied in the last period */
} sim_power_stage_t;

/* joint_inertia: kg m^2 at the joint (sim_arm_t.drive_inertia). The brake starts engaged. */
void sim_power_stage_init(sim_power_stage_t *ps, const sim_brake_config_t *brake, double torque_limit,
                          double joint_inertia);
/* The brake open from the start (the arm held by its drive as the run begins). */
void sim_power_stage_release_brake(sim_power_stage_t *ps);
/* The CiA 402 state machine moved the drive from *power to next (sim_cia402_next; a quick stop
 * entered with option qs_option and decelerations slow_down/quick, rad/s^2 at the joint; a ramp
 * starts from the velocity of the next period): the power stage follows, and *power becomes what
 * the drive reports (an energised state until the brake has closed). */
void sim_power_stage_transition(sim_power_stage_t *ps, sim_power_t *power, sim_power_t next, int qs_option,
                                double slow_down, double quick);
/* A fault: fault reaction active with reaction fr_option, then fault (reported at once if the
 * drive was not energised). */
void sim_power_stage_fault(sim_power_stage_t *ps, sim_power_t *power, int fr_option, double slow_down, double quick);
/* The power stage loses its supply: no torque from now on, the brake closes on its own. */
void sim_power_stage_power_lost(sim_power_stage_t *ps, sim_power_t *power);
/* One period of dt s: the torque the drive applies (target_nm in operation enabled; qd the joint's
 * velocity as the drive measures it); the delays run and *power takes the state the closing brake
 * held back. */
double sim_power_stage_period(sim_power_stage_t *ps, sim_power_t *power, double target_nm, double qd, double dt);
/* The holding torque the brake has engaged now (N m at the joint). */
double sim_power_stage_brake_nm(const sim_power_stage_t *ps);
/* Whether the power stage is on (an energised state, or holding while the brake closes). */
int sim_power_stage_energised(const sim_power_stage_t *ps);

#endif
