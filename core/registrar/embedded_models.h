// The models linked into the binary (core/models/<name>/ at configure time): their weights
// (.rpsrw) and, when one was shipped, the confidence calibration beside them (confidence.txt).
// The service and the CLI load the default model with no file at hand.
#ifndef RPSR_CORE_REGISTRAR_EMBEDDED_MODELS_H_
#define RPSR_CORE_REGISTRAR_EMBEDDED_MODELS_H_

#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace rpsr::core {

// The model Registrar::Create loads by default.
inline constexpr absl::string_view kDefaultEmbeddedModel = "objects";

struct EmbeddedModel {
  std::string name;
  absl::string_view weights;                    // the .rpsrw bytes (static storage)
  std::optional<absl::string_view> confidence;  // the confidence.txt text, when shipped
};

// Names of the embedded models, sorted.
std::vector<std::string> EmbeddedModelNames();

// NotFound naming the embedded models when `name` is not one of them.
absl::StatusOr<EmbeddedModel> FindEmbeddedModel(absl::string_view name);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REGISTRAR_EMBEDDED_MODELS_H_
