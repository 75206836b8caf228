/* Text form of frames shared by the test tools, parsed by tests/python/test_pycan_wire.py. */
#ifndef FRAME_TEXT_H
#define FRAME_TEXT_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "arm/can_frame.h"

/* Lower-case hex of buf, or "-" when n is 0 (keeps every field non-empty). */
void frame_text_hex(FILE *out, const uint8_t *buf, size_t n);

/* Parses hex ("-" or "" is empty) into out; returns 0, or -1 on odd length, bad digit, overflow. */
int frame_text_parse_hex(const char *hex, uint8_t *out, size_t cap, size_t *n);

/* "0xID LEN 0xFLAGS HEXDATA" with no newline; RTR frames print "-" for data. */
void frame_text_print(FILE *out, const arm_can_frame_t *f);

#endif
