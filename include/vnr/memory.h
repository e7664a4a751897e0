#pragma once
#include <sys/mman.h>
#include <cstddef>
#include <cstdlib>
#include <new>
#include <vector>

namespace vnr {

// Allocator for large, randomly accessed arrays (grid tables, their gradients, optimizer state):
// 2 MiB-aligned and madvise(MADV_HUGEPAGE)d, because random gathers over tens of MiB otherwise
// miss the TLB on almost every access (the kernel's THP mode here is "madvise").
template <typename T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() = default;
  template <typename U>
  HugePageAllocator(const HugePageAllocator<U>&) {}
  T* allocate(size_t n) {
    const size_t bytes = n * sizeof(T);
    if (bytes < (size_t(1) << 21)) {
      void* p = std::malloc(bytes ? bytes : 1);
      if (!p) throw std::bad_alloc();
      return static_cast<T*>(p);
    }
    const size_t align = size_t(1) << 21;
    void* p = std::aligned_alloc(align, (bytes + align - 1) / align * align);
    if (!p) throw std::bad_alloc();
    ::madvise(p, bytes, MADV_HUGEPAGE);
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t) { std::free(p); }
  template <typename U>
  bool operator==(const HugePageAllocator<U>&) const { return true; }
};

template <typename T>
using big_vector = std::vector<T, HugePageAllocator<T>>;

}  // namespace vnr
