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

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_CLI_SUBCOMMANDS_H_
