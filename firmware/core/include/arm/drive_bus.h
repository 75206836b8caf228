/* Bus master side of the drive protocol (firmware/protocol/arm_drives.dbc): builds the frames the
 * controller sends and validates and decodes the frames the drives send. No I/O here. */
#ifndef ARM_DRIVE_BUS_H
#define ARM_DRIVE_BUS_H

#include <stdint.h>

#include "arm/can_frame.h"
#include "arm/robot_model.h"

#define ARM_NMT_START 0x01u
#define ARM_NMT_STOP 0x02u
#define ARM_NMT_STATE_OPERATIONAL 0x05u

/* CiA 402 controlwords the controller uses. */
#define ARM_CW_DISABLE_VOLTAGE 0x0000u
#define ARM_CW_QUICK_STOP 0x0002u
#define ARM_CW_SHUTDOWN 0x0006u
#define ARM_CW_SWITCH_ON 0x0007u
#define ARM_CW_ENABLE_OPERATION 0x000Fu

static inline int arm_sw_operation_enabled(uint16_t sw)
{
    return (sw & 0x006Fu) == 0x0027u;
}

static inline int arm_sw_fault(uint16_t sw)
{
    return (sw & 0x004Fu) == 0x0008u;
}

/* The controlword that moves a drive one step towards operation enabled (CiA 402 device
 * control: switch on disabled -> ready to switch on -> switched on -> operation enabled).
 * A drive in fault is not reset automatically: that is an operator's decision. */
uint16_t arm_cia402_enable_controlword(uint16_t statusword);

typedef enum {
    ARM_RX_STATE = 0,      /* a joint state for the current period */
    ARM_RX_HEARTBEAT,
    ARM_RX_EMCY,
    ARM_RX_FOREIGN_MASTER, /* SYNC, NMT or a command from another node: only the master sends
                            * them, and no transport returns our own frames. Ignored */
    ARM_RX_UNKNOWN_ID,
    ARM_RX_BAD_LENGTH,
    ARM_RX_WRONG_COUNTER,  /* a state for another period (late or duplicated) */
    ARM_RX_BAD_FORMAT,     /* FD/classic or RTR/ERR flags do not match the definition */
    ARM_RX_SIM_IDENTITY,   /* HIL: the arm the simulator runs (its model hash and joint count) */
    ARM_RX_DUPLICATE_STATE, /* a second state of one drive for one SYNC: another node uses its id */
} arm_rx_kind_t;

typedef struct {
    uint32_t state;
    uint32_t heartbeat;
    uint32_t emcy;
    uint32_t foreign_master;
    uint32_t unknown_id;
    uint32_t bad_length;
    uint32_t wrong_counter;
    uint32_t bad_format;
    uint32_t sim_identity;
    uint32_t duplicate_state;
} arm_rx_counters_t;

typedef struct {
    uint8_t counter;    /* SYNC counter of the current period */
    uint32_t fresh_mask; /* bit i: joint i's state for this period arrived */
    float q[ARM_N_JOINTS];
    float qd[ARM_N_JOINTS];
    float tau_measured[ARM_N_JOINTS];
    uint16_t statusword[ARM_N_JOINTS];
    uint8_t drive_error[ARM_N_JOINTS];
    uint8_t nmt_state[ARM_N_JOINTS];
    uint32_t heartbeat_mask; /* bit i: drive i has sent a heartbeat since boot */
    uint16_t last_emcy_code[ARM_N_JOINTS];
    uint32_t emcy_mask;      /* bit i: drive i sent an EMCY since the port last cleared it */
    uint32_t duplicate_mask; /* bit i: drive i's state came twice this period */
    /* HIL: the simulator's SIM_IDENTITY, if one came (real drives never send it) */
    int sim_identity_seen;
    uint32_t sim_model_hash32;
    uint8_t sim_n_joints;
    arm_rx_counters_t rx;
    uint32_t foreign_master_seen; /* rx.foreign_master as of the last supervision */
} arm_drive_bus_t;

/* What the drives' frames of a period say about the bus, checked by arm_bus_supervise after the
 * period's states are in (every port runs the same supervision). */
typedef enum {
    ARM_BUS_WELL = 0,
    ARM_BUS_STATES_MISSING,  /* a drive's state did not come (joint: the first missing) */
    ARM_BUS_DRIVE_EMCY,      /* a drive reported a fault (value: its EMCY code) */
    ARM_BUS_DUPLICATE_STATE, /* a drive's state came twice for one SYNC: another node uses its id */
    ARM_BUS_FOREIGN_MASTER,  /* SYNC or commands this master did not send (value: how many) */
    ARM_BUS_LEFT_ENABLED,    /* a drive left operation enabled while running (value: statusword) */
} arm_bus_condition_t;

typedef struct {
    arm_bus_condition_t condition;
    int joint;       /* 0-based, -1 when it concerns no one drive */
    uint32_t value;
} arm_bus_fault_t;

/* The first thing wrong with this period's frames, in the order above (ARM_BUS_WELL: none).
 * require_all: every state must have come (lockstep: a missing one is a lost peer); running: the
 * drives should be operation enabled. Clears what it reported once (EMCY, foreign frames). */
arm_bus_fault_t arm_bus_supervise(arm_drive_bus_t *bus, int require_all, int running);
const char *arm_bus_condition_str(arm_bus_condition_t c);

void arm_bus_init(arm_drive_bus_t *bus);
/* Start period k: the returned SYNC carries k mod 256; states of other periods are rejected. */
void arm_bus_begin_period(arm_drive_bus_t *bus, uint32_t step, arm_can_frame_t *sync);
void arm_bus_make_nmt(uint8_t command, uint8_t node_id, arm_can_frame_t *out);
void arm_bus_make_cmd(const arm_drive_bus_t *bus, int joint, uint16_t controlword, float torque_nm,
                      arm_can_frame_t *out);
arm_rx_kind_t arm_bus_handle_rx(arm_drive_bus_t *bus, const arm_can_frame_t *frame);
/* Joint index of a drive frame's node, or -1. */
int arm_bus_joint_of(const arm_can_frame_t *frame);

#endif
