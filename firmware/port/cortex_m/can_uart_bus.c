/* arm/can_bus.h on the MCU: SLCAN on the board's UARTs (can_uart_bus.h). */
#include "arm/can_bus.h"

#include <stdio.h>
#include <string.h>

#include "loop_port.h"
#include "mcu_uart.h"

#define RX_RING 1024u
#define TX_RING 2048u

static uint8_t g_rx[ARM_CAN_BUS_UARTS][RX_RING];
static uint8_t g_tx[ARM_CAN_BUS_UARTS][TX_RING];
static const arm_can_bus_t *g_bus[ARM_CAN_BUS_UARTS];

const arm_can_bus_t *can_uart_bus_of(unsigned uart)
{
    return uart < ARM_CAN_BUS_UARTS ? g_bus[uart] : NULL;
}

static void reply(arm_can_bus_t *bus, const char *text)
{
    (void)mcu_uart_write(bus->uart, text, strlen(text));
}

/* A command line from the peer, answered as an SLCAN adapter answers it. */
static void command(arm_can_bus_t *bus, const char *line)
{
    switch (line[0]) {
    case 'O':
    case 'L': bus->open = 1; reply(bus, "\r"); return;  /* L: listen-only, taken as open */
    case 'C': bus->open = 0; reply(bus, "\r"); return;
    case 'V': reply(bus, "V1013\r"); return;
    case 'v': reply(bus, "v1013\r"); return;
    case 'N': reply(bus, "NPIL0\r"); return;
    case 'F': reply(bus, "F00\r"); return;           /* no error flags: no bus errors modelled */
    default: reply(bus, "\r"); return;                /* bit rates, filters, time stamps: no effect */
    }
}

/* The next frame from what the UART received (1), or 0 when its bytes are used up. */
static int take(arm_can_bus_t *bus, arm_can_frame_t *f)
{
    uint8_t b;
    for (unsigned i = 0; i < CAN_UART_MAX_BYTES && mcu_uart_read(bus->uart, &b); ++i) {
        switch (arm_slcan_rx_byte(&bus->dec, b, f)) {
        case ARM_SLCAN_FRAME:
            if (bus->open) return 1;
            bus->rx_closed++;
            break;
        case ARM_SLCAN_COMMAND: command(bus, bus->dec.line); break;
        default: break;
        }
    }
    return 0;
}

int arm_can_bus_open(arm_can_bus_t *bus, const char *spec, char *err, size_t errcap)
{
    arm_can_bus_spec_t s;
    memset(bus, 0, sizeof(*bus));
    if (arm_can_bus_parse_spec(spec, &s, err, errcap) != 0) return -1;
    if (s.kind != ARM_BUS_UART) {
        snprintf(err, errcap, "--bus: '%s': the MCU image's buses are its UARTs (uart:0 .. uart:%u)", spec,
                 ARM_CAN_BUS_UARTS - 1u);
        return -1;
    }
    bus->kind = ARM_BUS_UART;
    bus->uart = s.line;
    g_bus[s.line] = bus;
    arm_slcan_rx_init(&bus->dec);
    mcu_uart_init(s.line, g_rx[s.line], RX_RING, g_tx[s.line], TX_RING);
    /* an adapter's channel opens when its host says so: wait for the peer's O */
    const int64_t give_up = port_clock_ns() + CAN_UART_OPEN_TIMEOUT_NS;
    arm_can_frame_t f;
    while (!bus->open && port_clock_ns() < give_up) {
        if (!take(bus, &f)) mcu_uart_wait();
    }
    if (!bus->open) {
        snprintf(err, errcap, "--bus: '%s': the peer never opened the SLCAN channel (no O within %.0f s)", spec,
                 (double)CAN_UART_OPEN_TIMEOUT_NS * 1e-9);
        return -1;
    }
    return 0;
}

int arm_can_bus_send(arm_can_bus_t *bus, const arm_can_frame_t *f)
{
    if (!bus->open) {
        bus->tx_closed++;
        return ARM_BUS_E_CLOSED;
    }
    char line[ARM_SLCAN_LINE_MAX + 1u];
    const size_t n = arm_slcan_encode(f, line);
    if (n == 0u) {
        bus->tx_invalid++;
        return ARM_BUS_E_INVALID;
    }
    if (!mcu_uart_write(bus->uart, line, n)) {
        bus->tx_dropped++;
        return ARM_BUS_E_WOULD_BLOCK;
    }
    bus->tx_frames++;
    return ARM_BUS_OK;
}

