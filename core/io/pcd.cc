#include "core/io/pcd.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/io/binary_scalars.h"
#include "core/io/declared_counts.h"
#include "core/io/file_bytes.h"
#include "core/io/text_tokens.h"

namespace rpsr::core {
namespace {

using io_internal::QuotedForMessage;

using io_internal::ScalarType;

// Upper bound on one field's COUNT: far above any real descriptor (FPFH has 33, SHOT 352), and
// it keeps record sizes far from overflowing.
constexpr uint64_t kMaxFieldCount = 1 << 20;

struct PcdField {
  std::string name;
  size_t size = 0;
  char type = 0;
  uint64_t count = 1;
  ScalarType scalar_type = ScalarType::kFloat32;
  size_t byte_offset = 0;  // within a binary record
  size_t first_value = 0;  // index of the field's first value within an ascii line
};

enum class PcdData { kAscii, kBinary };

struct PcdHeader {
  std::vector<PcdField> fields;
  uint64_t num_points = 0;
  PcdData data = PcdData::kAscii;
  size_t data_offset = 0;
  size_t data_first_line = 0;
  size_t record_bytes = 0;
  size_t values_per_line = 0;
  int x = -1, y = -1, z = -1, intensity = -1;  // field indices
};

absl::Status HeaderError(absl::string_view name, size_t line, absl::string_view what) {
  return absl::InvalidArgumentError(absl::StrCat(name, ": line ", line, ": ", what));
}

bool ScalarTypeOf(char type, size_t size, ScalarType* scalar_type) {
  if (type == 'F') {
    if (size == 4) *scalar_type = ScalarType::kFloat32;
    if (size == 8) *scalar_type = ScalarType::kFloat64;
    return size == 4 || size == 8;
  }
  if (type != 'I' && type != 'U') return false;
  const bool is_signed = type == 'I';
  switch (size) {
    case 1:
      *scalar_type = is_signed ? ScalarType::kInt8 : ScalarType::kUint8;
      return true;
    case 2:
      *scalar_type = is_signed ? ScalarType::kInt16 : ScalarType::kUint16;
      return true;
    case 4:
      *scalar_type = is_signed ? ScalarType::kInt32 : ScalarType::kUint32;
      return true;
    case 8:
      *scalar_type = is_signed ? ScalarType::kInt64 : ScalarType::kUint64;
      return true;
    default:
      return false;
  }
}

absl::StatusOr<uint64_t> ParseHeaderCount(absl::string_view name, size_t line,
                                          absl::string_view keyword, absl::string_view token) {
  uint64_t value = 0;
  if (!io_internal::ParseUint64Token(token, &value)) {
    return HeaderError(name, line,
                       absl::StrCat(keyword, " value ", QuotedForMessage(token),
                                    " is not a non-negative integer"));
  }
  if (value > io_internal::kMaxDeclaredCount) {
    return HeaderError(name, line,
                       absl::StrCat(keyword, " ", value, " is more than the limit of ",
                                    io_internal::kMaxDeclaredCount));
  }
  return value;
}

absl::StatusOr<PcdHeader> ParsePcdHeader(absl::string_view bytes, absl::string_view name) {
  if (bytes.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": empty file; not a PCD file"));
  }
  PcdHeader header;
  io_internal::LineScanner lines(bytes);
  absl::string_view line;
  std::vector<absl::string_view> tokens;
  size_t fields_line = 0, size_line = 0, type_line = 0, count_line = 0, width_line = 0,
         height_line = 0, points_line = 0;
  std::vector<std::string> size_text, type_text, count_text;
  uint64_t width = 0, height = 1, points = 0;
  while (lines.Next(&line)) {
    const size_t n = lines.line_number();
    io_internal::SplitOnTextSpace(line, &tokens);
    if (tokens.empty() || tokens[0][0] == '#') continue;
    const absl::string_view keyword = tokens[0];
    auto values = [&]() { return std::vector<std::string>(tokens.begin() + 1, tokens.end()); };
    if (keyword == "VERSION") {
      continue;
    } else if (keyword == "FIELDS") {
      if (fields_line != 0) return HeaderError(name, n, "a second FIELDS line");
      if (tokens.size() < 2) return HeaderError(name, n, "FIELDS lists no field");
      fields_line = n;
      for (size_t i = 1; i < tokens.size(); ++i) {
        PcdField field;
        field.name = std::string(tokens[i]);
        header.fields.push_back(std::move(field));
      }
    } else if (keyword == "SIZE") {
      if (size_line != 0) return HeaderError(name, n, "a second SIZE line");
      size_line = n;
      size_text = values();
    } else if (keyword == "TYPE") {
      if (type_line != 0) return HeaderError(name, n, "a second TYPE line");
      type_line = n;
      type_text = values();
    } else if (keyword == "COUNT") {
      if (count_line != 0) return HeaderError(name, n, "a second COUNT line");
      count_line = n;
      count_text = values();
    } else if (keyword == "WIDTH" || keyword == "HEIGHT" || keyword == "POINTS") {
      if (tokens.size() != 2)
        return HeaderError(name, n, absl::StrCat(keyword, " needs one value"));
      size_t& seen =
          keyword == "WIDTH" ? width_line : (keyword == "HEIGHT" ? height_line : points_line);
      if (seen != 0) return HeaderError(name, n, absl::StrCat("a second ", keyword, " line"));
      seen = n;
      absl::StatusOr<uint64_t> value = ParseHeaderCount(name, n, keyword, tokens[1]);
      if (!value.ok()) return value.status();
      (keyword == "WIDTH" ? width : (keyword == "HEIGHT" ? height : points)) = *value;
    } else if (keyword == "VIEWPOINT") {
      continue;
    } else if (keyword == "DATA") {
      if (tokens.size() != 2) return HeaderError(name, n, "DATA needs one value");
      if (tokens[1] == "ascii") {
        header.data = PcdData::kAscii;
      } else if (tokens[1] == "binary") {
        header.data = PcdData::kBinary;
      } else if (tokens[1] == "binary_compressed") {
        return absl::UnimplementedError(absl::StrCat(
            name, ": line ", n,
            ": DATA binary_compressed (LZF) is not supported; convert the file to binary or "
            "ascii first (e.g. pcl_convert_pcd_ascii_binary <in> <out> 1)"));
      } else {
        return HeaderError(name, n,
                           absl::StrCat("unknown DATA kind ", QuotedForMessage(tokens[1]),
                                        " (ascii, binary, binary_compressed)"));
      }
      header.data_offset = lines.offset();
      header.data_first_line = n + 1;
      // Cross-checks of the header, now that all of it has been seen.
      if (fields_line == 0) return HeaderError(name, n, "no FIELDS line before DATA");
      if (size_line == 0) return HeaderError(name, n, "no SIZE line before DATA");
      if (type_line == 0) return HeaderError(name, n, "no TYPE line before DATA");
      if (width_line == 0) return HeaderError(name, n, "no WIDTH line before DATA");
      const size_t num_fields = header.fields.size();
      if (size_text.size() != num_fields) {
        return HeaderError(
            name, size_line,
            absl::StrCat("SIZE has ", size_text.size(), " values but FIELDS has ", num_fields));
      }
      if (type_text.size() != num_fields) {
        return HeaderError(
            name, type_line,
            absl::StrCat("TYPE has ", type_text.size(), " values but FIELDS has ", num_fields));
      }
      if (count_line != 0 && count_text.size() != num_fields) {
        return HeaderError(
            name, count_line,
            absl::StrCat("COUNT has ", count_text.size(), " values but FIELDS has ", num_fields));
      }
      uint64_t record_bytes = 0;
      uint64_t values_per_line = 0;
      for (size_t i = 0; i < num_fields; ++i) {
        PcdField& field = header.fields[i];
        uint64_t size = 0;
        if (!io_internal::ParseUint64Token(size_text[i], &size) || size > 8 ||
            type_text[i].size() != 1 ||
            !ScalarTypeOf(type_text[i][0], static_cast<size_t>(size), &field.scalar_type)) {
          return HeaderError(name, type_line,
                             absl::StrCat("field ", QuotedForMessage(field.name), " has SIZE ",
                                          QuotedForMessage(size_text[i]), " and TYPE ",
                                          QuotedForMessage(type_text[i]),
                                          "; supported are F 4/8, I 1/2/4/8, U 1/2/4/8"));
        }
        field.size = static_cast<size_t>(size);
        field.type = type_text[i][0];
        if (count_line != 0) {
          if (!io_internal::ParseUint64Token(count_text[i], &field.count) || field.count == 0 ||
              field.count > kMaxFieldCount) {
            return HeaderError(
                name, count_line,
                absl::StrCat("field ", QuotedForMessage(field.name), " has COUNT ",
                             QuotedForMessage(count_text[i]), "; expected 1 to ", kMaxFieldCount));
          }
        }
        field.byte_offset = static_cast<size_t>(record_bytes);
        field.first_value = static_cast<size_t>(values_per_line);
        record_bytes += field.size * field.count;
        values_per_line += field.count;
        int* role = field.name == "x"           ? &header.x
                    : field.name == "y"         ? &header.y
                    : field.name == "z"         ? &header.z
                    : field.name == "intensity" ? &header.intensity
                                                : nullptr;
        if (role == nullptr) continue;
        if (*role >= 0) {
          return HeaderError(
              name, fields_line,
              absl::StrCat("field ", QuotedForMessage(field.name), " appears twice"));
        }
        if (field.count != 1) {
          if (role == &header.intensity) continue;  // a multi-valued intensity: ignored
          return HeaderError(name, count_line,
                             absl::StrCat("field ", QuotedForMessage(field.name), " has COUNT ",
                                          field.count, "; a coordinate needs COUNT 1"));
        }
        *role = static_cast<int>(i);
      }
      for (const char* axis : {"x", "y", "z"}) {
        const int index = axis[0] == 'x' ? header.x : (axis[0] == 'y' ? header.y : header.z);
        if (index < 0) {
          return HeaderError(name, fields_line, absl::StrCat("no field '", axis, "' in FIELDS"));
        }
      }
      header.record_bytes = static_cast<size_t>(record_bytes);
      header.values_per_line = static_cast<size_t>(values_per_line);
      uint64_t cells = 0;
      if (__builtin_mul_overflow(width, height, &cells) || cells > io_internal::kMaxDeclaredCount) {
        return HeaderError(
            name, height_line != 0 ? height_line : width_line,
            absl::StrCat("WIDTH ", width, " * HEIGHT ", height, " is more than the limit of ",
                         io_internal::kMaxDeclaredCount));
      }
      if (points_line != 0 && points != cells) {
        return HeaderError(name, points_line,
                           absl::StrCat("POINTS ", points, " does not equal WIDTH ", width,
                                        " * HEIGHT ", height, " = ", cells));
      }
      header.num_points = cells;
      return header;
    } else {
      return HeaderError(name, n,
                         absl::StrCat("unknown header keyword ", QuotedForMessage(keyword),
                                      lines.line_number() == 1 ? "; not a PCD file" : ""));
    }
  }
  return absl::InvalidArgumentError(
      absl::StrCat(name, ": header: the file ends before the DATA line"));
}

