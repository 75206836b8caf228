/* Recursive Newton-Euler inverse dynamics of the nominal model. */
#ifndef ARM_RNEA_H
#define ARM_RNEA_H

#include "arm/robot_model.h"

/* tau = M(q) qdd + V(q, qd) + G(q), computed directly in O(n) without forming M.
 * Used by inverse dynamics control with qdd = q_ddot_d - u. */
void arm_rnea(const arm_robot_model_t *model, const float q[ARM_N_JOINTS],
              const float qd[ARM_N_JOINTS], const float qdd[ARM_N_JOINTS],
              float tau[ARM_N_JOINTS]);

#endif
