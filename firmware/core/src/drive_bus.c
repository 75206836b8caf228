#include "arm/drive_bus.h"

#include <string.h>

#include "arm_drive_ids.h" /* every drive slot's frame ids, from the DBC (gen/drive_ids.py) */
#include "arm_drives.h"    /* generated from firmware/protocol/arm_drives.dbc by cantools */

#if ARM_N_JOINTS > ARM_DBC_MAX_DRIVES
#error "the arm has more joints than arm_drives.dbc has drive slots: add slots to the DBC"
#endif

/* Every drive's frames share one layout in the DBC (gen/drive_ids.py checks it), but the
 * generated code has one struct per drive; the id tables keep the lookups data-driven. */
#define k_state_id ARM_DRIVE_STATE_ID
#define k_cmd_id ARM_DRIVE_CMD_ID
#define k_hb_id ARM_DRIVE_HEARTBEAT_ID
#define k_emcy_id ARM_DRIVE_EMCY_ID
/* CiA 301: emergency error code 0x0000 is "error reset or no error", a drive's all-clear after a
 * fault reset (python-canopen's EmcyProducer.reset sends it): no fault. */
#define EMCY_NO_ERROR 0x0000u

static int index_of(const uint32_t *table, uint32_t id)
{
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        if (table[i] == id) {
            return i;
        }
    }
    return -1;
}

int arm_bus_joint_of(const arm_can_frame_t *frame)
{
    int j = index_of(k_state_id, frame->id);
    if (j < 0) j = index_of(k_cmd_id, frame->id);
    if (j < 0) j = index_of(k_hb_id, frame->id);
    if (j < 0) j = index_of(k_emcy_id, frame->id);
    return j;
}

void arm_bus_init(arm_drive_bus_t *bus)
{
    memset(bus, 0, sizeof(*bus));
}

void arm_bus_begin_period(arm_drive_bus_t *bus, uint32_t step, arm_can_frame_t *sync)
{
    struct arm_drives_sync_t msg;
    bus->counter = (uint8_t)(step & 0xFFu);
    bus->fresh_mask = 0u;
    bus->duplicate_mask = 0u;
    memset(sync, 0, sizeof(*sync));
    arm_drives_sync_init(&msg);
    msg.counter = bus->counter;
    sync->id = ARM_DRIVES_SYNC_FRAME_ID;
    sync->len = (uint8_t)arm_drives_sync_pack(sync->data, &msg, sizeof(sync->data));
}

void arm_bus_make_nmt(uint8_t command, uint8_t node_id, arm_can_frame_t *out)
{
    struct arm_drives_nmt_t msg;
    memset(out, 0, sizeof(*out));
    arm_drives_nmt_init(&msg);
    msg.command = command;
    msg.node_id = node_id;
    out->id = ARM_DRIVES_NMT_FRAME_ID;
    out->len = (uint8_t)arm_drives_nmt_pack(out->data, &msg, sizeof(out->data));
}

void arm_bus_make_cmd(const arm_drive_bus_t *bus, int joint, uint16_t controlword, float torque_nm,
                      arm_can_frame_t *out)
{
    /* Identical layout for every drive (checked by the protocol tests): pack with drive 1's code. */
    struct arm_drives_drive_1_cmd_t msg;
    memset(out, 0, sizeof(*out));
    arm_drives_drive_1_cmd_init(&msg);
    msg.controlword = controlword;
    /* The generated encoder truncates toward zero; round to the nearest step instead so the
     * quantisation error is at most half a step and unbiased. */
    const double want = (double)torque_nm;
    const double step = arm_drives_drive_1_cmd_target_torque_decode(1) -
                        arm_drives_drive_1_cmd_target_torque_decode(0);
    int32_t raw = arm_drives_drive_1_cmd_target_torque_encode(want);
    const double residual = want - arm_drives_drive_1_cmd_target_torque_decode(raw);
    if (residual >= 0.5 * step) {
        raw += 1;
    } else if (residual <= -0.5 * step) {
        raw -= 1;
    }
    msg.target_torque = raw;
    msg.sync_counter = bus->counter;
    out->id = k_cmd_id[joint];
    out->len = (uint8_t)arm_drives_drive_1_cmd_pack(out->data, &msg, sizeof(out->data));
}

