// rpsr::Client against the real service started in-process on 127.0.0.1 (server/rpsr_server.h):
// every call the library offers, its recovery (retries while the server is away, re-upload of an
// evicted cloud, a re-created session) and its errors.
#include "client/rpsr_client.h"

#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <future>
#include <iterator>
#include <map>
#include <set>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/data/object_pairs.h"
#include "core/data/pair_manifest.h"
#include "core/data/registration_metrics.h"
#include "core/io/point_cloud_io.h"
#include "core/registrar/confidence_calibration.h"
#include "core/synth/lidar_sequence.h"
#include "core/synth/seeded_random.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/rpsr_server.h"
#include "tests/core/refine/refinement_test_geometry.h"

namespace rpsr::client {
namespace {

using ::testing::HasSubstr;

struct SamplePair {
  core::PointCloud source;
  core::PointCloud target;
  Eigen::Isometry3d truth;
};

SamplePair LoadSample(const std::string& name) {
  const std::string manifest =
      absl::StrCat(RPSR_SOURCE_DIR, "/client/examples/data/", name, "/manifest.csv");
  absl::StatusOr<std::vector<core::ManifestRow>> rows = core::ReadPairManifest(manifest);
  EXPECT_TRUE(rows.ok()) << rows.status();
  SamplePair pair;
  pair.source = *core::ReadPointCloud(rows->front().source);
  pair.target = *core::ReadPointCloud(rows->front().target);
  pair.truth = *rows->front().T_target_source;
  return pair;
}

server::ServerOptions TestServerOptions() {
  server::ServerOptions options;
  options.address = "127.0.0.1:0";
  options.metrics_address = "";
  options.log_requests = false;
  options.log_lifecycle = false;
  return options;
}

// A port nothing listens on (bound and released by the kernel's choice).
int FreePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = 0;
  bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address));
  socklen_t length = sizeof(address);
  getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length);
  close(fd);
  return ntohs(address.sin_port);
}

// Options with the fields a test sets (designated initializers would leave -Wextra's
// missing-field-initializers warnings).
ClientOptions At(const std::string& address, const std::string& token = "") {
  ClientOptions options;
  options.address = address;
  options.bearer_token = token;
  return options;
}

SessionOptions TreeDepth(int depth, bool keep_points_for_reupload = true) {
  SessionOptions options;
  options.tree_max_depth = depth;
  options.keep_points_for_reupload = keep_points_for_reupload;
  return options;
}

class RpsrClientTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    absl::StatusOr<std::unique_ptr<server::RunningServer>> running =
        server::StartServer(TestServerOptions());
    ASSERT_TRUE(running.ok()) << running.status();
    server_ = running->release();
    object_ = new SamplePair(LoadSample("object"));
  }
  static void TearDownTestSuite() {
    delete server_;
    delete object_;
  }

  std::unique_ptr<Client> Connect(ClientOptions options = {}) {
    options.address = server_->target();
    absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(options);
    EXPECT_TRUE(client.ok()) << client.status();
    return *std::move(client);
  }

  static server::RunningServer* server_;
  static SamplePair* object_;
};

server::RunningServer* RpsrClientTest::server_ = nullptr;
SamplePair* RpsrClientTest::object_ = nullptr;

TEST_F(RpsrClientTest, ServerInfoNamesTheModelAndLimits) {
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<ServerInfo> info = client->GetServerInfo();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->model_name, "objects");
  EXPECT_EQ(info->api_version, "rpsr.v1");
  EXPECT_THAT(info->modes, ::testing::Contains("refine"));
  EXPECT_GT(info->limits.max_points_per_cloud, 0u);
  EXPECT_FALSE(info->auth_required);
}

