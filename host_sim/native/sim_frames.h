/* The drive side of the protocol (firmware/protocol/arm_drives.dbc): the frames a drive sends,
 * and the controller's commands decoded. Packing is cantools' generated code (arm_drives.c), the
 * same the controller uses; ids come from the DBC's drive slots (arm_drive_ids.h). */
#ifndef ARM_SIM_FRAMES_H
#define ARM_SIM_FRAMES_H

#include <stdint.h>

#include "arm/can_frame.h"

/* Joint index of a DRIVE_i_CMD id among n drives, or -1. */
int sim_cmd_joint(uint32_t id, int n);
/* 1 for an id a drive sends (STATE, HEARTBEAT, EMCY of any slot). */
int sim_is_drive_id(uint32_t id);
void sim_make_state(int joint, double q, double qd, double tau, uint16_t statusword, uint8_t counter,
                    uint8_t error_code, arm_can_frame_t *out);
void sim_make_heartbeat(int joint, uint8_t nmt_state, arm_can_frame_t *out);
void sim_make_emcy(int joint, uint16_t error_code, uint8_t error_register, arm_can_frame_t *out);
/* SIM_IDENTITY: the arm this simulator runs (its model hash, low 32 bits, and joint count). */
void sim_make_identity(unsigned long long model_hash, int n_joints, arm_can_frame_t *out);
/* 0 and the fields, or -1 for a frame that is not a well-formed command (wrong length). */
int sim_decode_cmd(const arm_can_frame_t *f, uint16_t *controlword, double *torque, uint8_t *counter);
uint32_t sim_state_id(int joint);
uint32_t sim_cmd_id(int joint);
uint32_t sim_heartbeat_id(int joint);
uint32_t sim_emcy_id(int joint);

#endif
