// Flags of the subcommands that register (register, odometry, bench, demo, serve): where the
// registration runs (--server or --local), how to reach the server, and the output format.
// `rpsr <name> --help` lists them for those subcommands.
#ifndef RPSR_CLIENT_CLI_SERVICE_FLAGS_H_
#define RPSR_CLIENT_CLI_SERVICE_FLAGS_H_

#include <string>

#include "absl/flags/declare.h"
#include "absl/status/statusor.h"
#include "client/cli/shared_flags.h"

ABSL_DECLARE_FLAG(std::string, server);
ABSL_DECLARE_FLAG(bool, local);
ABSL_DECLARE_FLAG(bool, json);
ABSL_DECLARE_FLAG(std::string, token);
ABSL_DECLARE_FLAG(std::string, tls_ca);
ABSL_DECLARE_FLAG(double, timeout_s);
ABSL_DECLARE_FLAG(std::string, data);

namespace rpsr::client {

// --mode as given, or empty when it was not given on the command line (the subcommand then
// chooses).
std::string ExplicitModeFlag();
// --tree_depth when given on the command line, else 0 (auto).
int ExplicitTreeDepthFlag();

// true: --server ADDR; false: local. InvalidArgument when both --server and --local are given.
absl::StatusOr<bool> UseServerFlag();

#if RPSR_CLI_HAS_SERVICE
}  // namespace rpsr::client
#include "client/rpsr_client.h"
namespace rpsr::client {
// ClientOptions from --server, --token, --tls_ca (PEM file read here) and --timeout_s.
absl::StatusOr<ClientOptions> ClientOptionsFromFlags();
// The shared registration flags (ApplyRegistrationFlags) on a request to the service; its mode
// and initial guess stay the caller's.
void ApplyRegistrationFlags(RegisterOptions& options);
#endif

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_CLI_SERVICE_FLAGS_H_
