/*
 * Batched inverse dynamics on a GPU with derive's generated C, unchanged: every generated
 * function is DERIVE_FN (__host__ __device__ under nvcc), so a kernel calls it per state.
 *
 * Build (any robot: replace panda; nvcc from the CUDA toolkit or `pip install nvidia-cuda-nvcc`):
 *   nvcc -O2 -x cu -rdc=true -Igenerated/panda/c examples/cuda/batch_inverse_dynamics.cu \
 *        generated/panda/c/panda_inverse_dynamics.c -o batch_inverse_dynamics
 *   ./batch_inverse_dynamics 1000000
 * It prints the states per second on the GPU and on one CPU core, and the largest difference
 * between the two (they run the same code; only libm may differ in the last bits).
 */
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <vector>

#include <cuda_runtime.h>

#include "panda.h"

#define NV PANDA_NV

__global__ void inverse_dynamics_kernel(long n, const DERIVE_REAL *q, const DERIVE_REAL *qd, const DERIVE_REAL *qdd,
                                        DERIVE_REAL *tau)
{
    for (long i = blockIdx.x * (long)blockDim.x + threadIdx.x; i < n; i += (long)blockDim.x * gridDim.x) {
        panda_inverse_dynamics(q + i * NV, qd + i * NV, qdd + i * NV, tau + i * NV);
    }
}

static double seconds(void)
{
    timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

#define CHECK(call)                                                                        \
    do {                                                                                   \
        cudaError_t err_ = (call);                                                         \
        if (err_ != cudaSuccess) {                                                         \
            std::fprintf(stderr, "%s: %s\n", #call, cudaGetErrorString(err_));             \
            return 1;                                                                      \
        }                                                                                  \
    } while (0)

int main(int argc, char **argv)
{
    const long n = argc > 1 ? std::atol(argv[1]) : 1000000;
    const size_t bytes = (size_t)n * NV * sizeof(DERIVE_REAL);
    std::vector<DERIVE_REAL> q(n * NV), qd(n * NV), qdd(n * NV), tau(n * NV), ref(n * NV);
    std::srand(0);
    for (long k = 0; k < n * NV; ++k) {
        q[k] = 2.0 * std::rand() / RAND_MAX - 1.0;
        qd[k] = 2.0 * std::rand() / RAND_MAX - 1.0;
        qdd[k] = 2.0 * std::rand() / RAND_MAX - 1.0;
    }
    DERIVE_REAL *dq, *dqd, *dqdd, *dtau;
    CHECK(cudaMalloc(&dq, bytes));
    CHECK(cudaMalloc(&dqd, bytes));
    CHECK(cudaMalloc(&dqdd, bytes));
    CHECK(cudaMalloc(&dtau, bytes));
    CHECK(cudaMemcpy(dq, q.data(), bytes, cudaMemcpyHostToDevice));
    CHECK(cudaMemcpy(dqd, qd.data(), bytes, cudaMemcpyHostToDevice));
    CHECK(cudaMemcpy(dqdd, qdd.data(), bytes, cudaMemcpyHostToDevice));
    const int threads = 128;
    const int blocks = (int)((n + threads - 1) / threads);
    inverse_dynamics_kernel<<<blocks, threads>>>(n, dq, dqd, dqdd, dtau);  /* warm-up */
    CHECK(cudaDeviceSynchronize());
    cudaEvent_t start, stop;
    CHECK(cudaEventCreate(&start));
    CHECK(cudaEventCreate(&stop));
    CHECK(cudaEventRecord(start));
    inverse_dynamics_kernel<<<blocks, threads>>>(n, dq, dqd, dqdd, dtau);
    CHECK(cudaEventRecord(stop));
    CHECK(cudaEventSynchronize(stop));
    float ms = 0.0f;
    CHECK(cudaEventElapsedTime(&ms, start, stop));
    CHECK(cudaMemcpy(tau.data(), dtau, bytes, cudaMemcpyDeviceToHost));
    const double t0 = seconds();
    for (long i = 0; i < n; ++i) {
        panda_inverse_dynamics(&q[i * NV], &qd[i * NV], &qdd[i * NV], &ref[i * NV]);
    }
    const double cpu = seconds() - t0;
    double worst = 0.0;
    for (long k = 0; k < n * NV; ++k) {
        const double d = std::fabs(tau[k] - ref[k]) / (1.0 + std::fabs(ref[k]));
        worst = d > worst ? d : worst;
    }
    std::printf("states %ld\ngpu_states_per_s %.6g\ncpu_states_per_s %.6g\nworst_relative_difference %.3g\n",
                n, n / (1e-3 * ms), n / cpu, worst);
    cudaFree(dq);
    cudaFree(dqd);
    cudaFree(dqdd);
    cudaFree(dtau);
    return 0;
}
