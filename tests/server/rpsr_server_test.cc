// Integration tests of the rpsr service: the real server (StartServer) on 127.0.0.1 with a free
// port, driven through the generated stubs. One shared server (with metrics) for most cases;
// cases that need other limits (memory budget, queue, auth, TLS, a failing model, shutdown) start
// their own, without a metrics exposer (it takes a while to stop).
#include "server/rpsr_server.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <random>
#include <thread>

#include "absl/strings/str_cat.h"
#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/synth/lidar_sequence.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/cloud_assembler.h"
#include "tests/server/service_test_client.h"

namespace rpsr::server {
namespace {

using ::rpsr::server::testing::MetricValue;
using ::rpsr::server::testing::ScrapeMetrics;
using ::rpsr::server::testing::ServiceTestClient;
using ::rpsr::server::testing::TrackFrameRequests;
using ::rpsr::server::testing::TransformOf;
using ::rpsr::server::testing::UploadMessagesFor;
using ::testing::HasSubstr;

std::shared_ptr<const core::Registrar> SharedRegistrar() {
  static const std::shared_ptr<const core::Registrar> registrar = [] {
    auto created = core::Registrar::Create();
    EXPECT_TRUE(created.ok()) << created.status();
    return std::shared_ptr<const core::Registrar>(*std::move(created));
  }();
  return registrar;
}

ServerOptions TestOptions() {
  ServerOptions options;
  options.address = "127.0.0.1:0";
  options.metrics_address = "";
  options.registrar = SharedRegistrar();
  options.log_requests = false;
  options.log_lifecycle = false;
  options.max_points_per_cloud = 200'000;
  options.max_message_bytes = 1u << 20;
  options.batching.max_batch = 8;
  options.batching.max_queue_delay = absl::Milliseconds(5);
  return options;
}

// An object pair of the paper's protocol: 2,048 points, rotations up to 10 degrees a axis.
const core::ObjectPair& ObjectPair() {
  static const core::ObjectPair pair = [] {
    core::PairOptions options;
    options.num_points = 2048;
    options.max_angle_deg = 10;
    options.max_translation = 0.1;
    auto made = core::MakeObjectPair(options, 3);
    EXPECT_TRUE(made.ok()) << made.status();
    return *made;
  }();
  return pair;
}

std::unique_ptr<RunningServer> Start(const ServerOptions& options) {
  auto server = StartServer(options);
  EXPECT_TRUE(server.ok()) << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

#define EXPECT_CODE(status, code, fragment)                                   \
  do {                                                                        \
    const grpc::Status s_ = (status);                                         \
    EXPECT_EQ(s_.error_code(), grpc::StatusCode::code) << s_.error_message(); \
    EXPECT_THAT(s_.error_message(), HasSubstr(fragment));                     \
  } while (0)

class ServerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ServerOptions options = TestOptions();
    options.metrics_address = "127.0.0.1:0";
    server_ = Start(options).release();
  }
  static void TearDownTestSuite() {
    delete server_;
    server_ = nullptr;
  }
  void SetUp() override {
    ASSERT_NE(server_, nullptr);
    client_ = std::make_unique<ServiceTestClient>(server_->target());
    ASSERT_TRUE(client_->CreateSession(&session_).ok());
  }

  // A short simulated drive of small scans (32 beams, 900 azimuths) for the Track tests.
  static absl::StatusOr<core::LidarSequenceSimulator> SmallLidarDrive(int frame_count) {
    core::LidarSequenceOptions options;
    options.frame_count = frame_count;
    options.seed = 5;
    options.sensor.beam_count = 32;
    options.sensor.azimuth_steps = 900;
    return core::LidarSequenceSimulator::Create(options);
  }

  // A Track stream, its start written: a new session of depth-8 trees, mode refine, each frame
  // started from the previous motion (what odometry asks for); `options` can add to that.
  std::unique_ptr<grpc::ClientReaderWriter<v1::TrackRequest, v1::TrackResponse>> StartLidarTrack(
      grpc::ClientContext* context, v1::RegisterOptions options = {}) {
    std::string lidar_session;
    v1::SessionOptions session_options;
    session_options.set_tree_max_depth(8);
    EXPECT_TRUE(client_->CreateSession(&lidar_session, session_options).ok());
    client_->Prepare(context);
    auto stream = client_->stub().Track(context);
    v1::TrackRequest start;
    start.mutable_start()->set_session_id(lidar_session);
    options.set_mode("refine");
    *start.mutable_start()->mutable_options() = options;
    start.mutable_start()->set_constant_velocity_prior(true);
    EXPECT_TRUE(stream->Write(start));
    return stream;
  }

  uint64_t UploadOrDie(const std::vector<Eigen::Vector3f>& points) {
    v1::UploadCloudResponse response;
    const grpc::Status status = client_->Upload(session_, points, &response);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return response.cloud_id();
  }