static arm_rx_kind_t handle_state(arm_drive_bus_t *bus, int j, const arm_can_frame_t *f)
{
    struct arm_drives_drive_1_state_t msg;
    if ((f->flags & ARM_CAN_FLAG_FD) == 0u) {
        bus->rx.bad_format++;
        return ARM_RX_BAD_FORMAT;
    }
    if (f->len != ARM_DRIVES_DRIVE_1_STATE_LENGTH ||
        arm_drives_drive_1_state_unpack(&msg, f->data, f->len) != 0) {
        bus->rx.bad_length++;
        return ARM_RX_BAD_LENGTH;
    }
    if (msg.sync_counter != bus->counter) {
        bus->rx.wrong_counter++;
        return ARM_RX_WRONG_COUNTER;
    }
    if ((bus->fresh_mask & (1u << j)) != 0u) {
        /* A drive answers a SYNC once: a second state is another node using its id. The first
         * stands; the port decides (it stops the arm). */
        bus->duplicate_mask |= 1u << j;
        bus->rx.duplicate_state++;
        return ARM_RX_DUPLICATE_STATE;
    }
    bus->q[j] = (float)arm_drives_drive_1_state_position_decode(msg.position);
    bus->qd[j] = (float)arm_drives_drive_1_state_velocity_decode(msg.velocity);
    bus->tau_measured[j] = (float)arm_drives_drive_1_state_torque_decode(msg.torque);
    bus->statusword[j] = msg.statusword;
    bus->drive_error[j] = msg.error_code;
    bus->fresh_mask |= 1u << j;
    bus->rx.state++;
    return ARM_RX_STATE;
}

arm_rx_kind_t arm_bus_handle_rx(arm_drive_bus_t *bus, const arm_can_frame_t *f)
{
    if ((f->flags & (ARM_CAN_FLAG_RTR | ARM_CAN_FLAG_ERR | ARM_CAN_FLAG_EXT)) != 0u) {
        bus->rx.bad_format++;
        return ARM_RX_BAD_FORMAT;
    }
    int j = index_of(k_state_id, f->id);
    if (j >= 0) {
        return handle_state(bus, j, f);
    }
    j = index_of(k_hb_id, f->id);
    if (j >= 0) {
        if (f->len != ARM_DRIVES_DRIVE_1_HEARTBEAT_LENGTH) {
            bus->rx.bad_length++;
            return ARM_RX_BAD_LENGTH;
        }
        bus->nmt_state[j] = f->data[0];
        bus->heartbeat_mask |= 1u << j;
        bus->rx.heartbeat++;
        return ARM_RX_HEARTBEAT;
    }
    j = index_of(k_emcy_id, f->id);
    if (j >= 0) {
        if (f->len != ARM_DRIVES_DRIVE_1_EMCY_LENGTH) {
            bus->rx.bad_length++;
            return ARM_RX_BAD_LENGTH;
        }
        bus->last_emcy_code[j] = (uint16_t)(f->data[0] | (uint16_t)(f->data[1] << 8));
        if (bus->last_emcy_code[j] != EMCY_NO_ERROR) {
            bus->emcy_mask |= 1u << j;
        }
        bus->rx.emcy++;
        return ARM_RX_EMCY;
    }
    if (f->id == ARM_DRIVES_SIM_IDENTITY_FRAME_ID) {
        struct arm_drives_sim_identity_t id;
        if (f->len != ARM_DRIVES_SIM_IDENTITY_LENGTH || arm_drives_sim_identity_unpack(&id, f->data, f->len) != 0) {
            bus->rx.bad_length++;
            return ARM_RX_BAD_LENGTH;
        }
        bus->sim_identity_seen = 1;
        bus->sim_model_hash32 = id.model_hash;
        bus->sim_n_joints = id.n_joints;
        bus->rx.sim_identity++;
        return ARM_RX_SIM_IDENTITY;
    }
    if (f->id == ARM_DRIVES_SYNC_FRAME_ID || f->id == ARM_DRIVES_NMT_FRAME_ID ||
        index_of(k_cmd_id, f->id) >= 0) {
        bus->rx.foreign_master++;
        return ARM_RX_FOREIGN_MASTER;
    }
    bus->rx.unknown_id++;
    return ARM_RX_UNKNOWN_ID;
}

