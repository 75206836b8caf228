/* SocketCAN transport without a kernel CAN: the pure frame <-> can_frame/canfd_frame
 * conversion, bus spec parsing, and the open errors (which name the interface and say why). */
#define _GNU_SOURCE
#include <errno.h>
#include <stdint.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "arm/can_bus.h"
#include "arm/can_socketcan.h"
#include "check.h"

static const unsigned FD_LENS[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};

static arm_can_frame_t frame(uint32_t id, uint8_t len, uint8_t flags)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof f);
    f.id = id;
    f.len = len;
    f.flags = flags;
    for (unsigned i = 0; i < len && i < ARM_CAN_MAX_DATA; ++i) {
        f.data[i] = (uint8_t)(0xA0u + i);
    }
    return f;
}

static void test_classic_to_kernel(void)
{
    /* DRIVE_1_CMD: classic, 8 bytes, 11-bit id 0x201 */
    arm_can_frame_t f = frame(0x201, 8, 0);
    arm_socketcan_frame_t k;
    memset(&k, 0xEE, sizeof k);
    CHECK(arm_socketcan_from_frame(&f, &k) == CAN_MTU);
    CHECK(k.cc.can_id == 0x201u);
    CHECK(k.cc.len == 8u);
    CHECK(k.cc.len8_dlc == 0u && k.cc.__pad == 0u && k.cc.__res0 == 0u);
    CHECK(memcmp(k.cc.data, f.data, 8) == 0);

    /* SYNC: 1 byte; the rest of the kernel struct is zero, not stack garbage */
    f = frame(0x080, 1, 0);
    CHECK(arm_socketcan_from_frame(&f, &k) == CAN_MTU);
    CHECK(k.cc.len == 1u && k.cc.data[0] == 0xA0u && k.cc.data[1] == 0u && k.fd.data[63] == 0u);

    /* 29-bit id */
    f = frame(0x1ABCDEF0, 4, ARM_CAN_FLAG_EXT);
    CHECK(arm_socketcan_from_frame(&f, &k) == CAN_MTU);
    CHECK(k.cc.can_id == (0x1ABCDEF0u | CAN_EFF_FLAG));

    /* remote frame: requested length in len, no data */
    f = frame(0x701, 1, ARM_CAN_FLAG_RTR);
    CHECK(arm_socketcan_from_frame(&f, &k) == CAN_MTU);
    CHECK(k.cc.can_id == (0x701u | CAN_RTR_FLAG));
    CHECK(k.cc.len == 1u && k.cc.data[0] == 0u);
}

static void test_fd_to_kernel(void)
{
    /* DRIVE_1_STATE: CAN FD, 16 bytes, bit-rate switch */
    arm_can_frame_t f = frame(0x181, 16, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS);
    arm_socketcan_frame_t k;
    CHECK(arm_socketcan_from_frame(&f, &k) == CANFD_MTU);
    CHECK(k.fd.can_id == 0x181u);
    CHECK(k.fd.len == 16u);
    CHECK((k.fd.flags & CANFD_BRS) != 0u);
    CHECK((k.fd.flags & CANFD_ESI) == 0u);
    CHECK(memcmp(k.fd.data, f.data, 16) == 0 && k.fd.data[16] == 0u);

    /* FD without BRS, with ESI; FD with <= 8 bytes is still an FD frame (72-byte write) */
    f = frame(0x7FF, 8, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_ESI);
    CHECK(arm_socketcan_from_frame(&f, &k) == CANFD_MTU);
    CHECK((k.fd.flags & CANFD_BRS) == 0u && (k.fd.flags & CANFD_ESI) != 0u);

    f = frame(CAN_EFF_MASK, 64, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_EXT | ARM_CAN_FLAG_BRS);
    CHECK(arm_socketcan_from_frame(&f, &k) == CANFD_MTU);
    CHECK(k.fd.can_id == (CAN_EFF_MASK | CAN_EFF_FLAG) && k.fd.len == 64u);
}

