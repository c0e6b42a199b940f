#include "core/io/off.h"

#include <cmath>
#include <cstdint>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "core/io/declared_counts.h"
#include "core/io/file_bytes.h"
#include "core/io/text_tokens.h"

namespace rpsr::core {
namespace {

using io_internal::QuotedForMessage;

// Walks the meaningful lines of an OFF file: comments stripped, blank lines skipped.
class OffLines {
 public:
  explicit OffLines(absl::string_view text) : lines_(text) {}

  // Splits the next meaningful line into `*tokens`; false at the end of the text.
  bool Next(std::vector<absl::string_view>* tokens) {
    absl::string_view line;
    while (lines_.Next(&line)) {
      const size_t comment = line.find('#');
      if (comment != absl::string_view::npos) line = line.substr(0, comment);
      io_internal::SplitOnTextSpace(line, tokens);
      if (!tokens->empty()) return true;
    }
    return false;
  }
  size_t line_number() const { return lines_.line_number(); }
  size_t remaining() const { return lines_.remaining(); }

 private:
  io_internal::LineScanner lines_;
};

absl::Status LineError(absl::string_view name, size_t line, absl::string_view what) {
  return absl::InvalidArgumentError(absl::StrCat(name, ": line ", line, ": ", what));
}

// True when `keyword` is OFF with an optional prefix made of the letters S, T, C, N.
bool IsOffKeyword(absl::string_view keyword) {
  if (!absl::EndsWith(keyword, "OFF")) return false;
  for (const char c : keyword.substr(0, keyword.size() - 3)) {
    if (c != 'S' && c != 'T' && c != 'C' && c != 'N') return false;
  }
  return true;
}

}  // namespace

absl::StatusOr<TriangleMesh> ParseOff(absl::string_view text, absl::string_view name) {
  OffLines lines(text);
  std::vector<absl::string_view> tokens;
  if (!lines.Next(&tokens)) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": empty file; not an OFF file"));
  }
  // The keyword, and the counts that may follow it on the same line ("OFF 8 6 0", "OFF8 6 0").
  absl::string_view keyword = tokens[0];
  std::vector<absl::string_view> counts(tokens.begin() + 1, tokens.end());
  const size_t off_at = keyword.find("OFF");
  if (off_at != absl::string_view::npos && off_at + 3 < keyword.size() &&
      keyword[off_at + 3] >= '0' && keyword[off_at + 3] <= '9') {
    counts.insert(counts.begin(), keyword.substr(off_at + 3));
    keyword = keyword.substr(0, off_at + 3);
  }
  if (keyword == "4OFF" || keyword == "nOFF" || keyword == "4COFF" || keyword == "nCOFF" ||
      (!counts.empty() && counts[0] == "BINARY")) {
    return absl::UnimplementedError(
        absl::StrCat(name, ": line ", lines.line_number(), ": ", QuotedForMessage(tokens[0]),
                     counts.empty() ? "" : " BINARY",
                     " OFF is not supported (only ascii 3D OFF / COFF / NOFF)"));
  }
  if (!IsOffKeyword(keyword)) {
    return LineError(name, lines.line_number(),
                     absl::StrCat("not an OFF file: the first keyword is ",
                                  QuotedForMessage(tokens[0]), ", not OFF"));
  }
  if (counts.empty()) {
    if (!lines.Next(&tokens)) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": the file ends before the vertex and face counts"));
    }
    counts.assign(tokens.begin(), tokens.end());
  }
  uint64_t num_vertices = 0, num_faces = 0;
  if (counts.size() < 2 || counts.size() > 3 ||
      !io_internal::ParseUint64Token(counts[0], &num_vertices) ||
      !io_internal::ParseUint64Token(counts[1], &num_faces)) {
    return LineError(name, lines.line_number(),
                     "expected the counts '<vertices> <faces> [<edges>]'");
  }
  if (num_vertices > io_internal::kMaxDeclaredCount || num_faces > io_internal::kMaxDeclaredCount) {
    return LineError(
        name, lines.line_number(),
        absl::StrCat("declares ", num_vertices, " vertices and ", num_faces,
                     " faces, more than the limit of ", io_internal::kMaxDeclaredCount));
  }

  TriangleMesh mesh;
  mesh.vertices.reserve(io_internal::TextReservation(num_vertices, lines.remaining()));
  for (uint64_t v = 0; v < num_vertices; ++v) {
    if (!lines.Next(&tokens)) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": line ", lines.line_number() + 1, ": the file ends after ", v,
                       " of the ", num_vertices, " vertices the header declares"));
    }
    if (tokens.size() < 3) {
      return LineError(
          name, lines.line_number(),
          absl::StrCat("(vertex ", v, ") ", tokens.size(), " values; a vertex needs x y z"));
    }
    Eigen::Vector3f vertex;
    for (int k = 0; k < 3; ++k) {
      double value = 0.0;
      if (!io_internal::ParseDoubleToken(tokens[k], &value)) {
        return LineError(
            name, lines.line_number(),
            absl::StrCat("(vertex ", v, ") ", QuotedForMessage(tokens[k]), " is not a number"));
      }
      vertex[k] = static_cast<float>(value);
      if (!std::isfinite(vertex[k])) {
        return LineError(name, lines.line_number(),
                         absl::StrCat("(vertex ", v, ") coordinate ", QuotedForMessage(tokens[k]),
                                      " is not a finite float"));
      }
    }
    mesh.vertices.push_back(vertex);
  }

  mesh.triangles.reserve(io_internal::TextReservation(num_faces, lines.remaining() / 4));
  for (uint64_t f = 0; f < num_faces; ++f) {
    if (!lines.Next(&tokens)) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": line ", lines.line_number() + 1,
                                                     ": the file ends after ", f, " of the ",
                                                     num_faces, " faces the header declares"));
    }
    uint64_t corners = 0;
    if (!io_internal::ParseUint64Token(tokens[0], &corners)) {
      return LineError(name, lines.line_number(),
                       absl::StrCat("(face ", f, ") vertex count ", QuotedForMessage(tokens[0]),
                                    " is not a non-negative integer"));
    }
    if (corners < 3) {
      return LineError(
          name, lines.line_number(),
          absl::StrCat("(face ", f, ") has ", corners, " vertices; a face needs at least 3"));
    }
    if (corners > tokens.size() - 1) {
      return LineError(name, lines.line_number(),
                       absl::StrCat("(face ", f, ") declares ", corners, " vertices but lists ",
                                    tokens.size() - 1));
    }
    int first = 0, previous = 0;
    for (size_t i = 0; i < corners; ++i) {
      int64_t index = 0;
      if (!io_internal::ParseInt64Token(tokens[i + 1], &index) || index < 0 ||
          static_cast<uint64_t>(index) >= num_vertices) {
        return LineError(
            name, lines.line_number(),
            absl::StrCat("(face ", f, ") vertex index ", QuotedForMessage(tokens[i + 1]),
                         " is not an index below the vertex count ", num_vertices));
      }
      const int current = static_cast<int>(index);
      if (i == 0) {
        first = current;
      } else if (i >= 2) {
        mesh.triangles.emplace_back(first, previous, current);
      }
      previous = current;
    }
  }
  if (lines.Next(&tokens)) {
    return LineError(name, lines.line_number(),
                     absl::StrCat("unexpected ", QuotedForMessage(tokens[0]),
                                  " after the last face; the header declares fewer vertices or "
                                  "faces than the file holds"));
  }
  return mesh;
}

