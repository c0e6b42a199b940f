// The trainer on a tiny network and a few pairs: files, resume, determinism, mismatch errors.
#include "core/net/trainer.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/data/training_pairs.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

RpsrNetConfig TinyConfig(int width = 16) {
  RpsrNetConfig config;
  config.conv_widths = {4, 8, 8};
  config.embedding_width = width;
  config.feedforward_width = 16;
  config.passes = 2;
  return config;
}

TrainerOptions TinyOptions(const std::string& dir, int epochs) {
  TrainerOptions options;
  options.epochs = epochs;
  options.pairs_per_epoch = 16;
  options.batch_size = 8;
  options.validation_pairs = 8;
  options.passes = 2;
  options.output_dir = dir;
  options.data_threads = 1;
  return options;
}

RegistrationPairGenerator Stream(uint64_t seed) {
  ObjectStreamOptions stream;
  stream.pair.num_points = 256;
  stream.stream_seed = seed;
  return MakeObjectPairStream(stream);
}

int CountLines(const std::string& path) {
  std::ifstream in(path);
  int lines = 0;
  for (std::string line; std::getline(in, line);) ++lines;
  return lines;
}

TEST(TrainerTest, WritesItsFilesResumesAndIsDeterministic) {
  const std::string dir = ::testing::TempDir() + "/trainer_test_run";
  fs::remove_all(dir);
  auto net = RpsrNet::Create(TinyConfig(), 1);
  ASSERT_TRUE(net.ok());
  auto first = TrainRpsrNet(**net, Stream(2), Stream(3), TinyOptions(dir, 1));
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_EQ(first->size(), 1u);
  EXPECT_TRUE(std::isfinite((*first)[0].validation_rotation_rmse_deg));
  for (const char* file : {"model.rpsrw", "last.rpsrw", "trainer_state.txt", "training_log.csv"}) {
    EXPECT_TRUE(fs::exists(dir + "/" + file)) << file;
  }
  EXPECT_EQ(CountLines(dir + "/training_log.csv"), 2);
  EXPECT_TRUE(RpsrNet::Load(dir + "/model.rpsrw").ok());

  // Resuming runs only the missing epoch and appends to the log.
  auto resumed_net = RpsrNet::Create(TinyConfig(), 99);
  ASSERT_TRUE(resumed_net.ok());
  auto second = TrainRpsrNet(**resumed_net, Stream(2), Stream(3), TinyOptions(dir, 2));
  ASSERT_TRUE(second.ok()) << second.status();
  ASSERT_EQ(second->size(), 1u);
  EXPECT_EQ((*second)[0].epoch, 2);
  EXPECT_EQ(CountLines(dir + "/training_log.csv"), 3);

  // A fresh run with the same seeds repeats the first epoch exactly.
  const std::string again = ::testing::TempDir() + "/trainer_test_again";
  fs::remove_all(again);
  auto same_net = RpsrNet::Create(TinyConfig(), 1);
  ASSERT_TRUE(same_net.ok());
  auto repeat = TrainRpsrNet(**same_net, Stream(2), Stream(3), TinyOptions(again, 1));
  ASSERT_TRUE(repeat.ok());
  EXPECT_EQ((*repeat)[0].train_loss, (*first)[0].train_loss);
  EXPECT_EQ((*repeat)[0].validation_rotation_rmse_deg, (*first)[0].validation_rotation_rmse_deg);
}

TEST(TrainerTest, ResumingWithOtherArchitectureSaysWhatToDo) {
  const std::string dir = ::testing::TempDir() + "/trainer_test_mismatch";
  fs::remove_all(dir);
  auto net = RpsrNet::Create(TinyConfig(16), 1);
  ASSERT_TRUE(net.ok());
  ASSERT_TRUE(TrainRpsrNet(**net, Stream(2), Stream(3), TinyOptions(dir, 1)).ok());
  auto other = RpsrNet::Create(TinyConfig(32), 1);
  ASSERT_TRUE(other.ok());
  auto result = TrainRpsrNet(**other, Stream(2), Stream(3), TinyOptions(dir, 2));
  EXPECT_EQ(result.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(result.status().message(), HasSubstr("resume with the flags"));
}

TEST(TrainerTest, ResumingWithAnotherCubeSaysWhatToDo) {
  // The cube is not in the tensors' shapes: the saved config has to be compared.
  const std::string dir = ::testing::TempDir() + "/trainer_test_cube";
  fs::remove_all(dir);
  RpsrNetConfig cropped = TinyConfig();
  cropped.cube_half_length = 1.5;
  auto net = RpsrNet::Create(cropped, 1);
  ASSERT_TRUE(net.ok());
  ASSERT_TRUE(TrainRpsrNet(**net, Stream(2), Stream(3), TinyOptions(dir, 1)).ok());
  auto uncropped = RpsrNet::Create(TinyConfig(), 1);
  ASSERT_TRUE(uncropped.ok());
  auto result = TrainRpsrNet(**uncropped, Stream(2), Stream(3), TinyOptions(dir, 2));
  EXPECT_EQ(result.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(result.status().message(), HasSubstr("cube_half_length 1.5"));
  // With the original cube it resumes.
  auto same = RpsrNet::Create(cropped, 1);
  ASSERT_TRUE(same.ok());
  EXPECT_TRUE(TrainRpsrNet(**same, Stream(2), Stream(3), TinyOptions(dir, 2)).ok());
}

TEST(TrainerTest, RejectsBadOptions) {
  auto net = RpsrNet::Create(TinyConfig(), 1);
  ASSERT_TRUE(net.ok());
  TrainerOptions options = TinyOptions("", 1);
  EXPECT_EQ(TrainRpsrNet(**net, Stream(2), Stream(3), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = TinyOptions(::testing::TempDir() + "/trainer_test_bad", 1);
  options.batch_size = 0;
  EXPECT_EQ(TrainRpsrNet(**net, Stream(2), Stream(3), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = TinyOptions(::testing::TempDir() + "/trainer_test_bad", 1);
  options.device = "tpu";
  EXPECT_EQ(TrainRpsrNet(**net, Stream(2), Stream(3), options).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace rpsr::core
