/* Unit tests for the SLCAN codec (arm/slcan.h): the lines python-can's slcan interface writes
 * and reads (its format strings: t%03X%d, T%08X%d, d/b/D/B with a hex DLC code, data upper-case
 * hex), the adapter's replies and commands, and what is refused: counted once, dropped, the next
 * line decoded as if nothing happened. tests/python/test_slcan.py checks the same lines against
 * python-can itself, and tests/c/transport/slcan_replay.txt is replayed here line by line. */
#include <stdio.h>
#include <string.h>

#include "arm/slcan.h"
#include "check.h"

static arm_can_frame_t frame(uint32_t id, uint8_t flags, uint8_t len, const char *data)
{
    arm_can_frame_t f;
    memset(&f, 0, sizeof(f));
    f.id = id;
    f.flags = flags;
    f.len = len;
    if (data != NULL) memcpy(f.data, data, len);
    return f;
}

static void check_encode(const arm_can_frame_t *f, const char *want)
{
    char line[ARM_SLCAN_LINE_MAX + 1u];
    const size_t n = arm_slcan_encode(f, line);
    CHECK_MSG(n == strlen(want) && memcmp(line, want, n) == 0, "encoded '%.*s', want '%s'", (int)n, line, want);
}

/* Feeds text; returns the last event, the frame of the last FRAME event in *f. */
static arm_slcan_event_t feed(arm_slcan_rx_t *rx, const char *text, arm_can_frame_t *f)
{
    arm_slcan_event_t last = ARM_SLCAN_NONE;
    for (const char *c = text; *c != '\0'; ++c) {
        const arm_slcan_event_t ev = arm_slcan_rx_byte(rx, (uint8_t)*c, f);
        if (ev != ARM_SLCAN_NONE) last = ev;
    }
    return last;
}

static void test_encode(void)
{
    const arm_can_frame_t sync = frame(0x080, 0, 0, NULL);
    check_encode(&sync, "t0800\r");
    const arm_can_frame_t tpdo1 = frame(0x181, 0, 8, "\x01\x23\x45\x67\x89\xAB\xCD\xEF");
    check_encode(&tpdo1, "t18180123456789ABCDEF\r");
    const arm_can_frame_t ext = frame(0x1ABCDEF0, ARM_CAN_FLAG_EXT, 2, "\xFF\x00");
    check_encode(&ext, "T1ABCDEF02FF00\r");
    const arm_can_frame_t rtr = frame(0x7FF, ARM_CAN_FLAG_RTR, 8, NULL);
    check_encode(&rtr, "r7FF8\r");
    char data[64];
    for (int i = 0; i < 64; ++i) data[i] = (char)i;
    const arm_can_frame_t fd12 = frame(0x123, ARM_CAN_FLAG_FD, 12, data);
    check_encode(&fd12, "d1239000102030405060708090A0B\r");
    const arm_can_frame_t brs = frame(0x12345, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS | ARM_CAN_FLAG_EXT, 1, data);
    check_encode(&brs, "B00012345100\r");
    /* what SLCAN cannot carry */
    char line[ARM_SLCAN_LINE_MAX + 1u];
    const arm_can_frame_t bad[] = {
        frame(0x800, 0, 0, NULL),                               /* 11-bit id out of range */
        frame(0x100, 0, 9, data),                               /* classic, 9 bytes */
        frame(0x100, ARM_CAN_FLAG_FD, 13, data),                /* no FD DLC for 13 */
        frame(0x100, ARM_CAN_FLAG_ERR, 0, NULL),                /* error frame */
        frame(0x100, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_ESI, 8, data), /* ESI */
        frame(0x100, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_RTR, 8, NULL), /* FD remote */
        frame(0x100, ARM_CAN_FLAG_BRS, 8, data),                /* BRS without FD */
    };
    for (size_t i = 0; i < sizeof(bad) / sizeof(bad[0]); ++i) {
        CHECK_MSG(arm_slcan_encode(&bad[i], line) == 0u, "bad frame %zu encoded", i);
    }
    /* the longest line fits */
    const arm_can_frame_t fd64 = frame(0x1FFFFFFF, ARM_CAN_FLAG_FD | ARM_CAN_FLAG_EXT, 64, data);
    CHECK(arm_slcan_encode(&fd64, line) == 1u + 8u + 1u + 128u + 1u);
}

