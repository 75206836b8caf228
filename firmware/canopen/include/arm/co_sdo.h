/* A CiA 301 SDO client for one server node: expedited and segmented upload and download, one
 * transfer at a time, no I/O. The port feeds it the frames it receives (arm_co_sdo_rx) and the time
 * (arm_co_sdo_tick), and sends what arm_co_sdo_take_tx hands it. No heap: a transfer carries at
 * most ARM_CO_SDO_BUF bytes.
 *
 * Timeouts: a whole transfer is one try. When the server does not answer within timeout_us the
 * transfer starts over from its initiate request (a segment cannot be repeated in CiA 301), up to
 * max_tries; after the last one the client sends abort 0x05040000 and ends with ARM_CO_SDO_TIMEOUT.
 * A server abort ends the transfer at once (ARM_CO_SDO_ABORTED, no retry: the answer is an answer)
 * with its code kept; a response the client cannot accept (wrong index, toggle, specifier, size)
 * is aborted by the client with the CiA 301 code, kept the same way. */
#ifndef ARM_CO_SDO_H
#define ARM_CO_SDO_H

#include <stdint.h>

#include "arm/can_frame.h"

#define ARM_CO_SDO_BUF 64u /* the largest object one transfer carries (segmented) */

#define ARM_CO_COB_SDO_TX 0x580u /* server -> client, + node id */
#define ARM_CO_COB_SDO_RX 0x600u /* client -> server, + node id */

/* CiA 301 abort codes the contract names. */
#define ARM_CO_ABORT_TOGGLE 0x05030000u
#define ARM_CO_ABORT_TIMEOUT 0x05040000u
#define ARM_CO_ABORT_COMMAND 0x05040001u
#define ARM_CO_ABORT_NO_MEMORY 0x05040005u
#define ARM_CO_ABORT_WRITE_ONLY 0x06010001u
#define ARM_CO_ABORT_READ_ONLY 0x06010002u
#define ARM_CO_ABORT_NO_OBJECT 0x06020000u
#define ARM_CO_ABORT_LENGTH 0x06070010u
#define ARM_CO_ABORT_NO_SUB 0x06090011u
#define ARM_CO_ABORT_RANGE 0x06090030u
#define ARM_CO_ABORT_STATE 0x08000022u

typedef enum {
    ARM_CO_SDO_IDLE = 0,  /* no transfer yet */
    ARM_CO_SDO_BUSY,      /* a transfer is under way */
    ARM_CO_SDO_DONE,      /* the last transfer succeeded (upload: data/len hold the value) */
    ARM_CO_SDO_ABORTED,   /* the server aborted, or the client aborted a bad response */
    ARM_CO_SDO_TIMEOUT,   /* no answer after max_tries tries */
} arm_co_sdo_status_t;

typedef struct {
    uint8_t node;          /* server node id 1..127 */
    uint32_t timeout_us;   /* per request */
    uint8_t max_tries;     /* tries of a whole transfer, >= 1 */
    /* the transfer */
    arm_co_sdo_status_t status;
    uint8_t upload;        /* 1: upload (read), 0: download (write) */
    uint8_t segmented;     /* the current try moves segments */
    uint8_t toggle;
    uint8_t tries;         /* tries started */
    uint16_t index;
    uint8_t sub;
    uint32_t abort_code;   /* ARM_CO_SDO_ABORTED / _TIMEOUT: the CiA 301 code */
    uint8_t abort_by_server; /* ARM_CO_SDO_ABORTED: 1 the server aborted, 0 the client did */
    uint8_t data[ARM_CO_SDO_BUF];
    uint32_t len;          /* download: bytes to send; upload: bytes received */
    uint32_t pos;          /* bytes moved so far in the segmented phase */
    uint64_t deadline_us;  /* the current request's answer is due by then */
    uint32_t stale;        /* initiate answers to an earlier request (a retry's twin), ignored */
    uint8_t tx_pending;
    arm_can_frame_t tx;
} arm_co_sdo_t;

void arm_co_sdo_init(arm_co_sdo_t *c, uint8_t node, uint32_t timeout_us, uint8_t max_tries);
/* Starts a transfer; -1 if one is under way, len is 0 or above ARM_CO_SDO_BUF. len <= 4 goes
 * expedited, longer segmented. */
int arm_co_sdo_download(arm_co_sdo_t *c, uint16_t index, uint8_t sub, const uint8_t *data, uint32_t len,
                        uint64_t now_us);
int arm_co_sdo_upload(arm_co_sdo_t *c, uint16_t index, uint8_t sub, uint64_t now_us);
/* A received frame; returns 1 if it was this client's server answering, else 0 (not ours). */
int arm_co_sdo_rx(arm_co_sdo_t *c, const arm_can_frame_t *f, uint64_t now_us);
/* Timeouts and retries. */
void arm_co_sdo_tick(arm_co_sdo_t *c, uint64_t now_us);
/* The frame to send, if one is due (1), else 0. */
int arm_co_sdo_take_tx(arm_co_sdo_t *c, arm_can_frame_t *out);
/* An uploaded value of up to 4 bytes, little-endian, zero-extended. */
uint32_t arm_co_sdo_u32(const arm_co_sdo_t *c);
/* A short English text of a CiA 301 abort code ("" if unknown). */
const char *arm_co_abort_text(uint32_t code);

#endif
