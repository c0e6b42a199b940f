// The subcommands of `rpsr`, one per file (<name>_command.cc). Each takes the arguments after
// its name (flags already parsed by absl) and returns the process exit code.
#ifndef RPSR_CLIENT_CLI_SUBCOMMANDS_H_
#define RPSR_CLIENT_CLI_SUBCOMMANDS_H_

#include <string>
#include <vector>

namespace rpsr::client {

int RunCalibrateCommand(const std::vector<std::string>& args);
int RunDataCommand(const std::vector<std::string>& args);
int RunEvalCommand(const std::vector<std::string>& args);
int RunTrainCommand(const std::vector<std::string>& args);
// Registration of files and sequences, locally or on a server (issue 7).
int RunRegisterCommand(const std::vector<std::string>& args);
int RunOdometryCommand(const std::vector<std::string>& args);
#if RPSR_CLI_HAS_SERVICE
// Through the client library (not in core-only builds).
int RunBenchCommand(const std::vector<std::string>& args);
#endif
#if RPSR_CLI_HAS_SERVER
// With the service in-process.
int RunDemoCommand(const std::vector<std::string>& args);
int RunServeCommand(const std::vector<std::string>& args);
#endif

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_CLI_SUBCOMMANDS_H_
