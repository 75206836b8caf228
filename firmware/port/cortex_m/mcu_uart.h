/* The CMSDK APB UARTs of QEMU's mps2 boards, interrupt-driven, each with a receive and a transmit
 * ring (no heap: the rings are the caller's static buffers). QEMU's UART holds one byte each way
 * and does not pace bytes at a baud rate: a byte written goes at once when the host side takes it.
 * The receive interrupt moves bytes into the ring; a full ring stops taking them (the byte waits
 * in the UART, and QEMU holds the rest in the host socket: flow control, nothing lost) until
 * mcu_uart_read makes room. The transmit side sends what the ring holds whenever the UART takes a
 * byte. All UARTs share one handler (mcu_uart_irq), which serves every UART's pending work. */
#ifndef ARM_MCU_UART_H
#define ARM_MCU_UART_H

#include <stddef.h>
#include <stdint.h>

#define MCU_UARTS 5u             /* UART0..UART4 of the mps2 boards */
#define MCU_SYSCLK_HZ 25000000u  /* the boards' APB and SysTick clock */

typedef struct {
    uint8_t *rx, *tx;      /* rings, sizes powers of two */
    uint32_t rx_mask, tx_mask;
    volatile uint32_t rx_head, rx_tail; /* the interrupt writes head, the reader tail */
    volatile uint32_t tx_head, tx_tail; /* the writer head, the interrupt tail */
    volatile uint8_t rx_paused;         /* the ring was full: the receive interrupt is off */
    volatile uint8_t on;                /* set before the UART's interrupt is enabled */
} mcu_uart_t;

/* Starts UART index with the given rings (sizes powers of two, >= 2). */
void mcu_uart_init(unsigned index, uint8_t *rx, uint32_t rx_size, uint8_t *tx, uint32_t tx_size);
/* Queues all n bytes, or none (returns 0) when the ring has not room for them. */
int mcu_uart_write(unsigned index, const void *data, size_t n);
uint32_t mcu_uart_tx_free(unsigned index);
int mcu_uart_tx_empty(unsigned index);
/* The next received byte (1), or 0 when none is queued. */
int mcu_uart_read(unsigned index, uint8_t *byte);
/* Sleeps until an interrupt (a byte, the next SysTick) unless a received byte already waits:
 * the check and the WFI with interrupts masked, so a byte that comes in between still wakes it. */
void mcu_uart_wait(void);
/* Every UART's receive and transmit work: the interrupt handler of all of them. */
void mcu_uart_irq(void);

/* Interrupt masking around the measured control step and the rings' shared indices. */
static inline uint32_t mcu_irq_save(void)
{
    uint32_t primask;
    __asm__ volatile("mrs %0, primask\n\tcpsid i" : "=r"(primask) : : "memory");
    return primask;
}

static inline void mcu_irq_restore(uint32_t primask)
{
    __asm__ volatile("msr primask, %0" : : "r"(primask) : "memory");
}

#endif
