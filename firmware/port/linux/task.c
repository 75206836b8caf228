#include "task.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "arm/rnea.h"
#include "arm_robot_model_data.h"

#define STREAM_STOP_S 0.2f     /* a stale stream's reference stops within this (constant deceleration) */
#define REFERENCE_RAMP_S 2.0f   /* the built-in reference's last seconds: its motion fades to rest at its start */
#define STREAM_JUMP_RAD 0.02f  /* a plan may differ this much from where the reference is */
#define OPEN_ENDED_STEPS 4000000000.0 /* the loop's cap for tasks that end themselves (46 days at 1 kHz) */

const char *task_name(int kind)
{
    static const char *const k_names[] = {"reference", "hold", "jog", "trajectory", "stream", "commission"};
    return kind >= 0 && kind < (int)(sizeof(k_names) / sizeof(k_names[0])) ? k_names[kind] : "?";
}

int task_check_options(options_t *opt, int given_jog, int given_trajectory, char *err, unsigned long errcap)
{
    const task_kind_t k = (task_kind_t)opt->task;
    if ((k == TASK_JOG) != (given_jog != 0)) {
        snprintf(err, errcap, k == TASK_JOG ? "--task jog: give --jog J:RAD" : "--jog: with --task jog");
        return -1;
    }
    if ((k == TASK_TRAJECTORY) != (given_trajectory != 0)) {
        snprintf(err, errcap, k == TASK_TRAJECTORY ? "--task trajectory: give --trajectory FILE"
                                                   : "--trajectory: with --task trajectory");
        return -1;
    }
    if (opt->reference_home && k != TASK_REFERENCE) {
        snprintf(err, errcap, "--reference-origin home: with --task reference");
        return -1;
    }
    if (k != TASK_REFERENCE || opt->reference_home) {
        /* the task ends the run (or --duration does, task_begin): the loop's count is only a cap */
        opt->steps = (uint32_t)OPEN_ENDED_STEPS;
    }
    return 0;
}

static void say(const task_t *t, uint32_t k_run, const char *level, const char *text)
{
    telemetry_event(t->telem, k_run, level, text);
#if !ARM_PORT_MCU
    fprintf(stderr, "arm_controller: %s\n", text); /* rare (a few a run): the person at the bench reads them */
#endif
}

/* The bounded move from q to `to` (at speed v); its length, s. */
static float plan_move(task_t *t, const float q[ARM_N_JOINTS], const float to[ARM_N_JOINTS], float v, float now)
{
    (void)arm_move_plan(&t->move, q, to, v, (float)t->opt->move_accel);
    t->moving = t->move.t_total > 0.0f;
    t->t_move_end = now + t->move.t_total;
    memcpy(t->hold, to, sizeof(t->hold));
    return t->move.t_total;
}

static float longest(const float a[ARM_N_JOINTS], const float b[ARM_N_JOINTS])
{
    float d = 0.0f;
    for (int j = 0; j < ARM_N_JOINTS; ++j) d = fabsf(a[j] - b[j]) > d ? fabsf(a[j] - b[j]) : d;
    return d;
}

