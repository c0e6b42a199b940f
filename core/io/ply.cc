#include "core/io/ply.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <utility>
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

enum class PropertyRole { kIgnored, kX, kY, kZ, kIntensity, kFaceIndices };

struct PlyProperty {
  std::string name;
  bool is_list = false;
  ScalarType type = ScalarType::kFloat32;      // the scalar's type, or a list's item type
  ScalarType count_type = ScalarType::kUint8;  // lists only
  PropertyRole role = PropertyRole::kIgnored;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  size_t header_line = 0;
  std::vector<PlyProperty> properties;
};

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  size_t data_offset = 0;      // byte offset of the first data byte
  size_t data_first_line = 0;  // line number the data starts on (ascii)
  int vertex_element = -1;
  int face_element = -1;
};

bool ScalarTypeFromName(absl::string_view name, ScalarType* type) {
  static constexpr std::pair<absl::string_view, ScalarType> kNames[] = {
      {"char", ScalarType::kInt8},      {"int8", ScalarType::kInt8},
      {"uchar", ScalarType::kUint8},    {"uint8", ScalarType::kUint8},
      {"short", ScalarType::kInt16},    {"int16", ScalarType::kInt16},
      {"ushort", ScalarType::kUint16},  {"uint16", ScalarType::kUint16},
      {"int", ScalarType::kInt32},      {"int32", ScalarType::kInt32},
      {"uint", ScalarType::kUint32},    {"uint32", ScalarType::kUint32},
      {"float", ScalarType::kFloat32},  {"float32", ScalarType::kFloat32},
      {"double", ScalarType::kFloat64}, {"float64", ScalarType::kFloat64},
  };
  for (const auto& [type_name, value] : kNames) {
    if (name == type_name) {
      *type = value;
      return true;
    }
  }
  return false;
}

absl::Status HeaderError(absl::string_view name, size_t line, absl::string_view what) {
  return absl::InvalidArgumentError(absl::StrCat(name, ": line ", line, ": ", what));
}

