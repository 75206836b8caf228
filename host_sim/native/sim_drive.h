/* One emulated motor drive, as the bus sees it: a CANopen NMT node with a CiA 402 power state
 * machine, a torque limit (a command above it faults the drive: refused, not clamped) and a
 * command timeout. No I/O: the simulator loop feeds it the
 * controller's frames and sends what it asks for (heartbeats, EMCY). */
#ifndef ARM_SIM_DRIVE_H
#define ARM_SIM_DRIVE_H

#include <stdint.h>

#include "sim_power_stage.h"

#define SIM_NMT_START 0x01u
#define SIM_NMT_STOP 0x02u
#define SIM_NMT_STATE_BOOT 0x00u
#define SIM_NMT_STATE_STOPPED 0x04u
#define SIM_NMT_STATE_OPERATIONAL 0x05u
#define SIM_NMT_STATE_PRE_OPERATIONAL 0x7Fu


#define SIM_EMCY_RPDO_TIMEOUT 0x8250u /* CiA 301: RPDO timeout */
#define SIM_EMCY_HEARTBEAT 0x8130u    /* CiA 301: life guard / heartbeat error */
#define SIM_ERR_NONE 0u
#define SIM_ERR_COMMAND_TIMEOUT 1u
#define SIM_ERR_CONTROLLER_LOST 5u
#define SIM_ERR_DIVERGED 2u
#define SIM_EMCY_DIVERGED 0xFF00u /* CiA 301: manufacturer specific (the simulated arm blew up) */
#define SIM_ERR_TORQUE_ABOVE_LIMIT 3u
#define SIM_EMCY_TORQUE_LIMIT 0x8300u /* CiA 402: torque control (a command above the drive's limit) */
#define SIM_TORQUE_TOLERANCE 2e-6      /* Nm: the wire's 1 uNm resolution, rounded either way */
#define SIM_ERR_TWO_MASTERS 4u
#define SIM_EMCY_PROTOCOL 0x8200u     /* CiA 301: protocol error (two commands for one SYNC) */
#define SIM_ERR_SYNC_SEQUENCE 6u      /* a SYNC that does not continue its master's sequence: another master */
#define SIM_EMCY_QUEUE 4u

typedef struct {
    uint8_t node_id;
    double torque_limit;
    uint32_t command_timeout_periods;
    uint8_t nmt_state;
    sim_power_t power;
    uint16_t controlword;
    double target_torque;
    uint32_t periods_without_command;
    uint8_t error_code;
    uint16_t emcy_pending[SIM_EMCY_QUEUE];
    unsigned n_emcy_pending;
    uint64_t commands_received;
    uint64_t commands_missed;
    sim_power_stage_t ps;    /* its power stage: brake, quick stop, fault reaction (sim_power_stage.h) */
    double quick_stop_decel; /* rad/s^2 at the joint: its quick stop and fault reaction ramps */
} sim_drive_t;

/* A drive without a brake that stops at once (quick stop deceleration 0: no ramp), until
 * sim_drive_set_stopping. */
void sim_drive_init(sim_drive_t *d, uint8_t node_id, double torque_limit, uint32_t command_timeout_periods);
/* Its brake, the joint's inertia its velocity loop is tuned for, and its quick stop deceleration
 * (rad/s^2; its quick stop is 0x605A option 2 and its fault reaction 0x605E option 2). */
void sim_drive_set_stopping(sim_drive_t *d, const sim_brake_config_t *brake, double joint_inertia,
                            double quick_stop_decel);
/* The transition a controlword causes (CiA 402 device control). quick_stop_option is 0x605A's
 * value: 0 a quick stop from operation enabled disables the drive function at once (switch on
 * disabled), 1-8 enter quick stop active, where the power stage ramps (sim_power_stage.h). Fault
 * and fault reaction active are left by a fault reset only, from fault. */
sim_power_t sim_cia402_next(sim_power_t state, uint16_t controlword, uint16_t prev_controlword,
                            int32_t quick_stop_option);
/* Returns 1 if the NMT state changed (the caller then sends a heartbeat). An energised drive that
 * is stopped by NMT quick-stops (CiA 402's abort connection, option 3). */
int sim_drive_on_nmt(sim_drive_t *d, uint8_t command);
void sim_drive_on_command(sim_drive_t *d, uint16_t controlword, double torque);
/* Once per simulated period; a silent controller trips the drive into fault. */
void sim_drive_on_period_end(sim_drive_t *d, int got_command);
void sim_drive_fault(sim_drive_t *d, uint8_t error_code, uint16_t emcy_code);
/* One period of dt s of the power stage at joint velocity qd: the torque the drive applies. */
double sim_drive_period(sim_drive_t *d, double qd, double dt);
/* The torque the drive applied in its last period (what it reports). */
double sim_drive_applied_torque(const sim_drive_t *d);

#endif
