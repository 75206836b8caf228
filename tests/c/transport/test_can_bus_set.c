/* The bus set (several buses, drives assigned to buses): SPEC[@DRIVES] parsing and validation,
 * and a live two-bus loopback check (UDP multicast on lo) that recv reports which bus a frame
 * came from, waiting on both at once. */
#define _GNU_SOURCE
#include <string.h>

#include "arm/can_bus.h"
#include "check.h"

#define N 6u

static int add(arm_can_bus_set_config_t *c, const char *arg, char *err, size_t cap)
{
    return arm_can_bus_set_add(c, arg, N, "--bus", err, cap);
}

/* A fresh configuration of bus a and, unless NULL, bus b, both of which must be accepted. */
static void config_of(arm_can_bus_set_config_t *c, const char *a, const char *b, char *err, size_t cap)
{
    arm_can_bus_set_config_init(c);
    CHECK(add(c, a, err, cap) == 0);
    if (b != NULL) CHECK(add(c, b, err, cap) == 0);
}

static void test_two_buses(void)
{
    char err[300];
    arm_can_bus_set_config_t c;
    config_of(&c, "socketcan:can0@1-3", "socketcan:can1@4,5,6", err, sizeof err);
    CHECK(c.n == 2u);
    CHECK(strcmp(c.spec[0], "socketcan:can0") == 0 && strcmp(c.spec[1], "socketcan:can1") == 0);
    CHECK(c.drive_mask[0] == 0x07u && c.drive_mask[1] == 0x38u);
    CHECK(arm_can_bus_set_check(&c, N, "--bus", err, sizeof err) == 0);
    for (unsigned j = 0; j < N; ++j) {
        CHECK(arm_can_bus_set_bus_of(&c, j) == (j < 3u ? 0 : 1));
    }
    CHECK(arm_can_bus_set_bus_of(&c, 6u) == -1);
}

static void test_without_drives_is_all(void)
{
    char err[300];
    arm_can_bus_set_config_t c;
    arm_can_bus_set_config_init(&c);
    CHECK(add(&c, "udp:239.74.163.2:43113", err, sizeof err) == 0);
    CHECK(c.drive_mask[0] == 0x3Fu && c.parsed[0].kind == ARM_BUS_UDP && c.parsed[0].port == 43113u);
    CHECK(arm_can_bus_set_check(&c, N, "--bus", err, sizeof err) == 0);
    arm_can_bus_set_config_init(&c);
    CHECK(add(&c, "udp@1-2,6", err, sizeof err) == 0 && c.drive_mask[0] == 0x23u);
}

static void expect_add_error(const char *first, const char *arg, const char *needle)
{
    char err[300] = "";
    arm_can_bus_set_config_t c;
    arm_can_bus_set_config_init(&c);
    if (first != NULL) CHECK(add(&c, first, err, sizeof err) == 0);
    const unsigned n = c.n;
    CHECK_MSG(add(&c, arg, err, sizeof err) == -1, "%s accepted", arg);
    CHECK(c.n == n);
    CHECK_MSG(strncmp(err, "--bus: ", 7) == 0 && strstr(err, needle) != NULL, "'%s' lacks '%s'", err, needle);
}

static void expect_check_error(const char *a, const char *b, const char *needle)
{
    char err[300] = "";
    arm_can_bus_set_config_t c;
    config_of(&c, a, b, err, sizeof err);
    CHECK(arm_can_bus_set_check(&c, N, "--bus", err, sizeof err) == -1);
    CHECK_MSG(strncmp(err, "--bus: ", 7) == 0 && strstr(err, needle) != NULL, "'%s' lacks '%s'", err, needle);
}

static void test_errors(void)
{
    expect_add_error(NULL, "can9@1-6", "unknown bus 'can9'");
    expect_add_error(NULL, "socketcan:@1-3", "interface name");
    expect_add_error(NULL, "udp@0-3", "drives '0-3'");
    expect_add_error(NULL, "udp@1-7", "drives '1-7'");
    expect_add_error(NULL, "udp@3-1", "drives '3-1'");
    expect_add_error(NULL, "udp@", "drives ''");
    expect_add_error(NULL, "udp@1,", "drives '1,'");
    expect_add_error(NULL, "udp@1-3x", "drives '1-3x'");
    expect_add_error("udp@1-3", "udp:239.74.163.2:43113@4-6", "given twice");
    expect_add_error("socketcan:vcan0@1-3", "socketcan:vcan0@4-6", "given twice");
    char err[300];
    arm_can_bus_set_config_t c;
    arm_can_bus_set_config_init(&c);
    CHECK(add(&c, "udp:239.74.163.2:1@1", err, sizeof err) == 0);
    CHECK(add(&c, "udp:239.74.163.2:2@2", err, sizeof err) == 0);
    CHECK(add(&c, "udp:239.74.163.2:3@3", err, sizeof err) == 0);
    CHECK(add(&c, "udp:239.74.163.2:4@4-6", err, sizeof err) == 0);
    CHECK(add(&c, "udp:239.74.163.2:5@5", err, sizeof err) == -1 && strstr(err, "at most 4 buses") != NULL);
    expect_check_error("socketcan:can0@1-4", "socketcan:can1@4-6",
                       "drive 4 is on two buses ('socketcan:can0' and 'socketcan:can1')");
    expect_check_error("socketcan:can0@1-3", NULL, "drive(s) 4,5,6 on no bus");
    expect_check_error("socketcan:can0@1-2", "socketcan:can1@4-5", "drive(s) 3,6 on no bus");
}

static arm_can_frame_t frame(uint32_t id)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.len = 1;
    f.data[0] = (uint8_t)id;
    return f;
}

