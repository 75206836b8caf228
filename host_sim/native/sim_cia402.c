#include "sim_cia402.h"

#include <math.h>

#define TWO_PI 6.283185307179586
#define MODES_OBJECT 0x6502u

int sim_cia402_mode_supported(const sim_co_od_t *od, int64_t mode)
{
    if (mode == SIM_CIA402_MODE_NONE) return 1;
    if (!sim_co_od_has(od, MODES_OBJECT, 0u)) return mode == SIM_CIA402_MODE_CST;
    return mode >= 1 && mode <= 16 && ((sim_co_od_get(od, MODES_OBJECT, 0u) >> (mode - 1)) & 1u) != 0u;
}

/* The object's value if the drive's file has it, else the drive table's (0: none). */
static double value_or(const sim_co_od_t *od, uint16_t index, uint8_t sub, uint32_t own)
{
    return sim_co_od_has(od, index, sub) ? (double)sim_co_od_get(od, index, sub) : (double)own;
}

int sim_cia402_scale(const sim_co_od_t *od, const sim_co_preset_t *own, sim_cia402_scale_t *sc)
{
    const double inc = value_or(od, 0x608Fu, 1u, own->encoder_increments), revs = value_or(od, 0x608Fu, 2u, 1u);
    const double motor = value_or(od, 0x6091u, 1u, own->gear_motor);
    const double shaft = value_or(od, 0x6091u, 2u, own->gear_shaft != 0u ? own->gear_shaft : 1u);
    const double rated = value_or(od, 0x6076u, 0u, own->rated_torque_mnm);
    const double efficiency = own->gear_efficiency > 0.0 ? own->gear_efficiency : 1.0;
    const int ok = inc > 0.0 && revs > 0.0 && motor > 0.0 && shaft > 0.0 && rated > 0.0 && efficiency <= 1.0;
    sc->inc_per_rad = ok ? inc / revs * motor / shaft / TWO_PI : 0.0;
    /* CiA 402: 0x6076 is the motor's; the driving shaft gets it times the gear, less the gear's losses */
    sc->joint_rated_nm = ok ? rated / (own->torque_units_per_nm != 0u ? (double)own->torque_units_per_nm : 1000.0) *
                                  (motor / shaft) * efficiency
                            : 0.0;
    return ok ? 0 : -1;
}

static double saturate(double x, double lo, double hi)
{
    if (isnan(x)) return 0.0;
    return x < lo ? lo : x > hi ? hi : x;
}

int32_t sim_cia402_increments(const sim_cia402_scale_t *sc, double rad)
{
    return (int32_t)saturate(nearbyint(rad * sc->inc_per_rad), -2147483648.0, 2147483647.0);
}

int16_t sim_cia402_permille(const sim_cia402_scale_t *sc, double nm)
{
    if (sc->joint_rated_nm <= 0.0) return 0;
    return (int16_t)saturate(nearbyint(nm / sc->joint_rated_nm * 1000.0), -32768.0, 32767.0);
}

double sim_cia402_target_nm(const sim_cia402_scale_t *sc, int32_t target_permille, uint32_t max_permille,
                            double limit_nm)
{
    const double m = (double)max_permille;
    const double nm = saturate((double)target_permille, -m, m) * 1e-3 * sc->joint_rated_nm;
    return saturate(nm, -limit_nm, limit_nm);
}