TEST_F(RpsrClientTest, UploadsInChunksAndRegistersByIds) {
  ClientOptions options;
  options.chunk_points = 100;  // 1,024 points: 11 messages
  std::unique_ptr<Client> client = Connect(options);
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession(TreeDepth(6));
  ASSERT_TRUE(session.ok()) << session.status();
  EXPECT_EQ((*session)->options().tree_max_depth, 6);
  absl::StatusOr<UploadedCloud> source = (*session)->Upload(object_->source.points);
  absl::StatusOr<UploadedCloud> target = (*session)->Upload(object_->target.points);
  ASSERT_TRUE(source.ok()) << source.status();
  ASSERT_TRUE(target.ok()) << target.status();
  EXPECT_EQ(source->tree.num_points, object_->source.size());
  EXPECT_EQ(source->tree.max_depth, 6);
  EXPECT_NE(source->cloud_id, target->cloud_id);
  absl::StatusOr<RegistrationResult> result =
      (*session)->Register(source->cloud_id, target->cloud_id);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_TRUE(result->valid) << result->failure_reason;
  const core::PairError error = core::ErrorOf(result->T_target_source, object_->truth);
  EXPECT_LT(error.rotation_deg, 2.0);
  EXPECT_LT(error.translation, 0.02);
  EXPECT_EQ(result->mode, "net+refine");
  EXPECT_GT(result->confidence, 0.0);
  EXPECT_GT(result->round_trip_seconds, 0.0);
  EXPECT_GE(result->timings.batch_size, 1u);
  EXPECT_GE(result->starts, 1);
  EXPECT_TRUE(result->start == "network" || result->start == "network_later_passes" ||
              result->start == "initial" || result->start == "round_axis")
      << result->start;
  // The later starts' switches reach the server: with all off, one start, the network's.
  RegisterOptions first_start_only;
  first_start_only.refine_from_initial = false;
  first_start_only.later_passes_when_unconfident = false;
  first_start_only.search_scene_start = false;
  first_start_only.round_axis_start = false;
  first_start_only.weak_direction_start = false;
  first_start_only.centroid_start = false;
  first_start_only.sensor_aligned_check = false;
  absl::StatusOr<RegistrationResult> alone =
      (*session)->Register(source->cloud_id, target->cloud_id, first_start_only);
  ASSERT_TRUE(alone.ok()) << alone.status();
  EXPECT_EQ(alone->start, "network");
  EXPECT_EQ(alone->starts, 1);
  RegisterOptions refine;
  refine.mode = "refine";
  absl::StatusOr<RegistrationResult> refined =
      (*session)->Register(source->cloud_id, target->cloud_id, refine);
  ASSERT_TRUE(refined.ok()) << refined.status();
  EXPECT_EQ(refined->start, "initial");
  // So does the refinement's switch: the source's own coarse cells take another path.
  RegisterOptions own_cells = refine;
  own_cells.rebin_coarse_depths = false;
  absl::StatusOr<RegistrationResult> on_own_cells =
      (*session)->Register(source->cloud_id, target->cloud_id, own_cells);
  ASSERT_TRUE(on_own_cells.ok()) << on_own_cells.status();
  EXPECT_NE(on_own_cells->T_target_source.matrix(), refined->T_target_source.matrix());
  // And the coarse stages' search: one cell, as the finest stage searches.
  RegisterOptions one_cell = refine;
  one_cell.coarse_wide_search = false;
  absl::StatusOr<RegistrationResult> searched_one_cell =
      (*session)->Register(source->cloud_id, target->cloud_id, one_cell);
  ASSERT_TRUE(searched_one_cell.ok()) << searched_one_cell.status();
  EXPECT_NE(searched_one_cell->T_target_source.matrix(), refined->T_target_source.matrix());
  EXPECT_TRUE((*session)->Release(source->cloud_id).ok());
  // Released: the library refuses the id before asking the server.
  EXPECT_EQ((*session)->Register(source->cloud_id, target->cloud_id).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST_F(RpsrClientTest, CloudsInOneCallInlineAndAsyncAgree) {
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession();
  ASSERT_TRUE(session.ok()) << session.status();
  absl::StatusOr<RegistrationResult> uploaded =
      (*session)->Register(object_->source.points, object_->target.points);
  ASSERT_TRUE(uploaded.ok()) << uploaded.status();
  absl::StatusOr<RegistrationResult> inline_result =
      client->RegisterInline(object_->source.points, object_->target.points);
  ASSERT_TRUE(inline_result.ok()) << inline_result.status();
  // Same trees (the server's default depth), same answer.
  EXPECT_TRUE(uploaded->T_target_source.isApprox(inline_result->T_target_source, 1e-6));
  std::vector<std::future<absl::StatusOr<RegistrationResult>>> futures;
  for (int i = 0; i < 6; ++i) {
    futures.push_back(client->RegisterInlineAsync(object_->source.points, object_->target.points));
  }
  for (auto& future : futures) {
    absl::StatusOr<RegistrationResult> result = future.get();
    ASSERT_TRUE(result.ok()) << result.status();
    // Batched or not, the same pose: the network's outputs differ by float rounding between batch
    // sizes (~1e-6), and the refinement's re-binned coarse stages can carry that into different
    // cells, so the refined poses agree within the registrar's batching tolerance, not bit for
    // bit (core/registrar/registrar.h, RegisterBatch).
    const core::PairError apart = core::ErrorOf(result->T_target_source, uploaded->T_target_source);
    EXPECT_LT(apart.rotation_deg, 0.05);
    EXPECT_LT(apart.translation, 1e-3);
  }
  absl::StatusOr<UploadedCloud> source = (*session)->UploadAsync(object_->source.points).get();
  ASSERT_TRUE(source.ok()) << source.status();
  absl::StatusOr<UploadedCloud> target = (*session)->UploadAsync(object_->target.points).get();
  ASSERT_TRUE(target.ok()) << target.status();
  absl::StatusOr<RegistrationResult> async_by_ids =
      (*session)->RegisterAsync(source->cloud_id, target->cloud_id).get();
  ASSERT_TRUE(async_by_ids.ok()) << async_by_ids.status();
  EXPECT_TRUE(async_by_ids->T_target_source.isApprox(uploaded->T_target_source, 1e-6));
}

TEST_F(RpsrClientTest, BadCloudsGetTheServersMessage) {
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession();
  ASSERT_TRUE(session.ok()) << session.status();
  std::vector<Eigen::Vector3f> bad = object_->source.points;
  bad[7].y() = std::nanf("");
  absl::StatusOr<UploadedCloud> uploaded = (*session)->Upload(bad);
  EXPECT_EQ(uploaded.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(uploaded.status().message().empty());
  EXPECT_EQ((*session)->Upload({}).status().code(), absl::StatusCode::kInvalidArgument);
  RegisterOptions options;
  options.mode = "sideways";
  absl::StatusOr<RegistrationResult> result =
      client->RegisterInline(object_->source.points, object_->target.points, options);
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(result.status().message(), HasSubstr("sideways"));
}

TEST_F(RpsrClientTest, TrackerComposesRelativePoses) {
  const SamplePair lidar = LoadSample("lidar");
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession(TreeDepth(9));
  ASSERT_TRUE(session.ok()) << session.status();
  TrackerOptions options;
  options.registration.mode = "refine";
  absl::StatusOr<std::unique_ptr<Tracker>> tracker = (*session)->StartTracker(options);
  ASSERT_TRUE(tracker.ok()) << tracker.status();
  // Frame 0 = the target scan, frame 1 = the source scan: the relative pose T_previous_current is
  // the manifest's T_target_source.
  absl::StatusOr<TrackedFrame> first = (*tracker)->AddFrame(lidar.target.points);
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_EQ(first->frame_index, 0u);
  EXPECT_FALSE(first->relative.has_value());
  EXPECT_TRUE(first->T_frame0_current.isApprox(Eigen::Isometry3d::Identity()));
  absl::StatusOr<TrackedFrame> second = (*tracker)->AddFrame(lidar.source.points);
  ASSERT_TRUE(second.ok()) << second.status();
  ASSERT_TRUE(second->relative.has_value());
  EXPECT_TRUE(second->relative->valid) << second->relative->failure_reason;
  const core::PairError error = core::ErrorOf(second->relative->T_target_source, lidar.truth);
  EXPECT_LT(error.rotation_deg, 0.5);
  EXPECT_LT(error.translation, 0.1);
  EXPECT_TRUE(second->T_frame0_current.isApprox(second->relative->T_target_source, 1e-9));
  EXPECT_TRUE((*tracker)->Finish().ok());
}

// RegisterOptions::hold_degenerate_at_initial reaches the server and held_at_initial comes back:
// a corridor along x from a guess 0.6 m along it keeps the guess's 0.6 m there.
TEST_F(RpsrClientTest, DegenerateAnswersHoldTheGuessAlongTheCorridor) {
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession();
  ASSERT_TRUE(session.ok()) << session.status();
  const core::PointCloud source = core::testing_util::Corridor(8000, 1);
  const core::PointCloud target = core::testing_util::Corridor(8000, 2);
  RegisterOptions options;
  options.mode = "refine";
  Eigen::Isometry3d guess = Eigen::Isometry3d::Identity();
  guess.translation() = Eigen::Vector3d(0.6, 0.15, 0.0);
  options.initial_T_target_source = guess;
  absl::StatusOr<RegistrationResult> held =
      (*session)->Register(source.points, target.points, options);
  ASSERT_TRUE(held.ok()) << held.status();
  EXPECT_FALSE(held->valid);
  EXPECT_TRUE(held->held_at_initial) << held->failure_reason;
  EXPECT_NEAR(held->T_target_source.translation().x(), 0.6, 1e-3);
  options.hold_degenerate_at_initial = false;
  absl::StatusOr<RegistrationResult> free =
      (*session)->Register(source.points, target.points, options);
  ASSERT_TRUE(free.ok()) << free.status();
  EXPECT_FALSE(free->held_at_initial);
}

// Mode refine's doubt reaches the caller: a held-out parking-lot pair 5 frames apart (7 m) whose
// refine answer slides to where the two sensors meet comes back valid, capped, with the reason and
// the pose the structure off the ground prefers (the motion itself); without the check, neither.
TEST_F(RpsrClientTest, DoubtedRefineAnswersCarryThePoseTheStructurePrefers) {
  absl::StatusOr<core::RegistrationPair> pair = core::CalibrationLidarPairs(5003, 5)(26);
  ASSERT_TRUE(pair.ok()) << pair.status();
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession(TreeDepth(9));
  ASSERT_TRUE(session.ok()) << session.status();
  RegisterOptions options;
  options.mode = "refine";
  absl::StatusOr<RegistrationResult> doubted =
      (*session)->Register(pair->source.points, pair->target.points, options);
  ASSERT_TRUE(doubted.ok()) << doubted.status();
  EXPECT_TRUE(doubted->valid);
  EXPECT_LE(doubted->confidence, 0.05);
  EXPECT_THAT(doubted->failure_reason, HasSubstr("doubted"));
  ASSERT_TRUE(doubted->structure_alternative_T_target_source.has_value());
  const core::PairError error =
      core::ErrorOf(*doubted->structure_alternative_T_target_source, pair->T_target_source);
  EXPECT_LT(error.rotation_deg, 1.0);
  EXPECT_LT(error.translation, 0.3);
  options.sensor_aligned_check = false;
  absl::StatusOr<RegistrationResult> trusted =
      (*session)->Register(pair->source.points, pair->target.points, options);
  ASSERT_TRUE(trusted.ok()) << trusted.status();
  EXPECT_GT(trusted->confidence, 0.9) << "no longer a confident slide; pick another pair";
  EXPECT_FALSE(trusted->structure_alternative_T_target_source.has_value());
  EXPECT_TRUE(trusted->failure_reason.empty()) << trusted->failure_reason;
}

// RegisterOptions::line_normals_from_planes reaches the server when given, and the rule that ran
// comes back; unset, the server chooses it: off for the shipped scan pair (an HDL-64E's: several
// rings a depth-9 cell), on for two consecutive frames of a simulated VLP-16 (most cells hold one
// ring's arc).
TEST_F(RpsrClientTest, LineRuleIsChosenUnlessGivenAndReported) {
  const SamplePair hdl64 = LoadSample("lidar");
  core::LidarSequenceOptions vlp16_drive;
  vlp16_drive.frame_count = 2;
  vlp16_drive.seed = 11;
  vlp16_drive.sensor = *core::LidarSensorPreset("vlp16");
  auto vlp16 = core::LidarSequenceSimulator::Create(vlp16_drive);
  ASSERT_TRUE(vlp16.ok()) << vlp16.status();
  const core::PointCloud vlp16_target = vlp16->SimulateFrame(0).cloud;
  const core::PointCloud vlp16_source = vlp16->SimulateFrame(1).cloud;
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession(TreeDepth(9));
  ASSERT_TRUE(session.ok()) << session.status();
  RegisterOptions options;
  options.mode = "refine";
  for (const auto& [scanner, source, target, chosen] :
       {std::tuple{"HDL-64E", &hdl64.source.points, &hdl64.target.points, false},
        std::tuple{"VLP-16", &vlp16_source.points, &vlp16_target.points, true}}) {
    for (std::optional<bool> given :
         {std::optional<bool>(), std::optional<bool>(true), std::optional<bool>(false)}) {
      options.line_normals_from_planes = given;
      absl::StatusOr<RegistrationResult> result = (*session)->Register(*source, *target, options);
      ASSERT_TRUE(result.ok()) << scanner << ": " << result.status();
      EXPECT_EQ(result->line_normals_from_planes, given.value_or(chosen))
          << scanner << ", given " << (given ? (*given ? "true" : "false") : "nothing");
    }
  }
}

// RegisterOptions::noise_polish reaches the server, and the result says how far the source's
// points scatter about the target's surface and whether the polish ran: it does for a heavily
// jittered object pair, not for the shipped clean one, and never when turned off.
// The client's start options reach the server's registrar (RegisterOptions ->
// proto -> RegistrationOptions), shown by what each changes on an unseen study pair that needs it
// (the registrar's own tests, second_start_test.cc, pin the same pairs): the weak-direction start's
// finest round (off by default) turns seed 1's blob of pair 1 back from 4 degrees; the
// centroid-aligned start (on by default) brings seed 3's gear of pair 95 back from 9 degrees.
TEST_F(RpsrClientTest, StartOptionsReachTheRegistrar) {
  core::PairOptions unseen;
  unseen.split = core::ObjectSplit::kM2Unseen;
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession();
  ASSERT_TRUE(session.ok()) << session.status();
  auto register_pair = [&](uint64_t seed, uint64_t i, const RegisterOptions& options) {
    absl::StatusOr<core::ObjectPair> pair = core::MakeObjectPair(unseen, core::DeriveSeed(seed, i));
    EXPECT_TRUE(pair.ok()) << pair.status();
    absl::StatusOr<RegistrationResult> got =
        (*session)->Register(pair->source.points, pair->target.points, options);
    EXPECT_TRUE(got.ok()) << got.status();
    return std::make_pair(*got, core::ErrorOf(got->T_target_source, pair->T_target_source));
  };
  RegisterOptions finest_round;
  finest_round.weak_direction_finest_round = true;
  const auto [blob, blob_error] = register_pair(1, 1, RegisterOptions{});
  const auto [blob_round, blob_round_error] = register_pair(1, 1, finest_round);
  EXPECT_GT(blob_error.rotation_deg, 2.0);
  EXPECT_LT(blob_round_error.rotation_deg, 1.0);
  EXPECT_EQ(blob_round.start, "weak_direction");
  EXPECT_EQ(blob_round.starts, blob.starts + 1);
  RegisterOptions no_centroid;
  no_centroid.centroid_start = false;
  const auto [gear, gear_error] = register_pair(3, 95, RegisterOptions{});
  const auto [gear_off, gear_off_error] = register_pair(3, 95, no_centroid);
  EXPECT_LT(gear_error.rotation_deg, 1.0);
  EXPECT_EQ(gear.start, "centroid");
  EXPECT_GT(gear_off_error.rotation_deg, 5.0);
  EXPECT_NE(gear_off.start, "centroid");
}

TEST_F(RpsrClientTest, NoisePolishRunsOnJitteredCloudsAndIsReported) {
  core::PairOptions jittered_options;
  jittered_options.split = core::ObjectSplit::kM2Unseen;
  jittered_options.disturbance = core::DisturbanceKind::kJitter;
  jittered_options.disturbance_level = 4;  // 0.08
  absl::StatusOr<core::ObjectPair> jittered = core::MakeObjectPair(jittered_options, 2000);
  ASSERT_TRUE(jittered.ok()) << jittered.status();
  const SamplePair clean = LoadSample("object");
  std::unique_ptr<Client> client = Connect();
  absl::StatusOr<std::unique_ptr<Session>> session = client->CreateSession();
  ASSERT_TRUE(session.ok()) << session.status();
  RegisterOptions options;
  absl::StatusOr<RegistrationResult> noisy =
      (*session)->Register(jittered->source.points, jittered->target.points, options);
  ASSERT_TRUE(noisy.ok()) << noisy.status();
  EXPECT_TRUE(noisy->noise_polished) << noisy->failure_reason;
  EXPECT_GE(noisy->surface_scatter_cells, 0.45);
  absl::StatusOr<RegistrationResult> quiet =
      (*session)->Register(clean.source.points, clean.target.points, options);
  ASSERT_TRUE(quiet.ok()) << quiet.status();
  EXPECT_FALSE(quiet->noise_polished);
  EXPECT_GE(quiet->surface_scatter_cells, 0.0);
  EXPECT_LT(quiet->surface_scatter_cells, 0.45);
  options.noise_polish = false;
  absl::StatusOr<RegistrationResult> off =
      (*session)->Register(jittered->source.points, jittered->target.points, options);
  ASSERT_TRUE(off.ok()) << off.status();
  EXPECT_FALSE(off->noise_polished);
  EXPECT_LT(off->surface_scatter_cells, 0.0);
}

TEST(RpsrClientRecoveryTest, EvictedCloudsAreUploadedAgain) {
  const SamplePair object = LoadSample("object");
  server::ServerOptions options = TestServerOptions();
  // Room for about two object trees at depth 6: uploading more evicts the oldest.
  options.cache.memory_budget_bytes = 700'000;
  absl::StatusOr<std::unique_ptr<server::RunningServer>> running = server::StartServer(options);
  ASSERT_TRUE(running.ok()) << running.status();
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(At((*running)->target()));
  ASSERT_TRUE(client.ok());
  for (bool keep_points : {true, false}) {
    SCOPED_TRACE(keep_points ? "points kept" : "points not kept");
    absl::StatusOr<std::unique_ptr<Session>> session =
        (*client)->CreateSession(TreeDepth(6, keep_points));
    ASSERT_TRUE(session.ok()) << session.status();
    absl::StatusOr<UploadedCloud> source = (*session)->Upload(object.source.points);
    absl::StatusOr<UploadedCloud> target = (*session)->Upload(object.target.points);
    ASSERT_TRUE(source.ok() && target.ok());
    ASSERT_LT(2 * source->tree.memory_bytes, options.cache.memory_budget_bytes);
    for (int i = 0; i < 3; ++i) ASSERT_TRUE((*session)->Upload(object.target.points).ok());
    absl::StatusOr<RegistrationResult> result =
        (*session)->Register(source->cloud_id, target->cloud_id);
    if (keep_points) {
      ASSERT_TRUE(result.ok()) << result.status();
      EXPECT_LT(core::ErrorOf(result->T_target_source, object.truth).rotation_deg, 2.0);
    } else {
      EXPECT_EQ(result.status().code(), absl::StatusCode::kNotFound);
      EXPECT_THAT(result.status().message(), HasSubstr("evicted"));
    }
  }
}

// An expired session answers NOT_FOUND; the library opens a new one (same options), uploads the
// kept points again and registers, so the caller's cloud ids keep working.
TEST(RpsrClientRecoveryTest, ExpiredSessionsAreReCreated) {
  const SamplePair object = LoadSample("object");
  absl::StatusOr<std::unique_ptr<server::RunningServer>> running =
      server::StartServer(TestServerOptions());
  ASSERT_TRUE(running.ok()) << running.status();
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(At((*running)->target()));
  ASSERT_TRUE(client.ok());
  SessionOptions session_options = TreeDepth(6);
  session_options.ttl = absl::Milliseconds(300);
  absl::StatusOr<std::unique_ptr<Session>> session = (*client)->CreateSession(session_options);
  ASSERT_TRUE(session.ok()) << session.status();
  const std::string first_id = (*session)->id();
  absl::StatusOr<UploadedCloud> source = (*session)->Upload(object.source.points);
  absl::StatusOr<UploadedCloud> target = (*session)->Upload(object.target.points);
  ASSERT_TRUE(source.ok() && target.ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));  // idle past the time to live
  absl::StatusOr<RegistrationResult> result =
      (*session)->Register(source->cloud_id, target->cloud_id);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_LT(core::ErrorOf(result->T_target_source, object.truth).rotation_deg, 2.0);
  EXPECT_NE((*session)->id(), first_id);
  // A new upload lands in the new session and registers against the re-uploaded target.
  absl::StatusOr<UploadedCloud> again = (*session)->Upload(object.source.points);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE((*session)->Register(again->cloud_id, target->cloud_id).ok());
}

TEST(RpsrClientRecoveryTest, RetriesWhileTheServerIsAway) {
  const int port = FreePort();
  ClientOptions client_options;
  client_options.address = absl::StrCat("127.0.0.1:", port);
  client_options.retry = {.max_attempts = 12,
                          .initial_backoff = absl::Milliseconds(100),
                          .max_backoff = absl::Milliseconds(800),
                          .multiplier = 2.0};
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(client_options);
  ASSERT_TRUE(client.ok());
  // Without retries, nobody listening is UNAVAILABLE at once.
  ClientOptions no_retry = client_options;
  no_retry.retry.max_attempts = 1;
  absl::StatusOr<std::unique_ptr<Client>> impatient = Client::Connect(no_retry);
  ASSERT_TRUE(impatient.ok());
  EXPECT_EQ((*impatient)->GetServerInfo().status().code(), absl::StatusCode::kUnavailable);

  std::unique_ptr<server::RunningServer> late_server;
  std::thread starter([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    server::ServerOptions options = TestServerOptions();
    options.address = client_options.address;
    absl::StatusOr<std::unique_ptr<server::RunningServer>> running = server::StartServer(options);
    ASSERT_TRUE(running.ok()) << running.status();
    late_server = *std::move(running);
  });
  absl::StatusOr<ServerInfo> info = (*client)->GetServerInfo();
  starter.join();
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->model_name, "objects");
}

TEST(RpsrClientRecoveryTest, BearerTokenIsSentAndChecked) {
  server::ServerOptions options = TestServerOptions();
  options.auth_tokens = {"s3cret"};
  absl::StatusOr<std::unique_ptr<server::RunningServer>> running = server::StartServer(options);
  ASSERT_TRUE(running.ok()) << running.status();
  absl::StatusOr<std::unique_ptr<Client>> anonymous = Client::Connect(At((*running)->target()));
  ASSERT_TRUE(anonymous.ok());
  EXPECT_EQ((*anonymous)->CreateSession().status().code(), absl::StatusCode::kUnauthenticated);
  absl::StatusOr<std::unique_ptr<Client>> wrong =
      Client::Connect(At((*running)->target(), "guess"));
  ASSERT_TRUE(wrong.ok());
  EXPECT_EQ((*wrong)->CreateSession().status().code(), absl::StatusCode::kUnauthenticated);
  absl::StatusOr<std::unique_ptr<Client>> trusted =
      Client::Connect(At((*running)->target(), "s3cret"));
  ASSERT_TRUE(trusted.ok());
  absl::StatusOr<std::unique_ptr<Session>> session = (*trusted)->CreateSession();
  EXPECT_TRUE(session.ok()) << session.status();
}

TEST(RpsrClientRecoveryTest, ConnectsOverTlsWithTheServersRoot) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / absl::StrCat("rpsr_client_tls_", getpid());
  std::filesystem::create_directories(dir);
  const std::string cert = (dir / "cert.pem").string();
  const std::string key = (dir / "key.pem").string();
  const std::string command = absl::StrCat(
      "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=localhost "
      "-addext subjectAltName=DNS:localhost,IP:127.0.0.1 -keyout ",
      key, " -out ", cert, " >/dev/null 2>&1");
  if (std::system(command.c_str()) != 0) GTEST_SKIP() << "openssl could not make a certificate";
  server::ServerOptions options = TestServerOptions();
  options.tls_cert_file = cert;
  options.tls_key_file = key;
  absl::StatusOr<std::unique_ptr<server::RunningServer>> running = server::StartServer(options);
  ASSERT_TRUE(running.ok()) << running.status();
  std::ifstream in(cert);
  const std::string root((std::istreambuf_iterator<char>(in)), {});
  ClientOptions tls = At((*running)->target());
  tls.use_tls = true;
  tls.tls_root_certs_pem = root;
  absl::StatusOr<std::unique_ptr<Client>> secure = Client::Connect(tls);
  ASSERT_TRUE(secure.ok());
  absl::StatusOr<ServerInfo> info = (*secure)->GetServerInfo();
  EXPECT_TRUE(info.ok()) << info.status();
  // Plaintext cannot talk to it (and is not retried for ever: UNAVAILABLE after the attempts).
  ClientOptions plaintext = At((*running)->target());
  plaintext.retry.max_attempts = 1;
  absl::StatusOr<std::unique_ptr<Client>> plain = Client::Connect(plaintext);
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ((*plain)->GetServerInfo().status().code(), absl::StatusCode::kUnavailable);
  std::filesystem::remove_all(dir);
}