  static RunningServer* server_;
  std::unique_ptr<ServiceTestClient> client_;
  std::string session_;
};
RunningServer* ServerTest::server_ = nullptr;

TEST_F(ServerTest, ServerInfoReportsTheModelAndLimits) {
  grpc::ClientContext context;
  client_->Prepare(&context);
  v1::ServerInfo info;
  ASSERT_TRUE(client_->stub().GetServerInfo(&context, {}, &info).ok());
  EXPECT_EQ(info.api_version(), "rpsr.v1");
  EXPECT_EQ(info.model_name(), "objects");
  EXPECT_THAT(info.model_description(), HasSubstr("RPSRNet"));
  EXPECT_THAT(info.modes(), ::testing::ElementsAre("net", "net+refine", "refine"));
  EXPECT_EQ(info.limits().max_points_per_cloud(), 200'000u);
  EXPECT_EQ(info.limits().max_message_bytes(), 1u << 20);
  EXPECT_EQ(info.limits().max_batch(), 8u);
  EXPECT_GT(info.limits().recommended_chunk_points(), 1000u);
  EXPECT_LT(info.limits().recommended_chunk_points() * kBytesPerPoint, 1u << 20);
  EXPECT_EQ(info.limits().max_open_streams(), 256u);
  EXPECT_FALSE(info.auth_required());
}

TEST_F(ServerTest, UploadAnswersTheCloudIdAndTreeStatistics) {
  v1::UploadCloudResponse response;
  // Odd chunk size so the last chunk is partial.
  ASSERT_TRUE(client_->Upload(session_, ObjectPair().target.points, &response, 700).ok());
  EXPECT_GT(response.cloud_id(), 0u);
  EXPECT_EQ(response.tree().num_points(), 2048u);
  EXPECT_EQ(response.tree().max_depth(), 6);
  ASSERT_EQ(response.tree().nodes_per_depth_size(), 7);
  EXPECT_EQ(response.tree().nodes_per_depth(0), 1u);
  EXPECT_GT(response.tree().nodes_per_depth(6), 500u);
  EXPECT_GT(response.tree().memory_bytes(), 10'000u);
  EXPECT_EQ(response.tree().cube_center_size(), 3);
  EXPECT_GT(response.tree().cube_half_length(), 0.1);
}

TEST_F(ServerTest, RegistersCachedCloudsAsTheRegistrarDoesInProcess) {
  const core::ObjectPair& pair = ObjectPair();
  const uint64_t source = UploadOrDie(pair.source.points);
  const uint64_t target = UploadOrDie(pair.target.points);
  v1::RegisterOptions options;
  options.set_mode("net+refine");
  v1::RegisterResponse response;
  ASSERT_TRUE(client_->RegisterIds(session_, source, target, options, &response).ok());
  const v1::RegistrationResult& result = response.result();
  const core::PairError error =
      core::ErrorOf(TransformOf(result.transform_target_source()), pair.T_target_source);
  std::printf(
      "service net+refine: rotation %.4f deg, translation %.5f, valid %d, confidence %.3f\n",
      error.rotation_deg, error.translation, result.valid(), result.confidence());
  EXPECT_LT(error.rotation_deg, 1.0);
  EXPECT_LT(error.translation, 0.01);
  EXPECT_TRUE(result.valid()) << result.failure_reason();
  EXPECT_EQ(result.mode(), "net+refine");
  EXPECT_EQ(result.information_size(), 36);
  EXPECT_EQ(result.degenerate_axes_size(), 6);
  EXPECT_GT(result.iterations(), 0);
  EXPECT_GT(result.timings().registrar_seconds(), 0.0);
  EXPECT_GE(result.timings().server_seconds(), result.timings().registrar_seconds());
  EXPECT_GE(result.timings().batch_size(), 1u);
  // Quaternion and matrix are the same rotation.
  const auto& q = result.transform_target_source().quaternion();
  const Eigen::Quaterniond quaternion(q.w(), q.x(), q.y(), q.z());
  EXPECT_TRUE(quaternion.toRotationMatrix().isApprox(
      TransformOf(result.transform_target_source()).linear(), 1e-9));

  // The same trees in process give the same answer: the service adds no numerical change.
  auto source_tree = BuildCloudTree(pair.source.points, 6, 1'000'000);
  auto target_tree = BuildCloudTree(pair.target.points, 6, 1'000'000);
  ASSERT_TRUE(source_tree.ok() && target_tree.ok());
  auto direct = SharedRegistrar()->Register(**source_tree, **target_tree);
  ASSERT_TRUE(direct.ok());
  const core::PairError difference =
      core::ErrorOf(TransformOf(result.transform_target_source()), direct->T_target_source);
  EXPECT_LT(difference.rotation_deg, 0.01);
  EXPECT_LT(difference.translation, 1e-4);

  // Again against the same cached target: the server now reuses its prepared target
  // (PreparedTargetCache), and the answer is the same to every bit.
  v1::RegisterResponse again;
  ASSERT_TRUE(client_->RegisterIds(session_, source, target, options, &again).ok());
  const Eigen::Isometry3d first = TransformOf(result.transform_target_source());
  EXPECT_EQ(TransformOf(again.result().transform_target_source()).matrix(), first.matrix());
  EXPECT_EQ(again.result().confidence(), result.confidence());

  // Mode refine uses the prepared target's refinement side: the same answer as in process.
  v1::RegisterOptions refine = options;
  refine.set_mode("refine");
  core::RegistrationOptions direct_refine;
  direct_refine.mode = core::RegistrationMode::kRefine;
  auto direct_refined = SharedRegistrar()->Register(**source_tree, **target_tree, direct_refine);
  ASSERT_TRUE(direct_refined.ok());
  const double hits_before =
      MetricValue(ScrapeMetrics(server_->metrics_port()), "rpsr_prepared_target_hits_total")
          .value_or(-1);
  std::vector<Eigen::Isometry3d> answers;
  for (int call = 0; call < 2; ++call) {
    v1::RegisterResponse refined;
    ASSERT_TRUE(client_->RegisterIds(session_, source, target, refine, &refined).ok());
    EXPECT_EQ(refined.result().mode(), "refine");
    answers.push_back(TransformOf(refined.result().transform_target_source()));
    const core::PairError off = core::ErrorOf(answers.back(), direct_refined->T_target_source);
    EXPECT_LT(off.rotation_deg, 1e-4) << "call " << call;
    EXPECT_LT(off.translation, 1e-6) << "call " << call;
  }
  EXPECT_EQ(answers[0].matrix(), answers[1].matrix());
  // Both refine calls found the target prepared by the net+refine calls above.
  EXPECT_EQ(MetricValue(ScrapeMetrics(server_->metrics_port()), "rpsr_prepared_target_hits_total")
                .value_or(-1),
            hits_before + 2);
}

TEST_F(ServerTest, RegistersInlineCloudsWithoutASession) {
  const core::ObjectPair& pair = ObjectPair();
  v1::RegisterRequest request;
  request.mutable_source_cloud()->set_xyz(EncodeXyz(pair.source.points));
  request.mutable_target_cloud()->set_xyz(EncodeXyz(pair.target.points));
  request.mutable_options()->set_mode("refine");
  // Start the refinement near the truth: the refinement alone has a bounded basin.
  const Eigen::Isometry3d guess = pair.T_target_source;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      request.mutable_options()->mutable_initial_guess()->add_rotation(guess.linear()(r, c));
    }
  }
  for (int a = 0; a < 3; ++a) {
    request.mutable_options()->mutable_initial_guess()->add_translation(guess.translation()[a] +
                                                                        0.02);
  }
  v1::RegisterResponse response;
  const grpc::Status status = client_->Register(request, &response);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response.result().mode(), "refine");
  EXPECT_GT(response.result().timings().tree_seconds(), 0.0);
  const core::PairError error =
      core::ErrorOf(TransformOf(response.result().transform_target_source()), pair.T_target_source);
  EXPECT_LT(error.rotation_deg, 1.0);
  EXPECT_LT(error.translation, 0.01);
}

