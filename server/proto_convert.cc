#include "server/proto_convert.h"

#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"

namespace rpsr::server {

absl::StatusOr<Eigen::Isometry3d> TransformFromProto(const v1::RigidTransform& proto,
                                                     absl::string_view what) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (proto.rotation_size() > 0) {
    if (proto.rotation_size() != 9) {
      return absl::InvalidArgumentError(absl::StrCat(what, ".rotation has ", proto.rotation_size(),
                                                     " numbers; 9 (3x3 row-major) expected"));
    }
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = proto.rotation(3 * r + c);
    }
    if (!R.allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat(what, ".rotation is not finite"));
    }
    const double orthogonality = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
    if (orthogonality > 1e-3 || std::abs(R.determinant() - 1.0) > 1e-3) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ".rotation is not a rotation (|R^T R - I| = ", orthogonality,
                       ", det = ", R.determinant(), "); give an orthonormal matrix with det +1"));
    }
    // Re-orthonormalise so the small slack allowed above does not reach the registrar.
    T.linear() = Eigen::Quaterniond(R).normalized().toRotationMatrix();
  } else if (proto.has_quaternion()) {
    const Eigen::Quaterniond q(proto.quaternion().w(), proto.quaternion().x(),
                               proto.quaternion().y(), proto.quaternion().z());
    if (!q.coeffs().allFinite() || q.norm() < 1e-9) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ".quaternion must be finite and non-zero"));
    }
    T.linear() = q.normalized().toRotationMatrix();
  }
  if (proto.translation_size() != 0 && proto.translation_size() != 3) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ".translation has ", proto.translation_size(), " numbers; 3 expected"));
  }
  if (proto.translation_size() == 3) {
    const Eigen::Vector3d t(proto.translation(0), proto.translation(1), proto.translation(2));
    if (!t.allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat(what, ".translation is not finite"));
    }
    T.translation() = t;
  }
  return T;
}

void TransformToProto(const Eigen::Isometry3d& T, v1::RigidTransform* proto) {
  proto->clear_rotation();
  proto->clear_translation();
  const Eigen::Matrix3d R = T.rotation();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) proto->add_rotation(R(r, c));
  }
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;  // one canonical sign
  proto->mutable_quaternion()->set_w(q.w());
  proto->mutable_quaternion()->set_x(q.x());
  proto->mutable_quaternion()->set_y(q.y());
  proto->mutable_quaternion()->set_z(q.z());
  for (int a = 0; a < 3; ++a) proto->add_translation(T.translation()[a]);
}

absl::StatusOr<core::RegistrationOptions> OptionsFromProto(const v1::RegisterOptions& proto) {
  core::RegistrationOptions options;
  if (!proto.mode().empty()) {
    absl::StatusOr<core::RegistrationMode> mode = core::ParseRegistrationMode(proto.mode());
    if (!mode.ok()) return mode.status();
    options.mode = *mode;
  }
  if (proto.passes() < 0 || proto.passes() > kMaxPasses) {
    return absl::InvalidArgumentError(absl::StrCat("options.passes is ", proto.passes(),
                                                   "; 0 (the model's default) to ", kMaxPasses,
                                                   " expected"));
  }
  options.passes = proto.passes();
  if (proto.has_initial_guess()) {
    absl::StatusOr<Eigen::Isometry3d> guess =
        TransformFromProto(proto.initial_guess(), "options.initial_guess");
    if (!guess.ok()) return guess.status();
    options.initial_T_target_source = *guess;
  }
  if (!std::isfinite(proto.deadline_seconds()) || proto.deadline_seconds() < 0) {
    return absl::InvalidArgumentError(absl::StrCat("options.deadline_seconds is ",
                                                   proto.deadline_seconds(),
                                                   "; a finite number >= 0 expected"));
  }
  if (proto.has_later_passes_when_unconfident()) {
    options.later_passes_only_when_unconfident = proto.later_passes_when_unconfident();
  }
  if (proto.has_refine_from_initial())
    options.also_refine_from_initial = proto.refine_from_initial();
  if (proto.has_search_scene_start()) options.search_scene_start = proto.search_scene_start();
  if (proto.has_symmetric_starts()) options.try_symmetric_starts = proto.symmetric_starts();
  if (proto.has_round_axis_start()) options.search_round_axis_start = proto.round_axis_start();
  if (proto.has_weak_direction_start()) {
    options.search_weak_direction_start = proto.weak_direction_start();
  }
  if (proto.has_centroid_start()) options.search_centroid_start = proto.centroid_start();
  if (proto.has_principal_axes_start()) {
    options.search_principal_axes_start = proto.principal_axes_start();
  }
  if (proto.has_extent_slide()) options.search_extent_slide = proto.extent_slide();
  if (proto.has_weak_direction_chamfer()) {
    options.search_weak_direction_chamfer = proto.weak_direction_chamfer();
  }
  if (proto.has_half_turn_start()) options.search_half_turn_start = proto.half_turn_start();
  if (proto.has_screw_turns()) options.round_axis_screw_turns = proto.screw_turns();
  if (proto.has_far_valley()) options.search_far_valley = proto.far_valley();
  if (proto.has_weak_direction_finest_round()) {
    options.weak_direction_finest_round = proto.weak_direction_finest_round();
  }
  if (proto.has_sensor_aligned_check()) {
    options.check_sensor_aligned_answers = proto.sensor_aligned_check();
  }
  if (proto.has_rebin_coarse_depths()) {
    options.refinement.rebin_coarse_depths = proto.rebin_coarse_depths();
  }
  if (proto.has_joint_finest_stage()) {
    options.refinement.joint_finest_stage = proto.joint_finest_stage();
  }
  if (proto.has_coarse_wide_search() && !proto.coarse_wide_search()) {
    core::SearchCoarseStagesAsTheFinest(options.refinement);
  }
  if (proto.has_noise_polish()) {
    options.refinement.noise_polish = proto.noise_polish();
  }
  if (proto.has_line_normals_from_planes()) {
    options.refinement.line_normals_from_planes = proto.line_normals_from_planes();
  }
  if (proto.has_hold_degenerate_at_initial()) {
    options.hold_degenerate_at_initial = proto.hold_degenerate_at_initial();
  }
  return options;
}

