/* The CANopen master's faults as one line (canopen_text.h). */
#define _POSIX_C_SOURCE 200809L
#include "canopen_text.h"

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm/co_sdo.h"

/* "pp, pv, hm" from 0x6502's bits (CiA 402: bit k is mode k + 1; 16..31 the manufacturer's). */
void canopen_modes_text(uint32_t modes, char *out, size_t cap)
{
    static const char *const names[] = {"pp", "vl", "pv", "tq", NULL, "hm", "ip", "csp", "csv", "cst", "cstca"};
    size_t used = 0u;
    out[0] = '\0';
    for (unsigned bit = 0; bit <= 16u && used < cap; ++bit) {
        const int set = bit < 16u ? ((modes >> bit) & 1u) != 0u : (modes >> 16) != 0u;
        const char *name = bit == 16u ? "manufacturer-specific" : bit < sizeof(names) / sizeof(names[0]) ? names[bit]
                                                                                                          : NULL;
        if (!set || name == NULL) continue;
        const int n = snprintf(out + used, cap - used, "%s%s", used ? ", " : "", name);
        used += n > 0 ? (size_t)n : 0u;
    }
    if (used == 0u) snprintf(out, cap, "none");
}

/* The unit object's name, and the drive table field that gives it. */
static void unit_names(uint16_t index, const char **what, const char **field)
{
    *what = index == 0x6076u ? "motor rated torque" : index == 0x608Fu ? "encoder increments per motor revolutions"
          : index == 0x6091u ? "gear ratio (motor per shaft revolutions)" : "max torque (per-mille)";
    *field = index == 0x6076u ? "rated_torque_nm" : index == 0x608Fu ? "encoder_increments" : "gear";
}

/* "2000/1" for a ratio (0x608F, 0x6091), "150000" for a plain value. */
static void ratio_text(uint16_t index, uint32_t num, uint32_t den, char *out, size_t cap)
{
    if (index == 0x608Fu || index == 0x6091u) {
        snprintf(out, cap, "%u/%u", num, den);
    } else {
        snprintf(out, cap, "%u", num);
    }
}

