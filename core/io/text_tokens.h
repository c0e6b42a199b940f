// Number parsing and line/token walking shared by the text formats in core/io (PLY ascii, PCD
// ascii, XYZ/CSV, OFF). Nothing here throws or allocates per token; positions are reported as
// 1-based line numbers so that parsers can name the place of an error.
#ifndef RPSR_CORE_IO_TEXT_TOKENS_H_
#define RPSR_CORE_IO_TEXT_TOKENS_H_

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/strings/string_view.h"

namespace rpsr::core::io_internal {

// Parses the whole of `token` as a decimal floating-point number (optional sign, digits, '.',
// exponent). "nan" and "inf" are accepted, so that callers can reject them with a message of their
// own; values out of double's range, hex floats, empty tokens and trailing characters are not.
bool ParseDoubleToken(absl::string_view token, double* value);

// Parses the whole of `token` as a decimal integer (optional sign). False on overflow.
bool ParseInt64Token(absl::string_view token, int64_t* value);

// Parses the whole of `token` as a non-negative decimal integer (optional '+'). False on overflow.
bool ParseUint64Token(absl::string_view token, uint64_t* value);

// Appends the shortest decimal text that reads back as exactly `value` (std::to_chars).
void AppendShortestDecimal(float value, std::string* out);
void AppendShortestDecimal(double value, std::string* out);

// `text` in single quotes for an error message: C-escaped (so binary garbage prints safely) and
// clipped to 40 characters.
std::string QuotedForMessage(absl::string_view text);

// True for ' ', '\t', '\n', '\v', '\f', '\r'.
inline bool IsTextSpace(char c) { return c == ' ' || (c >= '\t' && c <= '\r'); }

// Removes leading and trailing IsTextSpace characters.
absl::string_view TrimTextSpace(absl::string_view text);

// Splits `line` on runs of IsTextSpace characters; no empty pieces. Replaces `*tokens`.
void SplitOnTextSpace(absl::string_view line, std::vector<absl::string_view>* tokens);

// Splits `line` on `delimiter` and trims each piece (empty pieces are kept). Replaces `*tokens`.
void SplitOnDelimiter(absl::string_view line, char delimiter,
                      std::vector<absl::string_view>* tokens);

// Hands out `text` one line at a time. A line ends at '\n'; a '\r' just before it is dropped, so
// "\r\n" files read like "\n" files. The last line need not end with '\n'.
class LineScanner {
 public:
  explicit LineScanner(absl::string_view text) : text_(text) {}

  // Stores the next line (without its ending) in `*line` and returns true, or returns false at
  // the end of the text.
  bool Next(absl::string_view* line);

  // 1-based number of the line last returned by Next (0 before the first call).
  size_t line_number() const { return line_number_; }
  // Byte offset of the first byte not yet returned (just after the last line's '\n').
  size_t offset() const { return offset_; }
  // Bytes not yet returned.
  size_t remaining() const { return text_.size() - offset_; }

 private:
  absl::string_view text_;
  size_t offset_ = 0;
  size_t line_number_ = 0;
};

// Hands out `text` one whitespace-separated token at a time, tracking the line each token is on.
class TokenScanner {
 public:
  TokenScanner(absl::string_view text, size_t first_line_number)
      : text_(text), line_number_(first_line_number) {}

  // Stores the next token in `*token` and returns true, or returns false at the end of the text.
  bool Next(absl::string_view* token);

  // Line of the token last returned by Next, or of the end of the text once Next returned false.
  size_t line_number() const { return line_number_; }
  // Bytes not yet scanned.
  size_t remaining() const { return text_.size() - offset_; }

 private:
  absl::string_view text_;
  size_t offset_ = 0;
  size_t line_number_;
};

}  // namespace rpsr::core::io_internal

#endif  // RPSR_CORE_IO_TEXT_TOKENS_H_
