/* arm_sim: the simulated arm and its emulated drives on the CAN bus, the per-period path of the
 * hardware-in-the-loop rig in C on MuJoCo's C API. Python (tools/run/hil.py, python -m host_sim)
 * configures and starts it; see host_sim/README.md.
 *
 * Exit codes: 0 the controller stopped the drives (a normal end); 1 bus or telemetry error;
 * 2 bad argument or model; 3 the controller was lost (drives faulted); 4 interrupted; 5 the
 * simulation diverged (drives faulted). */
#define _GNU_SOURCE
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "json_file.h"
#include "sim_loop.h"
#include "sim_options.h"
#include "sim_summary.h"
#include "stop_signals.h"

static void on_signal(int sig)
{
    (void)sig;
    sim_stop_requested = 1;
}

/* MuJoCo's warnings go to stderr (simulator.log), not to a MUJOCO_LOG.TXT in the current folder. */
static void on_mujoco_warning(const char *msg)
{
    fprintf(stderr, "arm_sim: MuJoCo: %s\n", msg);
}

static int64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* The limit of a period: MuJoCo alone, nothing else, on the same model. */
static int bench_mj_step(const sim_arm_t *arm, long steps)
{
    mjData *d = mj_makeData(arm->model);
    if (d == NULL) return 1;
    mj_copyData(d, arm->model, arm->data);
    const int64_t t0 = mono_ns();
    for (long i = 0; i < steps; ++i) {
        mj_step(arm->model, d);
    }
    const double ns = (double)(mono_ns() - t0) / (double)steps;
    printf("{\"mj_step_ns\": %.1f, \"steps\": %ld}\n", ns, steps);
    mj_deleteData(d);
    return 0;
}

int main(int argc, char **argv)
{
    static sim_options_t o;
    char err[1024];
    const int prc = sim_options_parse(argc, argv, &o, err, sizeof(err));
    if (prc == 1) return 0;
    if (prc != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        return 2;
    }
    mju_user_warning = on_mujoco_warning;
    static sim_arm_t arm;
    if (sim_arm_open(&arm, o.model, o.plant, o.keyframe, o.substeps, &o.unc, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        return 2;
    }
    if (o.bench_mj_steps > 0) {
        const int rc = bench_mj_step(&arm, o.bench_mj_steps);
        sim_arm_close(&arm);
        return rc;
    }
    if (sim_options_finish(&o, &arm, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        sim_arm_close(&arm);
        return 2;
    }
    static sim_plant_t plant;
    if (sim_plant_apply(&plant, &o.truth, &arm, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        sim_arm_close(&arm);
        return 2;
    }
    o.co.plant = &plant;
    sim_telemetry_t *tel = sim_telemetry_open(o.lcm_url, err, sizeof(err));
    if (tel == NULL) {
        fprintf(stderr, "arm_sim: %s\n", err);
        sim_arm_close(&arm);
        return 1;
    }
    /* No page fault in the loop once it runs (MuJoCo, the buses and LCM are set up by now): a
     * realtime run's peer must not stall on one. Not permitted (not root): runs anyway. */
    const int locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    stop_signals_install(on_signal);
    static sim_capture_t capture;
    if (sim_capture_open(&capture, o.capture, o.capture_wall, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        sim_telemetry_close(tel);
        sim_arm_close(&arm);
        return 1;
    }
    o.cfg.capture = &capture;
    static sim_report_t rep;
    int exit_code = 0;
    const int run_rc = o.protocol == SIM_PROTOCOL_CANOPEN ? sim_canopen_run(&o.cfg, &o.co, &arm, tel, &rep, err, sizeof(err))
                                                          : sim_run(&o.cfg, &arm, tel, &rep, err, sizeof(err));
    if (run_rc != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        snprintf(rep.result, sizeof(rep.result), "bus-error");
        snprintf(rep.reason, sizeof(rep.reason), "%.390s", err);
    }
    exit_code = sim_exit_code(&rep);
    if (sim_capture_close(&capture, o.capture, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        exit_code = exit_code ? exit_code : 1;
    }
    if (o.summary[0] != '\0' && sim_write_summary(o.summary, &o, &arm, &rep, tel, locked, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_sim: %s\n", err);
        exit_code = exit_code ? exit_code : 1;
    }
    sim_telemetry_close(tel);
    sim_arm_close(&arm);
    if (exit_code != 0) {
        fprintf(stderr, "arm_sim: %s\n", rep.reason);
    } else {
        printf("arm_sim: %llu periods, %llu frames sent, %llu received\n", (unsigned long long)rep.periods,
               (unsigned long long)rep.frames_tx, (unsigned long long)rep.frames_rx);
    }
    return exit_code;
}