void ResultToProto(const core::RegistrationResult& result, v1::RegistrationResult* proto) {
  TransformToProto(result.T_target_source, proto->mutable_transform_target_source());
  proto->set_start(result.start);
  proto->set_starts(static_cast<uint32_t>(result.starts));
  proto->set_valid(result.valid);
  proto->set_failure_reason(result.failure_reason);
  proto->set_confidence(result.confidence);
  proto->set_fitness(result.fitness);
  proto->set_inlier_rmse(result.inlier_rmse);
  proto->set_iterations(result.iterations);
  proto->set_converged(result.converged);
  proto->clear_information();
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) proto->add_information(result.information(r, c));
  }
  proto->clear_degenerate_axes();
  for (bool axis : result.degenerate_axes) proto->add_degenerate_axes(axis);
  proto->set_held_at_initial(result.held_at_initial);
  proto->set_line_normals_from_planes(result.line_normals_from_planes);
  proto->set_surface_scatter_cells(result.surface_scatter_cells);
  proto->set_noise_polished(result.noise_polished);
  if (result.structure_alternative_T_target_source.has_value()) {
    TransformToProto(*result.structure_alternative_T_target_source,
                     proto->mutable_structure_alternative_transform_target_source());
  } else {
    proto->clear_structure_alternative_transform_target_source();
  }
  proto->set_num_degenerate(result.num_degenerate);
  TransformToProto(result.net_T_target_source, proto->mutable_net_transform_target_source());
  proto->set_net_score_peak(result.net_score_peak);
  proto->set_mode(std::string(core::RegistrationModeName(result.mode)));
  v1::Timings* timings = proto->mutable_timings();
  timings->set_net_seconds(result.timings.net_seconds);
  timings->set_refine_seconds(result.timings.refine_seconds);
  timings->set_confidence_seconds(result.timings.confidence_seconds);
  timings->set_registrar_seconds(result.timings.total_seconds);
}

void TreeStatsToProto(const core::Octree& tree, double build_seconds, v1::TreeStats* proto) {
  proto->set_num_points(tree.num_points());
  proto->set_max_depth(tree.max_depth());
  proto->clear_nodes_per_depth();
  for (const core::Octree::Level& level : tree.levels()) {
    proto->add_nodes_per_depth(static_cast<uint32_t>(level.size()));
  }
  proto->set_memory_bytes(tree.MemoryBytes());
  proto->clear_cube_center();
  for (int a = 0; a < 3; ++a) proto->add_cube_center(tree.center()[a]);
  proto->set_cube_half_length(tree.half_length());
  proto->set_build_seconds(build_seconds);
}

grpc::Status ToGrpcStatus(const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()), std::string(status.message()));
}

}  // namespace rpsr::server
