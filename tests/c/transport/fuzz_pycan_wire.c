/*
 * libFuzzer target for the codec (clang only; see CMakeLists.txt).
 * Decoder: any input must be rejected or yield a sendable frame that
 * survives encode -> decode unchanged. Encoder: any frame bytes either fail
 * cleanly or produce a datagram the decoder accepts as the same frame.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "arm/pycan_wire.h"

static void same_or_abort(const arm_can_frame_t *a, const arm_can_frame_t *b)
{
    const size_t n = (a->flags & ARM_CAN_FLAG_RTR) ? 0u : a->len;
    if (a->id != b->id || a->len != b->len || a->flags != b->flags ||
        memcmp(a->data, b->data, n) != 0) {
        abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    arm_can_frame_t f, g;
    double ts = 0.0, ts2 = 0.0;
    uint8_t out[ARM_PYCAN_MAX_ENCODED];

    if (arm_pycan_decode(data, size, &f, &ts) == ARM_PYCAN_OK) {
        const size_t n = arm_pycan_encode(&f, ts, out, sizeof out);
        if (n == 0u || arm_pycan_decode(out, n, &g, &ts2) != ARM_PYCAN_OK) {
            abort();
        }
        same_or_abort(&f, &g);
    }

    if (size >= sizeof f + sizeof ts) {
        memcpy(&f, data, sizeof f);
        memcpy(&ts, data + sizeof f, sizeof ts);
        const size_t n = arm_pycan_encode(&f, ts, out, sizeof out);
        if (n != 0u) {
            if (arm_pycan_decode(out, n, &g, &ts2) != ARM_PYCAN_OK) {
                abort();
            }
            same_or_abort(&f, &g);
        }
    }
    return 0;
}