absl::StatusOr<TriangleMesh> ReadOff(const std::string& path) {
  absl::StatusOr<std::string> bytes = ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  return ParseOff(*bytes, path);
}

absl::StatusOr<std::string> SerializeOff(const TriangleMesh& mesh) {
  if (absl::Status valid = ValidateTriangleMesh(mesh); !valid.ok()) return valid;
  std::string out = absl::StrCat("OFF\n", mesh.vertices.size(), " ", mesh.triangles.size(), " 0\n");
  for (const Eigen::Vector3f& v : mesh.vertices) {
    io_internal::AppendShortestDecimal(v.x(), &out);
    out.push_back(' ');
    io_internal::AppendShortestDecimal(v.y(), &out);
    out.push_back(' ');
    io_internal::AppendShortestDecimal(v.z(), &out);
    out.push_back('\n');
  }
  for (const Eigen::Vector3i& tri : mesh.triangles) {
    absl::StrAppend(&out, "3 ", tri.x(), " ", tri.y(), " ", tri.z(), "\n");
  }
  return out;
}

absl::Status WriteOff(const std::string& path, const TriangleMesh& mesh) {
  absl::StatusOr<std::string> bytes = SerializeOff(mesh);
  if (!bytes.ok()) {
    return absl::Status(bytes.status().code(), absl::StrCat(path, ": ", bytes.status().message()));
  }
  return WriteFileBytes(path, *bytes);
}

}  // namespace rpsr::core