absl::Status ParseBinaryPoints(absl::string_view bytes, absl::string_view name,
                               const PcdHeader& header, PointCloud& cloud) {
  const size_t available = bytes.size() - header.data_offset;
  uint64_t needed = 0;
  const bool overflow = __builtin_mul_overflow(header.num_points, header.record_bytes, &needed);
  if (overflow || needed != available) {
    return absl::InvalidArgumentError(absl::StrCat(
        name, ": byte offset ", header.data_offset, ": DATA binary declares ", header.num_points,
        " points of ", header.record_bytes, " bytes but ", available,
        " bytes follow the header; the file is ",
        overflow || needed > available ? "truncated" : "too long", " or POINTS is wrong"));
  }
  const size_t count = static_cast<size_t>(header.num_points);
  cloud.points.resize(count);
  if (header.intensity >= 0) cloud.intensities.resize(count);
  const PcdField* axes[3] = {&header.fields[header.x], &header.fields[header.y],
                             &header.fields[header.z]};
  for (size_t i = 0; i < count; ++i) {
    const size_t record_offset = header.data_offset + i * header.record_bytes;
    const char* record = bytes.data() + record_offset;
    for (int k = 0; k < 3; ++k) {
      const double value = io_internal::DecodeScalarAsDouble(
          record + axes[k]->byte_offset, axes[k]->scalar_type, std::endian::little);
      const float narrowed = static_cast<float>(value);
      if (!std::isfinite(narrowed)) {
        return absl::InvalidArgumentError(absl::StrCat(
            name, ": byte offset ", record_offset + axes[k]->byte_offset, " (point ", i,
            ", field '", axes[k]->name, "'): coordinate ", value, " is not a finite float"));
      }
      cloud.points[i][k] = narrowed;
    }
    if (header.intensity >= 0) {
      const PcdField& field = header.fields[header.intensity];
      cloud.intensities[i] = static_cast<float>(io_internal::DecodeScalarAsDouble(
          record + field.byte_offset, field.scalar_type, std::endian::little));
    }
  }
  return absl::OkStatus();
}