int task_begin(task_t *t, const options_t *opt, const float q[ARM_N_JOINTS], telemetry_t *telem, task_report_t *report,
               uint32_t k_run, char *err, unsigned long errcap)
{
    memset(t, 0, sizeof(*t));
    t->opt = opt;
    t->telem = telem;
    t->report = report;
    memset(report, 0, sizeof(*report));
    report->begun = 1;
    report->last_seq = -1;
    memcpy(report->start_pose, q, sizeof(report->start_pose));
    memcpy(t->hold, q, sizeof(t->hold));
    memcpy(t->last_q_d, q, sizeof(t->last_q_d));
    /* nothing moves before the drives' brakes are open (their release delay): the pose held until then */
    const float now = (float)k_run * opt->ctl.period_s + (float)opt->brake_release_s;
    t->t_released = now;
    const float duration = (float)opt->duration_s;
    float first[ARM_N_JOINTS];
    memcpy(first, q, sizeof(first));
    char text[320];
    t->t_end = -1.0f;
    switch ((task_kind_t)opt->task) {
    case TASK_REFERENCE:
        if (opt->reference_home) {
            memcpy(first, ARM_HOME_Q, sizeof(first));
        }
        if (opt->ref_given) {
            arm_reference_set(&t->ref, first, opt->ref_amp, opt->ref_freq_hz);
        } else {
            arm_reference_default(&t->ref, first);
        }
        arm_reference_set_hold(&t->ref, (float)opt->ref_hold_s);
        report->task_s = (float)opt->ref_hold_s + duration + (opt->reference_home ? (float)opt->end_hold_s : 0.0f);
        break;
    case TASK_HOLD:
    case TASK_STREAM:
        report->task_s = duration;
        break;
    case TASK_JOG:
        first[opt->jog_joint] += opt->jog_rad;
        report->task_s = (float)opt->end_hold_s;
        break;
    case TASK_TRAJECTORY:
        t->traj = opt->trajectory;
        for (int j = 0; j < ARM_N_JOINTS; ++j) first[j] = t->traj.q[j];
        report->task_s = arm_traj_duration(&t->traj) + (float)opt->end_hold_s;
        break;
    case TASK_COMMISSION: {
        arm_cm_config_t cfg;
        arm_commission_default_config(&cfg);
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            cfg.pulse_nm[j] = opt->commission_pulse[j] > 0.0f ? opt->commission_pulse[j] : 0.05f * ARM_ROBOT_MODEL.link[j].torque_limit;
        }
        if (arm_commission_init(&t->cm, &cfg, opt->ctl.period_s, q) != 0) {
            snprintf(err, errcap, "commission: the sequence's configuration cannot run");
            return -1;
        }
        report->task_s = 0.0f;
        break;
    }
    }
    memcpy(report->first_point, first, sizeof(report->first_point));
    const int legacy = (task_kind_t)opt->task == TASK_REFERENCE && !opt->reference_home; /* a HIL run: as ever */
    for (int j = 0; j < ARM_N_JOINTS && !legacy; ++j) { /* where the task goes first: inside the joint's range */
        const float lo = opt->ctl.q_min[j] + (float)opt->position_margin_rad;
        const float hi = opt->ctl.q_max[j] - (float)opt->position_margin_rad;
        if (!(first[j] >= lo && first[j] <= hi)) {
            snprintf(err, errcap, "%s: its first point puts joint %d (%s) at %.4g rad, outside its range [%.4g, %.4g]",
                     task_name(opt->task), j + 1, ARM_JOINT_NAMES[j], (double)first[j], (double)lo, (double)hi);
            return -1;
        }
    }
    /* a jog is itself the move, at its own speed; every other task moves to its first point */
    const float v = (task_kind_t)opt->task == TASK_JOG ? (float)opt->jog_speed : (float)opt->move_speed;
    const float move_s = legacy ? 0.0f : plan_move(t, q, first, v, now);
    if ((task_kind_t)opt->task != TASK_JOG) {
        report->start_move_s = move_s;
        report->start_move_rad = longest(q, first);
    }
    if (report->task_s > 0.0f) t->t_end = now + move_s + report->task_s;
    if ((task_kind_t)opt->task == TASK_JOG) {
        snprintf(text, sizeof(text), "jog: joint %d (%s) by %.4g rad in %.2f s (at most %.3g rad/s), then a %.2g s hold",
                 opt->jog_joint + 1, ARM_JOINT_NAMES[opt->jog_joint], (double)opt->jog_rad, (double)move_s, opt->jog_speed, opt->end_hold_s);
        say(t, k_run, "info", text);
    } else if (move_s > 0.0f) {
        snprintf(text, sizeof(text), "%s: moving to its first point: %.3g rad at most, %.2f s (at most %.3g rad/s, "
                 "%.3g rad/s^2)", task_name(opt->task), (double)report->start_move_rad, (double)move_s,
                 opt->move_speed, opt->move_accel);
        say(t, k_run, "info", text);
    }
#if !ARM_PORT_MCU
    if ((task_kind_t)opt->task == TASK_STREAM) {
        if (plan_stream_open(&t->stream, opt->stream_url, err, errcap) != 0) return -1;
        snprintf(text, sizeof(text), "stream: holding the pose until a plan comes on %.150s (ARM_PLAN)", opt->stream_url);
        say(t, k_run, "info", text);
    }
#endif
    if ((task_kind_t)opt->task == TASK_HOLD) {
        if (duration >= (float)ARM_P_CONTROLLER_DURATION_MAX) {
            snprintf(text, sizeof(text), "hold: holding the pose the arm is in until stopped");
        } else {
            snprintf(text, sizeof(text), "hold: holding the pose the arm is in for %.6g s", duration);
        }
        say(t, k_run, "info", text);
    }
    return 0;
}

static void set_pose(arm_ctl_input_t *in, const float q[ARM_N_JOINTS])
{
    memcpy(in->q_d, q, sizeof(in->q_d));
    memset(in->qd_d, 0, sizeof(in->qd_d));
    memset(in->qdd_d, 0, sizeof(in->qdd_d));
}

