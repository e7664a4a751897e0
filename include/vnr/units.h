#pragma once
#include <cstdint>
#include <string>

namespace vnr {

// "16MiB", "2GiB", "512k", "1.5G", "4096" (bytes). Binary units (K/Ki/KiB = 1024 ...), case-insensitive;
// a trailing "B" is optional. One clear error line for anything else.
uint64_t parse_byte_size(const std::string& text);
// The other way, for people: "1.50 MiB" (two decimals, binary units up to TiB).
std::string human_bytes(double bytes);

// Physical memory and memory currently available to new allocations (/proc/meminfo MemAvailable,
// falling back to total), in bytes; available_memory_bytes() is at most VNR_MEMORY_LIMIT (e.g. "4GiB") when set.
uint64_t physical_memory_bytes();
uint64_t available_memory_bytes();

}  // namespace vnr
