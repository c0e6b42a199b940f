#include "server/structured_log.h"

#include <unistd.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"

namespace rpsr::server {
namespace {

void AppendValue(absl::string_view value, std::string* line) {
  const bool quote = value.empty() || value.find_first_of(" \"=\t\n") != absl::string_view::npos;
  if (!quote) {
    absl::StrAppend(line, value);
    return;
  }
  absl::StrAppend(line, "\"",
                  absl::StrReplaceAll(value, {{"\\", "\\\\"}, {"\"", "\\\""}, {"\n", "\\n"}}),
                  "\"");
}

}  // namespace

std::string FormatLogLine(absl::string_view level, absl::string_view event,
                          std::initializer_list<LogField> fields) {
  std::string line = absl::StrCat(
      "ts=", absl::FormatTime("%Y-%m-%dT%H:%M:%E6SZ", absl::Now(), absl::UTCTimeZone()),
      " level=", level, " event=", event);
  for (const auto& [key, value] : fields) {
    absl::StrAppend(&line, " ", key, "=");
    AppendValue(value, &line);
  }
  return line;
}

void LogEvent(absl::string_view level, absl::string_view event,
              std::initializer_list<LogField> fields) {
  std::string line = FormatLogLine(level, event, fields);
  line.push_back('\n');
  // One write so that lines of concurrent calls never interleave.
  [[maybe_unused]] ssize_t written = write(STDERR_FILENO, line.data(), line.size());
}

}  // namespace rpsr::server
