/* libFuzzer: an LCM URL as the controller, the simulator and the logger parse it: no crash, and
 * an accepted URL is "none" or a multicast group (224.0.0.0/4). */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "arm/lcm_url.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char url[600];
    const size_t n = size < sizeof url - 1u ? size : sizeof url - 1u;
    memcpy(url, data, n);
    url[n] = '\0';
    arm_lcm_url_t u;
    char err[300];
    if (arm_lcm_url_parse(url, "--lcm-url", &u, err, sizeof err) == 0 && !u.none &&
        (((const uint8_t *)&u.group_be)[0] & 0xF0u) != 0xE0u) {
        __builtin_trap();
    }
    return 0;
}