absl::Status AssignRoles(absl::string_view name, PlyHeader& header) {
  for (size_t e = 0; e < header.elements.size(); ++e) {
    PlyElement& element = header.elements[e];
    if (element.count > 0 && element.properties.empty()) {
      return HeaderError(name, element.header_line,
                         absl::StrCat("element ", QuotedForMessage(element.name), " declares ",
                                      element.count, " records but no properties"));
    }
    const bool is_vertex = element.name == "vertex";
    const bool is_face = element.name == "face";
    if ((is_vertex && header.vertex_element >= 0) || (is_face && header.face_element >= 0)) {
      return HeaderError(name, element.header_line,
                         absl::StrCat("a second element ", QuotedForMessage(element.name)));
    }
    if (is_vertex) header.vertex_element = static_cast<int>(e);
    if (is_face) header.face_element = static_cast<int>(e);
    bool has_intensity = false;
    for (PlyProperty& property : element.properties) {
      if (is_vertex) {
        const absl::string_view n = property.name;
        if (n == "x" || n == "y" || n == "z") {
          if (property.is_list) {
            return HeaderError(name, element.header_line,
                               absl::StrCat("vertex property ", QuotedForMessage(n), " is a list"));
          }
          property.role =
              n == "x" ? PropertyRole::kX : (n == "y" ? PropertyRole::kY : PropertyRole::kZ);
        } else if ((n == "intensity" || n == "reflectance") && !property.is_list &&
                   !has_intensity) {
          property.role = PropertyRole::kIntensity;
          has_intensity = true;
        }
      } else if (is_face &&
                 (property.name == "vertex_indices" || property.name == "vertex_index")) {
        if (!property.is_list || !io_internal::IsIntegerScalarType(property.type)) {
          return HeaderError(name, element.header_line,
                             absl::StrCat("face property ", QuotedForMessage(property.name),
                                          " must be a list of integers"));
        }
        property.role = PropertyRole::kFaceIndices;
      }
    }
  }
  if (header.vertex_element < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": header: no element 'vertex' (a PLY cloud needs one)"));
  }
  const PlyElement& vertex = header.elements[header.vertex_element];
  for (const PropertyRole role : {PropertyRole::kX, PropertyRole::kY, PropertyRole::kZ}) {
    bool found = false;
    for (const PlyProperty& property : vertex.properties) found |= property.role == role;
    if (!found) {
      const char* axis = role == PropertyRole::kX ? "x" : (role == PropertyRole::kY ? "y" : "z");
      return HeaderError(name, vertex.header_line,
                         absl::StrCat("element 'vertex' has no property '", axis, "'"));
    }
  }
  if (header.face_element >= 0) {
    const PlyElement& face = header.elements[header.face_element];
    bool found = false;
    for (const PlyProperty& property : face.properties) {
      found |= property.role == PropertyRole::kFaceIndices;
    }
    if (!found) {
      return HeaderError(name, face.header_line,
                         "element 'face' has no list property 'vertex_indices' or 'vertex_index'");
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<PlyHeader> ParsePlyHeader(absl::string_view bytes, absl::string_view name) {
  if (bytes.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": empty file; not a PLY file"));
  }
  io_internal::LineScanner lines(bytes);
  absl::string_view line;
  lines.Next(&line);
  if (io_internal::TrimTextSpace(line) != "ply") {
    return HeaderError(name, 1, "not a PLY file: the first line is not 'ply'");
  }
  PlyHeader header;
  bool has_format = false;
  std::vector<absl::string_view> tokens;
  while (lines.Next(&line)) {
    const size_t line_number = lines.line_number();
    io_internal::SplitOnTextSpace(line, &tokens);
    if (tokens.empty()) continue;
    const absl::string_view keyword = tokens[0];
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "end_header") {
      if (!has_format) return HeaderError(name, line_number, "no 'format' line before end_header");
      header.data_offset = lines.offset();
      header.data_first_line = line_number + 1;
      absl::Status roles = AssignRoles(name, header);
      if (!roles.ok()) return roles;
      return header;
    }
    if (keyword == "format") {
      if (has_format) return HeaderError(name, line_number, "a second 'format' line");
      if (tokens.size() != 3) {
        return HeaderError(name, line_number, "expected 'format <kind> 1.0'");
      }
      if (tokens[1] == "ascii") {
        header.format = PlyFormat::kAscii;
      } else if (tokens[1] == "binary_little_endian") {
        header.format = PlyFormat::kBinaryLittleEndian;
      } else if (tokens[1] == "binary_big_endian") {
        header.format = PlyFormat::kBinaryBigEndian;
      } else {
        return HeaderError(name, line_number,
                           absl::StrCat("unknown format ", QuotedForMessage(tokens[1]),
                                        " (ascii, binary_little_endian, binary_big_endian)"));
      }
      has_format = true;
    } else if (keyword == "element") {
      uint64_t count = 0;
      if (tokens.size() != 3 || !io_internal::ParseUint64Token(tokens[2], &count)) {
        return HeaderError(name, line_number, "expected 'element <name> <count>'");
      }
      if (count > io_internal::kMaxDeclaredCount) {
        return HeaderError(
            name, line_number,
            absl::StrCat("element ", QuotedForMessage(tokens[1]), " declares ", count,
                         " records, more than the limit of ", io_internal::kMaxDeclaredCount));
      }
      PlyElement element;
      element.name = std::string(tokens[1]);
      element.count = count;
      element.header_line = line_number;
      header.elements.push_back(std::move(element));
    } else if (keyword == "property") {
      if (header.elements.empty()) {
        return HeaderError(name, line_number, "'property' before any 'element'");
      }
      PlyProperty property;
      if (tokens.size() == 5 && tokens[1] == "list") {
        property.is_list = true;
        if (!ScalarTypeFromName(tokens[2], &property.count_type) ||
            !io_internal::IsIntegerScalarType(property.count_type)) {
          return HeaderError(name, line_number,
                             absl::StrCat("list count type ", QuotedForMessage(tokens[2]),
                                          " is not an integer type"));
        }
        if (!ScalarTypeFromName(tokens[3], &property.type)) {
          return HeaderError(name, line_number,
                             absl::StrCat("unknown property type ", QuotedForMessage(tokens[3])));
        }
        property.name = std::string(tokens[4]);
      } else if (tokens.size() == 3 && tokens[1] != "list") {
        if (!ScalarTypeFromName(tokens[1], &property.type)) {
          return HeaderError(name, line_number,
                             absl::StrCat("unknown property type ", QuotedForMessage(tokens[1])));
        }
        property.name = std::string(tokens[2]);
      } else {
        return HeaderError(name, line_number,
                           "expected 'property <type> <name>' or "
                           "'property list <count type> <item type> <name>'");
      }
      for (const PlyProperty& other : header.elements.back().properties) {
        if (other.name == property.name) {
          return HeaderError(
              name, line_number,
              absl::StrCat("a second property ", QuotedForMessage(property.name), " in element ",
                           QuotedForMessage(header.elements.back().name)));
        }
      }
      header.elements.back().properties.push_back(std::move(property));
    } else {
      return HeaderError(name, line_number,
                         absl::StrCat("unknown header keyword ", QuotedForMessage(keyword)));
    }
  }
  return absl::InvalidArgumentError(
      absl::StrCat(name, ": header: the file ends before 'end_header'"));
}

