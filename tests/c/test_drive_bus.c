/* The bus master's frame building and validation (frames from firmware/protocol/arm_drives.dbc). */
#include <string.h>

#include "arm/drive_bus.h"
#include "check.h"

static arm_can_frame_t state_frame(int joint, uint8_t counter, int32_t pos_urad)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof(f));
    f.id = 0x181u + (uint32_t)joint;
    f.len = 16u;
    f.flags = ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS;
    memcpy(f.data, &pos_urad, 4); /* little-endian host, as the DBC's @1 byte order */
    f.data[12] = 0x37;
    f.data[13] = 0x02;
    f.data[14] = counter;
    return f;
}

int main(void)
{
    arm_drive_bus_t bus;
    arm_can_frame_t sync;
    arm_bus_init(&bus);
    arm_bus_begin_period(&bus, 300u, &sync);
    CHECK(sync.id == 0x80u && sync.len == 1u && sync.data[0] == (uint8_t)(300u & 0xFFu));

    arm_can_frame_t f = state_frame(2, bus.counter, 1234567);
    CHECK(arm_bus_handle_rx(&bus, &f) == ARM_RX_STATE);
    CHECK(bus.fresh_mask == (1u << 2));
    CHECK(bus.q[2] > 1.2345f && bus.q[2] < 1.2346f);
    CHECK(bus.statusword[2] == 0x0237u);

    f = state_frame(3, (uint8_t)(bus.counter + 1u), 0);
    CHECK(arm_bus_handle_rx(&bus, &f) == ARM_RX_WRONG_COUNTER);
    f = state_frame(3, bus.counter, 0);
    f.len = 12u;
    CHECK(arm_bus_handle_rx(&bus, &f) == ARM_RX_BAD_LENGTH);
    f = state_frame(3, bus.counter, 0);
    f.flags = 0u;
    CHECK(arm_bus_handle_rx(&bus, &f) == ARM_RX_BAD_FORMAT);
    f.id = 0x3FFu;
    f.flags = ARM_CAN_FLAG_FD;
    CHECK(arm_bus_handle_rx(&bus, &f) == ARM_RX_UNKNOWN_ID);
    CHECK(bus.fresh_mask == (1u << 2)); /* none of the bad frames counted as fresh */
    CHECK(bus.rx.wrong_counter == 1u && bus.rx.bad_length == 1u && bus.rx.bad_format == 1u &&
          bus.rx.unknown_id == 1u);

    /* A SYNC, NMT or command from another node (a second master on the bus: no transport returns
     * our own frames) is recognised and ignored, not counted as unknown. */
    CHECK(arm_bus_handle_rx(&bus, &sync) == ARM_RX_FOREIGN_MASTER);

    arm_can_frame_t cmd;
    arm_bus_make_cmd(&bus, 4, ARM_CW_ENABLE_OPERATION, -12.34567f, &cmd);
    CHECK(cmd.id == 0x205u && cmd.len == 8u);
    int32_t raw;
    memcpy(&raw, &cmd.data[2], 4);
    CHECK(raw == -12345670); /* rounded to the nearest uNm (float32 input), not truncated */
    CHECK(cmd.data[0] == 0x0Fu && cmd.data[6] == bus.counter);

    arm_can_frame_t hb;
    memset(&hb, 0, sizeof(hb));
    hb.id = 0x706u;
    hb.len = 1u;
    hb.data[0] = ARM_NMT_STATE_OPERATIONAL;
    CHECK(arm_bus_handle_rx(&bus, &hb) == ARM_RX_HEARTBEAT);
    CHECK(bus.heartbeat_mask == (1u << 5) && bus.nmt_state[5] == ARM_NMT_STATE_OPERATIONAL);

    /* EMCY: a fault, except 0x0000, CiA 301's "error reset or no error" */
    arm_can_frame_t emcy;
    memset(&emcy, 0, sizeof(emcy));
    emcy.id = 0x82u;
    emcy.len = 8u;
    CHECK(arm_bus_handle_rx(&bus, &emcy) == ARM_RX_EMCY && bus.emcy_mask == 0u && bus.rx.emcy == 1u);
    emcy.data[0] = 0x10u;
    emcy.data[1] = 0x23u;
    emcy.data[2] = 0x01u;
    CHECK(arm_bus_handle_rx(&bus, &emcy) == ARM_RX_EMCY && bus.emcy_mask == (1u << 1));
    CHECK(bus.last_emcy_code[1] == 0x2310u && bus.rx.emcy == 2u);
    bus.emcy_mask = 0u;

    /* HIL: the simulator's SIM_IDENTITY (0x7F0) is read, and a malformed one is not believed. */
    arm_can_frame_t id;
    memset(&id, 0, sizeof(id));
    id.id = 0x7F0u;
    id.len = 7u;
    CHECK(arm_bus_handle_rx(&bus, &id) == ARM_RX_BAD_LENGTH && !bus.sim_identity_seen);
    id.len = 8u;
    const uint32_t hash = 0x93ddabb3u;
    memcpy(id.data, &hash, 4);
    id.data[4] = 7u;
    id.data[5] = 1u;
    CHECK(arm_bus_handle_rx(&bus, &id) == ARM_RX_SIM_IDENTITY);
    CHECK(bus.sim_identity_seen && bus.sim_model_hash32 == hash && bus.sim_n_joints == 7u && bus.rx.sim_identity == 1u);
    TEST_MAIN_END();
}
