/* libFuzzer: an SLCAN byte stream (arm/slcan.h) fed to the line decoder byte by byte, as the MCU's
 * UART and the TCP transport feed it. Any bytes: no crash, no undefined behaviour; every line is
 * counted exactly once (a frame, a command, a reply, or refused); every decoded frame is one SLCAN
 * can carry and survives its own encoding. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "arm/slcan.h"

static void check_round_trip(const arm_can_frame_t *f)
{
    char line[ARM_SLCAN_LINE_MAX + 1u];
    const size_t n = arm_slcan_encode(f, line);
    if (n == 0u || n > ARM_SLCAN_LINE_MAX + 1u || line[n - 1u] != '\r') __builtin_trap();
    arm_slcan_rx_t rx;
    arm_slcan_rx_init(&rx);
    arm_can_frame_t g;
    memset(&g, 0, sizeof(g));
    arm_slcan_event_t ev = ARM_SLCAN_NONE;
    for (size_t i = 0; i < n; ++i) ev = arm_slcan_rx_byte(&rx, (uint8_t)line[i], &g);
    if (ev != ARM_SLCAN_FRAME || g.id != f->id || g.len != f->len || g.flags != f->flags ||
        memcmp(g.data, f->data, f->len) != 0) {
        __builtin_trap();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    arm_slcan_rx_t rx;
    arm_slcan_rx_init(&rx);
    uint64_t lines = 0;
    for (size_t i = 0; i < size; ++i) {
        arm_can_frame_t f;
        const arm_slcan_event_t ev = arm_slcan_rx_byte(&rx, data[i], &f);
        lines += data[i] == '\r' || data[i] == '\a';
        if (ev == ARM_SLCAN_FRAME) {
            const int fd = (f.flags & ARM_CAN_FLAG_FD) != 0u;
            if ((!fd && f.len > 8u) || f.len > 64u || f.id > 0x1FFFFFFFu) __builtin_trap();
            check_round_trip(&f);
        }
        if (ev == ARM_SLCAN_COMMAND && strlen(rx.line) > ARM_SLCAN_LINE_MAX) __builtin_trap();
    }
    const arm_slcan_counters_t *n = &rx.n;
    /* a too-long line is counted when it overflows, the others at their end */
    if (n->frames + n->commands + n->replies + n->garbage + n->bad_dlc > lines ||
        n->frames + n->commands + n->replies + n->garbage + n->bad_dlc + n->too_long < lines) {
        __builtin_trap();
    }
    return 0;
}
