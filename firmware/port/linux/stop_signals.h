/* SIGTERM (a CI timeout, kill), SIGINT (Ctrl-C) and SIGHUP (the terminal went) ask a program to
 * stop the way a fault does: arm_controller, arm_sim and arm_sil install their handler with this,
 * which also asks for that SIGTERM when the parent named by ARM_PARENT_PID dies. */
#ifndef ARM_STOP_SIGNALS_H
#define ARM_STOP_SIGNALS_H

/* Set by armctl to its pid (tools/run/procs.py): the program then gets a SIGTERM when armctl dies. */
#define ARM_PARENT_PID_ENV "ARM_PARENT_PID"

void stop_signals_install(void (*handler)(int));

#endif