// The value of `name=` in a logfmt line ("" when absent; quotes stripped).
std::string LogField(absl::string_view line, absl::string_view name) {
  const std::string key = absl::StrCat(" ", name, "=");
  const size_t at = line.find(key);
  if (at == absl::string_view::npos) return "";
  absl::string_view rest = line.substr(at + key.size());
  if (!rest.empty() && rest.front() == '"') {
    rest.remove_prefix(1);
    return std::string(rest.substr(0, rest.find('"')));
  }
  return std::string(rest.substr(0, rest.find(' ')));
}

// Every call of one session carries the same x-rpsr-affinity key, so that a balancer hashing it
// (deploy/envoy/envoy.yaml) keeps the session, whose clouds live in one server's memory, on one
// server; two sessions carry different keys, so sessions spread. Read off the real server's
// request log, which names each call's key.
TEST(RpsrClientAffinityTest, EveryCallOfASessionCarriesOneKeyAndSessionsDiffer) {
  server::ServerOptions options = TestServerOptions();
  options.log_requests = true;
  absl::StatusOr<std::unique_ptr<server::RunningServer>> running = server::StartServer(options);
  ASSERT_TRUE(running.ok()) << running.status();
  const SamplePair sample = LoadSample("object");
  ::testing::internal::CaptureStderr();
  {
    absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(At((*running)->target()));
    ASSERT_TRUE(client.ok()) << client.status();
    for (int s = 0; s < 2; ++s) {
      absl::StatusOr<std::unique_ptr<Session>> session = (*client)->CreateSession(TreeDepth(6));
      ASSERT_TRUE(session.ok()) << session.status();
      absl::StatusOr<UploadedCloud> source = (*session)->Upload(sample.source.points);
      absl::StatusOr<UploadedCloud> target = (*session)->Upload(sample.target.points);
      ASSERT_TRUE(source.ok() && target.ok());
      ASSERT_TRUE((*session)->Register(source->cloud_id, target->cloud_id).ok());
      ASSERT_TRUE((*session)->Release(source->cloud_id).ok());
    }  // each session closes as it goes out of scope
  }
  const std::string log = ::testing::internal::GetCapturedStderr();
  const std::set<std::string> session_methods = {"CreateSession", "UploadCloud", "Register",
                                                 "ReleaseCloud", "CloseSession"};
  std::map<std::string, std::multiset<std::string>> methods_by_key;
  for (absl::string_view line : absl::StrSplit(log, '\n')) {
    if (LogField(line, "event") != "call") continue;
    const std::string method = LogField(line, "method");
    if (session_methods.count(method) == 0) continue;
    const std::string key = LogField(line, "affinity");
    EXPECT_FALSE(key.empty()) << "a session call without a key: " << line;
    methods_by_key[key].insert(method);
  }
  ASSERT_EQ(methods_by_key.size(), 2u) << log;
  for (const auto& [key, methods] : methods_by_key) {
    EXPECT_EQ(methods.count("CreateSession"), 1u) << key;
    EXPECT_EQ(methods.count("UploadCloud"), 2u) << key;
    EXPECT_EQ(methods.count("Register"), 1u) << key;
    EXPECT_EQ(methods.count("ReleaseCloud"), 1u) << key;
    EXPECT_EQ(methods.count("CloseSession"), 1u) << key;
  }
}