void canopen_fault_text(const arm_co_fault_t *f, char *out, size_t cap)
{
    const char *what = NULL, *field = NULL;
    char a[96], b[32], modes[160];
    switch (f->code) {
    case ARM_CO_FAULT_SDO_ABORT:
    case ARM_CO_FAULT_CLIENT_ABORT:
        snprintf(out, cap, "node %u: 0x%04X:%02X: %s 0x%08X (%s)", f->node, f->index, f->sub,
                 f->code == ARM_CO_FAULT_SDO_ABORT ? "SDO abort" : "master aborted the response with",
                 f->abort_code, arm_co_abort_text(f->abort_code));
        break;
    case ARM_CO_FAULT_NO_ANSWER:
        snprintf(out, cap, "node %u: 0x%04X:%02X: no answer after %u tries (SDO abort 0x%08X sent)", f->node,
                 f->index, f->sub, f->tries, f->abort_code);
        break;
    case ARM_CO_FAULT_WRONG_VALUE:
        if (f->index == 0x1000u) {
            snprintf(out, cap, "node %u: 0x1000:00: device type 0x%08X: profile 0x%04X, not CiA 402 (0x%04X)", f->node,
                     f->value, f->value & 0xFFFFu, f->expected);
        } else {
            snprintf(out, cap, "node %u: 0x%04X:%02X: read 0x%08X, expected 0x%08X", f->node, f->index, f->sub,
                     f->value, f->expected);
        }
        break;
    case ARM_CO_FAULT_NO_CST:
        canopen_modes_text(f->modes, modes, sizeof(modes));
        if (f->index == 0x6060u) {
            snprintf(a, sizeof(a), " (SDO abort 0x%08X)", f->abort_code);
        } else {
            a[0] = '\0';
        }
        if (f->has_modes) {
            snprintf(out, cap, "node %u: 0x%04X:00: no cyclic synchronous torque (mode 10), which this controller needs%s; "
                     "the drive offers %s (0x6502 = 0x%08X)", f->node, f->index, a, modes, f->modes);
        } else {
            snprintf(out, cap, "node %u: 0x6060:00: the drive refused mode 10 (cyclic synchronous torque), which this "
                     "controller needs%s; it has no 0x6502 to say which modes it offers", f->node, a);
        }
        break;
    case ARM_CO_FAULT_UNITS_MISMATCH:
        unit_names(f->index, &what, &field);
        ratio_text(f->index, f->value, f->value_den, a, sizeof(a));
        ratio_text(f->index, f->expected, f->expected_den, b, sizeof(b));
        snprintf(out, cap, "node %u: 0x%04X %s: the drive has %s, the drive table says %s (%s)", f->node, f->index,
                 what, a, b, field);
        break;
    case ARM_CO_FAULT_UNITS_MISSING:
        unit_names(f->index, &what, &field);
        snprintf(out, cap, "node %u: 0x%04X %s: the drive has no such object, and the drive table gives no %s",
                 f->node, f->index, what, field);
        break;
    case ARM_CO_FAULT_BAD_UNITS:
        unit_names(f->index, &what, &field);
        ratio_text(f->index, f->value, f->value_den, a, sizeof(a));
        snprintf(out, cap, "node %u: 0x%04X %s: the drive has %s, from which no unit can be made", f->node, f->index,
                 what, a);
        break;
    case ARM_CO_FAULT_TORQUE_LIMIT: {
        const arm_co_drive_units_t *u = &f->units;
        arm_co_units_t si;
        const double max_nm = arm_co_units_init(&si, u->rated_torque, u->torque_units_per_nm, (double)u->gear_efficiency,
                                                u->encoder_increments, u->encoder_revs, u->gear_motor_revs,
                                                u->gear_shaft_revs, (int16_t)u->max_torque_permille) == 0
                                  ? arm_co_units_max_joint_torque_nm(&si) : 0.0;
        snprintf(out, cap, "node %u: the joint's torque limit %.6g N m is more than the drive gives at the joint, "
                 "%.6g N m = 0x6072 %u per-mille x 0x6076 %u %s x gear %u/%u x efficiency %.6g", f->node,
                 (double)f->limit_nm, max_nm, u->max_torque_permille, u->rated_torque,
                 u->torque_units_per_nm == 1000000u ? "uN m" : "mN m", u->gear_motor_revs, u->gear_shaft_revs,
                 (double)u->gear_efficiency);
        break;
    }
    case ARM_CO_FAULT_NO_WATCHDOG:
        if (f->abort_code == ARM_CO_ABORT_NO_OBJECT || f->abort_code == ARM_CO_ABORT_NO_SUB) {
            snprintf(a, sizeof(a), "the drive has no such object (SDO abort 0x%08X)", f->abort_code);
        } else if (f->abort_code != 0u) {
            snprintf(a, sizeof(a), "the drive refused the master's 0x%08X (SDO abort 0x%08X)", f->value, f->abort_code);
        } else {
            snprintf(a, sizeof(a), "a consumer time of 0 ms turns it off");
        }
        snprintf(out, cap, "node %u: 0x1016:01 (consumer heartbeat, the drive's watchdog on the master): %s; a dead "
                 "master would leave this drive applying its last torque; refused (a drive table that accepts this "
                 "says accept_no_master_watchdog = true)", f->node, a);
        break;
    case ARM_CO_FAULT_STATE_TIMEOUT:
        snprintf(out, cap, "node %u: 0x6041:00: statusword 0x%04X did not reach 0x%02X (under mask 0x%02X)", f->node,
                 f->value, f->expected & 0xFFu, f->expected >> 8);
        break;
    case ARM_CO_FAULT_DRIVE_FAULT:
        snprintf(out, cap, "node %u: 0x6041:00: statusword 0x%04X shows fault (bit 3) while waiting for 0x%02X",
                 f->node, f->value, f->expected & 0xFFu);
        break;
    case ARM_CO_FAULT_BAD_CONFIG:
        snprintf(out, cap, "node %u: bad configuration (value %u)", f->node, f->value);
        break;
    case ARM_CO_FAULT_NONE:
    default:
        snprintf(out, cap, "no fault");
        break;
    }
}

int canopen_parse_u32(const char *s, uint32_t lo, uint32_t hi, uint32_t *out)
{
    char *end = NULL;
    errno = 0;
    const unsigned long long v = strtoull(s, &end, 0);
    if (errno != 0 || end == s || *end != '\0' || s[0] == '-' || v < lo || v > hi) {
        return -1;
    }
    *out = (uint32_t)v;
    return 0;
}

/* A finite number, as a whole string; -1 otherwise. */
static int canopen_parse_double(const char *s, double *out)
{
    char *end = NULL;
    errno = 0;
    const double v = strtod(s, &end);
    if (errno != 0 || end == s || *end != '\0' || !(v == v) || v - v != 0.0) {
        return -1;
    }
    *out = v;
    return 0;
}