static void test_decode(void)
{
    arm_slcan_rx_t rx;
    arm_slcan_rx_init(&rx);
    arm_can_frame_t f;
    CHECK(feed(&rx, "t18180123456789ABCDEF\r", &f) == ARM_SLCAN_FRAME);
    CHECK(f.id == 0x181 && f.len == 8 && f.flags == 0 && f.data[0] == 0x01 && f.data[7] == 0xEF);
    CHECK(feed(&rx, "t1812abcd\r", &f) == ARM_SLCAN_FRAME && f.data[0] == 0xAB && f.data[1] == 0xCD); /* lower case */
    CHECK(feed(&rx, "t0800\r", &f) == ARM_SLCAN_FRAME && f.id == 0x80 && f.len == 0);
    CHECK(feed(&rx, "t0801\r", &f) == ARM_SLCAN_NONE); /* a DLC of 1 without its byte: garbage */
    CHECK(feed(&rx, "t08001A2B\r", &f) == ARM_SLCAN_FRAME && f.len == 0); /* a time stamp, ignored */
    CHECK(feed(&rx, "T1ABCDEF02FF00\r", &f) == ARM_SLCAN_FRAME && f.id == 0x1ABCDEF0 && f.flags == ARM_CAN_FLAG_EXT);
    CHECK(feed(&rx, "r7FF8\r", &f) == ARM_SLCAN_FRAME && f.flags == ARM_CAN_FLAG_RTR && f.len == 8);
    CHECK(feed(&rx, "R000000010\r", &f) == ARM_SLCAN_FRAME && f.flags == (ARM_CAN_FLAG_RTR | ARM_CAN_FLAG_EXT));
    CHECK(feed(&rx, "d1239000102030405060708090A0B\r", &f) == ARM_SLCAN_FRAME && f.len == 12 &&
          f.flags == ARM_CAN_FLAG_FD && f.data[11] == 0x0B);
    CHECK(feed(&rx, "b1230\r", &f) == ARM_SLCAN_FRAME && f.flags == (ARM_CAN_FLAG_FD | ARM_CAN_FLAG_BRS));
    CHECK(feed(&rx, "t0800\r\n", &f) == ARM_SLCAN_FRAME); /* "\r\n": the '\n' starts nothing */
    CHECK(rx.n.frames == 10 && rx.n.garbage == 1 && rx.n.too_long == 0 && rx.n.bad_dlc == 0);
    /* adapter replies and commands */
    CHECK(feed(&rx, "\r", &f) == ARM_SLCAN_OK);
    CHECK(feed(&rx, "\a", &f) == ARM_SLCAN_ERROR);
    CHECK(feed(&rx, "O\r", &f) == ARM_SLCAN_COMMAND && strcmp(rx.line, "O") == 0);
    CHECK(feed(&rx, "S8\r", &f) == ARM_SLCAN_COMMAND && strcmp(rx.line, "S8") == 0);
    CHECK(feed(&rx, "s031C\r", &f) == ARM_SLCAN_COMMAND);
    CHECK(rx.n.replies == 2 && rx.n.commands == 3);
}

