/* 10,000 control steps of every method, float and fixed, allocate nothing: malloc & co are
 * wrapped at link time (-Wl,--wrap) and counted. */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "arm/controller.h"
#include "arm_robot_model_data.h"
#include "check.h"

static long g_allocs;

void *__real_malloc(size_t n);
void *__real_calloc(size_t n, size_t m);
void *__real_realloc(void *p, size_t n);
void __real_free(void *p);
void *__wrap_malloc(size_t n);
void *__wrap_calloc(size_t n, size_t m);
void *__wrap_realloc(void *p, size_t n);
void __wrap_free(void *p);

void *__wrap_malloc(size_t n)
{
    ++g_allocs;
    return __real_malloc(n);
}
void *__wrap_calloc(size_t n, size_t m)
{
    ++g_allocs;
    return __real_calloc(n, m);
}
void *__wrap_realloc(void *p, size_t n)
{
    ++g_allocs;
    return __real_realloc(p, n);
}
void __wrap_free(void *p)
{
    if (p != NULL) ++g_allocs;
    __real_free(p);
}

int main(void)
{
    static arm_ctl_t ctl;
    arm_ctl_config_t cfg;
    arm_ctl_input_t in;
    arm_ctl_output_t out;
    for (int m = 0; m < (int)ARM_METHOD_COUNT; ++m) {
        for (int numeric = 0; numeric < 2; ++numeric) {
            arm_ctl_default_config(&ARM_ROBOT_MODEL, &cfg);
            cfg.method = (arm_method_t)m;
            cfg.numeric = numeric ? ARM_NUMERIC_FIXED : ARM_NUMERIC_FLOAT;
            CHECK(arm_ctl_init(&ctl, &ARM_ROBOT_MODEL, &cfg) == ARM_CTL_OK);
            memset(&in, 0, sizeof(in));
            in.fresh_mask = (1u << ARM_N_JOINTS) - 1u;
            const long before = g_allocs;
            for (int k = 0; k < 10000; ++k) {
                const float t = 0.001f * (float)k;
                for (int j = 0; j < ARM_N_JOINTS; ++j) {
                    in.q[j] = 0.3f * sinf(t + (float)j);
                    in.qd[j] = 0.3f * cosf(t + (float)j);
                    in.q_d[j] = in.q[j] + 0.01f;
                }
                arm_ctl_step(&ctl, &in, &out);
                memcpy(in.tau_measured, out.tau, sizeof(in.tau_measured)); /* drives that do as told */
            }
            CHECK_MSG(g_allocs == before, "method %s numeric %d allocated %ld times",
                      arm_method_str((arm_method_t)m), numeric, g_allocs - before);
            CHECK(out.state == ARM_STATE_RUNNING);
        }
    }
    printf("static memory of the core for n = %d: arm_ctl_t %zu bytes, arm_ctl_output_t %zu bytes\n",
           ARM_N_JOINTS, sizeof(arm_ctl_t), sizeof(arm_ctl_output_t));
    TEST_MAIN_END();
}
