// A one-line progress bar with ETA on stderr (redrawn in place on a terminal, one line every few
// seconds otherwise, so that logs stay readable).
#ifndef RPSR_CLIENT_CLI_CLI_PROGRESS_H_
#define RPSR_CLIENT_CLI_CLI_PROGRESS_H_

#include <chrono>
#include <string>

namespace rpsr::client {

class ProgressBar {
 public:
  explicit ProgressBar(std::string label);
  // done of total units; `detail` is printed after the bar (e.g. "loss 0.123").
  void Update(double done, double total, double seconds_remaining, const std::string& detail);
  void Finish();

 private:
  std::string label_;
  bool terminal_;
  std::chrono::steady_clock::time_point last_print_;
};

std::string FormatDuration(double seconds);

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_CLI_CLI_PROGRESS_H_