#if !ARM_PORT_MCU
/* Whether plan p may be followed from where the reference is now (q_ref); else the reason. */
static int plan_ok(const task_t *t, const plan_point_t *p, const float q_ref[ARM_N_JOINTS], int first, char *why,
                   unsigned long cap)
{
    const arm_ctl_config_t *c = &t->opt->ctl;
    const float margin = (float)t->opt->position_margin_rad;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        if (!isfinite(p->q[j]) || !isfinite(p->qd[j]) || !isfinite(p->qdd[j])) {
            snprintf(why, cap, "joint %d: not a finite number", j + 1);
            return 0;
        }
        if (p->q[j] < c->q_min[j] + margin || p->q[j] > c->q_max[j] - margin) {
            snprintf(why, cap, "joint %d: q_d %.4g rad is outside its range [%.4g, %.4g]", j + 1, (double)p->q[j],
                     (double)(c->q_min[j] + margin), (double)(c->q_max[j] - margin));
            return 0;
        }
        if (fabsf(p->qd[j]) > c->velocity_limit[j]) {
            snprintf(why, cap, "joint %d: qd_d %.4g rad/s is above its limit %.4g", j + 1, (double)p->qd[j],
                     (double)c->velocity_limit[j]);
            return 0;
        }
        if (!first && fabsf(p->q[j] - q_ref[j]) > STREAM_JUMP_RAD) {
            snprintf(why, cap, "joint %d: q_d %.4g rad jumps %.3g rad from the reference (%.4g): a plan continues "
                     "from where the reference is (ARM_CTL's q_d)", j + 1, (double)p->q[j],
                     (double)(p->q[j] - q_ref[j]), (double)q_ref[j]);
            return 0;
        }
    }
    return 1;
}

static void stream_step(task_t *t, float now, uint32_t k_run, arm_ctl_input_t *in)
{
    plan_point_t p;
    task_report_t *r = t->report;
    char text[240];
    if (plan_stream_poll(&t->stream, &p) && !t->moving) {
        char why[160];
        const int first = !t->have_plan;
        if (plan_ok(t, &p, t->last_q_d, first, why, sizeof(why))) {
            r->plans_taken++;
            r->last_seq = p.seq;
            if (first && longest(p.q, t->last_q_d) > STREAM_JUMP_RAD) { /* the first plan: moved to, bounded */
                const float s = plan_move(t, t->last_q_d, p.q, (float)t->opt->move_speed, now);
                r->start_move_s = s;
                r->start_move_rad = longest(p.q, t->last_q_d);
                memcpy(r->first_point, p.q, sizeof(r->first_point));
                snprintf(text, sizeof(text), "stream: moving to the first plan: %.3g rad at most, %.2f s",
                         (double)r->start_move_rad, (double)s);
                say(t, k_run, "info", text);
                t->have_plan = 1;
                t->following = 0;
            } else {
                if (first) memcpy(r->first_point, p.q, sizeof(r->first_point));
                if (!t->following) {
                    say(t, k_run, "info", r->stale_events > 0u ? "stream: following the plan again" : "stream: following the plan");
                }
                t->plan = p;
                t->t_plan = now;
                t->have_plan = 1;
                t->following = 1;
                t->stopping = 0;
            }
        } else {
            r->plans_refused++;
            if (strcmp(why, r->last_refusal) != 0) { /* each new reason once: a refusing planner keeps sending */
                snprintf(r->last_refusal, sizeof(r->last_refusal), "%s", why);
                snprintf(text, sizeof(text), "stream: plan %lld refused, the pose held: %s", (long long)p.seq, why);
                say(t, k_run, "warn", text);
            }
        }
    }
    if (t->moving) return; /* the move's reference (task_step) */
    if (t->following && now - t->t_plan > (float)t->opt->stream_timeout_s) { /* stale: stop the reference */
        t->following = 0;
        t->stopping = 1;
        t->t_stale = now;
        memcpy(t->stop_q, t->last_q_d, sizeof(t->stop_q));
        memcpy(t->stop_v, t->last_qd_d, sizeof(t->stop_v));
        r->stale_events++;
        snprintf(text, sizeof(text), "stream: no plan for %.3g s: stopping the reference within %.2g s and holding",
                 t->opt->stream_timeout_s, (double)STREAM_STOP_S);
        say(t, k_run, "warn", text);
    }
    if (t->following) {
        const float dt = now - t->t_plan;
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            in->q_d[j] = t->plan.q[j] + t->plan.qd[j] * dt + 0.5f * t->plan.qdd[j] * dt * dt;
            in->qd_d[j] = t->plan.qd[j] + t->plan.qdd[j] * dt;
            in->qdd_d[j] = t->plan.qdd[j];
        }
        return;
    }
    if (t->stopping) { /* each joint from its speed to rest in STREAM_STOP_S, at constant deceleration */
        const float s = now - t->t_stale;
        const float tau = s < STREAM_STOP_S ? s : STREAM_STOP_S;
        for (int j = 0; j < ARM_N_JOINTS; ++j) {
            const float a = -t->stop_v[j] / STREAM_STOP_S;
            in->q_d[j] = t->stop_q[j] + t->stop_v[j] * tau + 0.5f * a * tau * tau;
            in->qd_d[j] = s < STREAM_STOP_S ? t->stop_v[j] + a * tau : 0.0f;
            in->qdd_d[j] = s < STREAM_STOP_S ? a : 0.0f;
        }
        if (s >= STREAM_STOP_S) {
            t->stopping = 0;
            memcpy(t->hold, in->q_d, sizeof(t->hold));
        }
        return;
    }
    set_pose(in, t->hold);
}
#endif

