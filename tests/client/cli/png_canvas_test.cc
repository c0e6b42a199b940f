#include "client/cli/png_canvas.h"

#include <png.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"

namespace rpsr::client {
namespace {

namespace fs = std::filesystem;

struct Image {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgb;
  Rgb At(int x, int y) const {
    const size_t i = (static_cast<size_t>(y) * width + x) * 3;
    return {rgb[i], rgb[i + 1], rgb[i + 2]};
  }
};

// Reads a PNG back with libpng's own reader.
Image ReadPng(const std::string& path) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  Image out;
  if (png_image_begin_read_from_file(&image, path.c_str()) == 0) return out;
  image.format = PNG_FORMAT_RGB;
  out.width = static_cast<int>(image.width);
  out.height = static_cast<int>(image.height);
  out.rgb.resize(PNG_IMAGE_SIZE(image));
  if (png_image_finish_read(&image, nullptr, out.rgb.data(), 0, nullptr) == 0) return Image{};
  return out;
}

bool Same(Rgb a, Rgb b) { return a.r == b.r && a.g == b.g && a.b == b.b; }

class PngCanvasTest : public ::testing::Test {
 protected:
  std::string Path(const std::string& name) const {
    return (fs::temp_directory_path() / absl::StrCat("rpsr_png_", getpid(), "_", name)).string();
  }
  void TearDown() override {
    for (const char* name : {"a.png", "pair.png", "trajectory.png"}) fs::remove(Path(name));
  }
};

TEST_F(PngCanvasTest, PixelsLinesAndBlendingRoundTrip) {
  PngCanvas canvas(40, 30);
  canvas.Paint(3, 4, kSourceRed);
  canvas.Paint(-1, 100, kBlack);  // outside: ignored
  canvas.DrawLine(0, 20, 39, 20, kTargetBlue);
  canvas.Paint(10, 10, kBlack, 0.5);
  ASSERT_TRUE(canvas.WritePng(Path("a.png")).ok());
  const Image image = ReadPng(Path("a.png"));
  ASSERT_EQ(image.width, 40);
  ASSERT_EQ(image.height, 30);
  EXPECT_TRUE(Same(image.At(3, 4), kSourceRed));
  EXPECT_TRUE(Same(image.At(0, 20), kTargetBlue));
  EXPECT_TRUE(Same(image.At(39, 20), kTargetBlue));
  EXPECT_TRUE(Same(image.At(0, 0), kWhite));
  EXPECT_EQ(image.At(10, 10).r, 128);  // half-way between white and black
}

TEST_F(PngCanvasTest, PlaneMapsWithEqualScaleAndYUp) {
  const PlaneToPixels to_pixels(Eigen::AlignedBox2d(Eigen::Vector2d(0, 0), Eigen::Vector2d(2, 1)),
                                10, 10, 100, 100);
  // 2 units fill 100 pixels: 50 px a unit; the 1-unit height is centred.
  EXPECT_TRUE(to_pixels({0, 0}).isApprox(Eigen::Vector2d(10, 85)));
  EXPECT_TRUE(to_pixels({2, 1}).isApprox(Eigen::Vector2d(110, 35)));
}

TEST_F(PngCanvasTest, PairPictureShowsTheAlignmentOnTheRight) {
  core::PointCloud target;
  for (int i = 0; i < 200; ++i) target.points.emplace_back(i / 200.0f, 0.5f * (i % 2), 0);
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  T_target_source.translation() = Eigen::Vector3d(0.3, 0, 0);
  const core::PointCloud source =
      core::TransformedCloud(target, T_target_source.inverse().cast<float>());
  ASSERT_TRUE(WritePairPicture(Path("pair.png"), source, target, T_target_source, 100).ok());
  const Image image = ReadPng(Path("pair.png"));
  ASSERT_EQ(image.width, 2 * 100 + 3 * 20);
  ASSERT_EQ(image.height, 100 + 2 * 20);
  // Left: the source sits beside the target, so target pixels stay blue (no red drawn over them).
  // Right: aligned, the source (drawn last) covers every target pixel: no blue left.
  int left_blue = 0;
  int right_blue = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const Rgb pixel = image.At(x, y);
      const bool blue = pixel.b > 150 && pixel.r < 120;
      if (blue && x < 130) ++left_blue;
      if (blue && x >= 130) ++right_blue;
    }
  }
  EXPECT_GT(left_blue, 20);
  EXPECT_EQ(right_blue, 0);
}

TEST_F(PngCanvasTest, TrajectoryPictureAndErrors) {
  std::vector<Eigen::Isometry3d> truth(5, Eigen::Isometry3d::Identity());
  for (int i = 0; i < 5; ++i) truth[i].translation() = Eigen::Vector3d(i, 0, i);
  ASSERT_TRUE(WriteTrajectoryPicture(Path("trajectory.png"), truth, truth, {0, 2}, 200).ok());
  EXPECT_EQ(ReadPng(Path("trajectory.png")).width, 240);
  EXPECT_EQ(WriteTrajectoryPicture(Path("trajectory.png"), truth, truth, {0, 3}).code(),
            absl::StatusCode::kInvalidArgument);
  const absl::Status unwritable = PngCanvas(4, 4).WritePng("/nonexistent/folder/a.png");
  EXPECT_FALSE(unwritable.ok());
  EXPECT_NE(unwritable.message().find("/nonexistent/folder/a.png"), std::string::npos);
}

}  // namespace
}  // namespace rpsr::client
