// rpsr demo: what rpsr does, on a fresh machine, in one command. Starts the registration service
// in this process with the model embedded in the binary, connects to it with the client library
// like any application, registers the shipped sample pairs (an object, two LiDAR scans; see
// client/examples/data/README.md), prints each pose, confidence and error against the known
// truth, and writes a picture of each pair before and after alignment (PNG).
// Exit codes: 0 every pair registered (valid or not, it is reported), 1 failure, 2 bad flags.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "client/cli/png_canvas.h"
#include "client/cli/registration_report.h"
#include "client/cli/sample_pairs.h"
#include "client/cli/service_flags.h"
#include "client/cli/shared_flags.h"
#include "client/cli/subcommands.h"
#include "client/rpsr_client.h"
#include "core/data/registration_metrics.h"
#include "server/rpsr_server.h"

namespace rpsr::client {
namespace {

namespace fs = std::filesystem;

int Fail(int code, const std::string& message) {
  std::fprintf(stderr, "rpsr demo: %s\n", message.c_str());
  return code;
}

struct Sample {
  std::string name;    // "object pair", "LiDAR scans"
  std::string folder;  // under --data
  std::string picture;
};

}  // namespace

int RunDemoCommand(const std::vector<std::string>& args) {
  if (!args.empty()) return Fail(2, "takes no arguments (see rpsr demo --help)");
  const bool json = absl::GetFlag(FLAGS_json);
  std::string output = absl::GetFlag(FLAGS_output);
  if (output.empty()) output = "rpsr-demo";
  std::error_code error;
  fs::create_directories(output, error);
  if (error) return Fail(1, absl::StrCat("cannot create ", output, ": ", error.message()));

  // 1. The service, in-process, on a free loopback port.
  const auto start = std::chrono::steady_clock::now();
  server::ServerOptions server_options;
  server_options.address = "127.0.0.1:0";
  server_options.metrics_address = "";
  server_options.log_requests = false;
  server_options.log_lifecycle = false;
  server_options.registrar_config = RegistrarConfigFromModelFlag(absl::GetFlag(FLAGS_model));
  absl::StatusOr<std::unique_ptr<server::RunningServer>> running =
      server::StartServer(server_options);
  if (!running.ok()) return Fail(1, absl::StrCat("server: ", running.status().ToString()));
  const double start_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  // 2. A client, as an application would connect.
  ClientOptions client_options;
  client_options.address = (*running)->target();
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(client_options);
  if (!client.ok()) return Fail(1, client.status().ToString());
  absl::StatusOr<ServerInfo> info = (*client)->GetServerInfo();
  if (!info.ok()) return Fail(1, absl::StrCat("GetServerInfo: ", info.status().ToString()));
  if (!json) {
    std::printf("rpsr demo: in-process server on %s (rpsr %s, model '%s'), up in %.2f s\n",
                (*running)->target().c_str(), info->server_version.c_str(),
                info->model_name.c_str(), start_seconds);
  }

  // 3. The samples.
  const std::vector<Sample> samples = {{"object pair", "object", "object_pair.png"},
                                       {"LiDAR scans", "lidar", "lidar_pair.png"}};
  const std::string data = absl::GetFlag(FLAGS_data);
  std::string json_pairs;
  for (const Sample& sample : samples) {
    absl::StatusOr<SamplePair> pair = LoadSamplePair(data, sample.folder);
    if (!pair.ok()) return Fail(1, std::string(pair.status().message()));
    const core::PointCloud* source = &pair->source;
    const core::PointCloud* target = &pair->target;

    std::string why;
    const std::string mode =
        ChooseMode(*source, *target, ExplicitModeFlag(), info->model_name, &why);
    SessionOptions session_options;
    session_options.tree_max_depth = ChooseTreeDepth(*source, *target, ExplicitTreeDepthFlag());
    absl::StatusOr<std::unique_ptr<Session>> session = (*client)->CreateSession(session_options);
    if (!session.ok()) return Fail(1, absl::StrCat("CreateSession: ", session.status().ToString()));
    RegisterOptions register_options;
    register_options.mode = mode;
    absl::StatusOr<RegistrationResult> result =
        (*session)->Register(source->points, target->points, register_options);
    if (!result.ok()) return Fail(1, absl::StrCat(sample.name, ": ", result.status().ToString()));

    PairReport report = ReportOf(*result);
    report.truth = pair->T_target_source;
    const std::string picture = (fs::path(output) / sample.picture).string();
    if (absl::Status status = WritePairPicture(picture, *source, *target, result->T_target_source);
        !status.ok()) {
      return Fail(1, std::string(status.message()));
    }
    if (json) {
      absl::StrAppend(
          &json_pairs, json_pairs.empty() ? "" : ", ", "{\"name\": ", JsonString(sample.name),
          ", \"source\": ", JsonString(pair->source_name),
          ", \"target\": ", JsonString(pair->target_name), ", \"source_points\": ", source->size(),
          ", \"target_points\": ", target->size(),
          ", \"tree_depth\": ", session_options.tree_max_depth,
          ", \"picture\": ", JsonString(picture), ", \"result\": ", FormatReportJson(report), "}");
    } else {
      std::printf("\n%s: %s (%zu points) -> %s (%zu points)\n", sample.name.c_str(),
                  pair->source_name.c_str(), source->size(), pair->target_name.c_str(),
                  target->size());
      std::printf("tree depth %d, mode %s (%s)\n", session_options.tree_max_depth, mode.c_str(),
                  why.c_str());
      std::printf("%s", FormatReportText(report).c_str());
      if (pair->T_target_source) {
        const Eigen::Vector3d t = pair->T_target_source->translation();
        std::printf(
            "truth: rotation %.2f deg, t = % .4f % .4f % .4f\n",
            core::ErrorOf(Eigen::Isometry3d::Identity(), *pair->T_target_source).rotation_deg,
            t.x(), t.y(), t.z());
      }
      std::printf(
          "picture: %s (from above; left as given, right aligned; blue target, red "
          "source)\n",
          picture.c_str());
    }
  }
  if (json) {
    std::printf(
        "{\"server\": %s, \"model\": %s, \"server_start_seconds\": %.3f, \"pairs\": [%s]}\n",
        JsonString((*running)->target()).c_str(), JsonString(info->model_name).c_str(),
        start_seconds, json_pairs.c_str());
  }
  client->reset();
  (*running)->Shutdown(absl::Seconds(5));
  return 0;
}

}  // namespace rpsr::client
