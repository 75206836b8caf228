/* Random numbers that are numpy's, bit for bit: np.random.default_rng(seed) is PCG64 seeded
 * through SeedSequence, and Generator.uniform(low, high) is low + (high - low) * next_double.
 * The simulator's uncertainty is drawn from this stream in the order the earlier Python
 * simulator drew it, so a seed means the same arm and the same disturbance in both, and a
 * study's numbers stay comparable across the port (tests/c/sim/test_sim_rng.c checks numpy's
 * own output). */
#ifndef ARM_SIM_RNG_H
#define ARM_SIM_RNG_H

#include <stdint.h>

typedef struct {
    unsigned __int128 state;
    unsigned __int128 inc;
} sim_rng_t;

/* np.random.default_rng(seed) for 0 <= seed < 2^64. */
void sim_rng_seed(sim_rng_t *r, uint64_t seed);
uint64_t sim_rng_next64(sim_rng_t *r);
/* [0, 1) with 53 random bits, numpy's next_double. */
double sim_rng_double(sim_rng_t *r);
/* Generator.uniform(low, high) for one value. */
double sim_rng_uniform(sim_rng_t *r, double low, double high);

/* Python's float floor division a // b (not floor(a / b): they differ at knot boundaries). */
double sim_py_floordiv(double a, double b);

#endif
