#include "sim_cia402.h"

#include <math.h>

#define TWO_PI 6.283185307179586

int sim_cia402_mode_supported(int32_t mode)
{
    return mode == SIM_CIA402_MODE_NONE || mode == SIM_CIA402_MODE_CST;
}

void sim_cia402_scale(const sim_co_od_t *od, sim_cia402_scale_t *sc)
{
    /* Zero is refused by the EDS's limits, so these divisions are defined. */
    const double enc = (double)sim_co_od_get(od, 0x608Fu, 1u) / (double)sim_co_od_get(od, 0x608Fu, 2u);
    const double gear = (double)sim_co_od_get(od, 0x6091u, 1u) / (double)sim_co_od_get(od, 0x6091u, 2u);
    sc->inc_per_rad = enc * gear / TWO_PI;
    sc->rated_nm = (double)sim_co_od_get(od, 0x6076u, 0u) * 1e-3;
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
    return (int16_t)saturate(nearbyint(nm / sc->rated_nm * 1000.0), -32768.0, 32767.0);
}

double sim_cia402_target_nm(const sim_cia402_scale_t *sc, int32_t target_permille, uint32_t max_permille,
                            double limit_nm)
{
    const double m = (double)max_permille;
    const double nm = saturate((double)target_permille, -m, m) * 1e-3 * sc->rated_nm;
    return saturate(nm, -limit_nm, limit_nm);
}
