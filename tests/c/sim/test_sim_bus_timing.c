/* The bus timeline: lowest id first among frames ready together, a later batch waits for the
 * bus, and a bus busy past the period's end carries the backlog into the next period. */
#include <math.h>

#include "check.h"
#include "sim_bus_timing.h"

#define NEAR(a, b) (fabs((a) - (b)) < 1e-12)

int main(void)
{
    static sim_timeline_t tl;
    sim_timeline_init(&tl);
    CHECK(sim_timeline_parse_frames(&tl, "1:100,2:200,0x3:300") == 0);
    const uint32_t ids[3] = {3, 1, 2};
    double ends[3];
    sim_timeline_transmit(&tl, 0.0, ids, 3, ends);
    CHECK(NEAR(ends[1], 1e-4) && NEAR(ends[2], 3e-4) && NEAR(ends[0], 6e-4)); /* by id, not by order given */
    const uint32_t one = 1;
    double end;
    sim_timeline_transmit(&tl, 1e-4, &one, 1, &end);
    CHECK(NEAR(end, 7e-4)); /* ready at 0.1 ms, but the bus is busy until 0.6 ms */
    const uint32_t three = 3;
    sim_timeline_transmit(&tl, 9e-4, &three, 1, &end); /* ends at 1.2 ms: 0.2 ms into the next period */
    sim_timeline_new_period(&tl, 1e-3);
    CHECK(NEAR(tl.free, 2e-4) && NEAR(tl.stats.backlog_max_s, 2e-4));
    sim_timeline_transmit(&tl, 0.0, &one, 1, &end);
    CHECK(NEAR(end, 3e-4));
    sim_timeline_new_period(&tl, 1e-3);
    CHECK(NEAR(tl.free, 0.0) && NEAR(tl.stats.backlog_max_s, 2e-4)); /* no backlog: idle from the start */
    /* malformed frame lists are refused whole */
    CHECK(sim_timeline_parse_frames(&tl, "2048:1") != 0);       /* not an 11-bit id */
    CHECK(sim_timeline_parse_frames(&tl, "5:-1") != 0);
    CHECK(sim_timeline_parse_frames(&tl, "5:1e7") != 0);
    CHECK(sim_timeline_parse_frames(&tl, "5=1") != 0);
    CHECK(sim_timeline_parse_frames(&tl, "5:nan") != 0);
    TEST_MAIN_END();
}
