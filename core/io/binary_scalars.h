// Fixed-size numeric scalars as binary formats store them (PLY binary, PCD binary): their types,
// sizes, and decoding / encoding in either byte order. Shared by the parsers and writers in
// core/io; callers check that enough bytes remain before decoding.
#ifndef RPSR_CORE_IO_BINARY_SCALARS_H_
#define RPSR_CORE_IO_BINARY_SCALARS_H_

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

namespace rpsr::core::io_internal {

enum class ScalarType {
  kInt8,
  kUint8,
  kInt16,
  kUint16,
  kInt32,
  kUint32,
  kInt64,
  kUint64,
  kFloat32,
  kFloat64
};

// Bytes one value of `type` takes: 1, 2, 4 or 8.
size_t ScalarTypeSize(ScalarType type);

// True for the integer types, false for kFloat32 / kFloat64.
bool IsIntegerScalarType(ScalarType type);

// Decodes the value of `type` stored at `data` in `byte_order` (at least ScalarTypeSize bytes).
double DecodeAnyScalarAsDouble(const char* data, ScalarType type, std::endian byte_order);

// DecodeAnyScalarAsDouble, inline for the common case of floats in the host's byte order.
inline double DecodeScalarAsDouble(const char* data, ScalarType type, std::endian byte_order) {
  if (byte_order == std::endian::native) {
    if (type == ScalarType::kFloat32) {
      float value;
      std::memcpy(&value, data, sizeof(value));
      return value;
    }
    if (type == ScalarType::kFloat64) {
      double value;
      std::memcpy(&value, data, sizeof(value));
      return value;
    }
  }
  return DecodeAnyScalarAsDouble(data, type, byte_order);
}

// Decodes an integer value; false for the float types or a kUint64 above INT64_MAX.
bool DecodeScalarAsInt64(const char* data, ScalarType type, std::endian byte_order, int64_t* value);

// Append the value in `byte_order` to `*out`.
void AppendFloat32(float value, std::endian byte_order, std::string* out);
void AppendFloat64(double value, std::endian byte_order, std::string* out);
void AppendInt32(int32_t value, std::endian byte_order, std::string* out);

}  // namespace rpsr::core::io_internal

#endif  // RPSR_CORE_IO_BINARY_SCALARS_H_