/* "ID[,key=value]..." into nc; -1 with a message naming the option's field. */
int canopen_parse_node(const char *arg, arm_co_node_config_t *nc, char *err, size_t cap)
{
    char buf[256];
    if (strlen(arg) >= sizeof(buf)) {
        snprintf(err, cap, "--node '%.40s...': too long", arg);
        return -1;
    }
    strcpy(buf, arg);
    *nc = (arm_co_node_config_t){0};
    char *save = NULL;
    char *tok = strtok_r(buf, ",", &save);
    uint32_t v = 0;
    if (tok == NULL || canopen_parse_u32(tok, 1u, 127u, &v) != 0) {
        snprintf(err, cap, "--node '%s': the node id must be 1..127", arg);
        return -1;
    }
    nc->node_id = (uint8_t)v;
    while ((tok = strtok_r(NULL, ",", &save)) != NULL) {
        char *eq = strchr(tok, '=');
        if (eq == NULL) {
            snprintf(err, cap, "--node '%s': '%s' is not key=value", arg, tok);
            return -1;
        }
        *eq = '\0';
        const char *val = eq + 1;
        int bad = 0;
        if (strcmp(tok, "rated") == 0) {
            bad = canopen_parse_u32(val, 1u, UINT32_MAX, &nc->rated_torque);
            nc->expect |= ARM_CO_EXPECT_RATED;
        } else if (strcmp(tok, "encoder") == 0) {
            bad = canopen_parse_u32(val, 1u, UINT32_MAX, &nc->encoder_increments);
            nc->expect |= ARM_CO_EXPECT_ENCODER;
        } else if (strcmp(tok, "gear") == 0) {
            char *slash = strchr(val, '/');
            if (slash == NULL) {
                bad = -1;
            } else {
                *slash = '\0';
                bad = canopen_parse_u32(val, 1u, UINT32_MAX, &nc->gear_motor_revs) ||
                      canopen_parse_u32(slash + 1, 1u, UINT32_MAX, &nc->gear_shaft_revs);
            }
            nc->expect |= ARM_CO_EXPECT_GEAR;
        } else if (strcmp(tok, "torque_unit") == 0) {
            bad = strcmp(val, "mNm") != 0 && strcmp(val, "uNm") != 0;
            nc->torque_units_per_nm = strcmp(val, "uNm") == 0 ? 1000000u : 1000u;
        } else if (strcmp(tok, "efficiency") == 0) {
            double e = 0.0;
            bad = canopen_parse_double(val, &e) != 0 || !(e > 0.0 && e <= 1.0);
            nc->gear_efficiency = (float)e;
        } else if (strcmp(tok, "limit") == 0) {
            double l = 0.0;
            bad = canopen_parse_double(val, &l) != 0 || !(l > 0.0 && l < 1e9);
            nc->joint_torque_limit_nm = (float)l;
        } else if (strcmp(tok, "accept_no_master_watchdog") == 0) {
            bad = strcmp(val, "true") != 0;
            nc->accept_no_master_watchdog = 1u;
        } else if (strcmp(tok, "vendor") == 0) {
            bad = canopen_parse_u32(val, 0u, UINT32_MAX, &nc->vendor_id);
        } else if (strcmp(tok, "product") == 0) {
            bad = canopen_parse_u32(val, 0u, UINT32_MAX, &nc->product_code);
        } else if (strcmp(tok, "quick_stop") == 0) {
            bad = canopen_parse_u32(val, 1u, UINT32_MAX, &nc->quick_stop_decel);
        } else {
            snprintf(err, cap, "--node '%s': unknown field '%s' (rated, encoder, gear, torque_unit, efficiency, limit, "
                     "accept_no_master_watchdog, vendor, product, quick_stop)", arg, tok);
            return -1;
        }
        if (bad) {
            snprintf(err, cap, "--node '%s': field %s: expected %s", arg, tok,
                     strcmp(tok, "gear") == 0          ? "MOTOR/SHAFT revolutions, both >= 1"
                     : strcmp(tok, "torque_unit") == 0 ? "mNm or uNm"
                     : strcmp(tok, "efficiency") == 0  ? "the gear's efficiency, above 0 and at most 1"
                     : strcmp(tok, "limit") == 0       ? "the joint's torque limit in N m, above 0"
                     : strcmp(tok, "accept_no_master_watchdog") == 0 ? "true"
                                                       : "an unsigned 32-bit number");
            return -1;
        }
    }
    return 0;
}

