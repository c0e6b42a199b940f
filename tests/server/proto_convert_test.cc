#include "server/proto_convert.h"

#include <cmath>
#include <optional>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/structured_log.h"

namespace rpsr::server {
namespace {

using ::testing::HasSubstr;

TEST(ProtoConvertTest, TransformsRoundTripThroughMatrixAndQuaternion) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.1, -2.0, 30.0);
  v1::RigidTransform proto;
  TransformToProto(T, &proto);
  ASSERT_EQ(proto.rotation_size(), 9);
  EXPECT_GE(proto.quaternion().w(), 0.0);
  auto back = TransformFromProto(proto, "t");
  ASSERT_TRUE(back.ok());
  EXPECT_TRUE(back->isApprox(T, 1e-12));
  proto.clear_rotation();  // the quaternion alone
  back = TransformFromProto(proto, "t");
  ASSERT_TRUE(back.ok());
  EXPECT_TRUE(back->isApprox(T, 1e-12));
}

TEST(ProtoConvertTest, RefusesNonRigidOrMalformedTransforms) {
  v1::RigidTransform proto;
  for (double v : {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0}) proto.add_rotation(v);
  EXPECT_THAT(TransformFromProto(proto, "guess").status().message(),
              HasSubstr("guess.rotation is not a rotation"));
  proto.clear_rotation();
  proto.add_rotation(1.0);
  EXPECT_THAT(TransformFromProto(proto, "guess").status().message(), HasSubstr("9 (3x3"));
  proto.clear_rotation();
  proto.mutable_quaternion();  // all zero
  EXPECT_THAT(TransformFromProto(proto, "guess").status().message(), HasSubstr("non-zero"));
  v1::RigidTransform t;
  t.add_translation(1.0);
  EXPECT_THAT(TransformFromProto(t, "guess").status().message(), HasSubstr("3 expected"));
  t.add_translation(NAN);
  t.add_translation(1.0);
  EXPECT_THAT(TransformFromProto(t, "guess").status().message(), HasSubstr("not finite"));
}

TEST(ProtoConvertTest, OptionsDefaultToNetRefineAndCheckRanges) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_EQ(options->mode, core::RegistrationMode::kNetRefine);
  EXPECT_FALSE(options->initial_T_target_source.has_value());
  v1::RegisterOptions proto;
  proto.set_mode("net");
  proto.set_passes(4);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_EQ(options->mode, core::RegistrationMode::kNet);
  EXPECT_EQ(options->passes, 4);
  proto.set_deadline_seconds(-1);
  EXPECT_EQ(OptionsFromProto(proto).status().code(), absl::StatusCode::kInvalidArgument);
}

// The re-binned coarse depths are on unless a client says otherwise.
TEST(ProtoConvertTest, RebinnedCoarseDepthsAreOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->refinement.rebin_coarse_depths);
  v1::RegisterOptions proto;
  proto.set_rebin_coarse_depths(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->refinement.rebin_coarse_depths);
  proto.set_rebin_coarse_depths(true);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->refinement.rebin_coarse_depths);
}

TEST(ProtoConvertTest, JointFinestStageIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->refinement.joint_finest_stage);
  v1::RegisterOptions proto;
  proto.set_joint_finest_stage(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->refinement.joint_finest_stage);
}

TEST(ProtoConvertTest, NoisePolishIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->refinement.noise_polish);
  v1::RegisterOptions proto;
  proto.set_noise_polish(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->refinement.noise_polish);
}

