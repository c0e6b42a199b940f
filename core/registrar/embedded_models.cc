#include "core/registrar/embedded_models.h"

#include <algorithm>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "core/registrar/embedded_models_table.h"

namespace rpsr::core {
namespace {

absl::string_view View(const embedded::EmbeddedBlob& blob) {
  return absl::string_view(blob.begin, static_cast<size_t>(blob.end - blob.begin));
}

}  // namespace

std::vector<std::string> EmbeddedModelNames() {
  std::vector<std::string> names;
  for (const embedded::EmbeddedModelEntry* e = embedded::kEmbeddedModels; e->name != nullptr; ++e) {
    names.push_back(e->name);
  }
  std::sort(names.begin(), names.end());
  return names;
}

absl::StatusOr<EmbeddedModel> FindEmbeddedModel(absl::string_view name) {
  for (const embedded::EmbeddedModelEntry* e = embedded::kEmbeddedModels; e->name != nullptr; ++e) {
    if (name != e->name) continue;
    EmbeddedModel model;
    model.name = e->name;
    model.weights = View(e->weights);
    if (e->confidence.begin != nullptr) model.confidence = View(e->confidence);
    return model;
  }
  const std::vector<std::string> names = EmbeddedModelNames();
  return absl::NotFoundError(absl::StrCat(
      "no embedded model '", name,
      "' (embedded: ", names.empty() ? std::string("none") : absl::StrJoin(names, ", "),
      "); models are core/models/<name>/model.rpsrw at configure time"));
}

}  // namespace rpsr::core
