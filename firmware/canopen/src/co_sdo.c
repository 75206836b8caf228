/* CiA 301 SDO client (arm/co_sdo.h). Command specifiers, byte 0 of every SDO frame:
 *   client: 1 initiate download, 0 download segment, 2 initiate upload, 3 upload segment, 4 abort
 *   server: 3 initiate download response, 1 download segment response, 2 initiate upload response,
 *           0 upload segment response, 4 abort */
#include "arm/co_sdo.h"

#include <stddef.h>

#define CS(b) ((uint8_t)((b) >> 5))

static void put_u32(uint8_t *p, uint32_t v)
{
    for (unsigned i = 0; i < 4u; ++i) {
        p[i] = (uint8_t)(v >> (8u * i));
    }
}

static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static void frame(arm_co_sdo_t *c, uint8_t b0)
{
    arm_can_frame_t *f = &c->tx;
    f->id = ARM_CO_COB_SDO_RX + c->node;
    f->len = 8u;
    f->flags = 0u;
    for (unsigned i = 0; i < 8u; ++i) {
        f->data[i] = 0u;
    }
    f->data[0] = b0;
    f->data[1] = (uint8_t)(c->index & 0xFFu);
    f->data[2] = (uint8_t)(c->index >> 8);
    f->data[3] = c->sub;
    c->tx_pending = 1u;
}

/* The initiate request of a new try. */
static void initiate(arm_co_sdo_t *c, uint64_t now_us)
{
    c->tries = (uint8_t)(c->tries + 1u);
    c->toggle = 0u;
    c->pos = 0u;
    c->segmented = 0u;
    if (c->upload) {
        c->len = 0u;
        frame(c, 0x40u);
    } else if (c->len <= 4u) {
        frame(c, (uint8_t)(0x23u | ((4u - c->len) << 2)));
        for (uint32_t i = 0; i < c->len; ++i) {
            c->tx.data[4u + i] = c->data[i];
        }
    } else {
        frame(c, 0x21u);
        put_u32(&c->tx.data[4], c->len);
    }
    c->deadline_us = now_us + c->timeout_us;
}

static void client_abort(arm_co_sdo_t *c, uint32_t code)
{
    frame(c, 0x80u);
    put_u32(&c->tx.data[4], code);
    c->abort_code = code;
    c->abort_by_server = 0u;
    c->status = ARM_CO_SDO_ABORTED;
}

static void download_segment(arm_co_sdo_t *c, uint64_t now_us)
{
    uint32_t n = c->len - c->pos;
    if (n > 7u) {
        n = 7u;
    }
    const uint8_t last = (c->pos + n == c->len) ? 1u : 0u;
    frame(c, (uint8_t)(((uint32_t)c->toggle << 4) | ((7u - n) << 1) | last));
    for (uint32_t i = 0; i < n; ++i) {
        c->tx.data[1u + i] = c->data[c->pos + i];
    }
    for (uint32_t i = n; i < 7u; ++i) {
        c->tx.data[1u + i] = 0u;
    }
    c->deadline_us = now_us + c->timeout_us;
}

static void upload_segment_request(arm_co_sdo_t *c, uint64_t now_us)
{
    frame(c, (uint8_t)(0x60u | ((uint32_t)c->toggle << 4)));
    for (unsigned i = 1; i < 8u; ++i) {
        c->tx.data[i] = 0u;
    }
    c->deadline_us = now_us + c->timeout_us;
}

void arm_co_sdo_init(arm_co_sdo_t *c, uint8_t node, uint32_t timeout_us, uint8_t max_tries)
{
    *c = (arm_co_sdo_t){0};
    c->node = node;
    c->timeout_us = timeout_us;
    c->max_tries = max_tries ? max_tries : 1u;
    c->status = ARM_CO_SDO_IDLE;
}

static int start(arm_co_sdo_t *c, uint16_t index, uint8_t sub, uint8_t upload)
{
    if (c->status == ARM_CO_SDO_BUSY) {
        return -1;
    }
    c->status = ARM_CO_SDO_BUSY;
    c->upload = upload;
    c->index = index;
    c->sub = sub;
    c->tries = 0u;
    c->abort_code = 0u;
    c->abort_by_server = 0u;
    return 0;
}

