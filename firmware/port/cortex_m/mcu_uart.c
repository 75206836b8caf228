#include "mcu_uart.h"

/* CMSDK APB UART registers (ARM DDI 0479) */
#define R_DATA 0u
#define R_STATE 1u
#define R_CTRL 2u
#define R_INT 3u /* INTSTATUS on read, INTCLEAR on write */
#define R_BAUDDIV 4u
#define STATE_TXFULL 0x1u
#define STATE_RXFULL 0x2u
#define CTRL_TXEN 0x1u
#define CTRL_RXEN 0x2u
#define CTRL_TXINT 0x4u
#define CTRL_RXINT 0x8u
#define INT_TX 0x1u
#define INT_RX 0x2u

#define NVIC_ISER ((volatile uint32_t *)0xE000E100u)

static const uint32_t k_base[MCU_UARTS] = {0x40004000u, 0x40005000u, 0x40006000u, 0x40007000u, 0x40009000u};
/* each UART's receive interrupt; its transmit interrupt is the next one */
static const uint8_t k_rx_irq[MCU_UARTS] = {0u, 2u, 4u, 18u, 20u};

static mcu_uart_t g_uart[MCU_UARTS];

static volatile uint32_t *reg(unsigned index)
{
    return (volatile uint32_t *)(uintptr_t)k_base[index];
}

/* What the UART has received, into the ring (stops when the ring is full). Interrupts masked. */
static void rx_service(unsigned index)
{
    mcu_uart_t *u = &g_uart[index];
    volatile uint32_t *r = reg(index);
    r[R_INT] = INT_RX;
    while ((r[R_STATE] & STATE_RXFULL) != 0u) {
        if (u->rx_head - u->rx_tail > u->rx_mask) {
            u->rx_paused = 1u; /* the byte stays in the UART until the reader makes room */
            r[R_CTRL] &= ~CTRL_RXINT;
            /* A byte taken since the clear above latched the receive status again, and the status
             * drives the interrupt line whatever RXINT says: left set, the interrupt would repeat
             * forever and the reader never run (seen: the image silent at 100 % CPU). */
            r[R_INT] = INT_RX;
            return;
        }
        u->rx[u->rx_head & u->rx_mask] = (uint8_t)r[R_DATA];
        u->rx_head++;
    }
}

/* What the ring holds, to the UART while it takes bytes. Interrupts masked. */
static void tx_service(unsigned index)
{
    mcu_uart_t *u = &g_uart[index];
    volatile uint32_t *r = reg(index);
    r[R_INT] = INT_TX;
    while (u->tx_tail != u->tx_head && (r[R_STATE] & STATE_TXFULL) == 0u) {
        r[R_DATA] = u->tx[u->tx_tail & u->tx_mask];
        u->tx_tail++;
    }
}

void mcu_uart_init(unsigned index, uint8_t *rx, uint32_t rx_size, uint8_t *tx, uint32_t tx_size)
{
    mcu_uart_t *u = &g_uart[index];
    u->rx = rx;
    u->tx = tx;
    u->rx_mask = rx_size - 1u;
    u->tx_mask = tx_size - 1u;
    u->rx_head = u->rx_tail = u->tx_head = u->tx_tail = 0u;
    u->rx_paused = 0u;
    /* On before its interrupt can fire: the handler passes over a UART that is not on, and a byte
     * the peer sent early (its O) raises the receive interrupt as soon as reception is enabled; a
     * level left set that way repeats forever (seen: one PIL boot in about 20, silent at 100 % CPU). */
    u->on = 1u;
    __asm__ volatile("" ::: "memory"); /* the rings' setup too, before the registers below */
    volatile uint32_t *r = reg(index);
    r[R_BAUDDIV] = MCU_SYSCLK_HZ / 115200u; /* QEMU does not pace bytes; a real UART would */
    r[R_CTRL] = CTRL_TXEN | CTRL_RXEN | CTRL_TXINT | CTRL_RXINT;
    const unsigned irq = k_rx_irq[index];
    NVIC_ISER[0] = (1u << irq) | (1u << (irq + 1u));
}

int mcu_uart_write(unsigned index, const void *data, size_t n)
{
    mcu_uart_t *u = &g_uart[index];
    if (n > mcu_uart_tx_free(index)) return 0;
    const uint8_t *b = data;
    for (size_t i = 0; i < n; ++i) {
        u->tx[(u->tx_head + i) & u->tx_mask] = b[i];
    }
    const uint32_t m = mcu_irq_save();
    u->tx_head += (uint32_t)n;
    tx_service(index);
    mcu_irq_restore(m);
    return 1;
}

uint32_t mcu_uart_tx_free(unsigned index)
{
    const mcu_uart_t *u = &g_uart[index];
    return u->tx_mask + 1u - (u->tx_head - u->tx_tail);
}

int mcu_uart_tx_empty(unsigned index)
{
    return g_uart[index].tx_head == g_uart[index].tx_tail;
}

int mcu_uart_read(unsigned index, uint8_t *byte)
{
    mcu_uart_t *u = &g_uart[index];
    if (u->rx_tail == u->rx_head) {
        if (!u->rx_paused) return 0;
        const uint32_t m = mcu_irq_save(); /* the ring was full: take what waits in the UART */
        u->rx_paused = 0u;
        reg(index)[R_CTRL] |= CTRL_RXINT;
        rx_service(index);
        mcu_irq_restore(m);
        if (u->rx_tail == u->rx_head) return 0;
    }
    *byte = u->rx[u->rx_tail & u->rx_mask];
    u->rx_tail++;
    return 1;
}

static int rx_waiting(void)
{
    int waiting = 0;
    for (unsigned i = 0; i < MCU_UARTS; ++i) {
        waiting |= g_uart[i].on && (g_uart[i].rx_head != g_uart[i].rx_tail || g_uart[i].rx_paused);
    }
    return waiting;
}

/* Polls first, then sleeps: bytes of an answer come a few tens of microseconds apart, and a WFI
 * between two of them costs QEMU two thread wake-ups (measured: 31 ms for a period's 216 bytes,
 * 0.6 ms polling). */
#define POLLS_BEFORE_WFI 2000000u

void mcu_uart_wait(void)
{
    for (uint32_t i = 0; i < POLLS_BEFORE_WFI; ++i) {
        if (rx_waiting()) return;
    }
    const uint32_t m = mcu_irq_save();
    if (!rx_waiting()) __asm__ volatile("wfi");
    mcu_irq_restore(m);
}

void mcu_uart_irq(void)
{
    for (unsigned i = 0; i < MCU_UARTS; ++i) {
        if (!g_uart[i].on) continue;
        const uint32_t status = reg(i)[R_INT];
        if ((status & INT_RX) != 0u) {
            if (g_uart[i].rx_paused) reg(i)[R_INT] = INT_RX; /* the reader takes the byte; never a status left set */
            else rx_service(i);
        }
        if ((status & INT_TX) != 0u) tx_service(i);
    }
}

void External_IRQHandler(void);
void External_IRQHandler(void)
{
    mcu_uart_irq(); /* the UARTs are the only interrupt sources the image enables */
}
