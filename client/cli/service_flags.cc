#include "client/cli/service_flags.h"

#include "absl/flags/flag.h"
#include "absl/strings/str_cat.h"
#include "core/io/file_bytes.h"

ABSL_FLAG(std::string, server, "",
          "register, odometry, bench: host:port of a running rpsrd (or `rpsr serve`); empty: "
          "register locally in this process");
ABSL_FLAG(bool, local, false,
          "register, odometry: run the registrar in this process (the default without --server)");
ABSL_FLAG(bool, json, false, "print machine-readable JSON on stdout instead of text");
ABSL_FLAG(std::string, token, "",
          "bearer token sent to the server (one of its accepted tokens); serve: the token it "
          "accepts (empty: no authentication)");
ABSL_FLAG(std::string, tls_ca, "",
          "PEM file of the root certificates that signed the server's TLS certificate; given: "
          "connect with TLS");
ABSL_FLAG(double, timeout_s, 60.0, "deadline of each call to the server, seconds");
ABSL_FLAG(std::string, data, "",
          "demo, bench: a folder of sample pairs laid out as client/examples/data (object/ and "
          "lidar/, each with a manifest.csv); default: that folder's copy linked into rpsr");

namespace rpsr::client {

std::string ExplicitModeFlag() {
  if (!GivenOnCommandLine("mode")) return "";
  return absl::GetFlag(FLAGS_mode);
}

int ExplicitTreeDepthFlag() {
  if (!GivenOnCommandLine("tree_depth")) return 0;
  return absl::GetFlag(FLAGS_tree_depth);
}

absl::StatusOr<bool> UseServerFlag() {
  const bool server = !absl::GetFlag(FLAGS_server).empty();
  if (server && absl::GetFlag(FLAGS_local)) {
    return absl::InvalidArgumentError("give either --server ADDR or --local, not both");
  }
  return server;
}

#if RPSR_CLI_HAS_SERVICE
void ApplyRegistrationFlags(RegisterOptions& options) {
  options.passes = absl::GetFlag(FLAGS_passes);
  options.refine_from_initial = absl::GetFlag(FLAGS_refine_from_initial);
  options.later_passes_when_unconfident = absl::GetFlag(FLAGS_later_passes_when_unconfident);
  options.search_scene_start = absl::GetFlag(FLAGS_search_scene_start);
  options.symmetric_starts = absl::GetFlag(FLAGS_symmetric_starts);
  options.round_axis_start = absl::GetFlag(FLAGS_round_axis_start);
  options.weak_direction_start = absl::GetFlag(FLAGS_weak_direction_start);
  options.weak_direction_finest_round = absl::GetFlag(FLAGS_weak_direction_finest_round);
  options.centroid_start = absl::GetFlag(FLAGS_centroid_start);
  options.principal_axes_start = absl::GetFlag(FLAGS_principal_axes_start);
  options.extent_slide = absl::GetFlag(FLAGS_extent_slide);
  options.weak_direction_chamfer = absl::GetFlag(FLAGS_weak_direction_chamfer);
  options.half_turn_start = absl::GetFlag(FLAGS_half_turn_start);
  options.screw_turns = absl::GetFlag(FLAGS_screw_turns);
  options.far_valley = absl::GetFlag(FLAGS_far_valley);
  options.sensor_aligned_check = absl::GetFlag(FLAGS_sensor_aligned_check);
  options.rebin_coarse_depths = absl::GetFlag(FLAGS_rebin_coarse_depths);
  options.joint_finest_stage = absl::GetFlag(FLAGS_joint_finest_stage);
  options.noise_polish = absl::GetFlag(FLAGS_noise_polish);
  options.coarse_wide_search = absl::GetFlag(FLAGS_coarse_wide_search);
  options.line_normals_from_planes = ExplicitLineNormalsFlag();
  options.hold_degenerate_at_initial = absl::GetFlag(FLAGS_hold_degenerate_at_initial);
}

absl::StatusOr<ClientOptions> ClientOptionsFromFlags() {
  ClientOptions options;
  options.address = absl::GetFlag(FLAGS_server);
  options.bearer_token = absl::GetFlag(FLAGS_token);
  const double timeout = absl::GetFlag(FLAGS_timeout_s);
  if (!(timeout > 0)) return absl::InvalidArgumentError("--timeout_s must be positive");
  options.default_deadline = absl::Seconds(timeout);
  const std::string ca = absl::GetFlag(FLAGS_tls_ca);
  if (!ca.empty()) {
    absl::StatusOr<std::string> pem = core::ReadFileBytes(ca);
    if (!pem.ok())
      return absl::Status(pem.status().code(), absl::StrCat("--tls_ca: ", pem.status().message()));
    options.use_tls = true;
    options.tls_root_certs_pem = *std::move(pem);
  }
  return options;
}
#endif

}  // namespace rpsr::client