TEST(RpsrClientOptionsTest, ConnectRejectsBadOptions) {
  EXPECT_EQ(Client::Connect(At("")).status().code(), absl::StatusCode::kInvalidArgument);
  ClientOptions options;
  options.retry.max_attempts = 0;
  EXPECT_EQ(Client::Connect(options).status().code(), absl::StatusCode::kInvalidArgument);
  options = {};
  options.tls_root_certs_pem = "-----BEGIN CERTIFICATE-----";
  EXPECT_EQ(Client::Connect(options).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(RpsrClientOptionsTest, BackoffGrowsWithFullJitterUnderTheCap) {
  const RetryOptions retry{.max_attempts = 10,
                           .initial_backoff = absl::Milliseconds(50),
                           .max_backoff = absl::Seconds(1),
                           .multiplier = 2.0};
  EXPECT_EQ(RetryBackoff(retry, 1, 1.0), absl::Milliseconds(50));
  EXPECT_EQ(RetryBackoff(retry, 3, 1.0), absl::Milliseconds(200));
  EXPECT_EQ(RetryBackoff(retry, 3, 0.5), absl::Milliseconds(100));
  EXPECT_EQ(RetryBackoff(retry, 3, 0.0), absl::ZeroDuration());
  EXPECT_EQ(RetryBackoff(retry, 9, 1.0), absl::Seconds(1));  // 12.8 s capped
}

}  // namespace
}  // namespace rpsr::client
