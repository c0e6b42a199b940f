// One log line per event, key=value pairs (logfmt) on stderr, so that log shippers parse them
// without a schema: ts=2026-11-22T19:40:00.123456Z level=info event=call method=Register code=OK
// seconds=0.0123 peer="ipv4:127.0.0.1:40000". Values with spaces, quotes or '=' are quoted.
#ifndef RPSR_SERVER_STRUCTURED_LOG_H_
#define RPSR_SERVER_STRUCTURED_LOG_H_

#include <initializer_list>
#include <string>
#include <utility>

#include "absl/strings/string_view.h"

namespace rpsr::server {

using LogField = std::pair<absl::string_view, std::string>;

// Formats one line (no trailing newline) without writing it; for tests.
std::string FormatLogLine(absl::string_view level, absl::string_view event,
                          std::initializer_list<LogField> fields);

// Writes one line to stderr atomically (one write call).
void LogEvent(absl::string_view level, absl::string_view event,
              std::initializer_list<LogField> fields);

}  // namespace rpsr::server

#endif  // RPSR_SERVER_STRUCTURED_LOG_H_
