/* Three-vector helpers for the dynamics; inline so the RNEA compiles to straight-line code. */
#ifndef ARM_VEC3_H
#define ARM_VEC3_H

static inline void arm_v3_cross(const float a[3], const float b[3], float out[3])
{
    const float x = a[1] * b[2] - a[2] * b[1];
    const float y = a[2] * b[0] - a[0] * b[2];
    const float z = a[0] * b[1] - a[1] * b[0];
    out[0] = x;
    out[1] = y;
    out[2] = z;
}

static inline float arm_v3_dot(const float a[3], const float b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* out = R v */
static inline void arm_m3_mul(const float r[3][3], const float v[3], float out[3])
{
    for (int i = 0; i < 3; ++i) {
        out[i] = r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2];
    }
}

/* out = R^T v */
static inline void arm_m3_tmul(const float r[3][3], const float v[3], float out[3])
{
    for (int i = 0; i < 3; ++i) {
        out[i] = r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2];
    }
}

#endif
