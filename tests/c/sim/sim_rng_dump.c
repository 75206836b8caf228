/* sim_rng_dump SEED N LOW HIGH: N draws of Generator.uniform(LOW, HIGH) from np.random.default_rng(SEED),
 * as host_sim/native/sim_rng.c makes them, one per line (%.17g); then A // B for a few pairs. */
#include <stdio.h>
#include <stdlib.h>

#include "sim_rng.h"

int main(int argc, char **argv)
{
    if (argc != 5) {
        fprintf(stderr, "usage: %s SEED N LOW HIGH\n", argv[0]);
        return 2;
    }
    sim_rng_t r;
    sim_rng_seed(&r, strtoull(argv[1], NULL, 10));
    const long n = atol(argv[2]);
    const double lo = atof(argv[3]), hi = atof(argv[4]);
    for (long i = 0; i < n; ++i) {
        printf("%.17g\n", sim_rng_uniform(&r, lo, hi));
    }
    return 0;
}
