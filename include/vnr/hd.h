#pragma once
// VNR_HD marks per-sample / per-ray functions that are written once for every backend
// (pbrt-v4 style): plain inline code over POD views, no allocation, exceptions or virtuals.
#if defined(__CUDACC__)
#define VNR_HD __host__ __device__
#define VNR_INLINE __forceinline__
#else
#define VNR_HD
// Forced inlining matters on the CPU: the per-sample functions are compiled into per-SIMD-target
// kernels (Highway foreach_target) and only inlined copies get that target's instructions (FMA,
// AVX-512); an out-of-line call would run baseline code and call libm for fmaf.
#define VNR_INLINE inline __attribute__((always_inline))
#endif

// Before a __host__ __device__ template that may be instantiated with a callee of one space only (a
// device-only evaluator, a host lambda): nvcc then checks the callee's space per instantiation.
#if defined(__CUDACC__)
#define VNR_HD_TEMPLATE _Pragma("nv_exec_check_disable")
#else
#define VNR_HD_TEMPLATE
#endif
