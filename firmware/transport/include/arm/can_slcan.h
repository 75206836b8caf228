/* A CAN bus over SLCAN (arm/slcan.h) on a TCP connection: the other end is an SLCAN adapter
 * behind a serial-to-TCP bridge (ser2net and the like), or the UART of an emulated MCU
 * (qemu-system-arm -chardev socket,server=on: tools/armctl hil --target). Spec "slcan:HOST:PORT".
 *
 * Open connects (retrying while nothing listens yet, for up to ARM_CAN_SLCAN_CONNECT_S: the peer
 * may start after us), then writes "O\r", the command that opens an adapter's channel: frames
 * flow from then on; close writes "C\r", which closes it. Each frame sent is one SLCAN line; each frame line received is a frame.
 * The adapter's replies (an empty line: ok; BEL: error) and command lines are not frames: read
 * and counted, never returned. A line the decoder refuses (garbage, too long, a bad DLC) is
 * counted in rx_undecodable and skipped.
 *
 * send never blocks: what the socket does not take at once waits in a transmit buffer, sent
 * before anything else; a frame that does not fit there is dropped and counted (tx_would_block).
 * recv waits up to a timeout, like the other socket transports (arm/fd_wait.h). Linux only. Not
 * thread-safe: one owner per arm_can_slcan_t. */
#ifndef ARM_CAN_SLCAN_H
#define ARM_CAN_SLCAN_H

#include <stddef.h>
#include <stdint.h>

#include "arm/can_frame.h"
#include "arm/slcan.h"

#define ARM_CAN_SLCAN_CONNECT_S 60.0 /* how long open waits for the peer to listen */
#define ARM_CAN_SLCAN_RX_BUF 4096u
#define ARM_CAN_SLCAN_TX_BUF 16384u
#define ARM_CAN_SLCAN_MAX_SKIP 64 /* refused lines one recv call may skip before it returns 0 */

typedef struct {
    int fd; /* -1 when closed */
    arm_slcan_rx_t dec;
    uint8_t rx[ARM_CAN_SLCAN_RX_BUF];
    size_t rx_pos, rx_len; /* bytes read, not yet decoded: rx[rx_pos .. rx_len) */
    char tx[ARM_CAN_SLCAN_TX_BUF];
    size_t tx_len; /* bytes the socket has not taken yet */
    int peer_closed;
    uint64_t tx_frames;      /* frames written (or buffered to be) */
    uint64_t tx_would_block; /* frames dropped: the transmit buffer was full */
    uint64_t tx_invalid;     /* frames SLCAN cannot carry (arm_slcan_encode) */
    uint64_t rx_frames;
    uint64_t rx_errors;      /* socket errors */
} arm_can_slcan_t;

/* host: an IPv4 address literal. 0, or -1 with a message naming the address in err. */
int arm_can_slcan_open(arm_can_slcan_t *bus, const char *host, uint16_t port, char *err, size_t errcap);
/* 0, or ARM_BUS_E_WOULD_BLOCK (dropped, counted), ARM_BUS_E_INVALID, ARM_BUS_E_IO, ARM_BUS_E_CLOSED. */
int arm_can_slcan_send(arm_can_slcan_t *bus, const arm_can_frame_t *f);
/* 1 with a frame, 0 on timeout, ARM_BUS_E_IO when the connection failed or the peer closed it. */
int arm_can_slcan_recv(arm_can_slcan_t *bus, arm_can_frame_t *f, int timeout_us);
void arm_can_slcan_close(arm_can_slcan_t *bus);

#endif