absl::Status ParseAsciiPoints(absl::string_view bytes, absl::string_view name,
                              const PcdHeader& header, PointCloud& cloud) {
  const absl::string_view text = bytes.substr(header.data_offset);
  const size_t reservation = io_internal::TextReservation(header.num_points, text.size());
  cloud.points.reserve(reservation);
  if (header.intensity >= 0) cloud.intensities.reserve(reservation);
  io_internal::LineScanner lines(text);
  absl::string_view line;
  std::vector<absl::string_view> tokens;
  const size_t axes[3] = {header.fields[header.x].first_value, header.fields[header.y].first_value,
                          header.fields[header.z].first_value};
  auto line_number = [&]() { return header.data_first_line + lines.line_number() - 1; };
  while (lines.Next(&line)) {
    io_internal::SplitOnTextSpace(line, &tokens);
    if (tokens.empty()) continue;
    const size_t point = cloud.points.size();
    if (point == header.num_points) {
      return absl::InvalidArgumentError(absl::StrCat(
          name, ": line ", line_number(), ": more point lines than POINTS ", header.num_points));
    }
    if (tokens.size() != header.values_per_line) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": line ", line_number(), " (point ", point, "): ", tokens.size(),
                       " values, but the fields need ", header.values_per_line));
    }
    Eigen::Vector3f p;
    for (int k = 0; k < 3; ++k) {
      double value = 0.0;
      const absl::string_view token = tokens[axes[k]];
      if (!io_internal::ParseDoubleToken(token, &value)) {
        return absl::InvalidArgumentError(absl::StrCat(name, ": line ", line_number(), " (point ",
                                                       point, "): ", QuotedForMessage(token),
                                                       " is not a number"));
      }
      p[k] = static_cast<float>(value);
      if (!std::isfinite(p[k])) {
        return absl::InvalidArgumentError(
            absl::StrCat(name, ": line ", line_number(), " (point ", point, ", field '",
                         absl::string_view("xyz").substr(k, 1), "'): coordinate ",
                         QuotedForMessage(token), " is not a finite float"));
      }
    }
    cloud.points.push_back(p);
    if (header.intensity >= 0) {
      double value = 0.0;
      const absl::string_view token = tokens[header.fields[header.intensity].first_value];
      if (!io_internal::ParseDoubleToken(token, &value)) {
        return absl::InvalidArgumentError(
            absl::StrCat(name, ": line ", line_number(), " (point ", point,
                         ", field 'intensity'): ", QuotedForMessage(token), " is not a number"));
      }
      cloud.intensities.push_back(static_cast<float>(value));
    }
  }
  if (cloud.points.size() != header.num_points) {
    return absl::InvalidArgumentError(absl::StrCat(
        name, ": line ", line_number() + 1, ": the file ends after ", cloud.points.size(),
        " of the ", header.num_points, " points that POINTS declares"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<PointCloud> ParsePcd(absl::string_view bytes, absl::string_view name) {
  absl::StatusOr<PcdHeader> header = ParsePcdHeader(bytes, name);
  if (!header.ok()) return header.status();
  PointCloud cloud;
  absl::Status status = header->data == PcdData::kBinary
                            ? ParseBinaryPoints(bytes, name, *header, cloud)
                            : ParseAsciiPoints(bytes, name, *header, cloud);
  if (!status.ok()) return status;
  return cloud;
}

absl::StatusOr<PointCloud> ReadPcd(const std::string& path) {
  absl::StatusOr<std::string> bytes = ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  return ParsePcd(*bytes, path);
}

absl::StatusOr<std::string> SerializePcd(const PointCloud& cloud, PcdFormat format) {
  absl::Status valid = ValidatePointCloud(cloud);
  if (!valid.ok()) return valid;
  const bool with_intensity = !cloud.intensities.empty();
  std::string out = "# .PCD v0.7 - Point Cloud Data file format (written by rpsr)\nVERSION 0.7\n";
  absl::StrAppend(&out, with_intensity ? "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\n"
                                         "COUNT 1 1 1 1\n"
                                       : "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n");
  absl::StrAppend(&out, "WIDTH ", cloud.size(), "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS ",
                  cloud.size(), "\nDATA ", format == PcdFormat::kAscii ? "ascii" : "binary", "\n");
  for (size_t i = 0; i < cloud.size(); ++i) {
    const float values[4] = {cloud.points[i].x(), cloud.points[i].y(), cloud.points[i].z(),
                             with_intensity ? cloud.intensities[i] : 0.0f};
    const int num_values = with_intensity ? 4 : 3;
    for (int k = 0; k < num_values; ++k) {
      if (format == PcdFormat::kBinary) {
        io_internal::AppendFloat32(values[k], std::endian::little, &out);
      } else {
        io_internal::AppendShortestDecimal(values[k], &out);
        out.push_back(k + 1 == num_values ? '\n' : ' ');
      }
    }
  }
  return out;
}

absl::Status WritePcd(const std::string& path, const PointCloud& cloud, PcdFormat format) {
  absl::StatusOr<std::string> bytes = SerializePcd(cloud, format);
  if (!bytes.ok()) {
    return absl::Status(bytes.status().code(), absl::StrCat(path, ": ", bytes.status().message()));
  }
  return WriteFileBytes(path, *bytes);
}

}  // namespace rpsr::core