int arm_co_sdo_download(arm_co_sdo_t *c, uint16_t index, uint8_t sub, const uint8_t *data, uint32_t len,
                        uint64_t now_us)
{
    if (c->status == ARM_CO_SDO_BUSY || data == NULL || len == 0u || len > ARM_CO_SDO_BUF) {
        return -1;
    }
    (void)start(c, index, sub, 0u);
    for (uint32_t i = 0; i < len; ++i) {
        c->data[i] = data[i];
    }
    c->len = len;
    initiate(c, now_us);
    return 0;
}

int arm_co_sdo_upload(arm_co_sdo_t *c, uint16_t index, uint8_t sub, uint64_t now_us)
{
    if (start(c, index, sub, 1u) != 0) {
        return -1;
    }
    initiate(c, now_us);
    return 0;
}

static int mux_matches(const arm_co_sdo_t *c, const uint8_t *d)
{
    return (uint16_t)(d[1] | (d[2] << 8)) == c->index && d[3] == c->sub;
}

/* An initiate answer (upload 2, download 3: they name their object) that is not the one awaited
 * now: the answer to an earlier request that came after its try timed out, once the retry's own
 * answer (or the next transfer) was under way. The server answers every request in order, so the
 * awaited answer still comes; taking the late one for a wrong answer would fail a sound transfer. */
static int stale_answer(arm_co_sdo_t *c, const uint8_t *d)
{
    const uint8_t cs = CS(d[0]);
    const int awaited = !c->segmented && cs == (c->upload ? 2u : 3u) && mux_matches(c, d);
    if ((cs == 2u || cs == 3u) && !awaited) {
        c->stale++;
        return 1;
    }
    return 0;
}

static void on_upload(arm_co_sdo_t *c, const uint8_t *d, uint64_t now_us)
{
    const uint8_t cs = CS(d[0]);
    if (!c->segmented) {
        if (cs != 2u) {
            client_abort(c, ARM_CO_ABORT_COMMAND);
            return;
        }
        if (d[0] & 0x02u) { /* expedited: n unused bytes when the size is indicated */
            const uint32_t n = (d[0] & 0x01u) ? 4u - ((d[0] >> 2) & 0x03u) : 4u;
            for (uint32_t i = 0; i < n; ++i) {
                c->data[i] = d[4u + i];
            }
            c->len = n;
            c->status = ARM_CO_SDO_DONE;
            return;
        }
        if ((d[0] & 0x01u) && get_u32(&d[4]) > ARM_CO_SDO_BUF) {
            client_abort(c, ARM_CO_ABORT_NO_MEMORY);
            return;
        }
        c->segmented = 1u;
        c->len = 0u;
        upload_segment_request(c, now_us);
        return;
    }
    if (cs != 0u) {
        client_abort(c, ARM_CO_ABORT_COMMAND);
        return;
    }
    if (((d[0] >> 4) & 1u) != c->toggle) {
        client_abort(c, ARM_CO_ABORT_TOGGLE);
        return;
    }
    const uint32_t n = 7u - ((d[0] >> 1) & 0x07u);
    if (c->len + n > ARM_CO_SDO_BUF) {
        client_abort(c, ARM_CO_ABORT_NO_MEMORY);
        return;
    }
    for (uint32_t i = 0; i < n; ++i) {
        c->data[c->len + i] = d[1u + i];
    }
    c->len += n;
    if (d[0] & 0x01u) {
        c->status = ARM_CO_SDO_DONE;
        return;
    }
    c->toggle ^= 1u;
    upload_segment_request(c, now_us);
}

