/* libFuzzer: python-can's udp_multicast wire format (msgpack) decoded, then re-encoded when valid.
 * Any byte string: no crash, no undefined behaviour, and a decoded frame round-trips. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "arm/pycan_wire.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    arm_can_frame_t f;
    double ts = 0.0;
    if (arm_pycan_decode(data, size, &f, &ts) == ARM_PYCAN_OK) {
        uint8_t buf[256];
        const size_t n = arm_pycan_encode(&f, ts, buf, sizeof buf);
        arm_can_frame_t g;
        double ts2 = 0.0;
        if (n == 0u || arm_pycan_decode(buf, n, &g, &ts2) != ARM_PYCAN_OK || g.id != f.id || g.len != f.len ||
            memcmp(g.data, f.data, f.len) != 0) {
            __builtin_trap(); /* a valid frame must survive its own encoding */
        }
    }
    return 0;
}
