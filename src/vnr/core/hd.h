#pragma once
// VNR_HD marks per-sample / per-ray functions that are written once for every backend
// (pbrt-v4 style): plain inline code over POD views, no allocation, exceptions or virtuals.
#if defined(__CUDACC__)
#define VNR_HD __host__ __device__
#else
#define VNR_HD
#endif