uint16_t arm_cia402_enable_controlword(uint16_t sw)
{
    if ((sw & 0x004Fu) == 0x0040u) { /* switch on disabled */
        return ARM_CW_SHUTDOWN;
    }
    if ((sw & 0x006Fu) == 0x0021u) { /* ready to switch on */
        return ARM_CW_SWITCH_ON;
    }
    if ((sw & 0x006Fu) == 0x0023u || arm_sw_operation_enabled(sw)) {
        return ARM_CW_ENABLE_OPERATION;
    }
    return ARM_CW_SHUTDOWN; /* fault or unknown: keep the power stage off */
}

static int first_joint(uint32_t mask)
{
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        if ((mask & (1u << j)) != 0u) return j;
    }
    return -1;
}

arm_bus_fault_t arm_bus_supervise(arm_drive_bus_t *bus, int require_all, int running)
{
    const uint32_t all = (uint32_t)((1ull << ARM_N_JOINTS) - 1u);
    const uint32_t fresh = bus->fresh_mask & all;
    arm_bus_fault_t f = {ARM_BUS_WELL, -1, 0u};
    const uint32_t foreign = bus->rx.foreign_master - bus->foreign_master_seen;
    bus->foreign_master_seen = bus->rx.foreign_master;
    const uint32_t emcy = bus->emcy_mask & all;
    bus->emcy_mask = 0u;
    uint32_t left = 0u;
    for (int j = 0; j < ARM_N_JOINTS && running; ++j) {
        if ((fresh & (1u << j)) != 0u && !arm_sw_operation_enabled(bus->statusword[j])) left |= 1u << j;
    }
    if (require_all && fresh != all) {
        f = (arm_bus_fault_t){ARM_BUS_STATES_MISSING, first_joint(all & ~fresh), 0u};
    } else if (emcy != 0u) {
        const int j = first_joint(emcy);
        f = (arm_bus_fault_t){ARM_BUS_DRIVE_EMCY, j, bus->last_emcy_code[j]};
    } else if ((bus->duplicate_mask & all) != 0u) {
        f = (arm_bus_fault_t){ARM_BUS_DUPLICATE_STATE, first_joint(bus->duplicate_mask & all), 0u};
    } else if (foreign != 0u) {
        f = (arm_bus_fault_t){ARM_BUS_FOREIGN_MASTER, -1, foreign};
    } else if (left != 0u) {
        const int j = first_joint(left);
        f = (arm_bus_fault_t){ARM_BUS_LEFT_ENABLED, j, bus->statusword[j]};
    }
    return f;
}

const char *arm_bus_condition_str(arm_bus_condition_t c)
{
    switch (c) {
    case ARM_BUS_WELL: return "well";
    case ARM_BUS_STATES_MISSING: return "joint states missing";
    case ARM_BUS_DRIVE_EMCY: return "a drive reports a fault";
    case ARM_BUS_DUPLICATE_STATE: return "a drive's state came twice for one SYNC";
    case ARM_BUS_FOREIGN_MASTER: return "another master on the bus";
    case ARM_BUS_LEFT_ENABLED: return "a drive left operation enabled";
    }
    return "?";
}
