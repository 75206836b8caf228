/* Which side was late (firmware/port/linux/lateness.c): each period that missed its states is put on
 * the side its own timing shows, and a stop names the side most of its periods were late on. */
#include <string.h>

#include "check.h"
#include "lateness.h"

#define MS 1000000LL

/* Period k: its SYNC at k ms plus `sync_after` ns (the controller woke `wake` ns late), a wait of
 * `wait` ns after it. */
static void begin(lateness_t *lt, uint32_t k, int64_t wake, int64_t wait, uint64_t tx, uint64_t rx)
{
    const int64_t sync = (int64_t)k * MS + wake + 50000;
    lateness_begin(lt, k, wake, sync, (double)sync * 1e-9, wait, tx, rx);
}

static void test_each_side_from_its_own_timing(void)
{
    lateness_t lt;
    lateness_init(&lt);
    int32_t by = 0;
    /* 0: in time */
    begin(&lt, 0, 20000, 700000, 0u, 0u);
    lateness_state(&lt, 0 * MS + 400000, 0.0004, 0u);
    lateness_missing(&lt, 0u);
    /* 1: the plant sent its answer 0.9 ms after SYNC (read in the next period's drain) */
    begin(&lt, 1, 20000, 700000, 0u, 0u);
    lateness_missing(&lt, 0x3Fu);
    lateness_state(&lt, 2 * MS, (double)(1 * MS + 20000 + 50000 + 900000) * 1e-9, 1u);
    /* 2: sent in time (0.3 ms after SYNC), read only 1.2 ms after it: the controller was not running */
    begin(&lt, 2, 20000, 700000, 0u, 0u);
    lateness_missing(&lt, 0x01u);
    lateness_state(&lt, 2 * MS + 70000 + 1200000, (double)(2 * MS + 70000 + 300000) * 1e-9, 1u);
    /* 3: the controller woke 0.9 ms late: its wait was gone */
    begin(&lt, 3, 900000, -100000, 0u, 0u);
    lateness_missing(&lt, 0x3Fu);
    /* 4: nothing ever came and the kernel dropped frames meanwhile: the bus */
    begin(&lt, 4, 20000, 700000, 0u, 0u);
    lateness_missing(&lt, 0x3Fu);
    begin(&lt, 5, 20000, 700000, 0u, 3u);
    CHECK(lateness_judge(lateness_at(&lt, 5), &by) == LATE_NONE);
    CHECK(lateness_judge(lateness_at(&lt, 4), &by) == LATE_PLANT && by == 900);
    CHECK(lateness_judge(lateness_at(&lt, 3), &by) == LATE_CONTROLLER && by == 1200 - 700);
    CHECK(lateness_judge(lateness_at(&lt, 2), &by) == LATE_CONTROLLER && by == 900);
    CHECK(lateness_judge(lateness_at(&lt, 1), &by) == LATE_BUS);
    CHECK(lt.count[LATE_PLANT] == 1u && lt.count[LATE_CONTROLLER] == 2u && lt.count[LATE_BUS] == 1u);
    CHECK(lt.worst_us[LATE_CONTROLLER] == 900 && lt.worst_us[LATE_PLANT] == 900);
}

/* A stop names the side most of its periods were late on, with the times, and the controller's own
 * wake-ups beside the plant's; a plant that never answered is said so. */
static void test_a_stop_says_which_side_and_by_how_much(void)
{
    lateness_t lt;
    lateness_init(&lt);
    for (uint32_t k = 10; k < 14; ++k) {
        begin(&lt, k, 30000, 700000, 0u, 0u);
        lateness_missing(&lt, 0x3Fu);
        if (k > 10) lateness_state(&lt, (int64_t)k * MS, (double)((int64_t)(k - 1) * MS + 80000 + 800000 + 10000 * k) * 1e-9, 2u);
    }
    char text[300];
    CHECK(lateness_explain(&lt, 0u, 4u, 0u, 0u, text, sizeof(text)) == LATE_PLANT);
    CHECK_MSG(strstr(text, "late: the plant's answer in 4 of the 4 periods 10-13") == text, "%s", text);
    CHECK_MSG(strstr(text, "answered 0.91-0.93 ms after SYNC; the controller waits 0.70 ms") != NULL, "%s", text);
    CHECK_MSG(strstr(text, "the controller woke at most 0.03 ms late") != NULL, "%s", text);
    lateness_init(&lt);
    for (uint32_t k = 0; k < 4; ++k) {
        begin(&lt, k, 2 * MS, -MS, 0u, 0u); /* a stalled machine: every wake-up 2 ms late */
        lateness_missing(&lt, 0x3Fu);
    }
    CHECK(lateness_explain(&lt, 0u, 4u, 0u, 0u, text, sizeof(text)) == LATE_CONTROLLER);
    CHECK_MSG(strstr(text, "late: the controller's wake-up in 4 of the 4 periods 0-3 that missed their states "
                           "(it woke or read 2.00-2.00 ms late)") == text, "%s", text);
    lateness_init(&lt);
    begin(&lt, 7, 10000, 900 * MS, 0u, 0u); /* lockstep: a second's wait, and nothing */
    lateness_missing(&lt, 0x04u);
    CHECK(lateness_explain(&lt, 0u, 1u, 0u, 0u, text, sizeof(text)) == LATE_PLANT);
    CHECK_MSG(strstr(text, "(no answer at all)") != NULL, "%s", text);
}

int main(void)
{
    test_each_side_from_its_own_timing();
    test_a_stop_says_which_side_and_by_how_much();
    TEST_MAIN_END();
}
