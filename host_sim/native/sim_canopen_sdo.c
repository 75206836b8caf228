#include "sim_canopen_sdo.h"

#include <string.h>

/* Command specifiers (bits 7..5 of byte 0), CiA 301 7.2.4.3. */
#define CCS_DOWNLOAD_SEGMENT 0u
#define CCS_INITIATE_DOWNLOAD 1u
#define CCS_INITIATE_UPLOAD 2u
#define CCS_UPLOAD_SEGMENT 3u
#define CCS_ABORT 4u

void sim_co_sdo_init(sim_co_sdo_t *s)
{
    memset(s, 0, sizeof(*s));
}

static void put_mux(uint8_t resp[8], uint16_t index, uint8_t sub)
{
    resp[1] = (uint8_t)index;
    resp[2] = (uint8_t)(index >> 8);
    resp[3] = sub;
}

static int abort_with(sim_co_sdo_t *s, uint16_t index, uint8_t sub, uint32_t code, uint8_t resp[8])
{
    memset(resp, 0, 8);
    resp[0] = 0x80u;
    put_mux(resp, index, sub);
    for (unsigned k = 0; k < 4u; ++k) resp[4 + k] = (uint8_t)(code >> (8u * k));
    s->state = SIM_SDO_IDLE;
    s->aborts_sent++;
    return 1;
}

static int initiate_upload(sim_co_sdo_t *s, const sim_co_sdo_access_t *a, uint16_t index, uint8_t sub,
                           uint8_t resp[8])
{
    unsigned n = 0;
    const uint32_t ab = a->read(a->ctx, index, sub, s->buf, sizeof(s->buf), &n);
    if (ab != 0u) return abort_with(s, index, sub, ab, resp);
    memset(resp, 0, 8);
    put_mux(resp, index, sub);
    if (n <= 4u && n > 0u) { /* expedited, size indicated */
        resp[0] = (uint8_t)(0x43u | ((4u - n) << 2));
        memcpy(&resp[4], s->buf, n);
        s->state = SIM_SDO_IDLE;
        return 1;
    }
    resp[0] = 0x41u; /* segmented, size indicated */
    for (unsigned k = 0; k < 4u; ++k) resp[4 + k] = (uint8_t)(n >> (8u * k));
    s->state = SIM_SDO_UPLOAD;
    s->index = index;
    s->sub = sub;
    s->len = n;
    s->pos = 0u;
    s->toggle = 0u;
    return 1;
}

static int upload_segment(sim_co_sdo_t *s, uint8_t cmd, uint8_t resp[8])
{
    if (s->state != SIM_SDO_UPLOAD) return abort_with(s, s->index, s->sub, SIM_CO_ABORT_COMMAND, resp);
    const uint8_t t = (uint8_t)((cmd >> 4) & 1u);
    if (t != s->toggle) return abort_with(s, s->index, s->sub, SIM_CO_ABORT_TOGGLE, resp);
    const unsigned left = s->len - s->pos;
    const unsigned k = left < 7u ? left : 7u;
    const unsigned last = s->pos + k == s->len;
    memset(resp, 0, 8);
    resp[0] = (uint8_t)((t << 4) | ((7u - k) << 1) | last);
    memcpy(&resp[1], &s->buf[s->pos], k);
    s->pos += k;
    s->toggle ^= 1u;
    if (last) s->state = SIM_SDO_IDLE;
    return 1;
}