// Reads values of a binary body; on failure `problem()` says what is wrong.
class BinaryValues {
 public:
  BinaryValues(absl::string_view bytes, size_t offset, std::endian byte_order)
      : bytes_(bytes), position_(offset), byte_order_(byte_order) {}

  size_t remaining() const { return bytes_.size() - position_; }
  size_t position() const { return position_; }
  std::endian byte_order() const { return byte_order_; }
  const std::string& problem() const { return problem_; }
  std::string Place() const { return absl::StrCat("byte offset ", value_offset_); }

  // Hands out the next `size` bytes, which the caller has checked are there.
  const char* TakeChecked(size_t size) {
    const char* data = bytes_.data() + position_;
    position_ += size;
    return data;
  }
  std::string PlaceOfEnd() const { return absl::StrCat("byte offset ", position_); }

  bool ReadDouble(ScalarType type, double* value) {
    if (!Take(type)) return false;
    *value = io_internal::DecodeScalarAsDouble(bytes_.data() + value_offset_, type, byte_order_);
    return true;
  }
  bool ReadInteger(ScalarType type, int64_t* value) {
    if (!Take(type)) return false;
    if (!io_internal::DecodeScalarAsInt64(bytes_.data() + value_offset_, type, byte_order_,
                                          value)) {
      problem_ = "integer value out of range";
      return false;
    }
    return true;
  }
  bool Skip(ScalarType type) { return Take(type); }
  bool SkipList(ScalarType item_type, int64_t count) {
    value_offset_ = position_;
    const size_t size = io_internal::ScalarTypeSize(item_type);
    if (static_cast<uint64_t>(count) > remaining() / size) {
      problem_ = absl::StrCat("a list of ", count, " ", size, "-byte items runs past the end (",
                              remaining(), " bytes left)");
      return false;
    }
    position_ += static_cast<size_t>(count) * size;
    return true;
  }
  // Error text when bytes are left after the last element, or "" when none are.
  std::string Leftover() const {
    if (remaining() == 0) return "";
    return absl::StrCat(remaining(),
                        " bytes after the last element; the header declares fewer records than "
                        "the file holds");
  }

 private:
  bool Take(ScalarType type) {
    value_offset_ = position_;
    const size_t size = io_internal::ScalarTypeSize(type);
    if (remaining() < size) {
      problem_ = absl::StrCat("the file ends: a ", size, "-byte value needs more than the ",
                              remaining(), " bytes left");
      return false;
    }
    position_ += size;
    return true;
  }

  absl::string_view bytes_;
  size_t position_;
  size_t value_offset_ = 0;
  std::endian byte_order_;
  std::string problem_;
};

