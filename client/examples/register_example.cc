// The rpsr client library in a few lines: connect, open a session, upload two clouds, register.
//
//   rpsr_register_example ADDRESS SOURCE_FILE TARGET_FILE
//   rpsr_register_example 127.0.0.1:50051 client/examples/data/object/clouds/000000_source.ply
//                         client/examples/data/object/clouds/000000_target.ply  (one line)
//
// Prints the pose T_target_source (maps source points into the target frame), whether it is
// valid and its confidence. Exit code 0 on a valid registration, 1 otherwise.
#include <cstdio>

#include "client/rpsr_client.h"
#include "core/io/point_cloud_io.h"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s ADDRESS SOURCE_FILE TARGET_FILE\n", argv[0]);
    return 2;
  }
  absl::StatusOr<rpsr::core::PointCloud> source = rpsr::core::ReadPointCloud(argv[2]);
  absl::StatusOr<rpsr::core::PointCloud> target = rpsr::core::ReadPointCloud(argv[3]);
  if (!source.ok() || !target.ok()) {
    std::fprintf(stderr, "%s\n",
                 std::string((source.ok() ? target.status() : source.status()).message()).c_str());
    return 1;
  }

  rpsr::client::ClientOptions options;
  options.address = argv[1];
  absl::StatusOr<std::unique_ptr<rpsr::client::Client>> client =
      rpsr::client::Client::Connect(options);
  if (!client.ok()) {
    std::fprintf(stderr, "connect: %s\n", client.status().ToString().c_str());
    return 1;
  }
  absl::StatusOr<std::unique_ptr<rpsr::client::Session>> session = (*client)->CreateSession();
  if (!session.ok()) {
    std::fprintf(stderr, "session: %s\n", session.status().ToString().c_str());
    return 1;
  }
  // Each cloud crosses the network once; the server keeps its tree for later registrations.
  absl::StatusOr<rpsr::client::UploadedCloud> source_cloud = (*session)->Upload(source->points);
  absl::StatusOr<rpsr::client::UploadedCloud> target_cloud = (*session)->Upload(target->points);
  if (!source_cloud.ok() || !target_cloud.ok()) {
    std::fprintf(
        stderr, "upload: %s\n",
        (source_cloud.ok() ? target_cloud.status() : source_cloud.status()).ToString().c_str());
    return 1;
  }
  absl::StatusOr<rpsr::client::RegistrationResult> result =
      (*session)->Register(source_cloud->cloud_id, target_cloud->cloud_id);
  if (!result.ok()) {
    std::fprintf(stderr, "register: %s\n", result.status().ToString().c_str());
    return 1;
  }
  const Eigen::Matrix4d T = result->T_target_source.matrix();
  std::printf("T_target_source =\n");
  for (int r = 0; r < 4; ++r) {
    std::printf("  % .6f % .6f % .6f % .6f\n", T(r, 0), T(r, 1), T(r, 2), T(r, 3));
  }
  std::printf("valid %s, confidence %.3f, fitness %.3f, mode %s, %.1f ms round trip\n",
              result->valid ? "yes" : "no", result->confidence, result->fitness,
              result->mode.c_str(), 1e3 * result->round_trip_seconds);
  // On a valid result a reason is a doubt (RegisterOptions::sensor_aligned_check in mode refine).
  if (!result->failure_reason.empty()) {
    std::printf("%s: %s\n", result->valid ? "note" : "reason", result->failure_reason.c_str());
  }
  return result->valid ? 0 : 1;
}