TEST(ProtoConvertTest, CoarseWideSearchIsOnUnlessTurnedOff) {
  const core::TreeRefinementOptions defaults;
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_EQ(options->refinement.coarse_search_27_neighbors, defaults.coarse_search_27_neighbors);
  EXPECT_EQ(options->refinement.coarse_max_correspondence_distance_cells,
            defaults.coarse_max_correspondence_distance_cells);
  v1::RegisterOptions proto;
  proto.set_coarse_wide_search(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_EQ(options->refinement.coarse_search_27_neighbors, defaults.search_27_neighbors);
  EXPECT_EQ(options->refinement.coarse_max_correspondence_distance_cells,
            defaults.max_correspondence_distance_cells);
  EXPECT_NE(defaults.coarse_max_correspondence_distance_cells,
            defaults.max_correspondence_distance_cells);
}

TEST(ProtoConvertTest, LineNormalsFromPlanesIsChosenUnlessGiven) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->refinement.line_normals_from_planes.has_value());
  for (bool given : {true, false}) {
    v1::RegisterOptions proto;
    proto.set_line_normals_from_planes(given);
    options = OptionsFromProto(proto);
    ASSERT_TRUE(options.ok());
    EXPECT_EQ(options->refinement.line_normals_from_planes, std::optional<bool>(given));
  }
}

TEST(ProtoConvertTest, HoldingDegenerateDirectionsAtTheGuessIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->hold_degenerate_at_initial);
  v1::RegisterOptions proto;
  proto.set_hold_degenerate_at_initial(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->hold_degenerate_at_initial);
}

// The later starts are on unless a client says otherwise (proto3 optional: absent is not false).
TEST(ProtoConvertTest, LaterStartsAreOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->also_refine_from_initial);
  EXPECT_TRUE(options->search_scene_start);
  v1::RegisterOptions proto;
  proto.set_search_scene_start(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->also_refine_from_initial);
  EXPECT_FALSE(options->search_scene_start);
  proto.set_refine_from_initial(false);
  proto.set_search_scene_start(true);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->also_refine_from_initial);
  EXPECT_TRUE(options->search_scene_start);
}

// The later network passes wait for an unconfident first answer (since session 32) unless a
// client turns that off.
TEST(ProtoConvertTest, LaterPassesWaitForAnUnconfidentAnswerUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->later_passes_only_when_unconfident);
  v1::RegisterOptions proto;
  proto.set_later_passes_when_unconfident(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->later_passes_only_when_unconfident);
}

// The symmetric start is on (since session 29) unless a client turns it off.
TEST(ProtoConvertTest, SymmetricStartsAreOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->try_symmetric_starts);
  v1::RegisterOptions proto;
  proto.set_symmetric_starts(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->try_symmetric_starts);
}

TEST(ProtoConvertTest, RoundAxisStartIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->search_round_axis_start);
  v1::RegisterOptions proto;
  proto.set_round_axis_start(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->search_round_axis_start);
}

TEST(ProtoConvertTest, WeakDirectionStartIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->search_weak_direction_start);
  v1::RegisterOptions proto;
  proto.set_weak_direction_start(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->search_weak_direction_start);
}

TEST(ProtoConvertTest, CentroidStartIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->search_centroid_start);
  v1::RegisterOptions proto;
  proto.set_centroid_start(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->search_centroid_start);
}

TEST(ProtoConvertTest, PrincipalAxesStartIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->search_principal_axes_start);
  v1::RegisterOptions proto;
  proto.set_principal_axes_start(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->search_principal_axes_start);
}

TEST(ProtoConvertTest, ExtentSlideIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->search_extent_slide);
  v1::RegisterOptions proto;
  proto.set_extent_slide(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->search_extent_slide);
}

TEST(ProtoConvertTest, WeakDirectionChamferIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->search_weak_direction_chamfer);
  v1::RegisterOptions proto;
  proto.set_weak_direction_chamfer(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->search_weak_direction_chamfer);
}

TEST(ProtoConvertTest, HalfTurnStartIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->search_half_turn_start);
  v1::RegisterOptions proto;
  proto.set_half_turn_start(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->search_half_turn_start);
}

TEST(ProtoConvertTest, ScrewTurnsAreOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->round_axis_screw_turns);
  v1::RegisterOptions proto;
  proto.set_screw_turns(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->round_axis_screw_turns);
}

TEST(ProtoConvertTest, FarValleyIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->search_far_valley);
  v1::RegisterOptions proto;
  proto.set_far_valley(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->search_far_valley);
}