TEST_F(ServerTest, ConcurrentRequestsAreBatchedWithTheSameResults) {
  const core::ObjectPair& pair = ObjectPair();
  const uint64_t source = UploadOrDie(pair.source.points);
  const uint64_t target = UploadOrDie(pair.target.points);
  v1::RegisterOptions options;
  options.set_mode("net");
  v1::RegisterResponse alone;
  ASSERT_TRUE(client_->RegisterIds(session_, source, target, options, &alone).ok());

  constexpr int kClients = 8;
  std::vector<v1::RegisterResponse> responses(kClients);
  std::vector<grpc::Status> statuses(kClients);
  std::vector<std::thread> threads;
  for (int i = 0; i < kClients; ++i) {
    threads.emplace_back([&, i] {
      statuses[i] = client_->RegisterIds(session_, source, target, options, &responses[i]);
    });
  }
  for (std::thread& thread : threads) thread.join();
  uint32_t largest_batch = 0;
  for (int i = 0; i < kClients; ++i) {
    ASSERT_TRUE(statuses[i].ok()) << statuses[i].error_message();
    largest_batch = std::max(largest_batch, responses[i].result().timings().batch_size());
    // To every bit: on CPU the network runs a batch's pairs one at a time.
    EXPECT_EQ(TransformOf(responses[i].result().transform_target_source()).matrix(),
              TransformOf(alone.result().transform_target_source()).matrix())
        << "client " << i;
  }
  EXPECT_GT(largest_batch, 1u) << "8 concurrent requests never shared a batch";
}

TEST_F(ServerTest, TrackFollowsSimulatedLidarFrames) {
  auto simulator = SmallLidarDrive(4);
  ASSERT_TRUE(simulator.ok()) << simulator.status();

  grpc::ClientContext context;
  auto stream = StartLidarTrack(&context);
  const auto& poses = simulator->T_world_lidar();
  for (int frame = 0; frame < simulator->frame_count(); ++frame) {
    const std::vector<Eigen::Vector3f> points = simulator->SimulateFrame(frame).cloud.points;
    for (const v1::TrackRequest& request : TrackFrameRequests(frame, points, 8192)) {
      ASSERT_TRUE(stream->Write(request));
    }
    v1::TrackResponse response;
    ASSERT_TRUE(stream->Read(&response)) << "no answer for frame " << frame;
    EXPECT_EQ(response.frame_index(), static_cast<uint64_t>(frame));
    EXPECT_EQ(response.tree().num_points(), points.size());
    const Eigen::Isometry3d truth = poses[0].inverse() * poses[frame];
    const core::PairError error = core::ErrorOf(TransformOf(response.accumulated()), truth);
    std::printf("frame %d: %zu points, accumulated error %.3f deg, %.3f m\n", frame, points.size(),
                error.rotation_deg, error.translation);
    if (frame == 0) {
      EXPECT_FALSE(response.has_relative());
      EXPECT_LT(error.translation, 1e-9);
    } else {
      ASSERT_TRUE(response.has_relative());
      EXPECT_LT(error.rotation_deg, 0.5);
      EXPECT_LT(error.translation, 0.2);
      const core::PairError relative =
          core::ErrorOf(TransformOf(response.relative().transform_target_source()),
                        poses[frame - 1].inverse() * poses[frame]);
      EXPECT_LT(relative.translation, 0.1);
    }
  }
  stream->WritesDone();
  const grpc::Status status = stream->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
}

