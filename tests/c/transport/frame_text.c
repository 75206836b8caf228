#include "frame_text.h"

#include <string.h>

void frame_text_hex(FILE *out, const uint8_t *buf, size_t n)
{
    if (n == 0u) {
        fputc('-', out);
        return;
    }
    for (size_t i = 0; i < n; ++i) {
        fprintf(out, "%02x", buf[i]);
    }
}

static int nibble(char c)
{
    if (c >= '0' && c <= '9') {
        return c - '0';
    }
    if (c >= 'a' && c <= 'f') {
        return c - 'a' + 10;
    }
    if (c >= 'A' && c <= 'F') {
        return c - 'A' + 10;
    }
    return -1;
}

int frame_text_parse_hex(const char *hex, uint8_t *out, size_t cap, size_t *n)
{
    *n = 0;
    if (strcmp(hex, "-") == 0) {
        return 0;
    }
    const size_t len = strlen(hex);
    if (len % 2u != 0u || len / 2u > cap) {
        return -1;
    }
    for (size_t i = 0; i < len / 2u; ++i) {
        const int hi = nibble(hex[2u * i]);
        const int lo = nibble(hex[2u * i + 1u]);
        if (hi < 0 || lo < 0) {
            return -1;
        }
        out[i] = (uint8_t)((hi << 4) | lo);
    }
    *n = len / 2u;
    return 0;
}

void frame_text_print(FILE *out, const arm_can_frame_t *f)
{
    fprintf(out, "0x%X %u 0x%02X ", (unsigned)f->id, (unsigned)f->len, (unsigned)f->flags);
    const size_t n = (f->flags & ARM_CAN_FLAG_RTR) ? 0u : f->len;
    frame_text_hex(out, f->data, n);
}
