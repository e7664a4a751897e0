// The CUDA backend's API in a build without CUDA (VNR_CUDA=OFF): no devices, and every GPU object fails
// with one line that says how to get one.
#include "vnr/error.h"
#include "vnr/cuda/cuda.h"

namespace vnr::cuda {
namespace {
[[noreturn]] void not_built() {
  fail("this vnr was built without the CUDA backend (configure with -DVNR_CUDA=ON and the CUDA toolkit); "
       "use --device cpu");
}
}  // namespace

bool built() { return false; }
std::vector<DeviceInfo> devices() { return {}; }
std::string no_device_reason() { return "built without the CUDA backend"; }
void require_device() { not_built(); }
uint64_t free_memory_bytes() { return 0; }
int use_device_for(int) { return -1; }

struct GpuTrainer::Impl {};
GpuTrainer::GpuTrainer(Network&, GridView, GpuTrainOptions) { not_built(); }
GpuTrainer::GpuTrainer(Network&, std::shared_ptr<HostBatchSource>, GpuTrainOptions) { not_built(); }
GpuTrainer::~GpuTrainer() = default;
void GpuTrainer::run(int) { not_built(); }
void GpuTrainer::synchronize() { not_built(); }
std::vector<float> GpuTrainer::losses(uint64_t) { not_built(); }
float GpuTrainer::last_loss() { not_built(); }
uint64_t GpuTrainer::steps_done() const { not_built(); }
float GpuTrainer::current_learning_rate() const { not_built(); }
void GpuTrainer::set_learning_rate_multiplier(float) { not_built(); }
void GpuTrainer::enable_online_ranges(Int3, int) { not_built(); }
bool GpuTrainer::has_online_ranges() const { not_built(); }
ValueRangeGrid GpuTrainer::online_ranges() { not_built(); }
void GpuTrainer::download() { not_built(); }
const void* GpuTrainer::device_half_params() { not_built(); }
void GpuTrainer::begin_quantized(const std::vector<float>&, const std::vector<ParamSegment>&, size_t, double) {
  not_built();
}
void GpuTrainer::end_quantized(std::vector<float>&) { not_built(); }
MlpPath GpuTrainer::mlp_path() const { not_built(); }
uint64_t GpuTrainer::peak_memory_bytes() const { not_built(); }
void GpuTrainer::set_profiling(bool) { not_built(); }
std::vector<double> GpuTrainer::phase_seconds() { not_built(); }

struct GpuNetwork::Impl {};
GpuNetwork::GpuNetwork(const Network&, MlpPath) { not_built(); }
GpuNetwork::~GpuNetwork() = default;
void GpuNetwork::infer(const float*, int64_t, float*) { not_built(); }
void GpuNetwork::reload_params(const void*) { not_built(); }
void GpuNetwork::decode_slices(Int3, int64_t, int64_t, float*) { not_built(); }
void GpuNetwork::set_slab(int64_t) { not_built(); }
MlpPath GpuNetwork::mlp_path() const { not_built(); }
uint64_t GpuNetwork::peak_memory_bytes() const { not_built(); }
GpuNetwork::ResidentTiming GpuNetwork::time_resident(int64_t, int) { not_built(); }

namespace testing {
std::vector<float> encode(const Network&, const float*, int) { not_built(); }
std::vector<float> gradient(const Network&, const float*, const float*, int, MlpPath, float*) { not_built(); }
}  // namespace testing

}  // namespace vnr::cuda
