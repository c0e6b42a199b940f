#include "client/cli/cli_progress.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>

#include "absl/strings/str_format.h"

namespace rpsr::client {

std::string FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  const long s = static_cast<long>(seconds + 0.5);
  if (s >= 3600) return absl::StrFormat("%ldh%02ldm", s / 3600, (s % 3600) / 60);
  if (s >= 60) return absl::StrFormat("%ldm%02lds", s / 60, s % 60);
  return absl::StrFormat("%lds", s);
}

ProgressBar::ProgressBar(std::string label)
    : label_(std::move(label)), terminal_(isatty(STDERR_FILENO) != 0) {}

void ProgressBar::Update(double done, double total, double seconds_remaining,
                         const std::string& detail) {
  const auto now = std::chrono::steady_clock::now();
  if (!terminal_ && now - last_print_ < std::chrono::seconds(10) && done < total) return;
  last_print_ = now;
  const double fraction = total > 0 ? std::min(1.0, done / total) : 1.0;
  constexpr int kWidth = 30;
  const int filled = static_cast<int>(fraction * kWidth);
  std::string bar(filled, '#');
  bar.resize(kWidth, '.');
  std::fprintf(stderr, "%s%s [%s] %5.1f%% ETA %s %s%s", terminal_ ? "\r" : "", label_.c_str(),
               bar.c_str(), 100.0 * fraction, FormatDuration(seconds_remaining).c_str(),
               detail.c_str(), terminal_ ? "\033[K" : "\n");
  std::fflush(stderr);
}

void ProgressBar::Finish() {
  if (terminal_) std::fprintf(stderr, "\n");
}

}  // namespace rpsr::client
