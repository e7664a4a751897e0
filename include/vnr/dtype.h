#pragma once
#include <cstddef>
#include <string>

namespace vnr {

enum class DType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

// Canonical names are numpy-style: int8 uint8 int16 uint16 int32 uint32 float32 float64.
// parse_dtype also accepts instantvnr names (BYTE, UNSIGNED_BYTE, SHORT, UNSIGNED_SHORT, INT,
// UNSIGNED_INT, FLOAT, DOUBLE), NRRD names (uchar, short, ushort, int, uint, float, double, ...);
// an unknown name is an error that lists the accepted canonical names.
DType parse_dtype(const std::string& name);
const char* dtype_name(DType t);
size_t dtype_size(DType t);
bool dtype_is_integer(DType t);
double dtype_max(DType t);  // largest value of an integer type (255, 127, 65535, ...); 1 for floats
double dtype_min(DType t);  // smallest value of an integer type; -max for floats

}  // namespace vnr
