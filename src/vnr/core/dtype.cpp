#include "vnr/dtype.h"
#include <cfloat>
#include <cstdint>
#include <limits>
#include "vnr/error.h"
#include "vnr/json.h"

namespace vnr {

DType parse_dtype(const std::string& name) {
  static const struct { const char* n; DType t; } table[] = {
      {"int8", DType::Int8}, {"uint8", DType::UInt8}, {"int16", DType::Int16}, {"uint16", DType::UInt16},
      {"int32", DType::Int32}, {"uint32", DType::UInt32}, {"float32", DType::Float32}, {"float64", DType::Float64},
      // instantvnr scene names
      {"byte", DType::Int8}, {"unsigned_byte", DType::UInt8}, {"short", DType::Int16},
      {"unsigned_short", DType::UInt16}, {"int", DType::Int32}, {"unsigned_int", DType::UInt32},
      {"float", DType::Float32}, {"double", DType::Float64},
      // NRRD / C names
      {"signed char", DType::Int8}, {"int8_t", DType::Int8}, {"uchar", DType::UInt8}, {"unsigned char", DType::UInt8},
      {"uint8_t", DType::UInt8}, {"short int", DType::Int16}, {"signed short", DType::Int16},
      {"signed short int", DType::Int16}, {"int16_t", DType::Int16}, {"ushort", DType::UInt16},
      {"unsigned short", DType::UInt16}, {"unsigned short int", DType::UInt16}, {"uint16_t", DType::UInt16},
      {"signed int", DType::Int32}, {"int32_t", DType::Int32}, {"uint", DType::UInt32},
      {"unsigned int", DType::UInt32}, {"uint32_t", DType::UInt32}, {"f32", DType::Float32},
      {"f64", DType::Float64}, {"u8", DType::UInt8}, {"i8", DType::Int8}, {"u16", DType::UInt16},
      {"i16", DType::Int16}, {"u32", DType::UInt32}, {"i32", DType::Int32},
  };
  std::string l = to_lower(name);
  for (auto& e : table)
    if (l == e.n) return e.t;
  fail("unknown data type '{}' (allowed: int8, uint8, int16, uint16, int32, uint32, float32, float64)", name);
}

const char* dtype_name(DType t) {
  switch (t) {
    case DType::Int8: return "int8";
    case DType::UInt8: return "uint8";
    case DType::Int16: return "int16";
    case DType::UInt16: return "uint16";
    case DType::Int32: return "int32";
    case DType::UInt32: return "uint32";
    case DType::Float32: return "float32";
    case DType::Float64: return "float64";
  }
  return "?";
}

size_t dtype_size(DType t) {
  switch (t) {
    case DType::Int8: case DType::UInt8: return 1;
    case DType::Int16: case DType::UInt16: return 2;
    case DType::Int32: case DType::UInt32: case DType::Float32: return 4;
    case DType::Float64: return 8;
  }
  return 0;
}

bool dtype_is_integer(DType t) { return t != DType::Float32 && t != DType::Float64; }

double dtype_max(DType t) {
  switch (t) {
    case DType::Int8: return 127;
    case DType::UInt8: return 255;
    case DType::Int16: return 32767;
    case DType::UInt16: return 65535;
    case DType::Int32: return 2147483647.0;
    case DType::UInt32: return 4294967295.0;
    case DType::Float32: case DType::Float64: return 1;
  }
  return 1;
}

double dtype_min(DType t) {
  switch (t) {
    case DType::Int8: return -128;
    case DType::UInt8: case DType::UInt16: case DType::UInt32: return 0;
    case DType::Int16: return -32768;
    case DType::Int32: return -2147483648.0;
    case DType::Float32: return -double(FLT_MAX);
    case DType::Float64: return -DBL_MAX;
  }
  return 0;
}

}  // namespace vnr