// Reads values of an ascii body (whitespace-separated tokens); on failure `problem()` says what
// is wrong.
class AsciiValues {
 public:
  AsciiValues(absl::string_view text, size_t first_line) : tokens_(text, first_line) {}

  size_t remaining() const { return tokens_.remaining(); }
  const std::string& problem() const { return problem_; }
  std::string Place() const { return absl::StrCat("line ", tokens_.line_number()); }
  std::string PlaceOfEnd() const { return Place(); }

  bool ReadDouble(ScalarType, double* value) {
    absl::string_view token;
    if (!NextToken(&token)) return false;
    if (!io_internal::ParseDoubleToken(token, value)) {
      problem_ = absl::StrCat(QuotedForMessage(token), " is not a number");
      return false;
    }
    return true;
  }
  bool ReadInteger(ScalarType, int64_t* value) {
    absl::string_view token;
    if (!NextToken(&token)) return false;
    if (!io_internal::ParseInt64Token(token, value)) {
      problem_ = absl::StrCat(QuotedForMessage(token), " is not an integer");
      return false;
    }
    return true;
  }
  bool Skip(ScalarType type) {
    double ignored;
    return ReadDouble(type, &ignored);
  }
  bool SkipList(ScalarType item_type, int64_t count) {
    for (int64_t i = 0; i < count; ++i) {
      if (!Skip(item_type)) return false;
    }
    return true;
  }
  std::string Leftover() {
    absl::string_view token;
    if (!tokens_.Next(&token)) return "";
    return absl::StrCat("unexpected ", QuotedForMessage(token),
                        " after the last element; the header declares fewer records than the "
                        "file holds");
  }

 private:
  bool NextToken(absl::string_view* token) {
    if (!tokens_.Next(token)) {
      problem_ = "the file ends before this value";
      return false;
    }
    return true;
  }

  io_internal::TokenScanner tokens_;
  std::string problem_;
};

// The fast path for a binary element without list properties, whose records all have one size:
// reads (vertex) or jumps over (any other element) all records at once. The caller has checked
// that count * record size bytes remain. Returns false, having read nothing, for an element with
// lists; sets `*status` only when a coordinate is not finite.
bool ReadFixedSizeBinaryRecords(const PlyElement& element, bool is_vertex, bool has_intensity,
                                absl::string_view name, BinaryValues& values, PlyContents& contents,
                                absl::Status* status) {
  size_t record_bytes = 0;
  // Byte offset within a record and type of x, y, z, intensity.
  size_t offsets[4] = {0, 0, 0, 0};
  ScalarType types[4] = {ScalarType::kFloat32, ScalarType::kFloat32, ScalarType::kFloat32,
                         ScalarType::kFloat32};
  const PlyProperty* properties[4] = {nullptr, nullptr, nullptr, nullptr};
  for (const PlyProperty& p : element.properties) {
    if (p.is_list) return false;
    if (p.role != PropertyRole::kIgnored) {
      const int slot = static_cast<int>(p.role) - static_cast<int>(PropertyRole::kX);
      offsets[slot] = record_bytes;
      types[slot] = p.type;
      properties[slot] = &p;
    }
    record_bytes += io_internal::ScalarTypeSize(p.type);
  }
  if (!is_vertex) {
    values.TakeChecked(static_cast<size_t>(element.count) * record_bytes);
    return true;
  }
  const std::endian order = values.byte_order();
  for (uint64_t record = 0; record < element.count; ++record) {
    const size_t record_offset = values.position();
    const char* data = values.TakeChecked(record_bytes);
    Eigen::Vector3f point;
    for (int k = 0; k < 3; ++k) {
      const double value = io_internal::DecodeScalarAsDouble(data + offsets[k], types[k], order);
      point[k] = static_cast<float>(value);
      if (!std::isfinite(point[k])) {
        *status = absl::InvalidArgumentError(
            absl::StrCat(name, ": byte offset ", record_offset + offsets[k], " (element ",
                         QuotedForMessage(element.name), " record ", record, ", property ",
                         QuotedForMessage(properties[k]->name), "): coordinate ", value,
                         " is not a finite float"));
        return true;
      }
    }
    contents.cloud.points.push_back(point);
    if (has_intensity) {
      contents.cloud.intensities.push_back(static_cast<float>(
          io_internal::DecodeScalarAsDouble(data + offsets[3], types[3], order)));
    }
  }
  return true;
}

