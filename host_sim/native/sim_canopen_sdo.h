/* A CiA 301 SDO server: expedited and segmented upload and download (block transfers are answered
 * with abort 0x05040001). No I/O: one request frame in, at most one response out. The object
 * dictionary is reached through `access`, so the node decides what a write means. */
#ifndef ARM_SIM_CANOPEN_SDO_H
#define ARM_SIM_CANOPEN_SDO_H

#include <stdint.h>

#include "sim_canopen_od.h"

typedef struct {
    /* 0 or an abort code; read fills buf (at most cap bytes) and len. */
    uint32_t (*read)(void *ctx, uint16_t index, uint8_t sub, uint8_t *buf, unsigned cap, unsigned *len);
    uint32_t (*write)(void *ctx, uint16_t index, uint8_t sub, const uint8_t *data, unsigned len);
    /* 0 if (index, sub) exists, else the abort code: a segmented download is refused at its start */
    uint32_t (*exists)(void *ctx, uint16_t index, uint8_t sub);
    void *ctx;
} sim_co_sdo_access_t;

typedef enum { SIM_SDO_IDLE = 0, SIM_SDO_UPLOAD, SIM_SDO_DOWNLOAD } sim_co_sdo_state_t;

typedef struct {
    sim_co_sdo_state_t state;
    uint16_t index;
    uint8_t sub;
    uint8_t toggle;
    uint8_t buf[SIM_CO_VALUE_MAX];
    unsigned len;  /* bytes in buf */
    unsigned pos;  /* upload: bytes sent */
    unsigned size; /* download: bytes announced (0: not said) */
    uint64_t aborts_sent;
} sim_co_sdo_t;

void sim_co_sdo_init(sim_co_sdo_t *s);
/* One client->server frame (data, len); 1 with the server->client frame's 8 bytes in resp, 0 for
 * no answer (a client's abort). */
int sim_co_sdo_on_request(sim_co_sdo_t *s, const sim_co_sdo_access_t *a, const uint8_t *data, unsigned len,
                          uint8_t resp[8]);

#endif
