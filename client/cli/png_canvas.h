// Pictures the CLI writes (PNG through libpng): a top-down view of a registration pair before and
// after alignment, and an estimated trajectory against its ground truth. Colours carry the
// meaning (the CLI prints the legend), so no font is needed.
#ifndef RPSR_CLIENT_CLI_PNG_CANVAS_H_
#define RPSR_CLIENT_CLI_PNG_CANVAS_H_

#include <cstdint>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::client {

struct Rgb {
  uint8_t r = 0;
  uint8_t g = 0;
  uint8_t b = 0;
};

inline constexpr Rgb kWhite = {255, 255, 255};
inline constexpr Rgb kBlack = {0, 0, 0};
inline constexpr Rgb kGrey = {160, 160, 160};
inline constexpr Rgb kTargetBlue = {30, 90, 200};
inline constexpr Rgb kSourceRed = {215, 40, 40};
inline constexpr Rgb kTruthBlack = {20, 20, 20};
inline constexpr Rgb kEstimateRed = {215, 40, 40};

// An RGB raster with 8 bits a channel; (0, 0) is the top-left pixel.
class PngCanvas {
 public:
  PngCanvas(int width, int height, Rgb background = kWhite);

  int width() const { return width_; }
  int height() const { return height_; }
  Rgb Pixel(int x, int y) const;

  // Pixels outside the canvas are ignored. `opacity` in [0, 1] blends over what is there, so
  // dense regions of a cloud come out darker than sparse ones.
  void Paint(int x, int y, Rgb colour, double opacity = 1.0);
  void FillRectangle(int x0, int y0, int x1, int y1, Rgb colour);
  // A line `thickness` pixels wide (Bresenham with a square brush).
  void DrawLine(double x0, double y0, double x1, double y1, Rgb colour, int thickness = 1);

  // Writes an 8-bit RGB PNG. Errors name the path.
  absl::Status WritePng(const std::string& path) const;

 private:
  int width_;
  int height_;
  std::vector<uint8_t> rgb_;
};

// Maps a rectangle of the plane onto a pixel rectangle with equal scale on both axes (the larger
// extent fills it, the other is centred), y up.
class PlaneToPixels {
 public:
  PlaneToPixels(const Eigen::AlignedBox2d& plane_bounds, int pixel_x0, int pixel_y0,
                int pixel_width, int pixel_height);
  Eigen::Vector2d operator()(const Eigen::Vector2d& p) const;

 private:
  Eigen::Vector2d plane_center_;
  Eigen::Vector2d pixel_center_;
  double scale_ = 1.0;
};

// Two panels side by side, both seen from above (x right, y up; z dropped): on the left the
// target (blue) and the source as given (red), on the right the target and the source moved by
// T_target_source. One scale for both panels.
absl::Status WritePairPicture(const std::string& path, const core::PointCloud& source,
                              const core::PointCloud& target,
                              const Eigen::Isometry3d& T_target_source, int panel_size = 600);

// The ground truth (black, may be empty) and the estimate (red) seen from above, positions
// projected on the plane spanned by the axes `plane_axes` (e.g. {0, 1} for LiDAR poses with z up,
// {0, 2} for KITTI's camera poses with y down); start marked by a square.
absl::Status WriteTrajectoryPicture(const std::string& path,
                                    const std::vector<Eigen::Isometry3d>& T_world_frame_estimate,
                                    const std::vector<Eigen::Isometry3d>& T_world_frame_truth,
                                    std::pair<int, int> plane_axes, int size = 700);

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_CLI_PNG_CANVAS_H_
