#include "core/net/inference_kernels.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "Eigen/Core"
#include "Eigen/LU"
#include "Eigen/SVD"

namespace rpsr::core::net {

bool UseInferenceKernels(const torch::Tensor& t) {
  return t.device().is_cpu() && t.scalar_type() == torch::kFloat32 &&
         !(torch::GradMode::is_enabled() && t.requires_grad());
}

torch::Tensor GatherRowsOrZero(const torch::Tensor& features, const torch::Tensor& indices) {
  const torch::Tensor source = features.contiguous();
  const torch::Tensor index = indices.contiguous().to(torch::kInt64);
  const int64_t rows = source.size(0);
  const int64_t channels = source.size(1);
  const int64_t count = index.numel();
  torch::Tensor out = torch::empty({count, channels}, source.options());
  const float* in = source.data_ptr<float>();
  const int64_t* idx = index.data_ptr<int64_t>();
  float* dst = out.data_ptr<float>();
  const size_t row_bytes = static_cast<size_t>(channels) * sizeof(float);
  at::parallel_for(0, count, 2048, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const int64_t k = idx[i];
      float* row = dst + i * channels;
      if (k == rows) {
        std::memset(row, 0, row_bytes);
      } else {
        TORCH_CHECK(k >= 0 && k < rows, "gather index ", k, " outside [0, ", rows, "]");
        std::memcpy(row, in + k * channels, row_bytes);
      }
    }
  });
  return out;
}

torch::Tensor MaxOverSlots(const torch::Tensor& features, const torch::Tensor& slots) {
  const torch::Tensor source = features.contiguous();
  const torch::Tensor index = slots.contiguous().to(torch::kInt64);
  TORCH_CHECK(index.dim() == 2 && index.size(1) == 8, "slots must be [P, 8]");
  const int64_t rows = source.size(0);
  const int64_t channels = source.size(1);
  const int64_t parents = index.size(0);
  torch::Tensor out = torch::empty({parents, channels}, source.options());
  const float* in = source.data_ptr<float>();
  const int64_t* idx = index.data_ptr<int64_t>();
  float* dst = out.data_ptr<float>();
  at::parallel_for(0, parents, 256, [&](int64_t begin, int64_t end) {
    for (int64_t p = begin; p < end; ++p) {
      float* o = dst + p * channels;
      for (int s = 0; s < 8; ++s) {
        const int64_t k = idx[p * 8 + s];
        TORCH_CHECK(k >= 0 && k <= rows, "slot index ", k, " outside [0, ", rows, "]");
        if (s == 0) {
          if (k == rows) {
            std::fill(o, o + channels, 0.0f);
          } else {
            std::copy(in + k * channels, in + (k + 1) * channels, o);
          }
          continue;
        }
        // Selects rather than branches, so that the compiler vectorises the channel loops (as
        // branches they were a tenth of an object pair's network time).
        if (k == rows) {
          for (int64_t c = 0; c < channels; ++c) {
            const float current = o[c];
            o[c] = current < 0.0f ? 0.0f : current;  // an empty child is a zero row; NaN stays
          }
        } else {
          const float* r = in + k * channels;
          // NaN wins, as in torch::max (v != v: NaN).
          for (int64_t c = 0; c < channels; ++c) {
            const float v = r[c];
            const float current = o[c];
            o[c] = (v > current || v != v) ? v : current;
          }
        }
      }
    }
  });
  return out;
}

torch::Tensor KabschRotation(const torch::Tensor& H) {
  const torch::Tensor h = H.to(torch::kFloat64).contiguous();
  const int64_t batch = h.size(0);
  torch::Tensor out = torch::empty({batch, 3, 3}, h.options());
  using RowMajor3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  for (int64_t b = 0; b < batch; ++b) {
    const Eigen::Map<const RowMajor3d> m(h.data_ptr<double>() + 9 * b);
    Eigen::Map<RowMajor3d> R(out.data_ptr<double>() + 9 * b);
    if (!m.allFinite()) {
      R.setConstant(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(Eigen::Matrix3d(m),
                                                Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Matrix3d& U = svd.matrixU();
    Eigen::Matrix3d V = svd.matrixV();
    const double det = (V * U.transpose()).determinant();
    // Same rule as the differentiable path: flip the last column of V where det < 0.
    if (det < 0) V.col(2) = -V.col(2);
    R = V * U.transpose();
  }
  return out;
}

}  // namespace rpsr::core::net
