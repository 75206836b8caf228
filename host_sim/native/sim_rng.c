#include "sim_rng.h"

#include <math.h>

/* numpy/random/bit_generator.pyx: SeedSequence with pool size 4. */
#define INIT_A 0x43b0d7e5u
#define MULT_A 0x931e8875u
#define INIT_B 0x8b51f9ddu
#define MULT_B 0x58f38dedu
#define MIX_MULT_L 0xca01f9ddu
#define MIX_MULT_R 0x4973f715u
#define XSHIFT 16u
#define POOL 4u

static uint32_t hashmix(uint32_t value, uint32_t *hash_const)
{
    value ^= *hash_const;
    *hash_const *= MULT_A;
    value *= *hash_const;
    value ^= value >> XSHIFT;
    return value;
}

static uint32_t mix(uint32_t x, uint32_t y)
{
    uint32_t result = MIX_MULT_L * x - MIX_MULT_R * y;
    result ^= result >> XSHIFT;
    return result;
}

static void seed_sequence_state(uint64_t seed, uint64_t out[4])
{
    /* The entropy of an integer seed: its 32-bit words, least significant first (0 is [0]). */
    uint32_t entropy[2] = {(uint32_t)seed, (uint32_t)(seed >> 32)};
    const unsigned n_entropy = (seed >> 32) != 0u ? 2u : 1u;
    uint32_t pool[POOL];
    uint32_t hash_const = INIT_A;
    for (unsigned i = 0; i < POOL; ++i) {
        pool[i] = hashmix(i < n_entropy ? entropy[i] : 0u, &hash_const);
    }
    for (unsigned src = 0; src < POOL; ++src) {
        for (unsigned dst = 0; dst < POOL; ++dst) {
            if (src != dst) {
                pool[dst] = mix(pool[dst], hashmix(pool[src], &hash_const));
            }
        }
    }
    uint32_t words[8];
    uint32_t hc = INIT_B;
    for (unsigned i = 0; i < 8u; ++i) {
        uint32_t v = pool[i % POOL];
        v ^= hc;
        hc *= MULT_B;
        v *= hc;
        v ^= v >> XSHIFT;
        words[i] = v;
    }
    for (unsigned i = 0; i < 4u; ++i) {
        out[i] = (uint64_t)words[2u * i] | ((uint64_t)words[2u * i + 1u] << 32);
    }
}

#define PCG_MULT ((((unsigned __int128)2549297995355413924ULL) << 64) | 4865540595714422341ULL)

static void step(sim_rng_t *r)
{
    r->state = r->state * PCG_MULT + r->inc;
}

void sim_rng_seed(sim_rng_t *r, uint64_t seed)
{
    uint64_t v[4];
    seed_sequence_state(seed, v);
    const unsigned __int128 initstate = ((unsigned __int128)v[0] << 64) | v[1];
    const unsigned __int128 initseq = ((unsigned __int128)v[2] << 64) | v[3];
    r->state = 0u;
    r->inc = (initseq << 1) | 1u;
    step(r);
    r->state += initstate;
    step(r);
}

uint64_t sim_rng_next64(sim_rng_t *r)
{
    step(r);
    const uint64_t hi = (uint64_t)(r->state >> 64);
    const uint64_t lo = (uint64_t)r->state;
    const unsigned rot = (unsigned)(r->state >> 122);
    const uint64_t x = hi ^ lo;
    return (x >> rot) | (x << ((64u - rot) & 63u));
}

double sim_rng_double(sim_rng_t *r)
{
    return (double)(sim_rng_next64(r) >> 11) * (1.0 / 9007199254740992.0);
}

double sim_rng_uniform(sim_rng_t *r, double low, double high)
{
    return low + (high - low) * sim_rng_double(r);
}

double sim_py_floordiv(double a, double b)
{
    /* CPython's float_floor_div (Objects/floatobject.c), b != 0. */
    double mod = fmod(a, b);
    double div = (a - mod) / b;
    if (mod != 0.0) {
        if ((b < 0.0) != (mod < 0.0)) {
            div -= 1.0;
        }
    }
    if (div != 0.0) {
        double floordiv = floor(div);
        if (div - floordiv > 0.5) {
            floordiv += 1.0;
        }
        return floordiv;
    }
    return copysign(0.0, a / b);
}
