/* One CAN or CAN FD frame as the core and every transport see it. */
#ifndef ARM_CAN_FRAME_H
#define ARM_CAN_FRAME_H

#include <stdint.h>

#define ARM_CAN_MAX_DATA 64u

#define ARM_CAN_FLAG_FD 0x01u  /* CAN FD frame (len may exceed 8) */
#define ARM_CAN_FLAG_BRS 0x02u /* FD bit-rate switch */
#define ARM_CAN_FLAG_EXT 0x04u /* 29-bit identifier */
#define ARM_CAN_FLAG_ESI 0x08u /* FD error state indicator */
#define ARM_CAN_FLAG_RTR 0x10u /* classic remote frame */
#define ARM_CAN_FLAG_ERR 0x20u /* error frame */

typedef struct {
    uint32_t id;    /* 11-bit, or 29-bit with ARM_CAN_FLAG_EXT */
    uint8_t len;    /* payload bytes: 0..8 classic, one of 0..8,12,16,20,24,32,48,64 FD */
    uint8_t flags;  /* ARM_CAN_FLAG_* */
    uint8_t data[ARM_CAN_MAX_DATA];
} arm_can_frame_t;

#endif
