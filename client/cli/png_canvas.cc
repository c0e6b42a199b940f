#include "client/cli/png_canvas.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"

namespace rpsr::client {
namespace {

uint8_t Blend(uint8_t under, uint8_t over, double opacity) {
  return static_cast<uint8_t>(std::lround(under + (over - under) * opacity));
}

// The [low, high] quantiles of one coordinate: far, sparse returns of a LiDAR scan would
// otherwise shrink the part that matters to a few pixels.
std::pair<double, double> QuantileRange(std::vector<double> values, double low, double high) {
  if (values.empty()) return {-1.0, 1.0};
  auto at = [&values](double q) {
    const size_t k = static_cast<size_t>(q * static_cast<double>(values.size() - 1));
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
    return values[k];
  };
  return {at(low), at(high)};
}

// Per-point opacity so that a thousand points and a hundred thousand both read.
double PointOpacity(size_t count) {
  return std::clamp(3000.0 / static_cast<double>(std::max<size_t>(count, 1)), 0.2, 0.85);
}

// Points outside the panel [x0, x0 + size) x [y0, y0 + size) are not drawn.
void DrawCloud(PngCanvas& canvas, const PlaneToPixels& to_pixels, int x0, int y0, int size,
               const core::PointCloud& cloud, const Eigen::Isometry3f& T, Rgb colour) {
  const double opacity = PointOpacity(cloud.size());
  for (const Eigen::Vector3f& point : cloud.points) {
    const Eigen::Vector3f moved = T * point;
    const Eigen::Vector2d pixel = to_pixels(Eigen::Vector2d(moved.x(), moved.y()));
    const int x = static_cast<int>(std::lround(pixel.x()));
    const int y = static_cast<int>(std::lround(pixel.y()));
    if (x < x0 || y < y0 || x >= x0 + size - 1 || y >= y0 + size - 1) continue;
    // Small clouds get 2x2 dots so that an object of 1,000 points is visible.
    canvas.Paint(x, y, colour, opacity);
    if (cloud.size() < 20000) {
      canvas.Paint(x + 1, y, colour, opacity);
      canvas.Paint(x, y + 1, colour, opacity);
      canvas.Paint(x + 1, y + 1, colour, opacity);
    }
  }
}

}  // namespace

PngCanvas::PngCanvas(int width, int height, Rgb background)
    : width_(std::max(width, 1)),
      height_(std::max(height, 1)),
      rgb_(static_cast<size_t>(width_) * height_ * 3) {
  for (size_t i = 0; i < rgb_.size(); i += 3) {
    rgb_[i] = background.r;
    rgb_[i + 1] = background.g;
    rgb_[i + 2] = background.b;
  }
}

Rgb PngCanvas::Pixel(int x, int y) const {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return {};
  const size_t i = (static_cast<size_t>(y) * width_ + x) * 3;
  return {rgb_[i], rgb_[i + 1], rgb_[i + 2]};
}

void PngCanvas::Paint(int x, int y, Rgb colour, double opacity) {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return;
  const size_t i = (static_cast<size_t>(y) * width_ + x) * 3;
  opacity = std::clamp(opacity, 0.0, 1.0);
  rgb_[i] = Blend(rgb_[i], colour.r, opacity);
  rgb_[i + 1] = Blend(rgb_[i + 1], colour.g, opacity);
  rgb_[i + 2] = Blend(rgb_[i + 2], colour.b, opacity);
}

void PngCanvas::FillRectangle(int x0, int y0, int x1, int y1, Rgb colour) {
  for (int y = std::min(y0, y1); y <= std::max(y0, y1); ++y) {
    for (int x = std::min(x0, x1); x <= std::max(x0, x1); ++x) Paint(x, y, colour);
  }
}

void PngCanvas::DrawLine(double x0, double y0, double x1, double y1, Rgb colour, int thickness) {
  if (!std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(x1) || !std::isfinite(y1)) return;
  // Clamp far-off coordinates: a diverged trajectory must not make the loop run for ever.
  const double limit = 4.0 * std::max(width_, height_);
  x0 = std::clamp(x0, -limit, limit);
  x1 = std::clamp(x1, -limit, limit);
  y0 = std::clamp(y0, -limit, limit);
  y1 = std::clamp(y1, -limit, limit);
  const int steps = static_cast<int>(std::ceil(std::max(std::abs(x1 - x0), std::abs(y1 - y0))));
  const int half = (thickness - 1) / 2;
  for (int s = 0; s <= steps; ++s) {
    const double f = steps == 0 ? 0.0 : static_cast<double>(s) / steps;
    const int x = static_cast<int>(std::lround(x0 + f * (x1 - x0)));
    const int y = static_cast<int>(std::lround(y0 + f * (y1 - y0)));
    FillRectangle(x - half, y - half, x - half + thickness - 1, y - half + thickness - 1, colour);
  }
}

absl::Status PngCanvas::WritePng(const std::string& path) const {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(width_);
  image.height = static_cast<png_uint_32>(height_);
  image.format = PNG_FORMAT_RGB;
  if (png_image_write_to_file(&image, path.c_str(), /*convert_to_8bit=*/0, rgb_.data(),
                              /*row_stride=*/width_ * 3, /*colormap=*/nullptr) == 0) {
    const std::string reason = image.message;
    png_image_free(&image);
    return absl::UnavailableError(absl::StrCat("cannot write ", path, ": ", reason));
  }
  return absl::OkStatus();
}

PlaneToPixels::PlaneToPixels(const Eigen::AlignedBox2d& plane_bounds, int pixel_x0, int pixel_y0,
                             int pixel_width, int pixel_height) {
  const Eigen::AlignedBox2d bounds =
      plane_bounds.isEmpty() ? Eigen::AlignedBox2d(Eigen::Vector2d(-1, -1), Eigen::Vector2d(1, 1))
                             : plane_bounds;
  plane_center_ = bounds.center();
  pixel_center_ = Eigen::Vector2d(pixel_x0 + 0.5 * pixel_width, pixel_y0 + 0.5 * pixel_height);
  const Eigen::Vector2d extent = bounds.sizes().cwiseMax(1e-9);
  scale_ = std::min(pixel_width / extent.x(), pixel_height / extent.y());
}

Eigen::Vector2d PlaneToPixels::operator()(const Eigen::Vector2d& p) const {
  const Eigen::Vector2d offset = (p - plane_center_) * scale_;
  return {pixel_center_.x() + offset.x(), pixel_center_.y() - offset.y()};
}

absl::Status WritePairPicture(const std::string& path, const core::PointCloud& source,
                              const core::PointCloud& target,
                              const Eigen::Isometry3d& T_target_source, int panel_size) {
  constexpr int kMargin = 20;
  // Bounds: the middle 98% of the target's points in x and y (the frame both panels show).
  std::vector<double> xs;
  std::vector<double> ys;
  for (const Eigen::Vector3f& p : target.points) {
    xs.push_back(p.x());
    ys.push_back(p.y());
  }
  const double low = target.size() > 5000 ? 0.01 : 0.0;
  const auto [x_min, x_max] = QuantileRange(std::move(xs), low, 1.0 - low);
  const auto [y_min, y_max] = QuantileRange(std::move(ys), low, 1.0 - low);
  Eigen::AlignedBox2d bounds(Eigen::Vector2d(x_min, y_min), Eigen::Vector2d(x_max, y_max));
  // Room for the source as given, which may stick out (objects are small: use all of both).
  if (target.size() <= 5000) {
    for (const Eigen::Vector3f& p : source.points) bounds.extend(Eigen::Vector2d(p.x(), p.y()));
    const Eigen::Vector2d pad = Eigen::Vector2d::Constant(0.03 * bounds.sizes().maxCoeff());
    bounds.extend(bounds.min() - pad);
    bounds.extend(bounds.max() + pad);
  }
  PngCanvas canvas(2 * panel_size + 3 * kMargin, panel_size + 2 * kMargin);
  const PlaneToPixels left(bounds, kMargin, kMargin, panel_size, panel_size);
  const PlaneToPixels right(bounds, 2 * kMargin + panel_size, kMargin, panel_size, panel_size);
  // A grey frame around each panel.
  for (int panel = 0; panel < 2; ++panel) {
    const int x0 = kMargin + panel * (panel_size + kMargin) - 1;
    const int x1 = x0 + panel_size + 1;
    canvas.DrawLine(x0, kMargin - 1, x1, kMargin - 1, kGrey);
    canvas.DrawLine(x0, kMargin + panel_size, x1, kMargin + panel_size, kGrey);
    canvas.DrawLine(x0, kMargin - 1, x0, kMargin + panel_size, kGrey);
    canvas.DrawLine(x1, kMargin - 1, x1, kMargin + panel_size, kGrey);
  }
  const int right_x0 = 2 * kMargin + panel_size;
  DrawCloud(canvas, left, kMargin, kMargin, panel_size, target, Eigen::Isometry3f::Identity(),
            kTargetBlue);
  DrawCloud(canvas, left, kMargin, kMargin, panel_size, source, Eigen::Isometry3f::Identity(),
            kSourceRed);
  DrawCloud(canvas, right, right_x0, kMargin, panel_size, target, Eigen::Isometry3f::Identity(),
            kTargetBlue);
  DrawCloud(canvas, right, right_x0, kMargin, panel_size, source, T_target_source.cast<float>(),
            kSourceRed);
  return canvas.WritePng(path);
}

absl::Status WriteTrajectoryPicture(const std::string& path,
                                    const std::vector<Eigen::Isometry3d>& T_world_frame_estimate,
                                    const std::vector<Eigen::Isometry3d>& T_world_frame_truth,
                                    std::pair<int, int> plane_axes, int size) {
  if (plane_axes.first < 0 || plane_axes.first > 2 || plane_axes.second < 0 ||
      plane_axes.second > 2) {
    return absl::InvalidArgumentError("plane axes must be 0, 1 or 2");
  }
  auto project = [&plane_axes](const Eigen::Isometry3d& T) {
    return Eigen::Vector2d(T.translation()[plane_axes.first], T.translation()[plane_axes.second]);
  };
  Eigen::AlignedBox2d bounds;
  for (const auto& T : T_world_frame_truth) bounds.extend(project(T));
  for (const auto& T : T_world_frame_estimate) {
    if (T.matrix().allFinite()) bounds.extend(project(T));
  }
  // A little room around the paths, and never a degenerate box (a straight drive).
  const double pad = 0.05 * bounds.sizes().maxCoeff() + 1e-3;
  bounds.min() -= Eigen::Vector2d::Constant(pad);
  bounds.max() += Eigen::Vector2d::Constant(pad);
  constexpr int kMargin = 20;
  PngCanvas canvas(size + 2 * kMargin, size + 2 * kMargin);
  const PlaneToPixels to_pixels(bounds, kMargin, kMargin, size, size);
  // The truth is drawn wider, so that it shows on both sides of an estimate that follows it.
  auto draw_path = [&](const std::vector<Eigen::Isometry3d>& poses, Rgb colour, int thickness) {
    for (size_t i = 1; i < poses.size(); ++i) {
      const Eigen::Vector2d a = to_pixels(project(poses[i - 1]));
      const Eigen::Vector2d b = to_pixels(project(poses[i]));
      canvas.DrawLine(a.x(), a.y(), b.x(), b.y(), colour, thickness);
    }
    if (!poses.empty()) {
      const Eigen::Vector2d start = to_pixels(project(poses.front()));
      const int x = static_cast<int>(std::lround(start.x()));
      const int y = static_cast<int>(std::lround(start.y()));
      canvas.FillRectangle(x - 4, y - 4, x + 4, y + 4, colour);
    }
  };
  draw_path(T_world_frame_truth, kTruthBlack, 6);
  draw_path(T_world_frame_estimate, kEstimateRed, 2);
  return canvas.WritePng(path);
}

}  // namespace rpsr::client
