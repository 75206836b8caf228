/* arm_controller: the Linux controller binary (bus master of the six joint drives). */
#define _GNU_SOURCE
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "arm_robot_model_data.h"
#include "controller_loop.h"
#include "options.h"
#include "rt.h"
#include "summary.h"
#include "telemetry.h"
#include "stop_signals.h"

static void on_stop_signal(int sig)
{
    controller_stop_signal = sig;
}

int main(int argc, char **argv)
{
    static options_t opt;
    char err[512];
    const int prc = options_parse(argc, argv, &ARM_ROBOT_MODEL, &opt, err, sizeof(err));
    if (prc == 1) {
        return 0;
    }
    if (prc != 0) {
        fprintf(stderr, "arm_controller: %s\n", err);
        return 2;
    }
    telemetry_t *telem = telemetry_start(opt.lcm_url, err, sizeof(err));
    if (telem == NULL) {
        fprintf(stderr, "arm_controller: %s\n", err);
        return 1;
    }
    /* After telemetry_start: only this (the loop's) thread gets SCHED_FIFO and the CPU pin. */
    static rt_status_t rt;
    if (rt_setup(&opt.rt, opt.mode == MODE_REALTIME, &rt) != 0) {
        fprintf(stderr, "arm_controller: %s\n", rt.message);
        telemetry_stop(telem);
        free(telem);
        return 2;
    }
    fprintf(stderr, "arm_controller: rt: %s\n", rt.message);
    telemetry_event(telem, 0, rt.sched_fifo || opt.mode != MODE_REALTIME ? "info" : "warn", rt.message);
    /* SIGTERM (a CI timeout, kill), SIGINT (Ctrl-C), SIGHUP (the terminal went): stop the way a
     * fault does, zero torque, shutdown and NMT stop, then the summary. */
    stop_signals_install(on_stop_signal);
    static run_report_t report;
    controller_run(&opt, &ARM_ROBOT_MODEL, telem, &report);
    telemetry_stop(telem);

    if (opt.summary_path[0] != '\0' &&
        summary_write(opt.summary_path, &opt, &report, telem, err, sizeof(err)) != 0) {
        fprintf(stderr, "arm_controller: %s\n", err);
        free(telem);
        return 1;
    }
    free(telem);
    if (report.result != RUN_OK) {
        fprintf(stderr, "arm_controller: %s; state %s; safe stop: %s\n", report.reason,
                arm_state_str(report.final_state), report.stop.cause != RUN_STOP_NONE ? report.stop.safe_state : "none (never enabled)");
        return (int)report.result;
    }
    printf("arm_controller: %u periods, %llu frames sent, %llu received, final state %s\n",
           report.steps_done, (unsigned long long)report.frames_tx,
           (unsigned long long)report.frames_rx, arm_state_str(report.final_state));
    return 0;
}