static void test_invalid_frames_are_not_sent(void)
{
    arm_socketcan_frame_t k;
    const struct {
        arm_can_frame_t f;
        const char *why;
    } bad[] = {
        {frame(0x800, 1, 0), "11-bit id above 0x7FF"},
        {frame(0x20000000, 1, ARM_CAN_FLAG_EXT), "29-bit id above 0x1FFFFFFF"},
        {frame(0x100, 9, 0), "classic len 9"},
        {frame(0x100, 13, ARM_CAN_FLAG_FD), "FD len 13 is not a DLC step"},
        {frame(0x100, 65, ARM_CAN_FLAG_FD), "FD len 65"},
        {frame(0x100, 1, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_RTR), "FD remote frame"},
        {frame(0x100, 1, ARM_CAN_FLAG_BRS), "BRS without FD"},
        {frame(0x100, 1, ARM_CAN_FLAG_ESI), "ESI without FD"},
        {frame(0x100, 1, ARM_CAN_FLAG_ERR), "error frame"},
        {frame(0x100, 1, 0x40), "unknown flag bit"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        CHECK_MSG(arm_socketcan_from_frame(&bad[i].f, &k) == 0u, "%s", bad[i].why);
    }
    CHECK(arm_socketcan_from_frame(NULL, &k) == 0u);
    CHECK(arm_socketcan_from_frame(&bad[0].f, NULL) == 0u);
}

static void test_round_trip(void)
{
    int n = 0;
    for (int ext = 0; ext < 2; ++ext) {
        for (size_t li = 0; li < sizeof FD_LENS / sizeof FD_LENS[0]; ++li) {
            for (unsigned extra = 0; extra < 4; ++extra) { /* bit 0 FD, bit 1 BRS (FD only) */
                const int fd = (extra & 1u) != 0u;
                if ((!fd && (extra & 2u) != 0u) || (!fd && FD_LENS[li] > 8u)) {
                    continue;
                }
                const uint8_t flags = (uint8_t)((fd ? ARM_CAN_FLAG_FD : 0u) |
                                                ((extra & 2u) ? ARM_CAN_FLAG_BRS : 0u) |
                                                (ext ? ARM_CAN_FLAG_EXT : 0u));
                const arm_can_frame_t in = frame(ext ? 0x12345678u : 0x555u, (uint8_t)FD_LENS[li], flags);
                arm_socketcan_frame_t k;
                const size_t nbytes = arm_socketcan_from_frame(&in, &k);
                CHECK(nbytes == (fd ? CANFD_MTU : CAN_MTU));
                arm_can_frame_t out;
                memset(&out, 0x55, sizeof out);
                CHECK(arm_socketcan_to_frame(&k, nbytes, &out) == ARM_SOCKETCAN_OK);
                CHECK_MSG(out.id == in.id && out.len == in.len && out.flags == in.flags &&
                              memcmp(out.data, in.data, sizeof in.data) == 0,
                          "ext=%d len=%u flags=0x%x", ext, FD_LENS[li], flags);
                ++n;
            }
        }
    }
    CHECK(n == 2 * (9 + 16 * 2)); /* classic 0..8, FD with and without BRS at 16 lengths */
}

static void test_kernel_to_frame(void)
{
    arm_socketcan_frame_t k;
    arm_can_frame_t f;

    /* size decides classic vs FD, nothing else does */
    memset(&k, 0, sizeof k);
    k.cc.can_id = 0x181;
    k.cc.len = 8;
    const size_t bad_sizes[] = {0u, 8u, CAN_MTU - 1u, CAN_MTU + 1u, CANFD_MTU - 1u, CANFD_MTU + 1u};
    for (size_t i = 0; i < sizeof bad_sizes / sizeof bad_sizes[0]; ++i) {
        CHECK(arm_socketcan_to_frame(&k, bad_sizes[i], &f) == ARM_SOCKETCAN_E_SIZE);
    }
    CHECK(arm_socketcan_to_frame(&k, CAN_MTU, &f) == ARM_SOCKETCAN_OK && f.flags == 0u);
    CHECK(arm_socketcan_to_frame(&k, CANFD_MTU, &f) == ARM_SOCKETCAN_OK && f.flags == ARM_CAN_FLAG_FD);

    /* newer kernels mark every FD frame with CANFD_FDF: accepted, not reported */
    k.fd.flags = CANFD_FDF | CANFD_BRS;
    k.fd.len = 16;
    CHECK(arm_socketcan_to_frame(&k, CANFD_MTU, &f) == ARM_SOCKETCAN_OK);
    CHECK(f.flags == (ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS) && f.len == 16u);

    k.fd.len = 13; /* vcan passes any length through; we accept DLC steps only */
    CHECK(arm_socketcan_to_frame(&k, CANFD_MTU, &f) == ARM_SOCKETCAN_E_BAD_LENGTH);
    k.fd.len = 65;
    CHECK(arm_socketcan_to_frame(&k, CANFD_MTU, &f) == ARM_SOCKETCAN_E_BAD_LENGTH);

    memset(&k, 0, sizeof k);
    k.cc.can_id = 0x181;
    k.cc.len = 9;
    CHECK(arm_socketcan_to_frame(&k, CAN_MTU, &f) == ARM_SOCKETCAN_E_BAD_LENGTH);
    CHECK(f.len == 0u && f.id == 0u); /* a rejected frame leaves nothing behind */

    k.cc.len = 2;
    k.cc.can_id = 0x1FFFu; /* id bits above 11 without CAN_EFF_FLAG */
    CHECK(arm_socketcan_to_frame(&k, CAN_MTU, &f) == ARM_SOCKETCAN_E_BAD_ID);

    k.fd.can_id = 0x181u | CAN_RTR_FLAG;
    k.fd.len = 8;
    CHECK(arm_socketcan_to_frame(&k, CANFD_MTU, &f) == ARM_SOCKETCAN_E_BAD_FLAGS);

    /* classic remote frame: requested length kept, whatever sits in data is not */
    memset(&k, 0, sizeof k);
    k.cc.can_id = 0x701u | CAN_RTR_FLAG;
    k.cc.len = 1;
    k.cc.data[0] = 0x77;
    CHECK(arm_socketcan_to_frame(&k, CAN_MTU, &f) == ARM_SOCKETCAN_OK);
    CHECK(f.id == 0x701u && f.len == 1u && f.flags == ARM_CAN_FLAG_RTR && f.data[0] == 0u);

    /* error frame (only with CAN_RAW_ERR_FILTER, which we never set) */
    k.cc.can_id = CAN_ERR_FLAG | 0x004u;
    k.cc.len = 8;
    CHECK(arm_socketcan_to_frame(&k, CAN_MTU, &f) == ARM_SOCKETCAN_OK);
    CHECK(f.flags == ARM_CAN_FLAG_ERR && f.id == 0x004u);

    CHECK(arm_socketcan_to_frame(NULL, CAN_MTU, &f) == ARM_SOCKETCAN_E_ARG);
    CHECK(arm_socketcan_to_frame(&k, CAN_MTU, NULL) == ARM_SOCKETCAN_E_ARG);
    CHECK(strcmp(arm_socketcan_errname(ARM_SOCKETCAN_E_BAD_LENGTH), "bad_length") == 0);
    CHECK(strcmp(arm_socketcan_errname(42), "unknown") == 0);
}

static void test_spec_parsing(void)
{
    arm_can_bus_spec_t s;
    char err[256];

    CHECK(arm_can_bus_parse_spec("udp", &s, err, sizeof err) == 0);
    CHECK(s.kind == ARM_BUS_UDP && strcmp(s.group, "239.74.163.2") == 0 && s.port == 43113u);
    CHECK(arm_can_bus_parse_spec("udp:239.74.163.9:44001", &s, err, sizeof err) == 0);
    CHECK(s.kind == ARM_BUS_UDP && strcmp(s.group, "239.74.163.9") == 0 && s.port == 44001u);
    CHECK(arm_can_bus_parse_spec("udp:239.74.163.9:0", &s, err, sizeof err) != 0);

    CHECK(arm_can_bus_parse_spec("socketcan:vcan0", &s, err, sizeof err) == 0);
    CHECK(s.kind == ARM_BUS_SOCKETCAN && strcmp(s.ifname, "vcan0") == 0);
    CHECK(arm_can_bus_parse_spec("socketcan:can_fd-1.2", &s, err, sizeof err) == 0);
    CHECK(arm_can_bus_parse_spec("socketcan:abcdefghijklmno", &s, err, sizeof err) == 0); /* 15 */
    CHECK(arm_can_bus_spec_valid("socketcan:can0", err, sizeof err) == 0);

    const char *bad[] = {"socketcan:", "socketcan:abcdefghijklmnop", "socketcan:a/b",
                         "socketcan:vcan0:1", "socketcan:.", "socketcan:..", "socketcan:v can",
                         "socketcan", "can0", "vcan0", "", "udp:", "SOCKETCAN:vcan0"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        err[0] = '\0';
        CHECK_MSG(arm_can_bus_parse_spec(bad[i], &s, err, sizeof err) != 0, "'%s'", bad[i]);
        CHECK_MSG(strstr(err, "--bus") != NULL && strstr(err, bad[i]) != NULL, "'%s': %s", bad[i], err);
    }
    CHECK(arm_can_bus_spec_valid("can9", err, sizeof err) != 0);
    CHECK(strstr(err, "socketcan:IFACE") != NULL);
}

static int kernel_has_af_can(void)
{
    const int fd = socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (fd < 0) {
        return errno == EAFNOSUPPORT ? 0 : 1;
    }
    close(fd);
    return 1;
}

static void test_open_errors_name_the_interface(void)
{
    arm_can_socketcan_t bus;
    char err[256];
    const int has_can = kernel_has_af_can();
    printf("kernel AF_CAN: %s\n", has_can ? "yes" : "no (EAFNOSUPPORT)");

    CHECK(arm_can_socketcan_open(&bus, "armnoexist0", err, sizeof err) == -1);
    CHECK(bus.fd == -1);
    printf("open armnoexist0: %s\n", err);
    CHECK(strncmp(err, "socketcan:armnoexist0: ", 23) == 0);
    if (has_can) {
        CHECK(strstr(err, "no such interface") != NULL);
    } else {
        CHECK(strstr(err, "this kernel has no SocketCAN (AF_CAN): use --bus udp or tools/armctl vcan run") != NULL);
    }
    if (has_can) {
        CHECK(arm_can_socketcan_open(&bus, "lo", err, sizeof err) == -1);
        CHECK(strstr(err, "socketcan:lo: not a CAN interface") != NULL);
    }
    CHECK(arm_can_socketcan_open(&bus, "a/b", err, sizeof err) == -1);
    CHECK(strstr(err, "not a valid interface name") != NULL);

    /* the same message reaches the controller through the bus interface */
    arm_can_bus_t b;
    CHECK(arm_can_bus_open(&b, "socketcan:armnoexist0", err, sizeof err) == -1);
    CHECK(strstr(err, "socketcan:armnoexist0: ") != NULL);
    CHECK(b.kind == ARM_BUS_SOCKETCAN && b.socketcan.fd == -1);
    arm_can_bus_close(&b); /* safe after a failed open */

    /* a closed bus refuses politely */
    arm_can_frame_t f = frame(0x80, 1, 0);
    CHECK(arm_can_socketcan_send(&bus, &f) == ARM_CAN_SOCKETCAN_E_CLOSED);
    CHECK(arm_can_socketcan_recv(&bus, &f, 0) == ARM_CAN_SOCKETCAN_E_CLOSED);
    CHECK(arm_can_socketcan_send(NULL, &f) == ARM_CAN_SOCKETCAN_E_INVALID);
    arm_can_socketcan_close(&bus);
    arm_can_socketcan_close(&bus);
}

int main(void)
{
    test_classic_to_kernel();
    test_fd_to_kernel();
    test_invalid_frames_are_not_sent();
    test_round_trip();
    test_kernel_to_frame();
    test_spec_parsing();
    test_open_errors_name_the_interface();
    TEST_MAIN_END();
}
