#include "core/io/xyz_text.h"

#include <cmath>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/io/file_bytes.h"
#include "core/io/text_tokens.h"

namespace rpsr::core {
namespace {

using io_internal::QuotedForMessage;

}  // namespace

absl::StatusOr<PointCloud> ParseXyzText(absl::string_view text, absl::string_view name,
                                        XyzTextDelimiter delimiter) {
  PointCloud cloud;
  io_internal::LineScanner lines(text);
  absl::string_view line;
  std::vector<absl::string_view> columns;
  bool first_data_line = true;
  while (lines.Next(&line)) {
    const absl::string_view trimmed = io_internal::TrimTextSpace(line);
    if (trimmed.empty() || trimmed[0] == '#') continue;
    if (delimiter == XyzTextDelimiter::kComma) {
      io_internal::SplitOnDelimiter(trimmed, ',', &columns);
    } else {
      io_internal::SplitOnTextSpace(trimmed, &columns);
    }
    const bool may_be_header = first_data_line && delimiter == XyzTextDelimiter::kComma;
    first_data_line = false;
    double values[3] = {0, 0, 0};
    if (may_be_header) {
      // A header names its columns: none of the first three reads as a number.
      bool any_number = false;
      for (size_t k = 0; k < columns.size() && k < 3; ++k) {
        any_number |= io_internal::ParseDoubleToken(columns[k], &values[k]);
      }
      if (!any_number) continue;
    }
    Eigen::Vector3f point;
    if (columns.size() < 3) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": line ", lines.line_number(), ": ",
                                                     columns.size(),
                                                     " columns; a point needs at least 3 (x y z)"));
    }
    for (int k = 0; k < 3; ++k) {
      if (!io_internal::ParseDoubleToken(columns[k], &values[k])) {
        return absl::InvalidArgumentError(
            absl::StrCat(name, ": line ", lines.line_number(), ", column ", k + 1, ": ",
                         QuotedForMessage(columns[k]), " is not a number"));
      }
      point[k] = static_cast<float>(values[k]);
      if (!std::isfinite(point[k])) {
        return absl::InvalidArgumentError(
            absl::StrCat(name, ": line ", lines.line_number(), ", column ", k + 1, ": coordinate ",
                         QuotedForMessage(columns[k]), " is not a finite float"));
      }
    }
    cloud.points.push_back(point);
  }
  return cloud;
}

absl::StatusOr<PointCloud> ReadXyzText(const std::string& path, XyzTextDelimiter delimiter) {
  absl::StatusOr<std::string> bytes = ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  return ParseXyzText(*bytes, path, delimiter);
}

absl::StatusOr<std::string> SerializeXyzText(const PointCloud& cloud, XyzTextDelimiter delimiter) {
  absl::Status valid = ValidatePointCloud(cloud);
  if (!valid.ok()) return valid;
  const char separator = delimiter == XyzTextDelimiter::kComma ? ',' : ' ';
  std::string out = delimiter == XyzTextDelimiter::kComma ? "x,y,z\n" : "";
  for (const Eigen::Vector3f& p : cloud.points) {
    io_internal::AppendShortestDecimal(p.x(), &out);
    out.push_back(separator);
    io_internal::AppendShortestDecimal(p.y(), &out);
    out.push_back(separator);
    io_internal::AppendShortestDecimal(p.z(), &out);
    out.push_back('\n');
  }
  return out;
}

absl::Status WriteXyzText(const std::string& path, const PointCloud& cloud,
                          XyzTextDelimiter delimiter) {
  absl::StatusOr<std::string> bytes = SerializeXyzText(cloud, delimiter);
  if (!bytes.ok()) {
    return absl::Status(bytes.status().code(), absl::StrCat(path, ": ", bytes.status().message()));
  }
  return WriteFileBytes(path, *bytes);
}

}  // namespace rpsr::core