TEST(ProtoConvertTest, WeakDirectionFinestRoundIsOffUnlessTurnedOn) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->weak_direction_finest_round);
  v1::RegisterOptions proto;
  proto.set_weak_direction_finest_round(true);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->weak_direction_finest_round);
}

TEST(ProtoConvertTest, SensorAlignedCheckIsOnUnlessTurnedOff) {
  auto options = OptionsFromProto({});
  ASSERT_TRUE(options.ok());
  EXPECT_TRUE(options->check_sensor_aligned_answers);
  v1::RegisterOptions proto;
  proto.set_sensor_aligned_check(false);
  options = OptionsFromProto(proto);
  ASSERT_TRUE(options.ok());
  EXPECT_FALSE(options->check_sensor_aligned_answers);
}

TEST(ProtoConvertTest, ResultCarriesEverythingTheRegistrarSays) {
  core::RegistrationResult result;
  result.valid = false;
  result.failure_reason = "degenerate: translation x";
  result.information(3, 4) = 7.0;
  result.degenerate_axes[3] = true;
  result.num_degenerate = 1;
  result.held_at_initial = true;
  result.line_normals_from_planes = true;
  result.surface_scatter_cells = 0.52;
  result.noise_polished = true;
  result.mode = core::RegistrationMode::kRefine;
  result.timings.refine_seconds = 0.004;
  result.start = "searched";
  result.starts = 3;
  v1::RegistrationResult proto;
  ResultToProto(result, &proto);
  EXPECT_FALSE(proto.valid());
  EXPECT_EQ(proto.failure_reason(), "degenerate: translation x");
  ASSERT_EQ(proto.information_size(), 36);
  EXPECT_EQ(proto.information(3 * 6 + 4), 7.0);
  ASSERT_EQ(proto.degenerate_axes_size(), 6);
  EXPECT_TRUE(proto.degenerate_axes(3));
  EXPECT_TRUE(proto.held_at_initial());
  EXPECT_TRUE(proto.line_normals_from_planes());
  EXPECT_EQ(proto.surface_scatter_cells(), 0.52);
  EXPECT_TRUE(proto.noise_polished());
  EXPECT_EQ(proto.mode(), "refine");
  EXPECT_EQ(proto.timings().refine_seconds(), 0.004);
  EXPECT_EQ(proto.start(), "searched");
  EXPECT_EQ(proto.starts(), 3u);
  EXPECT_FALSE(proto.has_structure_alternative_transform_target_source());
  // A doubted answer's alternative pose travels with it.
  result.structure_alternative_T_target_source =
      Eigen::Isometry3d(Eigen::Translation3d(-7.4, 0.1, 0.0));
  ResultToProto(result, &proto);
  ASSERT_TRUE(proto.has_structure_alternative_transform_target_source());
  ASSERT_EQ(proto.structure_alternative_transform_target_source().translation_size(), 3);
  EXPECT_EQ(proto.structure_alternative_transform_target_source().translation(0), -7.4);
}

TEST(ProtoConvertTest, StatusCodesAndMessagesPassThrough) {
  const grpc::Status status = ToGrpcStatus(absl::NotFoundError("cloud 7 is gone"));
  EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(status.error_message(), "cloud 7 is gone");
  EXPECT_TRUE(ToGrpcStatus(absl::OkStatus()).ok());
}

TEST(StructuredLogTest, WritesKeyValuePairsQuotingWhereNeeded) {
  const std::string line = FormatLogLine(
      "warn", "call", {{"method", "Register"}, {"error", "cloud 7 \"x\" gone"}, {"empty", ""}});
  EXPECT_THAT(line, ::testing::StartsWith("ts="));
  EXPECT_THAT(
      line,
      HasSubstr(
          " level=warn event=call method=Register error=\"cloud 7 \\\"x\\\" gone\" empty=\"\""));
}

}  // namespace
}  // namespace rpsr::server
