/* Live check of the SocketCAN transport on a real (v)can interface:
 *   can_socketcan_selftest IFACE
 * Two buses on IFACE: classic, FD, 29-bit and remote frames cross the kernel unchanged; a bus
 * does not hear itself; recv honours its timeout; frames the transport cannot represent are
 * counted and skipped; a flood the receiver does not read shows up as kernel drops, not as a
 * blocked sender. Needs a kernel with CAN (tests/python/test_vcan_vm.py runs it in the VM). */
#define _GNU_SOURCE
#include <errno.h>
#include <net/if.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <linux/can/raw.h>

#include "arm/can_bus.h"
#include "arm/can_socketcan.h"
#include "check.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static arm_can_frame_t frame(uint32_t id, uint8_t len, uint8_t flags)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.len = len;
    f.flags = flags;
    if ((flags & ARM_CAN_FLAG_RTR) == 0u) {
        for (unsigned i = 0; i < len; ++i) {
            f.data[i] = (uint8_t)(i * 7u + 1u);
        }
    }
    return f;
}

static int same(const arm_can_frame_t *a, const arm_can_frame_t *b)
{
    return a->id == b->id && a->len == b->len && a->flags == b->flags &&
           memcmp(a->data, b->data, sizeof a->data) == 0;
}

/* A raw socket writing what our transport refuses to, as a misbehaving node would. */
static int raw_write(const char *ifname, const void *buf, size_t n)
{
    const int fd = socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (fd < 0) {
        return -1;
    }
    int on = 1;
    (void)setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on);
    struct sockaddr_can addr;
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = (int)if_nametoindex(ifname);
    int rc = bind(fd, (struct sockaddr *)&addr, sizeof addr);
    if (rc == 0) {
        rc = write(fd, buf, n) == (ssize_t)n ? 0 : -1;
    }
    close(fd);
    return rc;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s IFACE\n", argv[0]);
        return 2;
    }
    const char *ifname = argv[1];
    char spec[64];
    snprintf(spec, sizeof spec, "socketcan:%s", ifname);
    char err[256];
    arm_can_bus_t a, b;
    if (arm_can_bus_open(&a, spec, err, sizeof err) != 0 || arm_can_bus_open(&b, spec, err, sizeof err) != 0) {
        fprintf(stderr, "open: %s\n", err);
        return 1;
    }
    printf("%s: mtu %d, rcvbuf %d\n", ifname, a.socketcan.mtu, a.socketcan.rcvbuf_bytes);

    /* 1. every frame kind crosses the kernel unchanged, in order */
    const arm_can_frame_t sent[] = {
        frame(0x080, 1, 0),                                      /* SYNC */
        frame(0x181, 16, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS),     /* DRIVE_1_STATE */
        frame(0x201, 8, 0),                                      /* DRIVE_1_CMD */
        frame(0x1ABCDEF0, 8, ARM_CAN_FLAG_EXT),
        frame(0x701, 1, ARM_CAN_FLAG_RTR),
        frame(0x123, 64, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_ESI),
        frame(0x124, 0, ARM_CAN_FLAG_FD),
    };
    const size_t n_sent = sizeof sent / sizeof sent[0];
    for (size_t i = 0; i < n_sent; ++i) {
        CHECK_MSG(arm_can_bus_send(&a, &sent[i]) == ARM_BUS_OK, "send %zu: %s", i, strerror(errno));
    }
    for (size_t i = 0; i < n_sent; ++i) {
        arm_can_frame_t got;
        CHECK_MSG(arm_can_bus_recv(&b, &got, 1000000) == 1, "frame %zu not received", i);
        CHECK_MSG(same(&got, &sent[i]), "frame %zu: id 0x%x len %u flags 0x%x", i, got.id, got.len,
                  got.flags);
    }

    /* 2. a bus does not receive its own frames; recv waits its timeout, no longer */
    arm_can_frame_t f;
    const double t0 = now_s();
    CHECK(arm_can_bus_recv(&a, &f, 50000) == 0);
    const double waited = now_s() - t0;
    CHECK_MSG(waited >= 0.045 && waited < 2.0, "waited %.3f s for a 50 ms timeout", waited);
    CHECK(arm_can_bus_recv(&b, &f, 0) == 0);

    /* 3. frames the transport cannot represent: counted, skipped, the next good one arrives */
    struct canfd_frame bad;
    memset(&bad, 0, sizeof bad);
    bad.can_id = 0x181;
    bad.len = 13; /* not a DLC step */
    CHECK(raw_write(ifname, &bad, CANFD_MTU) == 0);
    const arm_can_frame_t good = frame(0x080, 1, 0);
    CHECK(arm_can_bus_send(&a, &good) == ARM_BUS_OK);
    CHECK(arm_can_bus_recv(&b, &f, 1000000) == 1 && same(&f, &good));
    CHECK(b.socketcan.rx_decode_errors == 1u);
    CHECK(b.socketcan.last_decode_error == ARM_SOCKETCAN_E_BAD_LENGTH);

    /* 4. invalid frames never reach the kernel */
    const arm_can_frame_t too_long = frame(0x100, 9, 0);
    CHECK(arm_can_bus_send(&a, &too_long) == ARM_BUS_E_INVALID);
    CHECK(a.socketcan.tx_invalid == 1u);

    /* 5. a flood nobody reads: the sender never blocks; losses are counted somewhere */
    const uint64_t rx0 = b.socketcan.rx_frames;
    const int flood = 20000;
    int ok = 0, would_block = 0, other = 0;
    const double tf = now_s();
    for (int i = 0; i < flood; ++i) {
        const arm_can_frame_t ff = frame(0x181, 16, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS);
        const int rc = arm_can_bus_send(&a, &ff);
        ok += rc == ARM_BUS_OK;
        would_block += rc == ARM_BUS_E_WOULD_BLOCK;
        other += rc != ARM_BUS_OK && rc != ARM_BUS_E_WOULD_BLOCK;
    }
    const double flood_s = now_s() - tf;
    while (arm_can_bus_recv(&b, &f, 20000) == 1) {
    }
    const uint64_t drained = b.socketcan.rx_frames - rx0;
    /* The drop count rides on the next frame queued after the drops: send one marker. */
    const arm_can_frame_t marker = frame(0x080, 1, 0);
    CHECK(arm_can_bus_send(&a, &marker) == ARM_BUS_OK);
    CHECK(arm_can_bus_recv(&b, &f, 1000000) == 1 && same(&f, &marker));
    printf("flood: %d sent in %.3f s: %d ok, %d would-block (tx_would_block %llu), %d other; "
           "receiver got %llu, kernel dropped %llu\n",
           flood, flood_s, ok, would_block, (unsigned long long)a.socketcan.tx_would_block, other,
           (unsigned long long)drained, (unsigned long long)b.socketcan.rx_kernel_drops);
    CHECK(other == 0);
    CHECK(ok + would_block == flood);
    CHECK((uint64_t)would_block == a.socketcan.tx_would_block);
    CHECK(drained + b.socketcan.rx_kernel_drops == (uint64_t)ok);

    arm_can_bus_close(&a);
    arm_can_bus_close(&b);
    TEST_MAIN_END();
}