// Reads the body of the file described by `header` from `values` into `contents`.
template <typename Values>
absl::Status ReadPlyBody(const PlyHeader& header, absl::string_view name, Values& values,
                         size_t min_bytes_per_value, PlyContents& contents) {
  const PlyElement* element = nullptr;
  const PlyProperty* property = nullptr;
  uint64_t record = 0;
  auto fail = [&](absl::string_view what) {
    return absl::InvalidArgumentError(absl::StrCat(
        name, ": ", values.Place(), " (element ", QuotedForMessage(element->name), " record ",
        record, ", property ", QuotedForMessage(property->name), "): ", what));
  };
  const uint64_t num_vertices = header.elements[header.vertex_element].count;
  for (const PlyElement& current : header.elements) {
    element = &current;
    // The least number of bytes one record can take: every scalar and every list's count.
    uint64_t min_record_bytes = 0;
    for (const PlyProperty& p : current.properties) {
      min_record_bytes += min_bytes_per_value == 1
                              ? io_internal::ScalarTypeSize(p.is_list ? p.count_type : p.type)
                              : min_bytes_per_value;
    }
    // In ascii the very last value may end the file without a separator: one byte of slack.
    const uint64_t available = values.remaining() + (min_bytes_per_value > 1 ? 1 : 0);
    uint64_t needed = 0;
    if (__builtin_mul_overflow(current.count, min_record_bytes, &needed) || needed > available) {
      return absl::InvalidArgumentError(absl::StrCat(
          name, ": ", values.PlaceOfEnd(), " (element ", QuotedForMessage(current.name),
          "): declares ", current.count, " records of at least ", min_record_bytes,
          " bytes each but only ", values.remaining(),
          " bytes remain; the file is truncated or the count is wrong"));
    }
    const bool is_vertex = &current == &header.elements[header.vertex_element];
    const bool is_face =
        header.face_element >= 0 && &current == &header.elements[header.face_element];
    // Reservations are bounded by the bytes present (checked just above), not by the header.
    bool has_intensity = false;
    if (is_vertex) {
      contents.cloud.points.reserve(current.count);
      for (const PlyProperty& p : current.properties) {
        has_intensity |= p.role == PropertyRole::kIntensity;
      }
      if (has_intensity) contents.cloud.intensities.reserve(current.count);
    }
    // A face takes at least 4 bytes (a count and three 1-byte indices) and gives a 12-byte
    // triangle per index beyond the second: reserve no more than the bytes could hold.
    if (is_face) {
      contents.mesh.triangles.reserve(
          std::min<uint64_t>(current.count, values.remaining() / (4 * min_bytes_per_value)));
    }
    if constexpr (std::is_same_v<Values, BinaryValues>) {
      absl::Status status;
      if (ReadFixedSizeBinaryRecords(current, is_vertex, has_intensity, name, values, contents,
                                     &status)) {
        if (!status.ok()) return status;
        continue;
      }
    }
    for (record = 0; record < current.count; ++record) {
      Eigen::Vector3f point = Eigen::Vector3f::Zero();
      float intensity = 0.0f;
      for (const PlyProperty& p : current.properties) {
        property = &p;
        if (!p.is_list) {
          if (p.role == PropertyRole::kIgnored) {
            if (!values.Skip(p.type)) return fail(values.problem());
            continue;
          }
          double value = 0.0;
          if (!values.ReadDouble(p.type, &value)) return fail(values.problem());
          const float narrowed = static_cast<float>(value);
          switch (p.role) {
            case PropertyRole::kX:
            case PropertyRole::kY:
            case PropertyRole::kZ:
              if (!std::isfinite(narrowed)) {
                return fail(absl::StrCat("coordinate ", value, " is not a finite float"));
              }
              point[static_cast<int>(p.role) - static_cast<int>(PropertyRole::kX)] = narrowed;
              break;
            default:
              intensity = narrowed;
              break;
          }
          continue;
        }
        int64_t count = 0;
        if (!values.ReadInteger(p.count_type, &count)) return fail(values.problem());
        if (count < 0) return fail(absl::StrCat("negative list length ", count));
        if (p.role != PropertyRole::kFaceIndices) {
          if (!values.SkipList(p.type, count)) return fail(values.problem());
          continue;
        }
        if (count < 3) {
          return fail(absl::StrCat("a face needs at least 3 vertex indices, this one has ", count));
        }
        int first = 0;
        int previous = 0;
        for (int64_t i = 0; i < count; ++i) {
          int64_t index = 0;
          if (!values.ReadInteger(p.type, &index)) return fail(values.problem());
          if (index < 0 || static_cast<uint64_t>(index) >= num_vertices) {
            return fail(absl::StrCat("vertex index ", index, " (item ", i,
                                     ") is out of range; the file has ", num_vertices,
                                     " vertices"));
          }
          const int current_index = static_cast<int>(index);
          if (i == 0) {
            first = current_index;
          } else if (i >= 2) {
            contents.mesh.triangles.emplace_back(first, previous, current_index);
          }
          previous = current_index;
        }
      }
      if (is_vertex) {
        contents.cloud.points.push_back(point);
        if (has_intensity) contents.cloud.intensities.push_back(intensity);
      }
    }
  }
  const std::string leftover = values.Leftover();
  if (!leftover.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": ", values.PlaceOfEnd(), ": ", leftover));
  }
  return absl::OkStatus();
}

