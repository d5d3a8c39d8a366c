#pragma once
// PROCAM_HOST_DEVICE marks a function that is compiled for the CPU and, where nvcc compiles the
// file, for the GPU as well (pbrt-v4's PBRT_CPU_GPU): the colour math of colour.h, the solver's
// rules of solver_records.h and the driver of Alg. 1 and 2 (solver_driver.h) are written once
// for both.

#if defined(__CUDACC__)
#define PROCAM_HOST_DEVICE __host__ __device__
#else
#define PROCAM_HOST_DEVICE
#endif

// Before a PROCAM_HOST_DEVICE function template whose instances call host-only or device-only
// functions of their template argument (the solver driver's executors: one per side): nvcc then
// checks each instance only on the side that calls it.
#if defined(__CUDACC__)
#define PROCAM_HOST_DEVICE_TEMPLATE _Pragma("nv_exec_check_disable")
#else
#define PROCAM_HOST_DEVICE_TEMPLATE
#endif
