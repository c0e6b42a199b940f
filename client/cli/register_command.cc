// rpsr register SOURCE TARGET [--server ADDR | --local]: registers two point clouds (any format
// core/io reads: .ply .pcd .xyz .txt .csv .bin .off) and prints T_target_source (R, t, the
// quaternion), its validity and confidence; --output_aligned writes the source moved into the
// target's frame; --json prints one JSON object instead.
// --initial gives a starting guess. Exit codes: 0 valid, 3 registered but not valid, 1 failure
// (files, server), 2 bad flags.
#include <chrono>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client/cli/registration_report.h"
#include "client/cli/service_flags.h"
#include "client/cli/shared_flags.h"
#include "client/cli/subcommands.h"
#include "core/data/transform_convention.h"
#include "core/io/point_cloud_io.h"
#include "core/registrar/registrar.h"

ABSL_FLAG(std::string, output_aligned, "",
          "register: write the source moved by the estimate (into the target's frame) to this "
          "file, in the format its extension names");
ABSL_FLAG(std::string, truth, "",
          "register: the true T_target_source as 16 row-major numbers (spaces or commas): also "
          "print the rotation and translation errors");
ABSL_FLAG(std::string, initial, "",
          "register: a starting guess of T_target_source as 16 row-major numbers (a GPS/INS "
          "prior, the last pose of a tracker): the network estimates the rest from it, refine "
          "starts there, scene-scale clouds choose refine; with --hold_degenerate_at_initial a "
          "degenerate answer keeps it along the unconstrained directions");

namespace rpsr::client {
namespace {

constexpr int kValid = 0;
constexpr int kFailure = 1;
constexpr int kBadFlags = 2;
constexpr int kNotValid = 3;

int Fail(int code, const std::string& message) {
  std::fprintf(stderr, "rpsr register: %s\n", message.c_str());
  return code;
}

// A rigid transform given on the command line as 16 row-major numbers (--truth, --initial);
// none when the flag is empty.
absl::StatusOr<std::optional<Eigen::Isometry3d>> ParseTransformFlag(const std::string& flag,
                                                                    const std::string& text) {
  if (text.empty()) return std::nullopt;
  std::vector<std::string> parts = absl::StrSplit(text, absl::ByAnyChar(" ,"), absl::SkipEmpty());
  if (parts.size() != 16) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", flag, " needs 16 numbers (row-major 4x4), got ", parts.size()));
  }
  std::array<double, 16> entries;
  for (int i = 0; i < 16; ++i) {
    if (!absl::SimpleAtod(parts[i], &entries[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("--", flag, ": '", parts[i], "' is not a number"));
    }
  }
  absl::StatusOr<Eigen::Isometry3d> transform = core::TransformFromRowMajor(entries);
  if (!transform.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("--", flag, ": ", transform.status().message()));
  }
  return *transform;
}

#if RPSR_CLI_HAS_SERVICE
absl::StatusOr<PairReport> RegisterOnServer(const core::PointCloud& source,
                                            const core::PointCloud& target,
                                            const std::string& requested_mode, int tree_depth,
                                            const std::optional<Eigen::Isometry3d>& initial) {
  absl::StatusOr<ClientOptions> options = ClientOptionsFromFlags();
  if (!options.ok()) return options.status();
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(*options);
  if (!client.ok()) return client.status();
  absl::StatusOr<ServerInfo> info = (*client)->GetServerInfo();
  if (!info.ok()) return info.status();
  SessionOptions session_options;
  session_options.tree_max_depth = tree_depth;
  session_options.keep_points_for_reupload = false;
  absl::StatusOr<std::unique_ptr<Session>> session = (*client)->CreateSession(session_options);
  if (!session.ok()) return session.status();
  RegisterOptions register_options;
  register_options.mode =
      ChooseMode(source, target, requested_mode, info->model_name, nullptr, initial.has_value());
  register_options.initial_T_target_source = initial;
  ApplyRegistrationFlags(register_options);
  absl::StatusOr<RegistrationResult> result =
      (*session)->Register(source.points, target.points, register_options);
  if (!result.ok()) return result.status();
  return ReportOf(*result);
}
#endif

}  // namespace

