#include "arm/slcan.h"

#include <string.h>

static const uint8_t k_fd_len[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};
static const char k_hex[] = "0123456789ABCDEF";

uint8_t arm_slcan_fd_len(unsigned dlc)
{
    return dlc < 16u ? k_fd_len[dlc] : 0u;
}

/* The DLC code of an FD length, or -1. */
static int fd_dlc(unsigned len)
{
    for (unsigned d = 0; d < 16u; ++d) {
        if (k_fd_len[d] == len) return (int)d;
    }
    return -1;
}

static size_t put_hex(char *out, uint32_t v, unsigned digits)
{
    for (unsigned i = 0; i < digits; ++i) {
        out[digits - 1u - i] = k_hex[(v >> (4u * i)) & 0xFu];
    }
    return digits;
}

size_t arm_slcan_encode(const arm_can_frame_t *f, char *out)
{
    const int ext = (f->flags & ARM_CAN_FLAG_EXT) != 0u;
    const int fd = (f->flags & ARM_CAN_FLAG_FD) != 0u;
    const int rtr = (f->flags & ARM_CAN_FLAG_RTR) != 0u;
    if ((f->flags & (ARM_CAN_FLAG_ERR | ARM_CAN_FLAG_ESI)) != 0u || (rtr && fd) ||
        ((f->flags & ARM_CAN_FLAG_BRS) != 0u && !fd) || f->id > (ext ? 0x1FFFFFFFu : 0x7FFu)) {
        return 0u;
    }
    int dlc = (int)f->len;
    if (fd) {
        dlc = fd_dlc(f->len);
    } else if (f->len > 8u) {
        dlc = -1;
    }
    if (dlc < 0) return 0u;
    char kind = rtr ? 'r' : (fd ? ((f->flags & ARM_CAN_FLAG_BRS) ? 'b' : 'd') : 't');
    if (ext) kind = (char)(kind - 'a' + 'A');
    size_t n = 0;
    out[n++] = kind;
    n += put_hex(out + n, f->id, ext ? 8u : 3u);
    out[n++] = k_hex[dlc];
    for (unsigned i = 0; !rtr && i < f->len; ++i) {
        n += put_hex(out + n, f->data[i], 2u);
    }
    out[n++] = ARM_SLCAN_CR;
    return n;
}

void arm_slcan_rx_init(arm_slcan_rx_t *rx)
{
    memset(rx, 0, sizeof(*rx));
}

static int hex_value(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
}

/* digits hex digits at s, or -1 if one is not a hex digit */
static int64_t read_hex(const char *s, unsigned digits)
{
    int64_t v = 0;
    for (unsigned i = 0; i < digits; ++i) {
        const int d = hex_value(s[i]);
        if (d < 0) return -1;
        v = (v << 4) | d;
    }
    return v;
}

typedef enum { LINE_FRAME, LINE_GARBAGE, LINE_BAD_DLC } line_kind_t;

/* A frame line (its first character is a frame kind) into f. */
static line_kind_t decode_frame(const char *s, unsigned len, arm_can_frame_t *f)
{
    const char kind = s[0];
    const int ext = kind >= 'A' && kind <= 'Z';
    const char lower = (char)(ext ? kind - 'A' + 'a' : kind);
    const int fd = lower == 'd' || lower == 'b';
    const int rtr = lower == 'r';
    const unsigned id_digits = ext ? 8u : 3u;
    if (len < 1u + id_digits + 1u) return LINE_GARBAGE;
    const int64_t id = read_hex(s + 1, id_digits);
    if (id < 0 || id > (ext ? 0x1FFFFFFF : 0x7FF)) return LINE_GARBAGE;
    const int dlc = hex_value(s[1u + id_digits]);
    if (dlc < 0 || (!fd && dlc > 8)) return LINE_BAD_DLC; /* no DLC of its kind */
    const unsigned bytes = fd ? k_fd_len[dlc] : (unsigned)dlc;
    const unsigned head = 1u + id_digits + 1u;
    const unsigned data_digits = rtr ? 0u : 2u * bytes;
    /* the frame, then at most a 4-digit time stamp */
    if (len != head + data_digits && len != head + data_digits + 4u) return LINE_GARBAGE;
    if (len == head + data_digits + 4u && read_hex(s + head + data_digits, 4u) < 0) return LINE_GARBAGE;
    arm_can_frame_t g;
    memset(&g, 0, sizeof(g));
    for (unsigned i = 0; i < data_digits / 2u; ++i) {
        const int64_t b = read_hex(s + head + 2u * i, 2u);
        if (b < 0) return LINE_GARBAGE;
        g.data[i] = (uint8_t)b;
    }
    g.id = (uint32_t)id;
    g.len = (uint8_t)bytes;
    g.flags = (uint8_t)((ext ? ARM_CAN_FLAG_EXT : 0u) | (fd ? ARM_CAN_FLAG_FD : 0u) |
                        (lower == 'b' ? ARM_CAN_FLAG_BRS : 0u) | (rtr ? ARM_CAN_FLAG_RTR : 0u));
    *f = g;
    return LINE_FRAME;
}

