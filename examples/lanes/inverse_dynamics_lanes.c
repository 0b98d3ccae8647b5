/*
 * Four states per call with derive's generated C, unchanged: panda_inverse_dynamics.c compiled a
 * second time in lane mode (derive_lanes.h: DERIVE_REAL a vector of 4 doubles, one state per lane),
 * under another name, beside the scalar build.
 *
 * Build (any robot and function: replace the names; -mavx2 for the vector sin and cos):
 *   cc -std=c99 -O2 -mavx2 -DDERIVE_LANES=4 -include derive_lanes.h \
 *      -Dpanda_inverse_dynamics=panda_inverse_dynamics_x4 -Igenerated/panda/c \
 *      -c generated/panda/c/panda_inverse_dynamics.c -o inverse_dynamics_x4.o
 *   cc -std=c99 -O2 -Igenerated/panda/c examples/lanes/inverse_dynamics_lanes.c \
 *      generated/panda/c/panda_inverse_dynamics.c inverse_dynamics_x4.o -lm -o inverse_dynamics_lanes
 *   ./inverse_dynamics_lanes
 * It prints tau of 4 states from one lane call, and the largest difference from 4 scalar calls
 * (the lanes' sin and cos are within 2 ulp of <math.h>'s; -DDERIVE_LANES_EXACT calls <math.h>
 * per lane: no difference, and slower).
 */
#include <math.h>
#include <stdio.h>

#include "panda.h" /* the scalar build: DERIVE_REAL is double here */

#define LANES 4
typedef double x4 __attribute__((vector_size(LANES * sizeof(double)))); /* lane k: state k */

/* the lane build's prototype: every array holds one x4 per element */
void panda_inverse_dynamics_x4(const x4 *q, const x4 *qd, const x4 *qdd, x4 *tau);

int main(void)
{
    double q[LANES][PANDA_NV], qd[LANES][PANDA_NV], qdd[LANES][PANDA_NV], tau[LANES][PANDA_NV];
    x4 vq[PANDA_NV], vqd[PANDA_NV], vqdd[PANDA_NV], vtau[PANDA_NV];
    double worst = 0.0;
    int k, j;
    for (k = 0; k < LANES; ++k) {      /* four states */
        for (j = 0; j < PANDA_NV; ++j) {
            q[k][j] = 0.3 * sin(1.0 + k + 0.7 * j);
            qd[k][j] = 0.5 * cos(2.0 * k + j);
            qdd[k][j] = 0.1 * (j - k);
        }
    }
    for (j = 0; j < PANDA_NV; ++j) {   /* pack: element j of state k into lane k of vector j */
        for (k = 0; k < LANES; ++k) {
            vq[j][k] = q[k][j];
            vqd[j][k] = qd[k][j];
            vqdd[j][k] = qdd[k][j];
        }
    }
    panda_inverse_dynamics_x4(vq, vqd, vqdd, vtau);  /* four states, one call */
    for (k = 0; k < LANES; ++k) {
        panda_inverse_dynamics(q[k], qd[k], qdd[k], tau[k]);  /* the same, state by state */
        printf("state %d: tau =", k);
        for (j = 0; j < PANDA_NV; ++j) {
            printf(" %+.6f", vtau[j][k]);  /* unpack: lane k of vector j */
            worst = fmax(worst, fabs(vtau[j][k] - tau[k][j]));
        }
        printf("\n");
    }
    printf("largest difference from the scalar calls: %.1e N m\n", worst);
    return 0;
}
