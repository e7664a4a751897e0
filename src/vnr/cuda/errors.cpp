// Error reporting for the .cu files, compiled by the host compiler (keeps fmt out of nvcc's way).
#include "vnr/error.h"
#include "vnr/cuda/common.h"

namespace vnr::cuda {

void cuda_fail(const char* call, const char* error, const char* file, int line) {
  fail("CUDA error in {} ({}:{}): {}", call, file, line, error);
}

void cuda_fail_message(const std::string& message) { throw Error(message); }

}  // namespace vnr::cuda