void AppendPlyHeader(PlyFormat format, PlyCoordinateType coordinate_type, size_t num_vertices,
                     bool with_intensity, const size_t* num_faces, std::string* out) {
  const char* format_name = format == PlyFormat::kAscii                ? "ascii"
                            : format == PlyFormat::kBinaryLittleEndian ? "binary_little_endian"
                                                                       : "binary_big_endian";
  const char* type = coordinate_type == PlyCoordinateType::kFloat32 ? "float" : "double";
  absl::StrAppend(out, "ply\nformat ", format_name, " 1.0\ncomment written by rpsr\n",
                  "element vertex ", num_vertices, "\nproperty ", type, " x\nproperty ", type,
                  " y\nproperty ", type, " z\n");
  if (with_intensity) absl::StrAppend(out, "property ", type, " intensity\n");
  if (num_faces != nullptr) {
    absl::StrAppend(out, "element face ", *num_faces, "\nproperty list uchar int vertex_indices\n");
  }
  out->append("end_header\n");
}

void AppendPlyValue(float value, PlyFormat format, PlyCoordinateType coordinate_type,
                    bool last_in_record, std::string* out) {
  if (format == PlyFormat::kAscii) {
    if (coordinate_type == PlyCoordinateType::kFloat32) {
      io_internal::AppendShortestDecimal(value, out);
    } else {
      io_internal::AppendShortestDecimal(static_cast<double>(value), out);
    }
    out->push_back(last_in_record ? '\n' : ' ');
    return;
  }
  const std::endian order =
      format == PlyFormat::kBinaryLittleEndian ? std::endian::little : std::endian::big;
  if (coordinate_type == PlyCoordinateType::kFloat32) {
    io_internal::AppendFloat32(value, order, out);
  } else {
    io_internal::AppendFloat64(value, order, out);
  }
}

void AppendPlyVertices(const std::vector<Eigen::Vector3f>& points,
                       const std::vector<float>& intensities, PlyFormat format,
                       PlyCoordinateType coordinate_type, std::string* out) {
  const bool with_intensity = !intensities.empty();
  for (size_t i = 0; i < points.size(); ++i) {
    AppendPlyValue(points[i].x(), format, coordinate_type, false, out);
    AppendPlyValue(points[i].y(), format, coordinate_type, false, out);
    AppendPlyValue(points[i].z(), format, coordinate_type, !with_intensity, out);
    if (with_intensity) AppendPlyValue(intensities[i], format, coordinate_type, true, out);
  }
}

}  // namespace

