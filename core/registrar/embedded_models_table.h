// The table that the generated embedded_models_data.cc defines (internal to core/registrar; use
// embedded_models.h).
#ifndef RPSR_CORE_REGISTRAR_EMBEDDED_MODELS_TABLE_H_
#define RPSR_CORE_REGISTRAR_EMBEDDED_MODELS_TABLE_H_

namespace rpsr::core::embedded {

struct EmbeddedBlob {
  const char* begin;
  const char* end;
};

struct EmbeddedModelEntry {
  const char* name;  // nullptr ends the table
  EmbeddedBlob weights;
  EmbeddedBlob confidence;  // {nullptr, nullptr}: no calibration shipped
};

extern const EmbeddedModelEntry kEmbeddedModels[];

}  // namespace rpsr::core::embedded

#endif  // RPSR_CORE_REGISTRAR_EMBEDDED_MODELS_TABLE_H_
