// rpsr: the command line of the rpsr registration service.
//   rpsr <subcommand> [flags]      rpsr <subcommand> --help
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/flags/usage_config.h"
#include "absl/strings/match.h"
#include "absl/strings/string_view.h"
#include "client/cli/subcommands.h"
#include "core/net/openblas_core_choice.h"

namespace {

struct Subcommand {
  const char* summary;
  std::function<int(const std::vector<std::string>&)> run;
};

const std::map<std::string, Subcommand>& Subcommands() {
  static const auto* commands = new std::map<std::string, Subcommand> {
    {"eval",
     {"run the network on pairs (a manifest or the object protocol) and report its errors",
      rpsr::client::RunEvalCommand}},
        {"calibrate",
         {"fit the confidence on seeded validation pairs (objects and LiDAR) or measure it "
          "(--evaluate)",
          rpsr::client::RunCalibrateCommand}},
        {"train",
         {"train RPSRNet end to end on a seeded pair protocol (objects or LiDAR)",
          rpsr::client::RunTrainCommand}},
        {"data",
         {"write object clouds, simulated LiDAR sequences or registration pairs with a manifest",
          rpsr::client::RunDataCommand}},
        {"register",
         {"register two point-cloud files (locally or on a server): R, t, confidence",
          rpsr::client::RunRegisterCommand}},
        {"odometry",
         {"register every consecutive frame pair of a KITTI-layout sequence; poses, KITTI metrics",
          rpsr::client::RunOdometryCommand}},
#if RPSR_CLI_HAS_SERVICE
        {"bench",
         {"load a server with N concurrent clients: throughput, latency percentiles, errors",
          rpsr::client::RunBenchCommand}},
        {"demo",
         {"start a server in-process and register the shipped sample pairs (start here)",
          rpsr::client::RunDemoCommand}},
        {"serve",
         {"run the registration service in this process (as rpsrd does)",
          rpsr::client::RunServeCommand}},
#endif
  };
  return *commands;
}

void PrintUsage() {
  std::fprintf(stderr, "usage: rpsr <subcommand> [flags]\n\nsubcommands:\n");
  for (const auto& [name, command] : Subcommands()) {
    std::fprintf(stderr, "  %-8s %s\n", name.c_str(), command.summary);
  }
  std::fprintf(stderr, "\n'rpsr <subcommand> --help' lists a subcommand's flags.\n");
}

}  // namespace

int main(int argc, char** argv) {
  // Before any thread runs: OpenBLAS's kernels for CPUs its Debian version does not know
  // (core/net/openblas_core_choice.h).
  rpsr::core::net::MatchOpenBlasCoreToCpu();
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "help") == 0) {
    PrintUsage();
    return argc < 2 ? 2 : 0;
  }
  const std::string name = argv[1];
  auto it = Subcommands().find(name);
  if (it == Subcommands().end()) {
    std::fprintf(stderr, "rpsr: unknown subcommand '%s'\n\n", name.c_str());
    PrintUsage();
    return 2;
  }
  // Flags are defined in <name>_command.cc, and those several subcommands read in
  // shared_flags.cc: `--help` shows these two files' flags only.
  absl::FlagsUsageConfig usage_config;
  // The registering subcommands also read service_flags.cc (--server, --json, ...).
  const bool registers = name == "register" || name == "odometry" || name == "bench" ||
                         name == "demo" || name == "serve";
  usage_config.contains_help_flags = [name, registers](absl::string_view file) {
    return absl::EndsWith(file, "/" + name + "_command.cc") ||
           absl::EndsWith(file, "/shared_flags.cc") ||
           (registers && absl::EndsWith(file, "/service_flags.cc"));
  };
  absl::SetFlagsUsageConfig(usage_config);
  std::vector<char*> args = {argv[0]};
  std::string help = "--help";
  // --output-aligned is accepted for --output_aligned: Abseil flag names cannot hold dashes.
  std::vector<std::string> underscored;
  underscored.reserve(argc);
  for (int i = 2; i < argc; ++i) {
    if (std::strcmp(argv[i], "-h") == 0) {
      args.push_back(help.data());
      continue;
    }
    std::string arg = argv[i];
    if (arg.size() > 2 && arg.rfind("--", 0) == 0) {
      const size_t name_end = std::min(arg.find('='), arg.size());
      std::replace(arg.begin() + 2, arg.begin() + static_cast<std::ptrdiff_t>(name_end), '-', '_');
    }
    underscored.push_back(std::move(arg));
    args.push_back(underscored.back().data());
  }
  absl::SetProgramUsageMessage("rpsr " + name + " [flags]: " + it->second.summary);
  std::vector<char*> rest = absl::ParseCommandLine(static_cast<int>(args.size()), args.data());
  std::vector<std::string> positional(rest.begin() + 1, rest.end());
  return it->second.run(positional);
}