/* The built-in reference after its move home: the arm's reference, its motion faded out over its
 * last REFERENCE_RAMP_S (q0 + (q - q0) s(t), s a quintic from 1 to 0), so that it ends at rest at
 * home instead of stopping the arm mid-motion. */
static void reference_to_rest(task_t *t, float since, arm_ctl_input_t *in)
{
    const float end = (float)t->opt->ref_hold_s + (float)t->opt->duration_s;
    const float ramp = REFERENCE_RAMP_S < 0.5f * (float)t->opt->duration_s ? REFERENCE_RAMP_S : 0.5f * (float)t->opt->duration_s;
    arm_reference_eval(&t->ref, since < end ? since : end, in->q_d, in->qd_d, in->qdd_d);
    float s = 1.0f, s1 = 0.0f, s2 = 0.0f;
    if (since >= end) {
        s = 0.0f;
    } else if (since > end - ramp) {
        const float u = (since - (end - ramp)) / ramp, u2 = u * u;
        s = 1.0f - u2 * u * (10.0f - 15.0f * u + 6.0f * u2);
        s1 = -30.0f * u2 * (1.0f - 2.0f * u + u2) / ramp;
        s2 = -60.0f * u * (1.0f - 3.0f * u + 2.0f * u2) / (ramp * ramp);
    }
    for (int i = 0; i < ARM_N_JOINTS; ++i) {
        const float y = in->q_d[i] - t->ref.q0[i], y1 = in->qd_d[i], y2 = in->qdd_d[i];
        in->q_d[i] = t->ref.q0[i] + y * s;
        in->qd_d[i] = y1 * s + y * s1;
        in->qdd_d[i] = y2 * s + 2.0f * y1 * s1 + y * s2;
    }
}

