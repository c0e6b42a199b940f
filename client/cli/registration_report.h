// What `rpsr register`, `rpsr demo` and `rpsr odometry` share: choosing tree depth and mode for a
// pair of clouds, one result type for local (core::Registrar) and remote (rpsr::client) answers,
// and printing it as text or JSON.
#ifndef RPSR_CLIENT_CLI_REGISTRATION_REPORT_H_
#define RPSR_CLIENT_CLI_REGISTRATION_REPORT_H_

#include <optional>
#include <string>

#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"
#include "core/registrar/registrar.h"
#if RPSR_CLI_HAS_SERVICE
#include "client/rpsr_client.h"
#endif

namespace rpsr::client {

// The registration of one pair, wherever it ran.
struct PairReport {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  bool valid = false;
  std::string failure_reason;
  double confidence = 0.0;
  double fitness = 0.0;
  double inlier_rmse = 0.0;
  int iterations = 0;
  std::string mode;
  std::string start;  // where it started: network, network_later_passes, initial, searched,
                      // searched_turns, structure, round_axis, weak_direction, centroid,
                      // principal_axes, extent_slide, weak_direction_chamfer, far_valley,
                      // half_turn, symmetric
  int starts = 0;     // refinement starts tried for this pair
  // Degenerate, and kept at the initial guess along the unconstrained directions.
  bool held_at_initial = false;
  bool line_normals_from_planes = false;  // the line rule that ran (as asked, or as chosen)
  double surface_scatter_cells = -1.0;    // negative: not measured
  bool noise_polished = false;
  // Mode refine, a doubted answer: the pose the structure off the ground prefers.
  std::optional<Eigen::Isometry3d> structure_alternative;
  double seconds = 0.0;  // wall time of the registration as the caller saw it
  // Against a known truth, when there is one.
  std::optional<Eigen::Isometry3d> truth;
};

PairReport ReportOf(const core::RegistrationResult& result, double seconds);
#if RPSR_CLI_HAS_SERVICE
// A result the service returned; `seconds` is its round trip.
PairReport ReportOf(const RegistrationResult& result);
#endif

// A scene (a LiDAR scan, in metres) is a cloud whose bounding box diagonal exceeds kSceneDiagonal
// AND whose points lie no farther apart than about a cell of kSceneTreeDepth: at least
// kSceneMinPointsPerCell points in its occupied cells one depth above (of its own bounding cube).
// Measured on simulated scans: an HDL-64E's hold 32 (13 at 0.1 m voxels, 2.3 at 0.5 m), a VLP-16's
// 8.7 (2.5 at 0.3 m voxels); an object about 1.0 whatever its units, also with 8,192 points. The
// diagonal alone took objects given in millimetres for scenes: depth-9 cells then hold single
// samples several cells apart, the finest depth found almost no partners and the registration
// ended "no overlap".
inline constexpr double kSceneDiagonal = 10.0;
inline constexpr int kSceneTreeDepth = 9;
inline constexpr double kSceneMinPointsPerCell = 1.5;
bool IsSceneScale(const core::PointCloud& cloud);

// Tree depth: `requested` when > 0, else 6 for objects (what the network was trained on) and 9
// for scenes (~0.5 m cells on a 240 m cube, where the refinement is accurate).
int ChooseTreeDepth(const core::PointCloud& source, const core::PointCloud& target, int requested);

// Mode: `requested` when not empty; else net+refine, except for scene-scale clouds with a
// non-LiDAR model when a motion prior will be given (`has_motion_prior`: odometry's previous
// motion), where it is refine from that prior: the shipped network knows objects only, and
// net+refine's second start (from the prior) would only add its cost to frames the prior already
// solves. Without a prior, net+refine's two starts (the network's estimate and the identity) are
// as accurate as refine from the identity or better on scans (README, KITTI-style table). `why`
// (may be null) receives a short reason for the choice.
std::string ChooseMode(const core::PointCloud& source, const core::PointCloud& target,
                       const std::string& requested, const std::string& model_name,
                       std::string* why, bool has_motion_prior = false);

// "R =\n ...\nt = ..." block with the quaternion, validity, confidence, fit and time; with the
// rotation/translation error against `truth` when set.
std::string FormatReportText(const PairReport& report);
// One JSON object (no trailing newline).
std::string FormatReportJson(const PairReport& report);

std::string JsonString(const std::string& text);

// Builds both trees (depth `tree_depth`) and registers in this process; the report's seconds
// include the trees.
absl::StatusOr<PairReport> RegisterWithRegistrar(const core::Registrar& registrar,
                                                 const core::PointCloud& source,
                                                 const core::PointCloud& target, int tree_depth,
                                                 const core::RegistrationOptions& options);

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_CLI_REGISTRATION_REPORT_H_