static void on_download(arm_co_sdo_t *c, const uint8_t *d, uint64_t now_us)
{
    const uint8_t cs = CS(d[0]);
    if (!c->segmented) {
        if (cs != 3u) {
            client_abort(c, ARM_CO_ABORT_COMMAND);
            return;
        }
        if (c->len <= 4u) {
            c->status = ARM_CO_SDO_DONE;
            return;
        }
        c->segmented = 1u;
        download_segment(c, now_us);
        return;
    }
    if (cs != 1u) {
        client_abort(c, ARM_CO_ABORT_COMMAND);
        return;
    }
    if (((d[0] >> 4) & 1u) != c->toggle) {
        client_abort(c, ARM_CO_ABORT_TOGGLE);
        return;
    }
    uint32_t n = c->len - c->pos;
    c->pos += n > 7u ? 7u : n;
    if (c->pos == c->len) {
        c->status = ARM_CO_SDO_DONE;
        return;
    }
    c->toggle ^= 1u;
    download_segment(c, now_us);
}

int arm_co_sdo_rx(arm_co_sdo_t *c, const arm_can_frame_t *f, uint64_t now_us)
{
    if (f->id != ARM_CO_COB_SDO_TX + c->node || (f->flags & (ARM_CAN_FLAG_EXT | ARM_CAN_FLAG_RTR |
                                                              ARM_CAN_FLAG_ERR)) != 0u) {
        return 0;
    }
    if (c->status != ARM_CO_SDO_BUSY) {
        return 1; /* late answer to a finished transfer (a retry's twin): ours, nothing to do */
    }
    if (f->len != 8u) {
        client_abort(c, ARM_CO_ABORT_COMMAND);
        return 1;
    }
    const uint8_t *d = f->data;
    if (CS(d[0]) == 4u) {
        c->abort_code = get_u32(&d[4]);
        c->abort_by_server = 1u;
        c->status = ARM_CO_SDO_ABORTED;
        return 1;
    }
    if (stale_answer(c, d)) {
        return 1;
    }
    if (c->upload) {
        on_upload(c, d, now_us);
    } else {
        on_download(c, d, now_us);
    }
    return 1;
}

void arm_co_sdo_tick(arm_co_sdo_t *c, uint64_t now_us)
{
    if (c->status != ARM_CO_SDO_BUSY || now_us < c->deadline_us) {
        return;
    }
    if (c->tries < c->max_tries) {
        initiate(c, now_us);
        return;
    }
    client_abort(c, ARM_CO_ABORT_TIMEOUT);
    c->status = ARM_CO_SDO_TIMEOUT;
}

int arm_co_sdo_take_tx(arm_co_sdo_t *c, arm_can_frame_t *out)
{
    if (!c->tx_pending) {
        return 0;
    }
    *out = c->tx;
    c->tx_pending = 0u;
    return 1;
}

uint32_t arm_co_sdo_u32(const arm_co_sdo_t *c)
{
    uint32_t v = 0u;
    for (uint32_t i = 0; i < c->len && i < 4u; ++i) {
        v |= (uint32_t)c->data[i] << (8u * i);
    }
    return v;
}

const char *arm_co_abort_text(uint32_t code)
{
    switch (code) {
    case ARM_CO_ABORT_TOGGLE: return "toggle bit not alternated";
    case ARM_CO_ABORT_TIMEOUT: return "SDO protocol timed out";
    case ARM_CO_ABORT_COMMAND: return "command specifier not valid or unknown";
    case ARM_CO_ABORT_NO_MEMORY: return "out of memory";
    case ARM_CO_ABORT_WRITE_ONLY: return "attempt to read a write-only object";
    case ARM_CO_ABORT_READ_ONLY: return "attempt to write a read-only object";
    case ARM_CO_ABORT_NO_OBJECT: return "object does not exist";
    case ARM_CO_ABORT_LENGTH: return "data type length does not match";
    case ARM_CO_ABORT_NO_SUB: return "sub-index does not exist";
    case ARM_CO_ABORT_RANGE: return "value range of parameter exceeded";
    case ARM_CO_ABORT_STATE: return "data cannot be transferred in the present device state";
    case 0x06040041u: return "object cannot be mapped to the PDO";
    case 0x06040042u: return "the number and length of the objects to be mapped would exceed the PDO length";
    case 0x08000000u: return "general error";
    case 0x08000020u: return "data cannot be transferred or stored";
    case 0x06010000u: return "unsupported access to an object";
    default: return "";
    }
}
