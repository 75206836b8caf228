/* PDO codec and unit conversion (arm/co_pdo.h). Conversions run in double: an i32 position is
 * exact in it, a float would lose increments above 2^24 (32 motor revolutions at 2^19). */
#include "arm/co_pdo.h"

#include "arm/co_boot.h"

#define TWO_PI 6.283185307179586476925

static int is_finite(double x)
{
    return x == x && x - x == 0.0; /* NaN fails the first, +-inf the second */
}

/* Nearest integer, halves away from zero, clamped to [lo, hi]; non-finite gives 0. */
static int64_t round_clamp(double x, int64_t lo, int64_t hi)
{
    if (!is_finite(x)) {
        return 0;
    }
    if (x >= (double)hi) {
        return hi;
    }
    if (x <= (double)lo) {
        return lo;
    }
    const double r = x >= 0.0 ? x + 0.5 : x - 0.5;
    return (int64_t)r; /* truncation toward zero after the half shift */
}

int arm_co_units_init(arm_co_units_t *u, uint32_t rated_torque, uint32_t torque_units_per_nm,
                      double gear_efficiency, uint32_t encoder_increments, uint32_t encoder_revs,
                      uint32_t gear_motor_revs, uint32_t gear_shaft_revs, int16_t max_permille)
{
    if (rated_torque == 0u || torque_units_per_nm == 0u || encoder_increments == 0u || encoder_revs == 0u ||
        gear_motor_revs == 0u || gear_shaft_revs == 0u || max_permille <= 0 ||
        !(gear_efficiency > 0.0 && gear_efficiency <= 1.0)) {
        return -1;
    }
    const double gear = (double)gear_motor_revs / (double)gear_shaft_revs;
    /* CiA 402: 0x6076 is the motor's; the driving shaft gets it times the gear, less the gear's losses */
    u->joint_rated_torque_nm = (double)rated_torque / (double)torque_units_per_nm * gear * gear_efficiency;
    u->increments_per_rad = (double)encoder_increments / (double)encoder_revs * (double)gear_motor_revs /
                            (double)gear_shaft_revs / TWO_PI;
    u->max_permille = max_permille;
    return 0;
}

double arm_co_units_max_joint_torque_nm(const arm_co_units_t *u)
{
    return (double)u->max_permille * u->joint_rated_torque_nm / 1000.0;
}

int16_t arm_co_torque_to_permille(const arm_co_units_t *u, float torque_nm)
{
    return (int16_t)round_clamp((double)torque_nm * 1000.0 / u->joint_rated_torque_nm, -(int64_t)u->max_permille,
                                (int64_t)u->max_permille);
}

float arm_co_permille_to_torque(const arm_co_units_t *u, int16_t permille)
{
    return (float)((double)permille * u->joint_rated_torque_nm / 1000.0);
}

float arm_co_increments_to_rad(const arm_co_units_t *u, int32_t increments)
{
    return (float)((double)increments / u->increments_per_rad);
}

int32_t arm_co_rad_to_increments(const arm_co_units_t *u, float rad)
{
    return (int32_t)round_clamp((double)rad * u->increments_per_rad, INT32_MIN, INT32_MAX);
}

static void put16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

static uint16_t get16(const uint8_t *p)
{
    return (uint16_t)(p[0] | (p[1] << 8));
}

static uint32_t get32(const uint8_t *p)
{
    return (uint32_t)get16(p) | ((uint32_t)get16(p + 2) << 16);
}

void arm_co_pack_rpdo1(uint8_t node, uint16_t controlword, int16_t target_permille, arm_can_frame_t *out)
{
    *out = (arm_can_frame_t){0};
    out->id = ARM_CO_COB_RPDO1 + node;
    out->len = 4u;
    put16(&out->data[0], controlword);
    put16(&out->data[2], (uint16_t)target_permille);
}

static int pdo_ok(const arm_can_frame_t *f, uint32_t id, uint8_t len)
{
    return f->id == id && f->len == len && (f->flags & (ARM_CAN_FLAG_FD | ARM_CAN_FLAG_EXT | ARM_CAN_FLAG_RTR |
                                                        ARM_CAN_FLAG_ERR)) == 0u;
}

int arm_co_unpack_tpdo1(uint8_t node, const arm_can_frame_t *f, int32_t *position_inc, int32_t *velocity_inc_s)
{
    if (!pdo_ok(f, ARM_CO_COB_TPDO1 + node, 8u)) {
        return -1;
    }
    *position_inc = (int32_t)get32(&f->data[0]);
    *velocity_inc_s = (int32_t)get32(&f->data[4]);
    return 0;
}

int arm_co_unpack_tpdo2(uint8_t node, const arm_can_frame_t *f, int16_t *torque_permille, uint16_t *statusword)
{
    if (!pdo_ok(f, ARM_CO_COB_TPDO2 + node, 4u)) {
        return -1;
    }
    *torque_permille = (int16_t)get16(&f->data[0]);
    *statusword = get16(&f->data[2]);
    return 0;
}

void arm_co_state_si(const arm_co_units_t *u, int32_t position_inc, int32_t velocity_inc_s,
                     int16_t torque_permille, float *q_rad, float *qd_rad_s, float *tau_nm)
{
    *q_rad = arm_co_increments_to_rad(u, position_inc);
    *qd_rad_s = arm_co_increments_to_rad(u, velocity_inc_s);
    *tau_nm = arm_co_permille_to_torque(u, torque_permille);
}