TEST_F(ServerTest, UploadsA120kPointScanInChunks) {
  core::LidarSequenceOptions options;
  options.frame_count = 1;
  options.seed = 7;
  auto simulator = core::LidarSequenceSimulator::Create(options);
  ASSERT_TRUE(simulator.ok()) << simulator.status();
  const std::vector<Eigen::Vector3f> points = simulator->SimulateFrame(0).cloud.points;
  ASSERT_GT(points.size(), 100'000u);
  std::string lidar_session;
  v1::SessionOptions session_options;
  session_options.set_tree_max_depth(9);
  ASSERT_TRUE(client_->CreateSession(&lidar_session, session_options).ok());
  std::vector<double> walls;
  for (int i = 0; i < 5; ++i) {
    v1::UploadCloudResponse response;
    const auto start = std::chrono::steady_clock::now();
    ASSERT_TRUE(client_->Upload(lidar_session, points, &response, 65536).ok());
    walls.push_back(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    EXPECT_EQ(response.tree().num_points(), points.size());
    EXPECT_EQ(response.tree().max_depth(), 9);
    std::printf("upload of %zu points (depth 9): %.1f ms wall, %.1f ms server tree build\n",
                points.size(), 1e3 * walls.back(), 1e3 * response.tree().build_seconds());
  }
  std::sort(walls.begin(), walls.end());
  std::printf("median upload: %.1f ms\n", 1e3 * walls[2]);
}

// --- bad input: each case its exact status code and a fragment of its message -----------------

std::vector<Eigen::Vector3f> SmallCloud(size_t n = 100) {
  std::vector<Eigen::Vector3f> points;
  for (size_t i = 0; i < n; ++i) {
    points.emplace_back(std::sin(0.1f * i), std::cos(0.37f * i), 0.01f * i);
  }
  return points;
}

TEST_F(ServerTest, RefusesNonFiniteCoordinates) {
  std::vector<Eigen::Vector3f> points = SmallCloud();
  points[57].y() = std::nanf("");
  v1::UploadCloudResponse response;
  EXPECT_CODE(client_->Upload(session_, points, &response, 40), INVALID_ARGUMENT,
              "point 57 has a non-finite coordinate");
  points[57].y() = INFINITY;
  EXPECT_CODE(client_->Upload(session_, points, &response, 40), INVALID_ARGUMENT,
              "chunk 1: point 57");
}

TEST_F(ServerTest, RefusesAnEmptyCloud) {
  v1::UploadCloudResponse response;
  EXPECT_CODE(client_->Upload(session_, {}, &response), INVALID_ARGUMENT, "point_count is 0");
}

TEST_F(ServerTest, RefusesTooManyPoints) {
  auto messages = UploadMessagesFor(session_, SmallCloud(), 100);
  messages[0].set_point_count(200'001);
  v1::UploadCloudResponse response;
  EXPECT_CODE(client_->UploadMessages(messages, &response), RESOURCE_EXHAUSTED,
              "200001 points is more than the server accepts per cloud (200000)");
}

TEST_F(ServerTest, RefusesChunksOutOfOrderRepeatedOrMissing) {
  const auto messages = UploadMessagesFor(session_, SmallCloud(), 25);  // 4 chunks
  v1::UploadCloudResponse response;
  auto reordered = messages;
  std::swap(reordered[1], reordered[2]);
  EXPECT_CODE(client_->UploadMessages(reordered, &response), INVALID_ARGUMENT,
              "chunk 2 arrived where chunk 1 was expected");
  auto repeated = messages;
  repeated.insert(repeated.begin() + 2, messages[1]);
  EXPECT_CODE(client_->UploadMessages(repeated, &response), INVALID_ARGUMENT,
              "chunk 1 arrived twice");
  auto missing = messages;
  missing.pop_back();
  EXPECT_CODE(client_->UploadMessages(missing, &response), INVALID_ARGUMENT,
              "ended after 3 chunks with 75 of 100 declared points");
  auto partial = messages;
  partial[1].mutable_xyz()->pop_back();
  EXPECT_CODE(client_->UploadMessages(partial, &response), INVALID_ARGUMENT,
              "not a whole number of points");
}

TEST_F(ServerTest, RefusesUnknownForeignAndMissingIds) {
  v1::UploadCloudResponse response;
  EXPECT_CODE(client_->Upload("0123456789abcdef0123456789abcdef", SmallCloud(), &response),
              NOT_FOUND, "unknown to this server");
  EXPECT_CODE(client_->Upload("", SmallCloud(), &response), INVALID_ARGUMENT,
              "must carry the session_id");
  std::string other;
  ASSERT_TRUE(client_->CreateSession(&other).ok());
  ASSERT_TRUE(client_->Upload(other, SmallCloud(), &response).ok());
  const uint64_t foreign = response.cloud_id();
  const uint64_t mine = UploadOrDie(SmallCloud());
  v1::RegisterResponse registered;
  EXPECT_CODE(client_->RegisterIds(session_, foreign, mine, {}, &registered), PERMISSION_DENIED,
              absl::StrCat("cloud ", foreign, " belongs to another session"));
  EXPECT_CODE(client_->RegisterIds(session_, mine, 987654321, {}, &registered), NOT_FOUND,
              "cloud 987654321 was never uploaded");
  v1::RegisterRequest no_target;
  no_target.set_session_id(session_);
  no_target.set_source_cloud_id(mine);
  EXPECT_CODE(client_->Register(no_target, &registered), INVALID_ARGUMENT, "no target");
}

TEST_F(ServerTest, RefusesAnOversizedMessage) {
  // One chunk of 100k points = 1.2 MB, over this server's 1 MiB limit.
  auto messages = UploadMessagesFor(session_, SmallCloud(100'000), 100'000);
  v1::UploadCloudResponse response;
  const grpc::Status status = client_->UploadMessages(messages, &response);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << status.error_message();
  EXPECT_THAT(status.error_message(), HasSubstr("larger than max"));
  // The same cloud in chunks that fit is fine.
  EXPECT_TRUE(client_->Upload(session_, SmallCloud(100'000), &response, 30'000).ok());
}

TEST_F(ServerTest, RefusesBadRegistrationOptions) {
  const uint64_t id = UploadOrDie(ObjectPair().target.points);
  v1::RegisterResponse response;
  v1::RegisterOptions options;
  options.set_mode("icp");
  EXPECT_CODE(client_->RegisterIds(session_, id, id, options, &response), INVALID_ARGUMENT,
              "net+refine");
  options.set_mode("refine");
  for (double v : {2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0}) {
    options.mutable_initial_guess()->add_rotation(v);
  }
  EXPECT_CODE(client_->RegisterIds(session_, id, id, options, &response), INVALID_ARGUMENT,
              "is not a rotation");
  options.clear_initial_guess();
  options.set_passes(100);
  EXPECT_CODE(client_->RegisterIds(session_, id, id, options, &response), INVALID_ARGUMENT,
              "options.passes is 100");
  options.set_passes(0);
  options.set_deadline_seconds(1e-9);
  EXPECT_CODE(client_->RegisterIds(session_, id, id, options, &response), DEADLINE_EXCEEDED,
              "deadline");

  std::string ignored;
  v1::SessionOptions session_options;
  session_options.set_tree_max_depth(3);
  EXPECT_CODE(client_->CreateSession(&ignored, session_options), INVALID_ARGUMENT,
              "tree_max_depth is 3");
  session_options.set_tree_max_depth(0);
  session_options.set_model("lidar");
  EXPECT_CODE(client_->CreateSession(&ignored, session_options), FAILED_PRECONDITION,
              "runs model \"objects\"");
}

// With the constant-velocity prior, a frame starts from the last motion worth trusting: an
// invalid answer (here a frame of flat ground only, degenerate) is not the next start. In
// mode refine the answer's net_transform_target_source is the start it was given.
TEST_F(ServerTest, TrackStartsFromTheLastValidMotion) {
  auto simulator = SmallLidarDrive(3);
  ASSERT_TRUE(simulator.ok()) << simulator.status();
  std::vector<std::vector<Eigen::Vector3f>> frames;
  for (int frame = 0; frame < 2; ++frame) {
    frames.push_back(simulator->SimulateFrame(frame).cloud.points);
  }
  // A frame that sees only flat ground: degenerate (along the ground and about the vertical),
  // so invalid, and (hold_degenerate_at_initial off) left where the refinement drifted.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> ground(-30.0f, 30.0f);
  std::vector<Eigen::Vector3f> flat(20000);
  for (Eigen::Vector3f& p : flat) p = Eigen::Vector3f(ground(rng), ground(rng), -1.73f);
  frames.push_back(flat);
  frames.push_back(simulator->SimulateFrame(2).cloud.points);

  grpc::ClientContext context;
  v1::RegisterOptions drift_kept;
  drift_kept.set_hold_degenerate_at_initial(false);
  auto stream = StartLidarTrack(&context, drift_kept);
  std::vector<v1::TrackResponse> responses;
  for (size_t frame = 0; frame < frames.size(); ++frame) {
    for (const v1::TrackRequest& request : TrackFrameRequests(frame, frames[frame], 8192)) {
      ASSERT_TRUE(stream->Write(request));
    }
    ASSERT_TRUE(stream->Read(&responses.emplace_back())) << "no answer for frame " << frame;
  }
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  const v1::RegistrationResult& valid = responses[1].relative();
  const v1::RegistrationResult& flat_answer = responses[2].relative();
  ASSERT_TRUE(valid.valid()) << valid.failure_reason();
  ASSERT_FALSE(flat_answer.valid());
  const Eigen::Isometry3d flat_motion = TransformOf(flat_answer.transform_target_source());
  const Eigen::Isometry3d valid_motion = TransformOf(valid.transform_target_source());
  ASSERT_GT(core::ErrorOf(flat_motion, valid_motion).translation, 0.01)
      << "the invalid answer must differ from the valid motion for this test to tell them apart";
  // Frame 2 started from frame 1's motion; frame 3 too, not from frame 2's invalid answer.
  EXPECT_TRUE(TransformOf(flat_answer.net_transform_target_source()).isApprox(valid_motion, 1e-9));
  EXPECT_TRUE(TransformOf(responses[3].relative().net_transform_target_source())
                  .isApprox(valid_motion, 1e-9));
}

TEST_F(ServerTest, TrackRefusesAStreamWithoutStart) {
  grpc::ClientContext context;
  client_->Prepare(&context);
  auto stream = client_->stub().Track(&context);
  v1::TrackRequest request;
  request.mutable_chunk()->set_point_count(10);
  stream->Write(request);
  stream->WritesDone();
  EXPECT_CODE(stream->Finish(), INVALID_ARGUMENT, "the first message must be a TrackStart");
}

TEST_F(ServerTest, ACancelledUploadLeavesTheServerHealthy) {
  const int port = server_->metrics_port();
  const auto cancelled_before = MetricValue(ScrapeMetrics(port), "rpsr_requests_total",
                                            {{"method", "UploadCloud"}, {"code", "CANCELLED"}})
                                    .value_or(0.0);
  {
    grpc::ClientContext context;
    client_->Prepare(&context);
    v1::UploadCloudResponse response;
    auto writer = client_->stub().UploadCloud(&context, &response);
    const auto messages = UploadMessagesFor(session_, SmallCloud(1000), 100);
    ASSERT_TRUE(writer->Write(messages[0]));
    ASSERT_TRUE(writer->Write(messages[1]));
    context.TryCancel();
    EXPECT_EQ(writer->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  // The server noticed, counted it, and serves the next upload.
  double cancelled_after = cancelled_before;
  for (int i = 0; i < 50 && cancelled_after == cancelled_before; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    cancelled_after = MetricValue(ScrapeMetrics(port), "rpsr_requests_total",
                                  {{"method", "UploadCloud"}, {"code", "CANCELLED"}})
                          .value_or(0.0);
  }
  EXPECT_EQ(cancelled_after, cancelled_before + 1);
  v1::UploadCloudResponse response;
  EXPECT_TRUE(client_->Upload(session_, SmallCloud(1000), &response).ok());
}

// --- the cache: release, close, expiry ------------------------------------------------------

TEST_F(ServerTest, ReleasedClosedAndExpiredAnswerNotFoundNamingWhatIsGone) {
  const uint64_t id = UploadOrDie(ObjectPair().target.points);
  grpc::ClientContext release_context;
  client_->Prepare(&release_context);
  v1::ReleaseCloudRequest release;
  release.set_session_id(session_);
  release.set_cloud_id(id);
  v1::ReleaseCloudResponse released;
  ASSERT_TRUE(client_->stub().ReleaseCloud(&release_context, release, &released).ok());
  v1::RegisterResponse response;
  EXPECT_CODE(client_->RegisterIds(session_, id, id, {}, &response), NOT_FOUND,
              absl::StrCat("cloud ", id, " of session ", session_, " was released"));

  grpc::ClientContext close_context;
  client_->Prepare(&close_context);
  v1::CloseSessionRequest close;
  close.set_session_id(session_);
  v1::CloseSessionResponse closed;
  ASSERT_TRUE(client_->stub().CloseSession(&close_context, close, &closed).ok());
  EXPECT_CODE(client_->RegisterIds(session_, id, id, {}, &response), NOT_FOUND,
              absl::StrCat("session ", session_, " was closed"));

  std::string brief;
  v1::SessionOptions options;
  options.set_ttl_seconds(0.3);
  ASSERT_TRUE(client_->CreateSession(&brief, options).ok());
  v1::UploadCloudResponse uploaded;
  ASSERT_TRUE(client_->Upload(brief, SmallCloud(), &uploaded).ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(800));
  EXPECT_CODE(client_->RegisterIds(brief, uploaded.cloud_id(), uploaded.cloud_id(), {}, &response),
              NOT_FOUND, "expired (unused for longer than its time to live of 0.3 s)");
}

// --- operations: health, reflection, metrics ----------------------------------------------------

TEST_F(ServerTest, HealthIsServingOnceTheModelIsLoaded) {
  EXPECT_TRUE(server_->ready());
  EXPECT_EQ(client_->HealthStatus(""), 1);
  EXPECT_EQ(client_->HealthStatus("rpsr.v1.RegistrationService"), 1);
}

TEST_F(ServerTest, ReflectionListsTheService) {
  EXPECT_THAT(client_->ReflectionListServices(), HasSubstr("rpsr.v1.RegistrationService"));
}

TEST_F(ServerTest, MetricsEndpointExportsTheSeries) {
  const core::ObjectPair& pair = ObjectPair();
  const uint64_t source = UploadOrDie(pair.source.points);
  const uint64_t target = UploadOrDie(pair.target.points);
  v1::RegisterResponse response;
  ASSERT_TRUE(client_->RegisterIds(session_, source, target, {}, &response).ok());
  ASSERT_FALSE(client_->RegisterIds(session_, source, 999'999'999, {}, &response).ok());

  const std::string text = ScrapeMetrics(server_->metrics_port());
  ASSERT_FALSE(text.empty());
  EXPECT_GE(MetricValue(text, "rpsr_requests_total", {{"method", "Register"}, {"code", "OK"}})
                .value_or(0),
            1);
  EXPECT_GE(
      MetricValue(text, "rpsr_requests_total", {{"method", "Register"}, {"code", "NOT_FOUND"}})
          .value_or(0),
      1);
  EXPECT_GE(MetricValue(text, "rpsr_request_duration_seconds_count", {{"method", "UploadCloud"}})
                .value_or(0),
            2);
  EXPECT_TRUE(MetricValue(text, "rpsr_request_duration_seconds_bucket",
                          {{"method", "Register"}, {"le", "0.1"}})
                  .has_value());
  for (const char* histogram :
       {"rpsr_queue_wait_seconds_count", "rpsr_tree_build_seconds_count",
        "rpsr_network_seconds_count", "rpsr_refinement_seconds_count", "rpsr_batch_size_count"}) {
    EXPECT_GE(MetricValue(text, histogram).value_or(0), 1) << histogram;
  }
  EXPECT_GE(MetricValue(text, "rpsr_cache_hits_total").value_or(0), 2);
  EXPECT_GE(MetricValue(text, "rpsr_cache_misses_total").value_or(0), 1);
  EXPECT_TRUE(
      MetricValue(text, "rpsr_cache_evictions_total", {{"reason", "memory_budget"}}).has_value());
  EXPECT_GT(MetricValue(text, "rpsr_cache_bytes").value_or(0), 10'000);
  EXPECT_GE(MetricValue(text, "rpsr_cache_clouds").value_or(0), 2);
  EXPECT_GE(MetricValue(text, "rpsr_sessions").value_or(0), 1);
  EXPECT_EQ(MetricValue(text, "rpsr_model_loaded").value_or(0), 1);
  EXPECT_TRUE(MetricValue(text, "rpsr_queue_depth").has_value());
  // The Register above prepared its cached target (the server's first use of these clouds).
  EXPECT_GE(MetricValue(text, "rpsr_prepared_target_misses_total").value_or(0), 1);
  EXPECT_TRUE(MetricValue(text, "rpsr_prepared_target_hits_total").has_value());
  EXPECT_GE(MetricValue(text, "rpsr_prepared_targets").value_or(0), 1);
  EXPECT_GT(MetricValue(text, "rpsr_prepared_target_bytes").value_or(0), 10000);
  // The Register above: an object pair, valid, the line rule off (too few shapes to choose it).
  EXPECT_GE(
      MetricValue(text, "rpsr_registrations_total", {{"outcome", "valid"}, {"line_rule", "off"}})
          .value_or(0),
      1);
  EXPECT_TRUE(
      MetricValue(text, "rpsr_registrations_total", {{"outcome", "held"}, {"line_rule", "on"}})
          .has_value());
  EXPECT_GE(MetricValue(text, "rpsr_registration_confidence_count").value_or(0), 1);
}

// --- servers of their own ------------------------------------------------------------------

TEST(ServerLimitsTest, TheMemoryBudgetEvictsTheLeastRecentlyUsedCloud) {
  const core::ObjectPair& pair = ObjectPair();
  auto tree = BuildCloudTree(pair.target.points, 6, 1'000'000);
  ASSERT_TRUE(tree.ok());
  ServerOptions options = TestOptions();
  // Room for two object trees (the source's is about the same size), not three.
  options.cache.memory_budget_bytes = (*tree)->MemoryBytes() * 5 / 2;
  auto server = Start(options);
  ASSERT_NE(server, nullptr);
  ServiceTestClient client(server->target());
  std::string session;
  ASSERT_TRUE(client.CreateSession(&session).ok());
  v1::UploadCloudResponse a, b, c;
  ASSERT_TRUE(client.Upload(session, pair.source.points, &a).ok());
  ASSERT_TRUE(client.Upload(session, pair.target.points, &b).ok());
  v1::RegisterResponse response;
  v1::RegisterOptions refine;
  refine.set_mode("refine");
  // Using a makes b the least recently used... then using b again makes a the oldest.
  ASSERT_TRUE(client.RegisterIds(session, a.cloud_id(), a.cloud_id(), refine, &response).ok());
  ASSERT_TRUE(client.RegisterIds(session, b.cloud_id(), b.cloud_id(), refine, &response).ok());
  ASSERT_TRUE(client.Upload(session, pair.source.points, &c).ok());
  EXPECT_CODE(client.RegisterIds(session, a.cloud_id(), c.cloud_id(), refine, &response), NOT_FOUND,
              absl::StrCat("cloud ", a.cloud_id(), " of session ", session,
                           " was evicted (memory budget); upload it again"));
  EXPECT_TRUE(client.RegisterIds(session, c.cloud_id(), b.cloud_id(), refine, &response).ok());
  server->Shutdown(absl::Seconds(5));
}

TEST(ServerLimitsTest, AFullQueueAnswersResourceExhaustedAtOnce) {
  ServerOptions options = TestOptions();
  options.batching.max_batch = 1;
  options.batching.max_queue = 1;
  options.batching.workers = 1;
  auto server = Start(options);
  ASSERT_NE(server, nullptr);
  ServiceTestClient client(server->target());
  std::string session;
  ASSERT_TRUE(client.CreateSession(&session).ok());
  v1::UploadCloudResponse source, target;
  ASSERT_TRUE(client.Upload(session, ObjectPair().source.points, &source).ok());
  ASSERT_TRUE(client.Upload(session, ObjectPair().target.points, &target).ok());
  constexpr int kClients = 12;
  std::vector<grpc::Status> statuses(kClients);
  std::vector<std::thread> threads;
  v1::RegisterOptions net_refine;
  for (int i = 0; i < kClients; ++i) {
    threads.emplace_back([&, i] {
      v1::RegisterResponse response;
      statuses[i] =
          client.RegisterIds(session, source.cloud_id(), target.cloud_id(), net_refine, &response);
    });
  }
  for (std::thread& thread : threads) thread.join();
  int ok = 0;
  int exhausted = 0;
  for (const grpc::Status& status : statuses) {
    if (status.ok()) ++ok;
    if (status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED) {
      ++exhausted;
      EXPECT_THAT(status.error_message(), HasSubstr("batch queue full"));
    }
  }
  EXPECT_GE(ok, 1);
  EXPECT_GE(exhausted, 1);
  EXPECT_EQ(ok + exhausted, kClients);
  server->Shutdown(absl::Seconds(5));
}

TEST(ServerLimitsTest, ExpiredAndCancelledRequestsLeaveTheQueueUnrun) {
  ServerOptions options = TestOptions();
  options.metrics_address = "127.0.0.1:0";
  options.batching.max_batch = 1;
  options.batching.workers = 1;
  auto server = Start(options);
  ASSERT_NE(server, nullptr);
  ServiceTestClient client(server->target());
  std::string session;
  ASSERT_TRUE(client.CreateSession(&session).ok());
  v1::UploadCloudResponse source, target;
  ASSERT_TRUE(client.Upload(session, ObjectPair().source.points, &source).ok());
  ASSERT_TRUE(client.Upload(session, ObjectPair().target.points, &target).ok());
  v1::RegisterRequest request;
  request.set_session_id(session);
  request.set_source_cloud_id(source.cloud_id());
  request.set_target_cloud_id(target.cloud_id());
  request.mutable_options()->set_mode("net");

  // A keeps the only worker busy (16 network passes); B's 5 ms budget and C's cancellation run out
  // while they wait behind it; D runs after A.
  v1::RegisterRequest slow = request;
  slow.mutable_options()->set_passes(16);
  v1::RegisterRequest brief = request;
  brief.mutable_options()->set_deadline_seconds(0.005);
  grpc::Status a, b, c, d;
  std::thread first([&] {
    v1::RegisterResponse response;
    a = client.Register(slow, &response);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // A reaches the worker first
  std::thread second([&] {
    v1::RegisterResponse response;
    b = client.Register(brief, &response);
  });
  grpc::ClientContext cancelled_context;
  client.Prepare(&cancelled_context);
  std::thread third([&] {
    v1::RegisterResponse response;
    c = client.stub().Register(&cancelled_context, request, &response);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  cancelled_context.TryCancel();
  std::thread fourth([&] {
    v1::RegisterResponse response;
    d = client.Register(request, &response);
  });
  for (std::thread* t : {&first, &second, &third, &fourth}) t->join();
  EXPECT_TRUE(a.ok()) << a.error_message();
  EXPECT_CODE(b, DEADLINE_EXCEEDED, "in the batch queue");
  EXPECT_EQ(c.error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_TRUE(d.ok()) << d.error_message();
  // Only A and D ran (one batch each); B and C left the queue unrun.
  EXPECT_EQ(MetricValue(ScrapeMetrics(server->metrics_port()), "rpsr_batch_size_count"), 2.0);
  server->Shutdown(absl::Seconds(5));
}

TEST(ServerLimitsTest, OpenStreamsAreBoundedAndTheirSlotsComeBack) {
  ServerOptions options = TestOptions();
  options.max_open_streams = 1;
  auto server = Start(options);
  ASSERT_NE(server, nullptr);
  ServiceTestClient client(server->target());
  std::string session;
  ASSERT_TRUE(client.CreateSession(&session).ok());
  v1::UploadCloudResponse response;
  {
    grpc::ClientContext context;
    client.Prepare(&context);
    auto track = client.stub().Track(&context);
    v1::TrackRequest start;
    start.mutable_start()->set_session_id(session);
    ASSERT_TRUE(track->Write(start));
    // Frame 0 answered: the server has opened the Track stream, which holds the only slot.
    const std::vector<Eigen::Vector3f> frame = SmallCloud();
    v1::TrackRequest chunk;
    chunk.mutable_chunk()->set_point_count(frame.size());
    chunk.mutable_chunk()->set_xyz(EncodeXyz(frame));
    ASSERT_TRUE(track->Write(chunk));
    v1::TrackResponse answer;
    ASSERT_TRUE(track->Read(&answer));
    const grpc::Status refused = client.Upload(session, SmallCloud(), &response);
    EXPECT_CODE(refused, RESOURCE_EXHAUSTED, "upload and track streams open");
    track->WritesDone();
    EXPECT_TRUE(track->Finish().ok());
  }
  // Closed streams give their slot back.
  grpc::Status accepted;
  for (int i = 0; i < 100; ++i) {
    accepted = client.Upload(session, SmallCloud(), &response);
    if (accepted.ok()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(accepted.ok()) << accepted.error_message();
  server->Shutdown(absl::Seconds(5));
}

TEST(ServerAuthTest, BearerTokensAuthenticateAndOwnTheirSessions) {
  ServerOptions options = TestOptions();
  options.auth_tokens = {"alpha-token", "beta-token"};
  auto server = Start(options);
  ASSERT_NE(server, nullptr);
  std::string session;
  EXPECT_CODE(ServiceTestClient(server->target()).CreateSession(&session), UNAUTHENTICATED,
              "requires a bearer token");
  EXPECT_CODE(ServiceTestClient(server->target(), "gamma").CreateSession(&session), UNAUTHENTICATED,
              "not accepted");
  ServiceTestClient alpha(server->target(), "alpha-token");
  ServiceTestClient beta(server->target(), "beta-token");
  ASSERT_TRUE(alpha.CreateSession(&session).ok());
  v1::UploadCloudResponse response;
  EXPECT_TRUE(alpha.Upload(session, SmallCloud(), &response).ok());
  EXPECT_CODE(beta.Upload(session, SmallCloud(), &response), PERMISSION_DENIED,
              "belongs to another client");
  grpc::ClientContext context;
  alpha.Prepare(&context);
  v1::ServerInfo info;
  ASSERT_TRUE(alpha.stub().GetServerInfo(&context, {}, &info).ok());
  EXPECT_TRUE(info.auth_required());
  server->Shutdown(absl::Seconds(5));
}

TEST(ServerAuthTest, ServesOverTls) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / absl::StrCat("rpsr_tls_", getpid());
  std::filesystem::create_directories(dir);
  const std::string cert = (dir / "cert.pem").string();
  const std::string key = (dir / "key.pem").string();
  const std::string command = absl::StrCat(
      "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=localhost "
      "-addext subjectAltName=DNS:localhost,IP:127.0.0.1 -keyout ",
      key, " -out ", cert, " >/dev/null 2>&1");
  if (std::system(command.c_str()) != 0) GTEST_SKIP() << "openssl could not make a certificate";
  ServerOptions options = TestOptions();
  options.tls_cert_file = cert;
  options.tls_key_file = key;
  auto server = Start(options);
  ASSERT_NE(server, nullptr);
  std::ifstream in(cert);
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs.assign(std::istreambuf_iterator<char>(in), {});
  grpc::ChannelArguments arguments;
  arguments.SetSslTargetNameOverride("localhost");
  ServiceTestClient secure(server->target(), "", grpc::SslCredentials(ssl), arguments);
  std::string session;
  EXPECT_TRUE(secure.CreateSession(&session).ok());
  v1::UploadCloudResponse response;
  EXPECT_TRUE(secure.Upload(session, SmallCloud(), &response).ok());
  // A plaintext client cannot talk to it.
  ServiceTestClient plain(server->target());
  grpc::ClientContext context;
  plain.Prepare(&context, 2.0);
  v1::ServerInfo info;
  EXPECT_EQ(plain.stub().GetServerInfo(&context, {}, &info).error_code(),
            grpc::StatusCode::UNAVAILABLE);
  server->Shutdown(absl::Seconds(5));
  std::filesystem::remove_all(dir);
}

TEST(ServerLifecycleTest, NotServingUntilTheModelLoadsAndAFailedLoadSaysWhy) {
  ServerOptions options = TestOptions();
  options.registrar = nullptr;
  options.registrar_config.model_path = "/nonexistent/model.rpsrw";
  options.wait_for_model = false;
  // A server that never served has nobody to warn: it does not wait out the drain notice.
  options.drain_notice = absl::Seconds(30);
  auto server = Start(options);
  ASSERT_NE(server, nullptr);
  ServiceTestClient client(server->target());
  EXPECT_FALSE(server->WaitForModel().ok());
  EXPECT_FALSE(server->ready());
  EXPECT_EQ(client.HealthStatus(""), 2);  // NOT_SERVING
  v1::RegisterRequest request;
  v1::RegisterResponse response;
  EXPECT_CODE(client.Register(request, &response), UNAVAILABLE, "loading its model");
  const absl::Time shutdown_start = absl::Now();
  server->Shutdown(absl::Seconds(5));
  EXPECT_LT(absl::Now() - shutdown_start, absl::Seconds(15));
}

TEST(ServerLifecycleTest, ShutdownFinishesWorkInFlightAndRefusesNewCalls) {
  ServerOptions options = TestOptions();
  options.drain_notice = absl::Milliseconds(1500);
  auto server = Start(options);
  ASSERT_NE(server, nullptr);
  ServiceTestClient client(server->target());
  EXPECT_EQ(client.HealthStatus(""), 1);
  const core::ObjectPair& pair = ObjectPair();
  grpc::ClientContext context;
  client.Prepare(&context);
  auto stream = client.stub().Track(&context);
  v1::TrackRequest start;
  start.mutable_start()->mutable_options()->set_mode("net+refine");
  ASSERT_TRUE(stream->Write(start));
  auto send_frame = [&](int frame, const std::vector<Eigen::Vector3f>& points) {
    for (const v1::TrackRequest& request : TrackFrameRequests(frame, points, 1024)) {
      ASSERT_TRUE(stream->Write(request));
    }
  };
  send_frame(0, pair.target.points);
  v1::TrackResponse response;
  ASSERT_TRUE(stream->Read(&response));

  std::thread shutdown([&] { server->Shutdown(absl::Seconds(20)); });
  // Draining: new calls are refused while the open stream goes on.
  grpc::Status refused;
  for (int i = 0; i < 100; ++i) {
    std::string session;
    refused = ServiceTestClient(server->target()).CreateSession(&session);
    if (!refused.ok()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::UNAVAILABLE) << refused.error_message();
  EXPECT_THAT(refused.error_message(), HasSubstr("shutting down"));
  EXPECT_EQ(client.HealthStatus(""), 2);  // NOT_SERVING while draining
  send_frame(1, pair.source.points);
  ASSERT_TRUE(stream->Read(&response)) << "the in-flight stream was cut";
  EXPECT_EQ(response.frame_index(), 1u);
  EXPECT_TRUE(response.has_relative());
  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
  shutdown.join();
  EXPECT_FALSE(server->ready());
}

}  // namespace
}  // namespace rpsr::server
