// ModelNet40 in the HDF5 layout that DCP, PointNetLK and RPM-Net train on
// (modelnet40_ply_hdf5_2048/): files ply_data_train0.h5 ... and ply_data_test0.h5 ..., each with
//   data  float32 [N, 2048, 3]  points of N shapes, normalised into the unit sphere
//   label uint8 (or any integer type) [N, 1] or [N]  class index in [0, 40)
// and shape_names.txt listing the 40 class names in index order.
//
// Reading needs the HDF5 C library (Debian: libhdf5-dev) at build time; without it every reader
// returns Unimplemented saying so, and ModelNet40H5Supported() is false.
#ifndef RPSR_CORE_DATA_MODELNET40_H5_H_
#define RPSR_CORE_DATA_MODELNET40_H5_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

struct ModelNet40Shapes {
  // One cloud a shape (2048 points in the published files), no intensities.
  std::vector<PointCloud> clouds;
  // Class index of each shape.
  std::vector<int> labels;
};

enum class ModelNet40Split { kTrain, kTest };

// True when rpsr was built with HDF5.
bool ModelNet40H5Supported();

// Reads one .h5 file. NotFound when it does not exist; InvalidArgument naming the file and the
// dataset when `data` or `label` is missing, `data` is not [N, P, 3] or `label` not [N, 1] / [N],
// the counts differ, a coordinate is not finite or a label is negative; Unimplemented without
// HDF5.
absl::StatusOr<ModelNet40Shapes> ReadModelNet40H5File(const std::string& path);

// Reads and concatenates every ply_data_<split>*.h5 in `directory`, in name order with shorter
// names first (ply_data_train2.h5 before ply_data_train10.h5). NotFound when there is none.
absl::StatusOr<ModelNet40Shapes> ReadModelNet40Split(const std::string& directory,
                                                     ModelNet40Split split);

// Reads shape_names.txt (one class name a line, blank lines ignored).
absl::StatusOr<std::vector<std::string>> ReadModelNet40ShapeNames(const std::string& directory);

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_MODELNET40_H5_H_