absl::StatusOr<PlyContents> ParsePly(absl::string_view bytes, absl::string_view name) {
  absl::StatusOr<PlyHeader> header = ParsePlyHeader(bytes, name);
  if (!header.ok()) return header.status();
  PlyContents contents;
  absl::Status status;
  if (header->format == PlyFormat::kAscii) {
    AsciiValues values(bytes.substr(header->data_offset), header->data_first_line);
    // An ascii value takes at least 2 bytes: a character and a separator.
    status = ReadPlyBody(*header, name, values, /*min_bytes_per_value=*/2, contents);
  } else {
    BinaryValues values(
        bytes, header->data_offset,
        header->format == PlyFormat::kBinaryLittleEndian ? std::endian::little : std::endian::big);
    status = ReadPlyBody(*header, name, values, /*min_bytes_per_value=*/1, contents);
  }
  if (!status.ok()) return status;
  if (header->face_element >= 0) {
    contents.has_faces = true;
    contents.mesh.vertices = contents.cloud.points;
  }
  return contents;
}

absl::StatusOr<PlyContents> ReadPly(const std::string& path) {
  absl::StatusOr<std::string> bytes = ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  return ParsePly(*bytes, path);
}

absl::StatusOr<std::string> SerializePly(const PointCloud& cloud, PlyFormat format,
                                         PlyCoordinateType coordinate_type) {
  absl::Status valid = ValidatePointCloud(cloud);
  if (!valid.ok()) return valid;
  std::string out;
  AppendPlyHeader(format, coordinate_type, cloud.size(), !cloud.intensities.empty(), nullptr, &out);
  AppendPlyVertices(cloud.points, cloud.intensities, format, coordinate_type, &out);
  return out;
}

absl::StatusOr<std::string> SerializePly(const TriangleMesh& mesh, PlyFormat format,
                                         PlyCoordinateType coordinate_type) {
  if (absl::Status valid = ValidateTriangleMesh(mesh); !valid.ok()) return valid;
  std::string out;
  const size_t num_faces = mesh.triangles.size();
  AppendPlyHeader(format, coordinate_type, mesh.vertices.size(), false, &num_faces, &out);
  AppendPlyVertices(mesh.vertices, {}, format, coordinate_type, &out);
  const std::endian order =
      format == PlyFormat::kBinaryLittleEndian ? std::endian::little : std::endian::big;
  for (const Eigen::Vector3i& tri : mesh.triangles) {
    if (format == PlyFormat::kAscii) {
      absl::StrAppend(&out, "3 ", tri.x(), " ", tri.y(), " ", tri.z(), "\n");
    } else {
      out.push_back(3);
      for (int k = 0; k < 3; ++k) io_internal::AppendInt32(tri[k], order, &out);
    }
  }
  return out;
}

absl::Status WritePly(const std::string& path, const PointCloud& cloud, PlyFormat format,
                      PlyCoordinateType coordinate_type) {
  absl::StatusOr<std::string> bytes = SerializePly(cloud, format, coordinate_type);
  if (!bytes.ok()) {
    return absl::Status(bytes.status().code(), absl::StrCat(path, ": ", bytes.status().message()));
  }
  return WriteFileBytes(path, *bytes);
}

absl::Status WritePly(const std::string& path, const TriangleMesh& mesh, PlyFormat format,
                      PlyCoordinateType coordinate_type) {
  absl::StatusOr<std::string> bytes = SerializePly(mesh, format, coordinate_type);
  if (!bytes.ok()) {
    return absl::Status(bytes.status().code(), absl::StrCat(path, ": ", bytes.status().message()));
  }
  return WriteFileBytes(path, *bytes);
}

}  // namespace rpsr::core
