/* Nominal model of a serial arm of revolute joints (filled by a generated header): rigid links,
 * each joint's armature, viscous damping and range. */
#ifndef ARM_ROBOT_MODEL_TYPES_H
#define ARM_ROBOT_MODEL_TYPES_H

#include "arm_robot_dims.h" /* generated: ARM_N_JOINTS */

#if !defined(ARM_N_JOINTS) || ARM_N_JOINTS < 1 || ARM_N_JOINTS > 16
#error "arm_robot_dims.h must define ARM_N_JOINTS in 1..16"
#endif

typedef struct {
    float pos[3];         /* parent -> body translation, parent frame */
    float rot[3][3];      /* parent -> body rotation at q = 0 */
    float axis[3];        /* joint axis, body frame, unit length */
    float mass;           /* kg */
    float com[3];         /* centre of mass, body frame */
    float inertia[3][3];  /* about the centre of mass, body frame */
    float torque_limit;   /* Nm, the drive's limit */
    float armature;       /* kg m^2, rotor inertia reflected to the joint: adds armature * qdd */
    float damping;        /* N m s/rad, viscous joint damping: adds damping * qd */
    float q_min, q_max;   /* rad, the joint's range (+-ARM_UNLIMITED when it has none) */
} arm_link_t;

#define ARM_UNLIMITED 1.0e30f /* a joint range without a limit */

typedef struct {
    float gravity[3]; /* world frame, m/s^2 (base frame = world frame) */
    arm_link_t link[ARM_N_JOINTS];
    unsigned long long model_hash; /* FNV-1a 64 of the prepared model file (gen/arm.py) */
} arm_robot_model_t;

#endif