int task_step(task_t *t, float time_s, uint32_t k_run, const float q[ARM_N_JOINTS], const float tau_last[ARM_N_JOINTS],
              arm_ctl_input_t *in, char *err, unsigned long errcap)
{
    const options_t *opt = t->opt;
    const task_kind_t kind = (task_kind_t)opt->task;
    in->torque_override_mask = 0u;
    int over = 0;
    if (kind == TASK_REFERENCE && !opt->reference_home) {
        arm_reference_eval(&t->ref, time_s, in->q_d, in->qd_d, in->qdd_d); /* a HIL run's, unchanged */
        return 0;
    }
    if (time_s < t->t_released) {
        set_pose(in, t->report->start_pose);
        memcpy(t->last_q_d, in->q_d, sizeof(t->last_q_d));
        memcpy(t->last_qd_d, in->qd_d, sizeof(t->last_qd_d));
        return 0;
    }
    if (t->moving && time_s >= t->t_move_end) {
        t->moving = 0;
        if (kind == TASK_JOG) say(t, k_run, "info", "jog: there; holding");
    }
    const float since = time_s - t->t_move_end; /* the task's own time, after the move */
#if !ARM_PORT_MCU
    if (kind == TASK_STREAM) stream_step(t, time_s, k_run, in);
#endif
    if (t->moving) {
        arm_move_eval(&t->move, time_s - (t->t_move_end - t->move.t_total), in->q_d, in->qd_d, in->qdd_d);
    } else {
        switch (kind) {
        case TASK_REFERENCE: reference_to_rest(t, since, in); break;
        case TASK_TRAJECTORY: arm_traj_eval(&t->traj, since, in->q_d, in->qd_d, in->qdd_d); break;
        case TASK_STREAM: break; /* stream_step */
        case TASK_COMMISSION: {
            const arm_cm_status_t st = arm_commission_step(&t->cm, q, tau_last, in);
            t->report->cm_status = st;
            if (st == ARM_CM_DONE && t->t_end < 0.0f) {
                t->t_end = time_s + (float)opt->end_hold_s;
                say(t, k_run, "info", "commission: every joint tested; holding, then stopping");
            } else if (st != ARM_CM_RUNNING && st != ARM_CM_DONE) {
                const arm_commission_t *c = &t->cm;
                snprintf(err, errcap, "commission: joint %d (%s) %s (%.3g deg) during %s of joint %d: the arm is stopped",
                         c->why_joint + 1, ARM_JOINT_NAMES[c->why_joint],
                         st == ARM_CM_LEFT_BOUND ? "left its start pose beyond the bound"
                         : st == ARM_CM_REVERSED ? "moved against its torque pulse: a reversed motor or encoder"
                                                 : "did not move under its torque pulse",
                         (double)(c->why_value * 57.29578f), arm_cm_step_str(c), c->joint + 1);
                over = -1;
            }
            break;
        }
        default: set_pose(in, t->hold); break; /* hold, the end of a jog */
        }
    }
    if (t->t_end >= 0.0f && time_s >= t->t_end && over == 0) {
        t->report->ended = 1;
        over = 1;
    }
    memcpy(t->last_q_d, in->q_d, sizeof(t->last_q_d));
    memcpy(t->last_qd_d, in->qd_d, sizeof(t->last_qd_d));
    return over;
}

void task_track(task_t *t, const float e[ARM_N_JOINTS])
{
    task_report_t *r = t->report;
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        const float a = fabsf(e[j]);
        if (a > r->track_max[j]) r->track_max[j] = a;
        r->track_sumsq[j] += (double)a * (double)a;
    }
    r->track_n++;
}

/* The model's side of commissioning: the controller's own nominal model (its RNEA) at the poses
 * each joint was measured at. Gravity: tau(q, 0, 0); inertia M_jj: tau(q, 0, e_j) - gravity. */
static void commission_model(task_t *t)
{
    task_report_t *r = t->report;
    const arm_commission_t *c = &t->cm;
    const float zero[ARM_N_JOINTS] = {0};
    for (int j = 0; j < ARM_N_JOINTS; ++j) {
        const arm_cm_joint_t *x = &c->j[j];
        float q[ARM_N_JOINTS], g[ARM_N_JOINTS], hi[ARM_N_JOINTS], lo[ARM_N_JOINTS], unit[ARM_N_JOINTS] = {0}, m[ARM_N_JOINTS];
        memcpy(q, c->q0, sizeof(q));
        if (x->sweep.n_up > 0u && x->sweep.n_down > 0u) q[j] = 0.5f * (x->sweep.q_up + x->sweep.q_down);
        arm_rnea(&ARM_ROBOT_MODEL, q, zero, zero, g);
        const float step = 1e-3f;
        q[j] += step;
        arm_rnea(&ARM_ROBOT_MODEL, q, zero, zero, hi);
        q[j] -= 2.0f * step;
        arm_rnea(&ARM_ROBOT_MODEL, q, zero, zero, lo);
        r->cm_gravity_model[j] = g[j];
        r->cm_gravity_slope[j] = (hi[j] - lo[j]) / (2.0f * step);
        unit[j] = 1.0f;
        arm_rnea(&ARM_ROBOT_MODEL, c->q0, zero, unit, m);
        arm_rnea(&ARM_ROBOT_MODEL, c->q0, zero, zero, g);
        r->cm_inertia_model[j] = m[j] - g[j];
    }
}

void task_end(task_t *t)
{
    if ((task_kind_t)t->opt->task == TASK_COMMISSION) {
        commission_model(t);
        task_report_t *r = t->report;
        const arm_commission_t *c = &t->cm;
        r->cm_status = c->status;
        r->cm_why_joint = c->why_joint;
        r->cm_why_value = c->why_value;
        r->cm_joint_under_test = c->joint;
        snprintf(r->cm_step, sizeof(r->cm_step), "%s", arm_cm_step_str(c));
        r->cm_config = c->cfg;
        memcpy(r->cm_joint, c->j, sizeof(r->cm_joint));
    }
#if !ARM_PORT_MCU
    if ((task_kind_t)t->opt->task == TASK_STREAM) plan_stream_close(&t->stream);
#endif
}
