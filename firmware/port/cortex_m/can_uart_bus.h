/* The MCU image's CAN buses (the interface is arm/can_bus.h, the Linux port's): SLCAN on the
 * board's UARTs, bus "uart:N" on UART N. QEMU's Cortex-M boards model no CAN controller, so the
 * controller's frames travel as SLCAN lines (arm/slcan.h) to the host, where the simulator's drives
 * read them (arm_sim --bus slcan:HOST:PORT). The port behaves as an SLCAN adapter to the other end:
 * its channel is closed until the peer sends O, and the port closes the bus once the peer sent C; it answers commands as an adapter does (\r ok,
 * \a error); frames are not acknowledged. What its decoder refuses (garbage, too long, a bad DLC)
 * is counted and dropped. No heap; every loop bounded. */
#ifndef ARM_CAN_UART_BUS_H
#define ARM_CAN_UART_BUS_H

#include <stdint.h>

#include "arm/can_bus_config.h"
#include "arm/slcan.h"

#define CAN_UART_OPEN_TIMEOUT_NS 60000000000LL /* for the peer's O, when the bus opens */
#define CAN_UART_MAX_BYTES 512u                 /* decoded per recv call at most, then it returns */
#define CAN_UART_CLOSE_TIMEOUT_NS 10000000000LL /* for the peer's C, when the bus closes */

typedef struct {
    arm_bus_kind_t kind;
    unsigned uart;
    int open;              /* the peer opened the channel (O) */
    arm_slcan_rx_t dec;
    uint64_t tx_frames;
    uint64_t tx_dropped;   /* the UART's ring had no room: dropped */
    uint64_t tx_closed;    /* sent while the channel was closed: dropped */
    uint64_t tx_invalid;   /* frames SLCAN cannot carry */
    uint64_t rx_closed;    /* frames that came while the channel was closed: dropped */
} arm_can_bus_t;

typedef struct {
    unsigned n;
    arm_can_bus_t bus[ARM_CAN_BUS_SET_MAX];
    unsigned next;
} arm_can_bus_set_t;

/* The bus opened on UART uart (its counters stay after the run's close), or NULL. */
const arm_can_bus_t *can_uart_bus_of(unsigned uart);

#endif
