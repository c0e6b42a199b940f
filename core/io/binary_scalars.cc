#include "core/io/binary_scalars.h"

#include <cstring>

namespace rpsr::core::io_internal {
namespace {

template <typename U>
U ByteSwapped(U value) {
  U swapped = 0;
  for (size_t i = 0; i < sizeof(U); ++i) {
    swapped = static_cast<U>((swapped << 8) | ((value >> (8 * i)) & 0xff));
  }
  return swapped;
}

// Loads sizeof(U) bytes as an unsigned integer in host order.
template <typename U>
U LoadBits(const char* data, std::endian byte_order) {
  U bits;
  std::memcpy(&bits, data, sizeof(U));
  return byte_order == std::endian::native ? bits : ByteSwapped(bits);
}

template <typename U>
void StoreBits(U bits, std::endian byte_order, std::string* out) {
  if (byte_order != std::endian::native) bits = ByteSwapped(bits);
  char bytes[sizeof(U)];
  std::memcpy(bytes, &bits, sizeof(U));
  out->append(bytes, sizeof(U));
}

}  // namespace

size_t ScalarTypeSize(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8:
    case ScalarType::kUint8:
      return 1;
    case ScalarType::kInt16:
    case ScalarType::kUint16:
      return 2;
    case ScalarType::kInt32:
    case ScalarType::kUint32:
    case ScalarType::kFloat32:
      return 4;
    case ScalarType::kInt64:
    case ScalarType::kUint64:
    case ScalarType::kFloat64:
      return 8;
  }
  return 1;
}

bool IsIntegerScalarType(ScalarType type) {
  return type != ScalarType::kFloat32 && type != ScalarType::kFloat64;
}

double DecodeAnyScalarAsDouble(const char* data, ScalarType type, std::endian byte_order) {
  switch (type) {
    case ScalarType::kFloat32:
      return std::bit_cast<float>(LoadBits<uint32_t>(data, byte_order));
    case ScalarType::kFloat64:
      return std::bit_cast<double>(LoadBits<uint64_t>(data, byte_order));
    case ScalarType::kUint64:
      return static_cast<double>(LoadBits<uint64_t>(data, byte_order));
    default: {
      int64_t value = 0;
      DecodeScalarAsInt64(data, type, byte_order, &value);
      return static_cast<double>(value);
    }
  }
}

bool DecodeScalarAsInt64(const char* data, ScalarType type, std::endian byte_order,
                         int64_t* value) {
  switch (type) {
    case ScalarType::kInt8:
      *value = static_cast<int8_t>(data[0]);
      return true;
    case ScalarType::kUint8:
      *value = static_cast<uint8_t>(data[0]);
      return true;
    case ScalarType::kInt16:
      *value = static_cast<int16_t>(LoadBits<uint16_t>(data, byte_order));
      return true;
    case ScalarType::kUint16:
      *value = LoadBits<uint16_t>(data, byte_order);
      return true;
    case ScalarType::kInt32:
      *value = static_cast<int32_t>(LoadBits<uint32_t>(data, byte_order));
      return true;
    case ScalarType::kUint32:
      *value = LoadBits<uint32_t>(data, byte_order);
      return true;
    case ScalarType::kInt64:
      *value = static_cast<int64_t>(LoadBits<uint64_t>(data, byte_order));
      return true;
    case ScalarType::kUint64: {
      const uint64_t bits = LoadBits<uint64_t>(data, byte_order);
      if (bits > static_cast<uint64_t>(INT64_MAX)) return false;
      *value = static_cast<int64_t>(bits);
      return true;
    }
    case ScalarType::kFloat32:
    case ScalarType::kFloat64:
      return false;
  }
  return false;
}

void AppendFloat32(float value, std::endian byte_order, std::string* out) {
  StoreBits(std::bit_cast<uint32_t>(value), byte_order, out);
}

void AppendFloat64(double value, std::endian byte_order, std::string* out) {
  StoreBits(std::bit_cast<uint64_t>(value), byte_order, out);
}

void AppendInt32(int32_t value, std::endian byte_order, std::string* out) {
  StoreBits(static_cast<uint32_t>(value), byte_order, out);
}

}  // namespace rpsr::core::io_internal
