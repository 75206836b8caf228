/* SIGTERM (a CI timeout, kill), SIGINT (Ctrl-C) and SIGHUP (the terminal went) ask a program to
 * stop the way a fault does: arm_controller, arm_sim and arm_sil install their handler with this. */
#ifndef ARM_STOP_SIGNALS_H
#define ARM_STOP_SIGNALS_H

void stop_signals_install(void (*handler)(int));

#endif
