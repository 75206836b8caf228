#include "sim_after_stop.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

uint64_t sim_after_stop_begin(sim_report_t *rep, const sim_config_t *cfg, const sim_arm_t *arm, sim_telemetry_t *tel,
                              const char *why, double q0[SIM_MAX_JOINTS])
{
    memcpy(q0, arm->data->qpos, (size_t)arm->n * sizeof(double));
    snprintf(rep->post_stop_why, sizeof(rep->post_stop_why), "%s", why);
    rep->post_stop_from_step = arm->step_count;
    rep->post_stop_mujoco_s = arm->data->time;
    char text[300];
    snprintf(text, sizeof(text), "after the stop (%s): the arm runs on for %g s", why, cfg->post_stop_s);
    sim_telemetry_event(tel, arm->step_count, "sim", "info", text);
    return (uint64_t)(cfg->post_stop_s / arm->period + 0.5);
}

void sim_after_stop_period(sim_report_t *rep, const sim_arm_t *arm, const double q0[SIM_MAX_JOINTS])
{
    rep->post_stop_periods++;
    for (int j = 0; j < arm->n; ++j) {
        const double moved = fabs(arm->data->qpos[j] - q0[j]);
        if (moved > rep->post_stop_moved_rad[j]) rep->post_stop_moved_rad[j] = moved;
    }
}

void sim_after_stop_drive(sim_report_t *rep, int j, uint16_t statusword, int braked)
{
    rep->post_stop_statusword[j] = statusword;
    if (braked) rep->post_stop_braked_mask |= 1u << j;
}