static void test_refused(void)
{
    arm_slcan_rx_t rx;
    arm_slcan_rx_init(&rx);
    arm_can_frame_t f = frame(0x42, 0, 0, NULL);
    /* bad DLC: classic above 8, a non-hex DLC character */
    CHECK(feed(&rx, "t1239\r", &f) == ARM_SLCAN_NONE);
    CHECK(feed(&rx, "t123G\r", &f) == ARM_SLCAN_NONE);
    CHECK(feed(&rx, "d123X00\r", &f) == ARM_SLCAN_NONE);
    CHECK(rx.n.bad_dlc == 3);
    /* garbage: unknown letters, non-hex ids and data, an 11-bit id above 0x7FF, binary bytes */
    CHECK(feed(&rx, "hello\r", &f) == ARM_SLCAN_NONE);
    CHECK(feed(&rx, "tXYZ0\r", &f) == ARM_SLCAN_NONE);
    CHECK(feed(&rx, "t1231ZZ\r", &f) == ARM_SLCAN_NONE);
    CHECK(feed(&rx, "t8000\r", &f) == ARM_SLCAN_NONE);
    CHECK(feed(&rx, "\x01\xff\x80\r", &f) == ARM_SLCAN_NONE);
    CHECK(feed(&rx, "S\r", &f) == ARM_SLCAN_NONE); /* a command missing its argument */
    CHECK(rx.n.garbage == 6);
    /* too long: counted once, when it overflows; the next line is whole again */
    for (unsigned i = 0; i < 3u * ARM_SLCAN_LINE_MAX; ++i) (void)arm_slcan_rx_byte(&rx, 'A', &f);
    CHECK(rx.n.too_long == 1);
    CHECK(feed(&rx, "t0800\r", &f) == ARM_SLCAN_NONE); /* still the too-long line's end */
    CHECK(feed(&rx, "t0800\r", &f) == ARM_SLCAN_FRAME && f.id == 0x80);
    CHECK(rx.n.too_long == 1 && rx.n.frames == 1);
    CHECK(f.id == 0x80); /* nothing refused ever touched the frame */
    CHECK(arm_slcan_rx_refused(&rx) == 3 + 6 + 1);
}

/* slcan_replay.txt: a drive's boot answers and states, with refused lines among them (each line
 * of the file is one SLCAN line; "#" lines are comments). The frames decode as if the refused lines
 * were not there, and each refused one is counted under its kind. */
static void test_replay(const char *path)
{
    FILE *fp = fopen(path, "rb");
    CHECK_MSG(fp != NULL, "cannot open %s", path);
    if (fp == NULL) return;
    arm_slcan_rx_t rx;
    arm_slcan_rx_init(&rx);
    char text[1024];
    unsigned frames = 0, want_frames = 0, want_garbage = 0, want_long = 0, want_dlc = 0;
    while (fgets(text, sizeof(text), fp) != NULL) {
        size_t n = strcspn(text, "\n");
        text[n] = '\0';
        if (text[0] == '#' || n == 0u) {
            /* "# expect frames=N garbage=N too_long=N bad_dlc=N" */
            (void)sscanf(text, "# expect frames=%u garbage=%u too_long=%u bad_dlc=%u", &want_frames, &want_garbage,
                         &want_long, &want_dlc);
            continue;
        }
        arm_can_frame_t f;
        for (size_t i = 0; i < n; ++i) frames += arm_slcan_rx_byte(&rx, (uint8_t)text[i], &f) == ARM_SLCAN_FRAME;
        frames += arm_slcan_rx_byte(&rx, '\r', &f) == ARM_SLCAN_FRAME;
    }
    fclose(fp);
    CHECK_MSG(want_frames > 0u && frames == want_frames && rx.n.garbage == want_garbage &&
                  rx.n.too_long == want_long && rx.n.bad_dlc == want_dlc,
              "frames %u (want %u), garbage %llu (%u), too long %llu (%u), bad DLC %llu (%u)", frames, want_frames,
              (unsigned long long)rx.n.garbage, want_garbage, (unsigned long long)rx.n.too_long, want_long,
              (unsigned long long)rx.n.bad_dlc, want_dlc);
}

int main(int argc, char **argv)
{
    test_encode();
    test_decode();
    test_refused();
    test_replay(argc > 1 ? argv[1] : "slcan_replay.txt");
    TEST_MAIN_END();
}
