#include "core/net/weights_file.h"

#include <filesystem>

#include "core/io/file_bytes.h"
#include "core/net/rpsr_net.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/net/test_clouds.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

// A small network that saves and loads in milliseconds.
RpsrNetConfig SmallConfig() {
  RpsrNetConfig config;
  config.embedding_width = 32;
  config.feedforward_width = 64;
  config.conv_widths = {8, 16, 32};
  return config;
}

TEST(WeightsFileTest, SaveLoadRoundTripGivesIdenticalEstimates) {
  RpsrNetConfig config = SmallConfig();
  config.passes = 2;
  auto net = RpsrNet::Create(config, 7);
  ASSERT_TRUE(net.ok()) << net.status();
  const std::string path = ::testing::TempDir() + "/roundtrip.rpsrw";
  ASSERT_TRUE((*net)->Save(path).ok());
  auto loaded = RpsrNet::Load(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ((*loaded)->config().embedding_width, 32);
  EXPECT_EQ((*loaded)->config().passes, 2);
  EXPECT_EQ((*loaded)->NumParameters(), (*net)->NumParameters());

  auto source = BuildOctree(testing::AsymmetricObject(1024, 1));
  auto target = BuildOctree(TransformedCloud(
      testing::AsymmetricObject(1024, 2), testing::SmallMotion(0.3, {0.1, 0.2, 0}).cast<float>()));
  ASSERT_TRUE(source.ok() && target.ok());
  const NetPair pair{&*source, &*target};
  auto a = (*net)->Estimate({&pair, 1});
  auto b = (*loaded)->Estimate({&pair, 1});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE((*a)[0].T_target_source.isApprox((*b)[0].T_target_source, 1e-12));
}

TEST(WeightsFileTest, TheCroppedCubeTravelsWithTheWeights) {
  RpsrNetConfig config = SmallConfig();
  config.cube_half_length = 1.5;
  auto net = RpsrNet::Create(config, 7);
  ASSERT_TRUE(net.ok()) << net.status();
  const std::string path = ::testing::TempDir() + "/cropped.rpsrw";
  ASSERT_TRUE((*net)->Save(path).ok());
  auto loaded = RpsrNet::Load(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ((*loaded)->config().cube_half_length, 1.5);

  // The cube changes what the network reads: with the same weights, a network binning in a 1.5
  // cube around the target's centre of mass and one binning in the target's own cube give
  // different estimates; the loaded one gives the saved one's.
  config.cube_half_length = 0.0;
  auto uncropped = RpsrNet::Create(config, 7);
  ASSERT_TRUE(uncropped.ok());
  auto source = BuildOctree(testing::AsymmetricObject(2048, 1));
  auto target = BuildOctree(TransformedCloud(
      testing::AsymmetricObject(2048, 2), testing::SmallMotion(0.2, {0.1, 0.0, 0}).cast<float>()));
  ASSERT_TRUE(source.ok() && target.ok());
  const NetPair pair{&*source, &*target};
  auto a = (*loaded)->Estimate({&pair, 1});
  auto b = (*uncropped)->Estimate({&pair, 1});
  ASSERT_TRUE(a.ok() && b.ok()) << a.status() << b.status();
  EXPECT_FALSE((*a)[0].T_target_source.isApprox((*b)[0].T_target_source, 1e-6));
  auto c = (*net)->Estimate({&pair, 1});
  ASSERT_TRUE(c.ok());
  EXPECT_TRUE((*a)[0].T_target_source.isApprox((*c)[0].T_target_source, 1e-12));
}

TEST(WeightsFileTest, CorruptFilesGiveClearErrors) {
  RpsrNetConfig config;
  config.embedding_width = 16;
  config.feedforward_width = 16;
  config.conv_widths = {4, 4, 4};
  auto net = RpsrNet::Create(config, 1);
  ASSERT_TRUE(net.ok());
  const std::string path = ::testing::TempDir() + "/corrupt.rpsrw";
  ASSERT_TRUE((*net)->Save(path).ok());
  std::string bytes = *ReadFileBytes(path);

  EXPECT_THAT(RpsrNet::LoadFromBytes("hello", "x.rpsrw").status().message(), HasSubstr("x.rpsrw"));
  EXPECT_THAT(RpsrNet::LoadFromBytes("NOTRPSRW0000", "x").status().message(),
              HasSubstr("not an rpsr weights file"));
  auto truncated =
      RpsrNet::LoadFromBytes(absl::string_view(bytes).substr(0, bytes.size() / 2), "t");
  EXPECT_EQ(truncated.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(truncated.status().message(), HasSubstr("truncated"));
  EXPECT_THAT(RpsrNet::LoadFromBytes(bytes + "junk", "j").status().message(),
              HasSubstr("unexpected bytes"));
  EXPECT_EQ(RpsrNet::Load("/nonexistent/model.rpsrw").status().code(), absl::StatusCode::kNotFound);

  // Weights of a different architecture do not load silently.
  config.embedding_width = 32;
  config.feedforward_width = 32;
  auto other = RpsrNet::Create(config, 1);
  ASSERT_TRUE(other.ok());
  const std::string other_path = ::testing::TempDir() + "/other.rpsrw";
  ASSERT_TRUE((*other)->Save(other_path).ok());
  std::string other_bytes = *ReadFileBytes(other_path);
  // Splice the small network's config into the big network's tensors.
  auto parsed = net::ParseWeights(other_bytes, "o");
  ASSERT_TRUE(parsed.ok());
  auto small = net::ParseWeights(bytes, "s");
  ASSERT_TRUE(small.ok());
  parsed->config_text = small->config_text;
  EXPECT_THAT(RpsrNet::LoadFromBytes(net::SerializeWeights(*parsed), "spliced").status().message(),
              HasSubstr("shape"));
}

}  // namespace
}  // namespace rpsr::core
