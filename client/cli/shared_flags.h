// Flags that more than one subcommand reads. Abseil flags are global to the binary, so a name can
// be defined only once: a flag that a second subcommand needs moves here, with a help text that
// covers every subcommand using it, and `rpsr <name> --help` lists these besides the
// subcommand's own.
#ifndef RPSR_CLIENT_CLI_SHARED_FLAGS_H_
#define RPSR_CLIENT_CLI_SHARED_FLAGS_H_

#include <cstdint>
#include <string>

#include "absl/flags/declare.h"

ABSL_DECLARE_FLAG(std::string, output);
ABSL_DECLARE_FLAG(std::string, protocol);
ABSL_DECLARE_FLAG(uint64_t, seed);
ABSL_DECLARE_FLAG(int, num_points);

#endif  // RPSR_CLIENT_CLI_SHARED_FLAGS_H_
