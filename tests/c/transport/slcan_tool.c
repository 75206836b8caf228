/* The SLCAN transport (arm/can_slcan.h) as a command-line peer for tests/python/test_slcan.py:
 *   slcan_tool HOST:PORT N_RECV
 * connects (slcan:HOST:PORT), sends a fixed set of frames (every kind SLCAN carries), printing
 * "sent FRAME" for each, then receives until N_RECV frames came or 5 s passed, printing
 * "recv FRAME" for each, and last "counts garbage=G too_long=L bad_dlc=D commands=C replies=R"
 * (FRAME: frame_text.h's form). Exit 0, or 1 on a transport error. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm/can_slcan.h"
#include "frame_text.h"

static arm_can_frame_t frame(uint32_t id, uint8_t flags, uint8_t len)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof(f));
    f.id = id;
    f.flags = flags;
    f.len = len;
    for (unsigned i = 0; i < len && (flags & ARM_CAN_FLAG_RTR) == 0u; ++i) f.data[i] = (uint8_t)(0xA0u + 7u * i);
    return f;
}

int main(int argc, char **argv)
{
    if (argc != 3 || strchr(argv[1], ':') == NULL) {
        fprintf(stderr, "usage: slcan_tool HOST:PORT N_RECV\n");
        return 2;
    }
    char host[64];
    const char *colon = strrchr(argv[1], ':');
    snprintf(host, sizeof(host), "%.*s", (int)(colon - argv[1]), argv[1]);
    static arm_can_slcan_t bus;
    char err[256];
    if (arm_can_slcan_open(&bus, host, (uint16_t)atoi(colon + 1), err, sizeof(err)) != 0) {
        fprintf(stderr, "slcan_tool: %s\n", err);
        return 1;
    }
    const arm_can_frame_t frames[] = {
        frame(0x080, 0, 0),                                                  /* SYNC */
        frame(0x181, 0, 8),                                                  /* a TPDO1 */
        frame(0x7FF, 0, 3),
        frame(0x1ABCDEF0, ARM_CAN_FLAG_EXT, 5),
        frame(0x123, ARM_CAN_FLAG_RTR, 4),
        frame(0x1FFFFFFF, ARM_CAN_FLAG_RTR | ARM_CAN_FLAG_EXT, 0),
        frame(0x201, ARM_CAN_FLAG_FD, 16),                                   /* an FD drive state */
        frame(0x0123456, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_EXT, 64),
        frame(0x321, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS, 12),
        frame(0x1000, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS | ARM_CAN_FLAG_EXT, 0),
    };
    for (size_t i = 0; i < sizeof(frames) / sizeof(frames[0]); ++i) {
        if (arm_can_slcan_send(&bus, &frames[i]) != 0) {
            fprintf(stderr, "slcan_tool: send %zu failed\n", i);
            return 1;
        }
        printf("sent ");
        frame_text_print(stdout, &frames[i]);
        printf("\n");
    }
    fflush(stdout);
    const int want = atoi(argv[2]);
    for (int got = 0; got < want;) {
        arm_can_frame_t f;
        const int rc = arm_can_slcan_recv(&bus, &f, 5000000);
        if (rc < 0) {
            fprintf(stderr, "slcan_tool: recv: error %d\n", rc);
            return 1;
        }
        if (rc == 0) break;
        printf("recv ");
        frame_text_print(stdout, &f);
        printf("\n");
        ++got;
    }
    const arm_slcan_counters_t *n = &bus.dec.n;
    printf("counts garbage=%llu too_long=%llu bad_dlc=%llu commands=%llu replies=%llu\n",
           (unsigned long long)n->garbage, (unsigned long long)n->too_long, (unsigned long long)n->bad_dlc,
           (unsigned long long)n->commands, (unsigned long long)n->replies);
    arm_can_slcan_close(&bus);
    return 0;
}