int RunRegisterCommand(const std::vector<std::string>& args) {
  if (args.size() != 2) {
    return Fail(kBadFlags,
                "usage: rpsr register SOURCE TARGET [--server ADDR | --local] [--mode "
                "net|net+refine|refine] [--tree_depth D] [--output_aligned FILE] [--truth "
                "'16 numbers'] [--initial '16 numbers'] [--json]");
  }
  absl::StatusOr<bool> use_server = UseServerFlag();
  if (!use_server.ok()) return Fail(kBadFlags, std::string(use_server.status().message()));
  absl::StatusOr<std::optional<Eigen::Isometry3d>> truth =
      ParseTransformFlag("truth", absl::GetFlag(FLAGS_truth));
  if (!truth.ok()) return Fail(kBadFlags, std::string(truth.status().message()));
  absl::StatusOr<std::optional<Eigen::Isometry3d>> initial =
      ParseTransformFlag("initial", absl::GetFlag(FLAGS_initial));
  if (!initial.ok()) return Fail(kBadFlags, std::string(initial.status().message()));
  const std::string requested_mode = ExplicitModeFlag();
  if (!requested_mode.empty() && !core::ParseRegistrationMode(requested_mode).ok()) {
    return Fail(kBadFlags, "--mode must be net, net+refine or refine");
  }
  absl::StatusOr<core::PointCloud> source = core::ReadPointCloud(args[0]);
  if (!source.ok()) return Fail(kFailure, std::string(source.status().message()));
  absl::StatusOr<core::PointCloud> target = core::ReadPointCloud(args[1]);
  if (!target.ok()) return Fail(kFailure, std::string(target.status().message()));
  const int tree_depth = ChooseTreeDepth(*source, *target, ExplicitTreeDepthFlag());

  absl::StatusOr<PairReport> report;
  if (*use_server) {
#if RPSR_CLI_HAS_SERVICE
    report = RegisterOnServer(*source, *target, requested_mode, tree_depth, *initial);
#else
    return Fail(kBadFlags, "this rpsr was built without the client library (core-only build)");
#endif
  } else {
    const std::string model_flag = absl::GetFlag(FLAGS_model);
    const std::string mode =
        ChooseMode(*source, *target, requested_mode, model_flag.empty() ? "objects" : model_flag,
                   nullptr, initial->has_value());
    absl::StatusOr<std::unique_ptr<core::Registrar>> registrar =
        core::Registrar::Create(RegistrarConfigFromModelFlag(model_flag));
    if (!registrar.ok()) return Fail(kFailure, std::string(registrar.status().message()));
    core::RegistrationOptions options;
    options.mode = *core::ParseRegistrationMode(mode);
    ApplyRegistrationFlags(options);
    options.initial_T_target_source = *initial;
    report = RegisterWithRegistrar(**registrar, *source, *target, tree_depth, options);
  }
  if (!report.ok()) return Fail(kFailure, std::string(report.status().message()));
  report->truth = *truth;

  if (!absl::GetFlag(FLAGS_output_aligned).empty()) {
    const core::PointCloud aligned =
        core::TransformedCloud(*source, report->T_target_source.cast<float>());
    if (absl::Status status = core::WritePointCloud(absl::GetFlag(FLAGS_output_aligned), aligned);
        !status.ok()) {
      return Fail(kFailure, std::string(status.message()));
    }
  }
  if (absl::GetFlag(FLAGS_json)) {
    std::printf(
        "{\"source\": %s, \"target\": %s, \"source_points\": %zu, \"target_points\": %zu, "
        "\"where\": %s, \"tree_depth\": %d, \"result\": %s}\n",
        JsonString(args[0]).c_str(), JsonString(args[1]).c_str(), source->size(), target->size(),
        JsonString(*use_server ? absl::GetFlag(FLAGS_server) : "local").c_str(), tree_depth,
        FormatReportJson(*report).c_str());
  } else {
    std::printf("source %s (%zu points) -> target %s (%zu points), %s, tree depth %d\n",
                args[0].c_str(), source->size(), args[1].c_str(), target->size(),
                *use_server ? ("server " + absl::GetFlag(FLAGS_server)).c_str() : "local",
                tree_depth);
    std::printf("%s", FormatReportText(*report).c_str());
    if (!absl::GetFlag(FLAGS_output_aligned).empty()) {
      std::printf("aligned source written to %s\n", absl::GetFlag(FLAGS_output_aligned).c_str());
    }
  }
  return report->valid ? kValid : kNotValid;
}

}  // namespace rpsr::client
