#include "core/data/modelnet40_h5.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <system_error>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "core/io/file_bytes.h"

#ifdef RPSR_HAVE_HDF5
#include "hdf5.h"
#endif

namespace rpsr::core {

namespace {

namespace fs = std::filesystem;

#ifdef RPSR_HAVE_HDF5
// The serial HDF5 library is not thread-safe: every call goes through this lock.
std::mutex& Hdf5Mutex() {
  static std::mutex mutex;
  return mutex;
}

// Closes an HDF5 handle when it goes out of scope.
class Hdf5Handle {
 public:
  Hdf5Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Hdf5Handle() {
    if (id_ >= 0) close_(id_);
  }
  Hdf5Handle(const Hdf5Handle&) = delete;
  Hdf5Handle& operator=(const Hdf5Handle&) = delete;
  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

// Dimensions of dataset `dataset`.
std::vector<hsize_t> DimensionsOf(hid_t dataset) {
  Hdf5Handle space(H5Dget_space(dataset), H5Sclose);
  if (!space.valid()) return {};
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 0) return {};
  std::vector<hsize_t> dims(rank);
  H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr);
  return dims;
}

std::string DimensionsText(const std::vector<hsize_t>& dims) {
  std::string text = "[";
  for (size_t i = 0; i < dims.size(); ++i) absl::StrAppend(&text, i ? ", " : "", dims[i]);
  return text + "]";
}
#endif

}  // namespace

bool ModelNet40H5Supported() {
#ifdef RPSR_HAVE_HDF5
  return true;
#else
  return false;
#endif
}

absl::StatusOr<ModelNet40Shapes> ReadModelNet40H5File(const std::string& path) {
#ifndef RPSR_HAVE_HDF5
  return absl::UnimplementedError(
      absl::StrCat(path,
                   ": rpsr was built without HDF5, so it cannot read ModelNet40 .h5 files; "
                   "install libhdf5-dev (deploy/setup.sh does) and rebuild"));
#else
  std::error_code error;
  if (!fs::exists(path, error)) return absl::NotFoundError(absl::StrCat(path, ": no such file"));
  if (!fs::is_regular_file(path, error)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a regular file"));
  }
  std::lock_guard<std::mutex> lock(Hdf5Mutex());
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors come back as statuses, not stderr
  if (H5Fis_hdf5(path.c_str()) <= 0) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not an HDF5 file"));
  }
  Hdf5Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) return absl::InvalidArgumentError(absl::StrCat(path, ": cannot open as HDF5"));
  for (const char* name : {"data", "label"}) {
    if (H5Lexists(file.get(), name, H5P_DEFAULT) <= 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": no dataset '", name,
                       "' (expected the modelnet40_ply_hdf5_2048 "
                       "layout: data float32 [N, 2048, 3], label [N, 1])"));
    }
  }
  Hdf5Handle data(H5Dopen2(file.get(), "data", H5P_DEFAULT), H5Dclose);
  Hdf5Handle label(H5Dopen2(file.get(), "label", H5P_DEFAULT), H5Dclose);
  if (!data.valid() || !label.valid()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": cannot open 'data' or 'label'"));
  }
  const std::vector<hsize_t> data_dims = DimensionsOf(data.get());
  const std::vector<hsize_t> label_dims = DimensionsOf(label.get());
  if (data_dims.size() != 3 || data_dims[2] != 3) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": dataset 'data' has shape ",
                                                   DimensionsText(data_dims),
                                                   ", expected [N, points, 3]"));
  }
  if (!(label_dims.size() == 1 || (label_dims.size() == 2 && label_dims[1] == 1))) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": dataset 'label' has shape ",
                                                   DimensionsText(label_dims),
                                                   ", expected [N, 1] or [N]"));
  }
  if (label_dims[0] != data_dims[0]) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": 'data' holds ", data_dims[0], " shapes but 'label' ", label_dims[0]));
  }
  const size_t shapes = data_dims[0], points = data_dims[1];
  if (shapes * points > (size_t{1} << 31)) {
    return absl::ResourceExhaustedError(
        absl::StrCat(path, ": too many points (", shapes, " x ", points, ")"));
  }
  std::vector<float> coordinates(shapes * points * 3);
  std::vector<int> labels(shapes);
  if (!coordinates.empty() && H5Dread(data.get(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT,
                                      coordinates.data()) < 0) {
    return absl::DataLossError(absl::StrCat(path, ": cannot read 'data' as float32"));
  }
  if (!labels.empty() &&
      H5Dread(label.get(), H5T_NATIVE_INT, H5S_ALL, H5S_ALL, H5P_DEFAULT, labels.data()) < 0) {
    return absl::DataLossError(absl::StrCat(path, ": cannot read 'label' as integers"));
  }
  ModelNet40Shapes result;
  result.clouds.resize(shapes);
  for (size_t s = 0; s < shapes; ++s) {
    if (labels[s] < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": shape ", s, " has negative label ", labels[s]));
    }
    PointCloud& cloud = result.clouds[s];
    cloud.points.resize(points);
    for (size_t p = 0; p < points; ++p) {
      const float* xyz = coordinates.data() + (s * points + p) * 3;
      if (!std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2])) {
        return absl::InvalidArgumentError(
            absl::StrCat(path, ": shape ", s, " point ", p, " has a non-finite coordinate"));
      }
      cloud.points[p] = Eigen::Vector3f(xyz[0], xyz[1], xyz[2]);
    }
  }
  result.labels = std::move(labels);
  return result;
#endif
}

absl::StatusOr<ModelNet40Shapes> ReadModelNet40Split(const std::string& directory,
                                                     ModelNet40Split split) {
  if (!ModelNet40H5Supported()) return ReadModelNet40H5File(directory);  // Unimplemented
  const std::string prefix = split == ModelNet40Split::kTrain ? "ply_data_train" : "ply_data_test";
  std::error_code error;
  std::vector<std::string> names;
  for (const fs::directory_entry& entry : fs::directory_iterator(directory, error)) {
    const std::string name = entry.path().filename().string();
    if (absl::StartsWith(name, prefix) && absl::EndsWith(name, ".h5")) names.push_back(name);
  }
  if (error) {
    return absl::NotFoundError(absl::StrCat(directory, ": cannot list: ", error.message()));
  }
  if (names.empty()) {
    return absl::NotFoundError(absl::StrCat(directory, ": no ", prefix, "*.h5 files"));
  }
  std::sort(names.begin(), names.end(), [](const std::string& a, const std::string& b) {
    return a.size() != b.size() ? a.size() < b.size() : a < b;
  });
  ModelNet40Shapes all;
  for (const std::string& name : names) {
    absl::StatusOr<ModelNet40Shapes> part = ReadModelNet40H5File(directory + "/" + name);
    if (!part.ok()) return part.status();
    for (PointCloud& cloud : part->clouds) all.clouds.push_back(std::move(cloud));
    all.labels.insert(all.labels.end(), part->labels.begin(), part->labels.end());
  }
  return all;
}

absl::StatusOr<std::vector<std::string>> ReadModelNet40ShapeNames(const std::string& directory) {
  absl::StatusOr<std::string> text = ReadFileBytes(directory + "/shape_names.txt", size_t{1} << 20);
  if (!text.ok()) return text.status();
  std::vector<std::string> names;
  for (absl::string_view line : absl::StrSplit(*text, '\n')) {
    line = absl::StripAsciiWhitespace(line);
    if (!line.empty()) names.emplace_back(line);
  }
  return names;
}

}  // namespace rpsr::core
