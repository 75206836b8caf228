#include "sim_canopen_od.h"

#include <string.h>

void sim_co_od_reset(sim_co_od_t *od, uint8_t node_id, int comm_only)
{
    od->node_id = node_id;
    for (unsigned i = 0; i < SIM_CO_OD_N; ++i) {
        const sim_co_entry_t *e = &SIM_CO_OD[i];
        if (comm_only && (e->index < 0x1000u || e->index > 0x1FFFu)) continue;
        od->value[i] = e->def + (e->nodeid_rel ? node_id : 0u);
    }
}

int sim_co_od_find(uint16_t index, uint8_t sub, uint32_t *abort_code)
{
    int seen_index = 0;
    for (unsigned i = 0; i < SIM_CO_OD_N; ++i) {
        if (SIM_CO_OD[i].index != index) continue;
        seen_index = 1;
        if (SIM_CO_OD[i].sub == sub) return (int)i;
    }
    *abort_code = seen_index ? SIM_CO_ABORT_NO_SUB : SIM_CO_ABORT_NO_OBJECT;
    return -1;
}

uint32_t sim_co_od_get(const sim_co_od_t *od, uint16_t index, uint8_t sub)
{
    uint32_t ab;
    const int i = sim_co_od_find(index, sub, &ab);
    return i < 0 ? 0u : od->value[i];
}

static int64_t as_signed(const sim_co_entry_t *e, uint32_t raw)
{
    switch (e->type) {
    case SIM_CO_T_I8: return (int8_t)(uint8_t)raw;
    case SIM_CO_T_I16: return (int16_t)(uint16_t)raw;
    case SIM_CO_T_I32: return (int32_t)raw;
    default: return (int64_t)raw;
    }
}

int32_t sim_co_od_get_signed(const sim_co_od_t *od, uint16_t index, uint8_t sub)
{
    uint32_t ab;
    const int i = sim_co_od_find(index, sub, &ab);
    return i < 0 ? 0 : (int32_t)as_signed(&SIM_CO_OD[i], od->value[i]);
}

void sim_co_od_set(sim_co_od_t *od, uint16_t index, uint8_t sub, uint32_t raw)
{
    uint32_t ab;
    const int i = sim_co_od_find(index, sub, &ab);
    if (i >= 0) od->value[i] = SIM_CO_OD[i].size >= 4u ? raw : raw & ((1u << (8u * SIM_CO_OD[i].size)) - 1u);
}

uint32_t sim_co_od_read(const sim_co_od_t *od, uint16_t index, uint8_t sub, uint8_t *buf, unsigned cap,
                        unsigned *len)
{
    uint32_t ab = 0;
    const int i = sim_co_od_find(index, sub, &ab);
    if (i < 0) return ab;
    const sim_co_entry_t *e = &SIM_CO_OD[i];
    if (e->access == SIM_CO_A_WO) return SIM_CO_ABORT_WRITE_ONLY;
    if (e->type == SIM_CO_T_VSTRING) {
        const size_t n = strlen(e->text);
        if (n > cap) return SIM_CO_ABORT_LENGTH;
        memcpy(buf, e->text, n);
        *len = (unsigned)n;
        return 0u;
    }
    if (e->size > cap) return SIM_CO_ABORT_LENGTH;
    for (unsigned k = 0; k < e->size; ++k) buf[k] = (uint8_t)(od->value[i] >> (8u * k));
    *len = e->size;
    return 0u;
}

uint32_t sim_co_od_check_write(uint16_t index, uint8_t sub, const uint8_t *data, unsigned len, uint32_t *raw)
{
    uint32_t ab = 0;
    const int i = sim_co_od_find(index, sub, &ab);
    if (i < 0) return ab;
    const sim_co_entry_t *e = &SIM_CO_OD[i];
    if (e->access == SIM_CO_A_RO || e->access == SIM_CO_A_CONST) return SIM_CO_ABORT_READ_ONLY;
    if (e->type == SIM_CO_T_VSTRING || len != e->size) return SIM_CO_ABORT_LENGTH;
    uint32_t v = 0;
    for (unsigned k = 0; k < len; ++k) v |= (uint32_t)data[k] << (8u * k);
    const int64_t x = as_signed(e, v);
    if ((e->has_low && x < e->low) || (e->has_high && x > e->high)) return SIM_CO_ABORT_RANGE;
    *raw = v;
    return 0u;
}
