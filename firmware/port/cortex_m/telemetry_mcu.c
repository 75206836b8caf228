/* telemetry.h on the MCU: each message is encoded (pil_link.h) into one fixed ring, the telemetry
 * UART's transmit ring, which its interrupt drains to the host; there the bridge (tools/pil_bridge)
 * publishes the same LCM messages arm_controller does. Never blocks the loop: a message the ring
 * has no room for is dropped and counted, its sequence number used, so the log shows the gap. */
#include <stdio.h>
#include <string.h>

#include "arm/can_bus.h"
#include "loop_port.h"
#include "mcu_clock.h"
#include "mcu_uart.h"
#include "pil_link.h"
#include "telemetry.h"

#define TELEM_UART 4u
#define TELEM_RING 8192u /* about 30 periods of telemetry (a period's messages: about 270 bytes) */
#define REPORT_MAX 8192u /* the report's frame: the SDO writes of 6 drives take about 2.5 kB */

struct telemetry {
    uint64_t seq[TELEM_KIND_COUNT];
    uint64_t dropped;
};

static telemetry_t g_telem;
static uint8_t g_ring[TELEM_RING];
static uint8_t g_rx[16];

static void send(telemetry_t *t, const uint8_t *frame, size_t n)
{
    if (n == 0u || !mcu_uart_write(TELEM_UART, frame, n)) t->dropped++;
}

telemetry_t *telemetry_start(const char *url, char *err, unsigned long errcap)
{
    (void)url; /* the host bridge publishes on LCM */
    (void)err;
    (void)errcap;
    memset(&g_telem, 0, sizeof(g_telem));
    mcu_uart_init(TELEM_UART, g_rx, sizeof(g_rx), g_ring, sizeof(g_ring));
    return &g_telem;
}

void telemetry_controller(telemetry_t *t, const telem_controller_t *m)
{
    uint8_t frame[PIL_HEADER + 320u];
    send(t, frame, pil_encode_controller(m, (uint32_t)t->seq[TELEM_CONTROLLER]++, frame, sizeof(frame)));
}

void telemetry_timing(telemetry_t *t, const telem_timing_t *m)
{
    uint8_t frame[PIL_HEADER + 64u];
    send(t, frame, pil_encode_timing(m, (uint32_t)t->seq[TELEM_TIMING]++, mcu_last_step_instructions(), frame,
                                     sizeof(frame)));
}

void telemetry_event(telemetry_t *t, int64_t step, const char *level, const char *text)
{
    telem_event_t e;
    e.step = step;
    snprintf(e.level, sizeof(e.level), "%s", level);
    snprintf(e.text, sizeof(e.text), "%s", text);
    uint8_t frame[PIL_HEADER + 200u];
    send(t, frame, pil_encode_event(&e, (uint32_t)t->seq[TELEM_EVENT]++, frame, sizeof(frame)));
}

void telemetry_stop(telemetry_t *t)
{
    (void)t;
    const int64_t give_up = port_clock_ns() + 5000000000LL;
    while (!mcu_uart_tx_empty(TELEM_UART) && port_clock_ns() < give_up) __asm__ volatile("wfi");
}

uint64_t telemetry_sent(const telemetry_t *t, telem_kind_t kind)
{
    return t->seq[kind];
}

uint64_t telemetry_published(const telemetry_t *t, telem_kind_t kind)
{
    return t->seq[kind]; /* published by the bridge: what it logged shows in the log itself */
}

uint64_t telemetry_dropped(const telemetry_t *t)
{
    return t->dropped;
}

/* The run's report, after the telemetry: the ring is empty by then and holds it (the report is
 * written whole, waiting for room: the loop is over). */
void telemetry_mcu_report(telemetry_t *t, const run_report_t *r, uint32_t stack)
{
    static pil_counts_t c;
    memset(&c, 0, sizeof(c));
    for (int k = 0; k < (int)TELEM_KIND_COUNT; ++k) c.telemetry_sent[k] = (uint32_t)t->seq[k];
    c.telemetry_dropped = (uint32_t)t->dropped;
    c.stack_high_water = stack;
    c.instructions_per_tick = mcu_instructions_per_tick();
    for (unsigned b = 0; b < ARM_CAN_BUS_UARTS && b < PIL_BUSES; ++b) { /* by UART: bus b on uart:b */
        const arm_can_bus_t *x = can_uart_bus_of(b);
        if (x == NULL) continue;
        c.n_buses = b + 1u;
        c.slcan_frames[b] = (uint32_t)x->dec.n.frames;
        c.slcan_commands[b] = (uint32_t)x->dec.n.commands;
        c.slcan_garbage[b] = (uint32_t)x->dec.n.garbage;
        c.slcan_too_long[b] = (uint32_t)x->dec.n.too_long;
        c.slcan_bad_dlc[b] = (uint32_t)x->dec.n.bad_dlc;
        c.tx_dropped[b] = (uint32_t)x->tx_dropped;
        c.rx_closed[b] = (uint32_t)x->rx_closed;
    }
    static uint8_t frame[REPORT_MAX];
    size_t n = 0; /* a boot log longer than the frame takes: its first writes (the report says how many) */
    for (unsigned writes = r->n_co_writes; n == 0u; writes /= 2u) {
        n = pil_encode_report(r, writes, &c, frame, sizeof(frame));
        if (writes == 0u) break;
    }
    const int64_t give_up = port_clock_ns() + 10000000000LL; /* a host that stopped reading: no report */
    for (size_t at = 0; at < n && port_clock_ns() < give_up;) {
        const size_t chunk = n - at < 256u ? n - at : 256u;
        if (mcu_uart_write(TELEM_UART, frame + at, chunk)) {
            at += chunk;
        } else {
            __asm__ volatile("wfi");
        }
    }
    telemetry_stop(t);
}
