/* The MCU image's service link to the host (its telemetry UART): telemetry records and, at the
 * end, the run's report, as frames a byte stream carries: 0xA5 0x5A, type, length (16 bits),
 * payload, CRC-16/CCITT of type, length and payload; little-endian fields. The image encodes
 * (telemetry_mcu.c), the host bridge decodes (tools/pil_bridge): both compile this file. The
 * decoder resynchronises on the next 0xA5 0x5A after a bad frame and counts it. No heap. */
#ifndef ARM_PIL_LINK_H
#define ARM_PIL_LINK_H

#include <stddef.h>
#include <stdint.h>

#include "controller_loop.h"
#include "telemetry.h"

#define PIL_SYNC0 0xA5u
#define PIL_SYNC1 0x5Au
#define PIL_HEADER 5u /* sync, type, length */
#define PIL_MAX_PAYLOAD 32768u

typedef enum {
    PIL_CTL = 1,     /* telem_controller_t, with the MCU's sequence number */
    PIL_TIMING = 2,  /* telem_timing_t, the MCU's sequence number, the step's instructions */
    PIL_EVENT = 3,   /* telem_event_t, the MCU's sequence number */
    PIL_REPORT = 4,  /* the run's report (run_report_t) and the image's own counts (pil_counts_t) */
} pil_type_t;

#define PIL_BUSES ARM_CAN_BUS_SET_MAX

/* What only the image knows: its telemetry ring's accounting, its stack, its SLCAN decoders. */
typedef struct {
    uint32_t telemetry_sent[TELEM_KIND_COUNT];
    uint32_t telemetry_dropped;
    uint32_t stack_high_water;   /* bytes of stack ever used (the painted stack) */
    uint32_t instructions_per_tick;
    uint32_t n_buses;
    uint32_t slcan_frames[PIL_BUSES], slcan_commands[PIL_BUSES], slcan_garbage[PIL_BUSES],
        slcan_too_long[PIL_BUSES], slcan_bad_dlc[PIL_BUSES], tx_dropped[PIL_BUSES], rx_closed[PIL_BUSES];
} pil_counts_t;

/* Encoders: the whole frame into out (cap bytes); its length, or 0 when it does not fit. */
size_t pil_encode_controller(const telem_controller_t *m, uint32_t seq, uint8_t *out, size_t cap);
size_t pil_encode_timing(const telem_timing_t *m, uint32_t seq, uint32_t step_instructions, uint8_t *out, size_t cap);
size_t pil_encode_event(const telem_event_t *m, uint32_t seq, uint8_t *out, size_t cap);
/* The report with its first max_writes SDO writes (of r->n_co_writes). */
size_t pil_encode_report(const run_report_t *r, unsigned max_writes, const pil_counts_t *c, uint8_t *out, size_t cap);

/* The decoder: bytes in, frames out. */
typedef struct {
    uint8_t buf[PIL_HEADER + PIL_MAX_PAYLOAD + 2u];
    size_t len;
    uint64_t frames, bad; /* frames decoded; frames refused (CRC, length, a record's own size) */
} pil_decoder_t;

typedef struct {
    pil_type_t type;
    uint32_t seq;
    union {
        telem_controller_t ctl;
        struct {
            telem_timing_t timing;
            uint32_t step_instructions;
        } t;
        telem_event_t event;
    } u;
} pil_record_t;

void pil_decoder_init(pil_decoder_t *d);
/* One byte. 1 when it ended a good frame: a telemetry record in *rec, or (PIL_REPORT) the report
 * and the counts in *report and *counts (both left untouched otherwise); 0 otherwise. */
int pil_decoder_byte(pil_decoder_t *d, uint8_t byte, pil_record_t *rec, run_report_t *report, pil_counts_t *counts);

#endif
