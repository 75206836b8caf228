#include "sim_frames.h"

#include <math.h>
#include <string.h>

#include "arm_drive_ids.h"
#include "arm_drives.h"

static int index_of(const uint32_t *table, uint32_t id, int n)
{
    for (int i = 0; i < n; ++i) {
        if (table[i] == id) {
            return i;
        }
    }
    return -1;
}

int sim_cmd_joint(uint32_t id, int n)
{
    return index_of(ARM_DRIVE_CMD_ID, id, n);
}

int sim_is_drive_id(uint32_t id)
{
    return index_of(ARM_DRIVE_STATE_ID, id, ARM_DBC_MAX_DRIVES) >= 0 ||
           index_of(ARM_DRIVE_HEARTBEAT_ID, id, ARM_DBC_MAX_DRIVES) >= 0 ||
           index_of(ARM_DRIVE_EMCY_ID, id, ARM_DBC_MAX_DRIVES) >= 0;
}

uint32_t sim_state_id(int joint) { return ARM_DRIVE_STATE_ID[joint]; }
uint32_t sim_cmd_id(int joint) { return ARM_DRIVE_CMD_ID[joint]; }
uint32_t sim_heartbeat_id(int joint) { return ARM_DRIVE_HEARTBEAT_ID[joint]; }
uint32_t sim_emcy_id(int joint) { return ARM_DRIVE_EMCY_ID[joint]; }

/* value / scale rounded to the nearest step (ties to even, as a drive's register would round),
 * saturating at the signal's range; NaN reads as the most negative raw value. */
static int32_t to_raw(double value, double scale)
{
    if (isnan(value)) {
        return INT32_MIN;
    }
    const double raw = nearbyint(value / scale);
    if (raw >= 2147483647.0) return INT32_MAX;
    if (raw <= -2147483648.0) return INT32_MIN;
    return (int32_t)raw;
}

void sim_make_state(int joint, double q, double qd, double tau, uint16_t statusword, uint8_t counter,
                    uint8_t error_code, arm_can_frame_t *out)
{
    /* Every slot is laid out like drive 1 (gen/drive_ids.py checks it). */
    struct arm_drives_drive_1_state_t m;
    arm_drives_drive_1_state_init(&m);
    const double scale = arm_drives_drive_1_state_position_decode(1);
    m.position = to_raw(q, scale);
    m.velocity = to_raw(qd, arm_drives_drive_1_state_velocity_decode(1));
    m.torque = to_raw(tau, arm_drives_drive_1_state_torque_decode(1));
    m.statusword = statusword;
    m.sync_counter = counter;
    m.error_code = error_code;
    memset(out, 0, sizeof(*out));
    out->id = ARM_DRIVE_STATE_ID[joint];
    out->flags = ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS;
    out->len = (uint8_t)arm_drives_drive_1_state_pack(out->data, &m, sizeof(out->data));
}

void sim_make_heartbeat(int joint, uint8_t nmt_state, arm_can_frame_t *out)
{
    memset(out, 0, sizeof(*out));
    out->id = ARM_DRIVE_HEARTBEAT_ID[joint];
    out->len = ARM_DRIVES_DRIVE_1_HEARTBEAT_LENGTH;
    out->data[0] = nmt_state;
}

void sim_make_emcy(int joint, uint16_t error_code, uint8_t error_register, arm_can_frame_t *out)
{
    struct arm_drives_drive_1_emcy_t m;
    arm_drives_drive_1_emcy_init(&m);
    m.error_code = error_code;
    m.error_register = error_register;
    memset(out, 0, sizeof(*out));
    out->id = ARM_DRIVE_EMCY_ID[joint];
    out->len = (uint8_t)arm_drives_drive_1_emcy_pack(out->data, &m, sizeof(out->data));
}

void sim_make_identity(unsigned long long model_hash, int n_joints, arm_can_frame_t *out)
{
    struct arm_drives_sim_identity_t m;
    arm_drives_sim_identity_init(&m);
    m.model_hash = (uint32_t)model_hash;
    m.n_joints = (uint8_t)n_joints;
    m.protocol_version = 1u;
    memset(out, 0, sizeof(*out));
    out->id = ARM_DRIVES_SIM_IDENTITY_FRAME_ID;
    out->len = (uint8_t)arm_drives_sim_identity_pack(out->data, &m, sizeof(out->data));
}

int sim_decode_cmd(const arm_can_frame_t *f, uint16_t *controlword, double *torque, uint8_t *counter)
{
    struct arm_drives_drive_1_cmd_t m;
    if (f->len != ARM_DRIVES_DRIVE_1_CMD_LENGTH || arm_drives_drive_1_cmd_unpack(&m, f->data, f->len) != 0) {
        return -1;
    }
    *controlword = m.controlword;
    *torque = arm_drives_drive_1_cmd_target_torque_decode(m.target_torque);
    *counter = m.sync_counter;
    return 0;
}
