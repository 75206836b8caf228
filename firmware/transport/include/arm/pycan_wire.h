/*
 * Codec for python-can's udp_multicast datagram: one msgpack map per CAN frame.
 *
 * Portable on purpose (only <stdint.h>, <stddef.h>, <string.h>; no heap, no
 * recursion, every loop bounded by the input length) so the same code can run
 * on the target and under a fuzzer. Assumes IEEE-754 binary64 `double`, which
 * is what msgpack float64 carries.
 */
#ifndef ARM_PYCAN_WIRE_H
#define ARM_PYCAN_WIRE_H

#include <stddef.h>
#include <stdint.h>

#include "arm/can_frame.h"

/*
 * Largest datagram arm_pycan_encode can produce (64-byte FD frame, 29-bit id).
 * Only a transmit bound: python-can senders with a channel string, wider
 * integer encodings or extra keys produce longer datagrams that still decode,
 * so receive buffers must be larger (can_udp uses python-can's 4096).
 */
#define ARM_PYCAN_MAX_ENCODED 220u

/* Decode results. Names are stable; tools print them (arm_pycan_errname). */
typedef enum {
    ARM_PYCAN_OK = 0,
    ARM_PYCAN_E_ARG = -1,           /* NULL pointer argument */
    ARM_PYCAN_E_TRUNCATED = -2,     /* input ends inside an object */
    ARM_PYCAN_E_NOT_MAP = -3,       /* top-level object is not a map */
    ARM_PYCAN_E_KEY_TYPE = -4,      /* a map key is not a string */
    ARM_PYCAN_E_DUPLICATE_KEY = -5, /* a known key appears twice */
    ARM_PYCAN_E_UNSUPPORTED = -6,   /* unknown key with array/map/ext value, or byte 0xc1 */
    ARM_PYCAN_E_WRONG_TYPE = -7,    /* known key carries the wrong msgpack type */
    ARM_PYCAN_E_MISSING_KEY = -8,   /* a required key is absent */
    ARM_PYCAN_E_BAD_LENGTH = -9,    /* dlc/data mismatch or length invalid for classic/FD */
    ARM_PYCAN_E_BAD_ID = -10,       /* id negative or out of range for its id width */
    ARM_PYCAN_E_BAD_FLAGS = -11,    /* flag combination python-can's Message check rejects */
    ARM_PYCAN_E_BAD_TIMESTAMP = -12,/* negative, infinite or NaN timestamp */
    ARM_PYCAN_E_TRAILING = -13      /* bytes after the map (msgpack "ExtraData") */
} arm_pycan_err_t;

/*
 * Encode `f` as python-can's pack_message would for an equal can.Message with
 * channel=None: same keys, same order, same msgpack encodings, so the bytes
 * are identical. For ARM_CAN_FLAG_RTR, f->len is the requested DLC and no data
 * is sent (python-can keeps remote frames data-less).
 * Returns bytes written, or 0 if cap is too small, an argument is NULL, the
 * frame is invalid (see arm_pycan_frame_valid) or the timestamp is negative,
 * infinite or NaN (python-can's Message check would reject it).
 */
size_t arm_pycan_encode(const arm_can_frame_t *f, double timestamp, uint8_t *buf, size_t cap);

/*
 * Decode one datagram. Key order is free. Required keys: every key
 * pack_message writes except "channel" (whose value, nil/str/int, is
 * ignored). Unknown keys with nil/bool/int/float/str/bin values are skipped;
 * unknown keys with container or ext values are rejected rather than walked.
 * On success fills *f (unused data bytes zeroed) and *timestamp and returns
 * ARM_PYCAN_OK; on failure returns a negative arm_pycan_err_t and leaves *f
 * and *timestamp in an unspecified state. `timestamp` may be NULL.
 */
int arm_pycan_decode(const uint8_t *buf, size_t n, arm_can_frame_t *f, double *timestamp);

/*
 * Frame validity shared by encoder and decoder: id in range for its width,
 * len legal for classic (0..8) or FD (0..8,12,16,20,24,32,48,64), BRS/ESI
 * only with FD, RTR neither with FD nor with ERR, classic RTR DLC <= 8.
 * Returns ARM_PYCAN_OK or ARM_PYCAN_E_BAD_ID / _BAD_LENGTH / _BAD_FLAGS / _ARG.
 */
int arm_pycan_frame_valid(const arm_can_frame_t *f);

/* Human-readable description of a result code; never NULL. */
const char *arm_pycan_strerror(int code);

/* Short stable token for a result code ("truncated", "bad_id", ...); never NULL. */
const char *arm_pycan_errname(int code);

#endif