static int initiate_download(sim_co_sdo_t *s, const sim_co_sdo_access_t *a, const uint8_t *d, uint16_t index,
                             uint8_t sub, uint8_t resp[8])
{
    const unsigned e = (d[0] >> 1) & 1u, sz = d[0] & 1u, n = (d[0] >> 2) & 3u;
    if (e) {
        const unsigned len = sz ? 4u - n : 4u;
        uint32_t ab = a->write(a->ctx, index, sub, &d[4], len);
        if (ab == SIM_CO_ABORT_LENGTH && !sz) { /* size not indicated: the object's own size, if shorter */
            for (unsigned l = 1u; l < 4u && ab == SIM_CO_ABORT_LENGTH; l *= 2u) ab = a->write(a->ctx, index, sub, &d[4], l);
        }
        if (ab != 0u) return abort_with(s, index, sub, ab, resp);
        memset(resp, 0, 8);
        resp[0] = 0x60u;
        put_mux(resp, index, sub);
        s->state = SIM_SDO_IDLE;
        return 1;
    }
    unsigned size = 0u;
    if (sz) {
        for (unsigned k = 0; k < 4u; ++k) size |= (unsigned)d[4 + k] << (8u * k);
        if (size > sizeof(s->buf)) return abort_with(s, index, sub, SIM_CO_ABORT_LENGTH, resp);
    }
    const uint32_t ab = a->exists(a->ctx, index, sub);
    if (ab != 0u) return abort_with(s, index, sub, ab, resp);
    s->state = SIM_SDO_DOWNLOAD;
    s->index = index;
    s->sub = sub;
    s->size = size;
    s->len = 0u;
    s->toggle = 0u;
    memset(resp, 0, 8);
    resp[0] = 0x60u;
    put_mux(resp, index, sub);
    return 1;
}

static int download_segment(sim_co_sdo_t *s, const sim_co_sdo_access_t *a, const uint8_t *d, uint8_t resp[8])
{
    if (s->state != SIM_SDO_DOWNLOAD) return abort_with(s, s->index, s->sub, SIM_CO_ABORT_COMMAND, resp);
    const uint8_t t = (uint8_t)((d[0] >> 4) & 1u);
    if (t != s->toggle) return abort_with(s, s->index, s->sub, SIM_CO_ABORT_TOGGLE, resp);
    const unsigned k = 7u - ((d[0] >> 1) & 7u), last = d[0] & 1u;
    if (s->len + k > sizeof(s->buf)) return abort_with(s, s->index, s->sub, SIM_CO_ABORT_LENGTH, resp);
    memcpy(&s->buf[s->len], &d[1], k);
    s->len += k;
    s->toggle ^= 1u;
    if (last) {
        if (s->size != 0u && s->len != s->size) return abort_with(s, s->index, s->sub, SIM_CO_ABORT_LENGTH, resp);
        const uint32_t ab = a->write(a->ctx, s->index, s->sub, s->buf, s->len);
        if (ab != 0u) return abort_with(s, s->index, s->sub, ab, resp);
        s->state = SIM_SDO_IDLE;
    }
    memset(resp, 0, 8);
    resp[0] = (uint8_t)(0x20u | (t << 4));
    return 1;
}

int sim_co_sdo_on_request(sim_co_sdo_t *s, const sim_co_sdo_access_t *a, const uint8_t *data, unsigned len,
                          uint8_t resp[8])
{
    uint8_t d[8] = {0};
    memcpy(d, data, len < 8u ? len : 8u);
    const uint16_t index = (uint16_t)(d[1] | (d[2] << 8));
    const uint8_t sub = d[3];
    if (len != 8u) return abort_with(s, index, sub, SIM_CO_ABORT_COMMAND, resp); /* CiA 301: SDOs are 8 bytes */
    switch (d[0] >> 5) {
    case CCS_INITIATE_UPLOAD: return initiate_upload(s, a, index, sub, resp);
    case CCS_UPLOAD_SEGMENT: return upload_segment(s, d[0], resp);
    case CCS_INITIATE_DOWNLOAD: return initiate_download(s, a, d, index, sub, resp);
    case CCS_DOWNLOAD_SEGMENT: return download_segment(s, a, d, resp);
    case CCS_ABORT: s->state = SIM_SDO_IDLE; return 0;
    default: return abort_with(s, index, sub, SIM_CO_ABORT_COMMAND, resp); /* block transfers, unknown */
    }
}
