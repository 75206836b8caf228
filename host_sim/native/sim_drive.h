/* One emulated motor drive, as the bus sees it: a CANopen NMT node with a CiA 402 power state
 * machine, a torque limit (a command above it faults the drive: refused, not clamped) and a
 * command timeout. No I/O: the simulator loop feeds it the
 * controller's frames and sends what it asks for (heartbeats, EMCY). */
#ifndef ARM_SIM_DRIVE_H
#define ARM_SIM_DRIVE_H

#include <stdint.h>

#define SIM_NMT_START 0x01u
#define SIM_NMT_STOP 0x02u
#define SIM_NMT_STATE_BOOT 0x00u
#define SIM_NMT_STATE_STOPPED 0x04u
#define SIM_NMT_STATE_OPERATIONAL 0x05u
#define SIM_NMT_STATE_PRE_OPERATIONAL 0x7Fu

/* CiA 402 statuswords of the power states this drive has. */
typedef enum {
    SIM_PS_SWITCH_ON_DISABLED = 0x0250,
    SIM_PS_READY_TO_SWITCH_ON = 0x0231,
    SIM_PS_SWITCHED_ON = 0x0233,
    SIM_PS_OPERATION_ENABLED = 0x0237,
    SIM_PS_QUICK_STOP_ACTIVE = 0x0217,
    SIM_PS_FAULT = 0x0218,
} sim_power_t;

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
} sim_drive_t;

void sim_drive_init(sim_drive_t *d, uint8_t node_id, double torque_limit, uint32_t command_timeout_periods);
/* The transition a controlword causes (CiA 402 device control). quick_stop_option is 0x605A's
 * value: 0-4 a quick stop from operation enabled ends in switch on disabled, 5-8 the drive stays
 * in quick stop active (torque off either way: this drive stops at once). */
sim_power_t sim_cia402_next(sim_power_t state, uint16_t controlword, uint16_t prev_controlword,
                            int32_t quick_stop_option);
/* 0x605A of a drive without the object (the arm protocol's): disable the drive function. */
#define SIM_QUICK_STOP_DISABLE 0
/* Returns 1 if the NMT state changed (the caller then sends a heartbeat). */
int sim_drive_on_nmt(sim_drive_t *d, uint8_t command);
void sim_drive_on_command(sim_drive_t *d, uint16_t controlword, double torque);
/* Once per simulated period; a silent controller trips the drive into fault. */
void sim_drive_on_period_end(sim_drive_t *d, int got_command);
void sim_drive_fault(sim_drive_t *d, uint8_t error_code, uint16_t emcy_code);
double sim_drive_applied_torque(const sim_drive_t *d);

#endif