/* Two UDP buses on lo, opened twice (two nodes): a frame one node sends on bus b arrives at the
 * other node on bus b, and never back at the sender. */
static void test_live_two_udp_buses(void)
{
    char err[300];
    arm_can_bus_set_config_t c;
    config_of(&c, "udp:239.74.163.2:43191@1-3", "udp:239.74.163.2:43192@4-6", err, sizeof err);
    static arm_can_bus_set_t tx, rx;
    if (arm_can_bus_set_open(&tx, &c, err, sizeof err) != 0 || arm_can_bus_set_open(&rx, &c, err, sizeof err) != 0) {
        CHECK_MSG(0, "open: %s", err);
        return;
    }
    arm_can_frame_t f = frame(0x101);
    CHECK(arm_can_bus_set_send(&tx, 1u, &f) == 0);
    f = frame(0x102);
    CHECK(arm_can_bus_set_send(&tx, 0u, &f) == 0);
    CHECK(arm_can_bus_set_send(&tx, 2u, &f) == ARM_BUS_E_INVALID);
    unsigned seen = 0u;
    for (int k = 0; k < 2; ++k) {
        unsigned idx = 9u;
        arm_can_frame_t r;
        CHECK(arm_can_bus_set_recv(&rx, &r, &idx, 500000) == 1);
        CHECK((r.id == 0x101 && idx == 1u) || (r.id == 0x102 && idx == 0u));
        seen |= 1u << idx;
    }
    CHECK(seen == 3u);
    unsigned idx = 9u;
    arm_can_frame_t r;
    CHECK(arm_can_bus_set_recv(&rx, &r, &idx, 20000) == 0); /* nothing left: times out */
    CHECK(arm_can_bus_set_recv(&tx, &r, &idx, 20000) == 0); /* and the sender heard no echo */
    arm_can_bus_set_close(&tx);
    arm_can_bus_set_close(&rx);
    CHECK(tx.n == 0u && rx.n == 0u);
}

static int idle_calls;
static arm_can_bus_set_t *idle_peer;

/* The drives' turn: answer each frame with one frame on the same line. */
static void answer_all(void *ctx)
{
    (void)ctx;
    idle_calls++;
    arm_can_frame_t f;
    unsigned bus = 0;
    while (arm_can_bus_set_recv(idle_peer, &f, &bus, 0) == 1) {
        f.id += 0x100u;
        CHECK(arm_can_bus_set_send(idle_peer, bus, &f) == 0);
    }
}

/* The in-process bus: one send order across lines, the idle hook on the master's receive, drops
 * when a queue is full, and no mixing with sockets. */
static void test_in_process_bus(void)
{
    char err[300];
    arm_can_bus_set_config_t c;
    config_of(&c, "mem:0@1-3", "mem:1@4-6", err, sizeof err);
    CHECK(add(&c, "mem:1@4-6", err, sizeof err) != 0 && strstr(err, "twice") != NULL);
    arm_can_mem_reset();
    static arm_can_bus_set_t master, drives;
    arm_can_mem_set_opening_side(ARM_CAN_MEM_DRIVES);
    CHECK(arm_can_bus_set_open(&drives, &c, err, sizeof err) == 0);
    arm_can_mem_set_opening_side(ARM_CAN_MEM_MASTER);
    CHECK(arm_can_bus_set_open(&master, &c, err, sizeof err) == 0);
    idle_peer = &drives;
    arm_can_mem_set_idle_hook(answer_all, NULL);
    const uint32_t ids[] = {0x80u, 0x81u, 0x82u, 0x83u};
    const unsigned lines[] = {1u, 0u, 1u, 0u};
    for (unsigned i = 0; i < 4u; ++i) {
        arm_can_frame_t f = {.id = ids[i], .len = 1u};
        CHECK(arm_can_bus_set_send(&master, lines[i], &f) == 0);
    }
    for (unsigned i = 0; i < 4u; ++i) { /* the answers, in the order the master sent: across lines */
        arm_can_frame_t f;
        unsigned bus = 9u;
        CHECK(arm_can_bus_set_recv(&master, &f, &bus, 1000) == 1);
        CHECK(f.id == ids[i] + 0x100u && bus == lines[i]);
    }
    CHECK(idle_calls == 1);
    arm_can_frame_t f;
    unsigned bus = 0;
    CHECK(arm_can_bus_set_recv(&master, &f, &bus, 1000) == 0 && idle_calls == 2); /* never waits */
    arm_can_mem_set_idle_hook(NULL, NULL);
    unsigned sent = 0;
    for (unsigned i = 0; i < ARM_CAN_MEM_QUEUE + 5u; ++i) {
        arm_can_frame_t g = {.id = 0x80u, .len = 1u};
        sent += arm_can_bus_set_send(&master, 0u, &g) == 0;
    }
    CHECK(sent == ARM_CAN_MEM_QUEUE); /* a full queue drops, as a full transmit queue does */
    arm_can_bus_set_close(&master);
    arm_can_bus_set_close(&drives);

    arm_can_bus_set_config_t mixed;
    arm_can_bus_set_config_init(&mixed);
    CHECK(add(&mixed, "mem:0@1-3", err, sizeof err) == 0);
    CHECK(add(&mixed, "udp:239.74.163.2:43119@4-6", err, sizeof err) == 0);
    static arm_can_bus_set_t m;
    CHECK(arm_can_bus_set_open(&m, &mixed, err, sizeof err) != 0 && strstr(err, "mixed") != NULL);
    CHECK(add(&mixed, "mem:4", err, sizeof err) != 0 && strstr(err, "mem:0 .. mem:3") != NULL);
}

int main(void)
{
    test_two_buses();
    test_without_drives_is_all();
    test_errors();
    test_live_two_udp_buses();
    test_in_process_bus();
    TEST_MAIN_END();
}