/* The Lawicel commands (and their lengths' rule): a letter, then what it takes. */
static int is_command(const char *s, unsigned len)
{
    switch (s[0]) {
    case 'O': case 'C': case 'L': case 'V': case 'v': case 'N': case 'F': case 'Q': case 'U':
        return len == 1u || (s[0] == 'Q' && len == 2u) || (s[0] == 'U' && len == 2u);
    case 'S': return len == 2u && s[1] >= '0' && s[1] <= '9';  /* S0-S8 (S9: 83.3k on some) */
    case 'Y': return len == 2u && s[1] >= '0' && s[1] <= '9';  /* CANable 2.0: FD data rate */
    case 'Z': return len == 2u && (s[1] == '0' || s[1] == '1'); /* time stamps off / on */
    case 's': return len == 5u && read_hex(s + 1, 4u) >= 0;    /* BTR0 BTR1 */
    case 'M': case 'm': return len == 9u && read_hex(s + 1, 8u) >= 0; /* acceptance code / mask */
    case 'W': case 'X': return len == 2u && s[1] >= '0' && s[1] <= '9';
    default: return 0;
    }
}

static int is_frame_kind(char c)
{
    return c == 't' || c == 'T' || c == 'r' || c == 'R' || c == 'd' || c == 'D' || c == 'b' || c == 'B';
}

arm_slcan_event_t arm_slcan_rx_byte(arm_slcan_rx_t *rx, uint8_t byte, arm_can_frame_t *f)
{
    if (byte != (uint8_t)ARM_SLCAN_CR && byte != (uint8_t)ARM_SLCAN_BEL) {
        if (byte == (uint8_t)'\n' && rx->len == 0u && !rx->overflow) {
            return ARM_SLCAN_NONE; /* "\r\n" line ends: the '\n' starts nothing */
        }
        if (rx->overflow) return ARM_SLCAN_NONE;
        if (rx->len >= ARM_SLCAN_LINE_MAX) {
            rx->overflow = 1u;
            rx->n.too_long++;
            return ARM_SLCAN_NONE;
        }
        rx->line[rx->len++] = (char)byte;
        return ARM_SLCAN_NONE;
    }
    const unsigned len = rx->len;
    const int overflow = rx->overflow;
    rx->len = 0u;
    rx->overflow = 0u;
    if (overflow) return ARM_SLCAN_NONE; /* counted when it overflowed */
    if (byte == (uint8_t)ARM_SLCAN_BEL) {
        rx->n.replies++;
        return ARM_SLCAN_ERROR;
    }
    if (len == 0u) {
        rx->n.replies++;
        return ARM_SLCAN_OK;
    }
    if (is_frame_kind(rx->line[0])) {
        switch (decode_frame(rx->line, len, f)) {
        case LINE_FRAME: rx->n.frames++; return ARM_SLCAN_FRAME;
        case LINE_BAD_DLC: rx->n.bad_dlc++; return ARM_SLCAN_NONE;
        case LINE_GARBAGE: rx->n.garbage++; return ARM_SLCAN_NONE;
        }
    }
    if (is_command(rx->line, len)) {
        rx->line[len] = '\0';
        rx->n.commands++;
        return ARM_SLCAN_COMMAND;
    }
    rx->n.garbage++;
    return ARM_SLCAN_NONE;
}

uint64_t arm_slcan_rx_refused(const arm_slcan_rx_t *rx)
{
    return rx->n.garbage + rx->n.too_long + rx->n.bad_dlc;
}
