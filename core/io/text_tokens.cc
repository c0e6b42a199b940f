#include "core/io/text_tokens.h"

#include <charconv>
#include <system_error>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"

namespace rpsr::core::io_internal {
namespace {

// std::from_chars rejects a leading '+'; drop one when a number follows it.
absl::string_view WithoutPlus(absl::string_view token) {
  if (token.size() > 1 && token[0] == '+' && token[1] != '-' && token[1] != '+') {
    token.remove_prefix(1);
  }
  return token;
}

template <typename T>
bool ParseWhole(absl::string_view token, T* value) {
  token = WithoutPlus(token);
  if (token.empty()) return false;
  const char* const end = token.data() + token.size();
  const std::from_chars_result result = std::from_chars(token.data(), end, *value);
  return result.ec == std::errc() && result.ptr == end;
}

}  // namespace

bool ParseDoubleToken(absl::string_view token, double* value) { return ParseWhole(token, value); }

bool ParseInt64Token(absl::string_view token, int64_t* value) { return ParseWhole(token, value); }

bool ParseUint64Token(absl::string_view token, uint64_t* value) {
  if (!token.empty() && token[0] == '-') return false;
  return ParseWhole(token, value);
}

void AppendShortestDecimal(float value, std::string* out) {
  char buffer[64];
  const std::to_chars_result result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out->append(buffer, result.ptr);
}

void AppendShortestDecimal(double value, std::string* out) {
  char buffer[64];
  const std::to_chars_result result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out->append(buffer, result.ptr);
}

std::string QuotedForMessage(absl::string_view text) {
  const bool clipped = text.size() > 40;
  return absl::StrCat("'", absl::CHexEscape(text.substr(0, 40)), clipped ? "...'" : "'");
}

absl::string_view TrimTextSpace(absl::string_view text) {
  while (!text.empty() && IsTextSpace(text.front())) text.remove_prefix(1);
  while (!text.empty() && IsTextSpace(text.back())) text.remove_suffix(1);
  return text;
}

void SplitOnTextSpace(absl::string_view line, std::vector<absl::string_view>* tokens) {
  tokens->clear();
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && IsTextSpace(line[i])) ++i;
    const size_t start = i;
    while (i < line.size() && !IsTextSpace(line[i])) ++i;
    if (i > start) tokens->push_back(line.substr(start, i - start));
  }
}

void SplitOnDelimiter(absl::string_view line, char delimiter,
                      std::vector<absl::string_view>* tokens) {
  tokens->clear();
  size_t start = 0;
  while (true) {
    const size_t end = line.find(delimiter, start);
    if (end == absl::string_view::npos) {
      tokens->push_back(TrimTextSpace(line.substr(start)));
      return;
    }
    tokens->push_back(TrimTextSpace(line.substr(start, end - start)));
    start = end + 1;
  }
}

bool LineScanner::Next(absl::string_view* line) {
  if (offset_ >= text_.size()) return false;
  const size_t newline = text_.find('\n', offset_);
  const size_t end = newline == absl::string_view::npos ? text_.size() : newline;
  absl::string_view found = text_.substr(offset_, end - offset_);
  if (!found.empty() && found.back() == '\r') found.remove_suffix(1);
  offset_ = newline == absl::string_view::npos ? text_.size() : newline + 1;
  ++line_number_;
  *line = found;
  return true;
}

bool TokenScanner::Next(absl::string_view* token) {
  while (offset_ < text_.size() && IsTextSpace(text_[offset_])) {
    if (text_[offset_] == '\n') ++line_number_;
    ++offset_;
  }
  if (offset_ >= text_.size()) return false;
  const size_t start = offset_;
  while (offset_ < text_.size() && !IsTextSpace(text_[offset_])) ++offset_;
  *token = text_.substr(start, offset_ - start);
  return true;
}

}  // namespace rpsr::core::io_internal