unsigned arm_can_bus_send_many(arm_can_bus_t *bus, const arm_can_frame_t *frames, unsigned n)
{
    unsigned sent = 0;
    for (unsigned i = 0; i < n; ++i) sent += arm_can_bus_send(bus, &frames[i]) == ARM_BUS_OK;
    return sent;
}

int arm_can_bus_recv(arm_can_bus_t *bus, arm_can_frame_t *f, int timeout_us)
{
    const int64_t deadline = port_clock_ns() + (int64_t)timeout_us * 1000;
    for (;;) {
        if (take(bus, f)) return 1;
        if (timeout_us == 0 || (timeout_us > 0 && port_clock_ns() >= deadline)) return 0;
        mcu_uart_wait(); /* a byte's interrupt or the next SysTick */
    }
}

void arm_can_bus_close(arm_can_bus_t *bus)
{
    /* The last frames (an NMT stop) leave before the image ends, and it ends once the peer closed
     * the channel (C, when the drives have stopped), reading what comes meanwhile: the emulator then
     * closes its socket on nothing unread (a socket closed on unread bytes resets the peer's side). */
    const int64_t give_up = port_clock_ns() + CAN_UART_CLOSE_TIMEOUT_NS;
    arm_can_frame_t f;
    while ((!mcu_uart_tx_empty(bus->uart) || bus->open) && port_clock_ns() < give_up) {
        if (!take(bus, &f)) mcu_uart_wait();
    }
}

uint64_t arm_can_bus_rx_undecodable(const arm_can_bus_t *bus)
{
    return arm_slcan_rx_refused(&bus->dec);
}

uint64_t arm_can_bus_rx_kernel_drops(const arm_can_bus_t *bus)
{
    (void)bus;
    return 0u; /* nothing overruns: a full ring holds the UART back (mcu_uart.h) */
}

int arm_can_bus_set_open(arm_can_bus_set_t *set, const arm_can_bus_set_config_t *cfg, char *err, size_t errcap)
{
    memset(set, 0, sizeof(*set));
    for (unsigned i = 0; i < cfg->n && i < ARM_CAN_BUS_SET_MAX; ++i) {
        if (arm_can_bus_open(&set->bus[i], cfg->spec[i], err, errcap) != 0) return -1;
        set->n = i + 1u;
    }
    return 0;
}

int arm_can_bus_set_send(arm_can_bus_set_t *set, unsigned index, const arm_can_frame_t *f)
{
    return index < set->n ? arm_can_bus_send(&set->bus[index], f) : ARM_BUS_E_INVALID;
}

unsigned arm_can_bus_set_send_many(arm_can_bus_set_t *set, unsigned index, const arm_can_frame_t *frames, unsigned n)
{
    return index < set->n ? arm_can_bus_send_many(&set->bus[index], frames, n) : 0u;
}

int arm_can_bus_set_recv(arm_can_bus_set_t *set, arm_can_frame_t *f, unsigned *index, int timeout_us)
{
    if (set->n == 0u) return ARM_BUS_E_CLOSED;
    const int64_t deadline = port_clock_ns() + (int64_t)timeout_us * 1000;
    for (;;) {
        for (unsigned k = 0; k < set->n; ++k) { /* round-robin: no bus starves another */
            const unsigned i = (set->next + k) % set->n;
            if (take(&set->bus[i], f)) {
                *index = i;
                set->next = (i + 1u) % set->n;
                return 1;
            }
        }
        if (timeout_us == 0 || (timeout_us > 0 && port_clock_ns() >= deadline)) return 0;
        mcu_uart_wait();
    }
}

void arm_can_bus_set_close(arm_can_bus_set_t *set)
{
    for (unsigned i = 0; i < set->n; ++i) arm_can_bus_close(&set->bus[i]);
    set->n = 0u;
}

double arm_can_bus_set_sent_s(const arm_can_bus_set_t *set, unsigned index)
{
    (void)set;
    (void)index;
    return -1.0; /* SLCAN lines carry no sender's time */
}

double arm_can_bus_clock_s(void)
{
    return -1.0;
}
