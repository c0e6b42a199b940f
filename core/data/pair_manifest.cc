#include "core/data/pair_manifest.h"

#include <array>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/data/transform_convention.h"

namespace rpsr::core {
namespace {

namespace fs = std::filesystem;

// The shortest decimal form that reads back to exactly `value`.
std::string ShortestNumber(double value) {
  if (value == 0.0) return "0";  // also turns -0 into 0
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

// `path` relative to `folder` when it lies inside it, absolute otherwise. Both are made absolute
// against the working directory and normalised first (no symlinks are resolved, so the result is
// what the caller named).
std::string PathForManifest(const std::string& path, const fs::path& folder) {
  const fs::path absolute = fs::absolute(fs::path(path)).lexically_normal();
  const fs::path relative = absolute.lexically_relative(folder);
  if (!relative.empty() && *relative.begin() != "..") return relative.generic_string();
  return absolute.generic_string();
}

absl::Status CheckPath(const std::string& path, size_t row, absl::string_view what) {
  if (path.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("manifest row ", row, ": empty ", what, " path"));
  }
  if (path.find_first_of(",\"\r\n") != std::string::npos) {
    return absl::InvalidArgumentError(absl::StrCat("manifest row ", row, ": ", what, " path '",
                                                   path,
                                                   "' contains a comma, quote or line break, "
                                                   "which the manifest cannot store"));
  }
  return absl::OkStatus();
}

std::string ResolvePath(absl::string_view stored, const std::string& folder) {
  const fs::path path{std::string(stored)};
  if (folder.empty() || path.is_absolute()) return path.generic_string();
  return (fs::path(folder) / path).lexically_normal().generic_string();
}

}  // namespace

absl::Status WritePairManifest(const std::string& path, const std::vector<ManifestRow>& rows) {
  const fs::path folder = fs::absolute(fs::path(path)).lexically_normal().parent_path();
  std::string text = absl::StrCat(kPairManifestHeader, "\n");
  for (size_t i = 0; i < rows.size(); ++i) {
    const ManifestRow& row = rows[i];
    if (absl::Status s = CheckPath(row.source, i + 1, "source"); !s.ok()) return s;
    if (absl::Status s = CheckPath(row.target, i + 1, "target"); !s.ok()) return s;
    absl::StrAppend(&text, PathForManifest(row.source, folder), ",",
                    PathForManifest(row.target, folder), ",");
    if (row.T_target_source.has_value()) {
      const std::array<double, 16> entries = RowMajorEntries(*row.T_target_source);
      for (size_t k = 0; k < entries.size(); ++k) {
        if (!std::isfinite(entries[k])) {
          return absl::InvalidArgumentError(
              absl::StrCat("manifest row ", i + 1, ": the transform has a non-finite entry"));
        }
        absl::StrAppend(&text, k == 0 ? "" : " ", ShortestNumber(entries[k]));
      }
    }
    text += '\n';
  }
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return absl::InternalError(absl::StrCat("cannot open ", path, " for writing"));
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  out.close();
  if (!out) return absl::InternalError(absl::StrCat("cannot write ", path));
  return absl::OkStatus();
}

absl::StatusOr<std::vector<ManifestRow>> ParsePairManifest(absl::string_view text,
                                                           absl::string_view name,
                                                           const std::string& folder) {
  std::vector<ManifestRow> rows;
  int line_number = 0;
  bool first_content_line = true;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line_number == 1 && absl::StartsWith(line, "\xEF\xBB\xBF")) line.remove_prefix(3);
    if (absl::StripAsciiWhitespace(line).empty()) continue;
    const auto error = [&](absl::string_view message) {
      return absl::InvalidArgumentError(absl::StrCat(name, ":", line_number, ": ", message));
    };
    if (first_content_line) {
      first_content_line = false;
      if (absl::StripAsciiWhitespace(line) == kPairManifestHeader) continue;
    }
    const std::vector<absl::string_view> fields = absl::StrSplit(line, ',');
    if (fields.size() != 3) {
      return error(absl::StrCat("expected 3 comma-separated fields (", kPairManifestHeader,
                                "), found ", fields.size()));
    }
    const absl::string_view source = absl::StripAsciiWhitespace(fields[0]);
    const absl::string_view target = absl::StripAsciiWhitespace(fields[1]);
    if (source.empty()) return error("empty source path");
    if (target.empty()) return error("empty target path");
    ManifestRow row;
    row.source = ResolvePath(source, folder);
    row.target = ResolvePath(target, folder);
    const std::vector<absl::string_view> numbers =
        absl::StrSplit(fields[2], absl::ByAnyChar(" \t"), absl::SkipEmpty());
    if (!numbers.empty()) {
      if (numbers.size() != 16) {
        return error(
            absl::StrCat("gt needs the 16 entries of the row-major 4x4 T_target_source, "
                         "found ",
                         numbers.size()));
      }
      std::array<double, 16> entries;
      for (size_t k = 0; k < 16; ++k) {
        if (!absl::SimpleAtod(numbers[k], &entries[k])) {
          return error(absl::StrCat("gt entry ", k + 1, " '", numbers[k], "' is not a number"));
        }
      }
      absl::StatusOr<Eigen::Isometry3d> transform = TransformFromRowMajor(entries);
      if (!transform.ok()) return error(absl::StrCat("gt: ", transform.status().message()));
      row.T_target_source = *transform;
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

absl::StatusOr<std::vector<ManifestRow>> ReadPairManifest(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open manifest ", path));
  std::ostringstream contents;
  contents << in.rdbuf();
  if (in.bad()) return absl::InternalError(absl::StrCat("cannot read manifest ", path));
  return ParsePairManifest(contents.str(), path, fs::path(path).parent_path().string());
}

}  // namespace rpsr::core
