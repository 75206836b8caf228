/* SLCAN (the Lawicel ASCII protocol of USB-CAN adapters such as the CANable): CAN frames as text
 * lines on a serial link, one line per frame, '\r' ends a line. The portable codec: frame -> line,
 * and a line decoder fed one byte at a time. No heap, no OS calls, no recursion; every loop is
 * bounded by ARM_SLCAN_LINE_MAX. The MCU port (SLCAN over a UART) and the Linux transport (SLCAN
 * over a TCP socket, arm/can_slcan.h) share it.
 *
 * Frames (both directions; hex digits upper case when written, either case when read):
 *   tIIILDD..    classic, 11-bit id (3 hex), L = 0..8 data bytes
 *   TIIIIIIIILDD.. classic, 29-bit id (8 hex)
 *   rIIIL, RIIIIIIIIL  remote frames (L: the requested length)
 *   dIIILDD.., DIIIIIIIILDD..  CAN FD, L a DLC code 0..F (0..8, 12, 16, 20, 24, 32, 48, 64 bytes)
 *   bIIILDD.., BIIIIIIIILDD..  CAN FD with bit-rate switch (the CANable 2.0 extension, which
 *                python-can's slcan interface reads and writes)
 * A received frame line may end in a 4-hex-digit time stamp (an adapter's Z1 mode): it is read
 * and ignored. Command lines (O, C, L, S0-S8, Y.., s...., V, v, N, F, Z0/Z1, W, M, m, X, Q, U)
 * are returned as commands for the port to answer; an empty line is an adapter's "ok" and a line
 * ended by BEL (0x07) its "error".
 *
 * What the decoder refuses is counted and the line dropped, never more: a line that is no frame
 * and no command (garbage: an unknown first character, a non-hex digit, the wrong length, an id
 * out of range), a line longer than ARM_SLCAN_LINE_MAX (too long: counted once, when it overflows,
 * and skipped up to its end), a frame whose DLC is not one its kind has (bad DLC: 't' with '9',
 * 'd' with 'G'). */
#ifndef ARM_SLCAN_H
#define ARM_SLCAN_H

#include <stddef.h>
#include <stdint.h>

#include "arm/can_frame.h"

/* The longest line read or written, '\r' not counted: 'D' + 8 id + 1 DLC + 128 data digits + a
 * 4-digit time stamp. */
#define ARM_SLCAN_LINE_MAX 142u
#define ARM_SLCAN_CR '\r'
#define ARM_SLCAN_BEL '\a'

/* frame -> line (with its '\r'), into out (at least ARM_SLCAN_LINE_MAX + 1 bytes). Returns the
 * line's length, or 0 for a frame SLCAN cannot carry (an error frame, ESI, an FD remote frame, an
 * id or length out of range). */
size_t arm_slcan_encode(const arm_can_frame_t *f, char *out);

typedef enum {
    ARM_SLCAN_NONE = 0,   /* the line goes on (or a refused line was dropped: see the counters) */
    ARM_SLCAN_FRAME,      /* a frame line ended: the frame */
    ARM_SLCAN_COMMAND,    /* a command line ended: its text (no '\r') in the decoder's line */
    ARM_SLCAN_OK,         /* an empty line: an adapter's "ok" */
    ARM_SLCAN_ERROR,      /* a line ended by BEL: an adapter's "error" */
} arm_slcan_event_t;

typedef struct {
    uint64_t frames;   /* frame lines decoded */
    uint64_t commands; /* command lines */
    uint64_t replies;  /* ok and error replies */
    uint64_t garbage;  /* lines that are neither */
    uint64_t too_long; /* lines over ARM_SLCAN_LINE_MAX */
    uint64_t bad_dlc;  /* frame lines with a DLC their kind does not have */
} arm_slcan_counters_t;

typedef struct {
    char line[ARM_SLCAN_LINE_MAX + 1u]; /* the line so far; NUL-terminated after a COMMAND */
    uint16_t len;
    uint8_t overflow; /* the line under way is too long: skipped to its end */
    arm_slcan_counters_t n;
} arm_slcan_rx_t;

void arm_slcan_rx_init(arm_slcan_rx_t *rx);
/* One received byte. A frame line's end gives ARM_SLCAN_FRAME and the frame in *f (f untouched
 * otherwise). */
arm_slcan_event_t arm_slcan_rx_byte(arm_slcan_rx_t *rx, uint8_t byte, arm_can_frame_t *f);
/* What the decoder refused: garbage + too long + bad DLC. */
uint64_t arm_slcan_rx_refused(const arm_slcan_rx_t *rx);

/* The frame length (bytes) of an FD DLC code 0..15. */
uint8_t arm_slcan_fd_len(unsigned dlc);

#endif
