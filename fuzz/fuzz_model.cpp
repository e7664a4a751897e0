// Model files through load_model: vnr's .vnr, or (built with VNR_FUZZ_BSON) instantvnr's BSON params.
// With VNR_FUZZ_DECODE a loaded .vnr is also decoded at its own dims under a 1 MiB memory limit: a
// header claiming huge dims must be refused before the decode allocates (libFuzzer reports any single
// allocation over -malloc_limit_mb as a finding).
#include <cstdlib>
#include "fuzz_support.h"
#include "vnr/train/model.h"
#ifdef VNR_FUZZ_DECODE
#include "vnr/model.h"
#endif

extern "C" int LLVMFuzzerInitialize(int*, char***) {
#ifdef VNR_FUZZ_DECODE
  setenv("VNR_MEMORY_LIMIT", "1MiB", 1);  // decodes of at most 2^18 voxels run; larger ones are refused
#endif
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vnr::fuzz;
#ifdef VNR_FUZZ_BSON
  const std::string path = write_scratch("params.bson", data, size);
#else
  const std::string path = write_scratch("model.vnr", data, size);
#endif
  expect_clean([&] {
    const vnr::Model m = vnr::load_model(path);
#ifdef VNR_FUZZ_DECODE
    vnr::ModelQuery query(m, vnr::Device::Cpu);
    const vnr::Volume v = query.decode();
    if (v.data.size() != m.dims.count()) std::abort();
#endif
  });
  return 0;
}
