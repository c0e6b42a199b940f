#include "core/data/modelnet40_h5.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "core/io/file_bytes.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

#ifdef RPSR_TEST_HAVE_HDF5
#include "hdf5.h"
#endif

namespace rpsr::core {
namespace {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;

std::string FreshDirectory(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / absl::StrCat("modelnet40_h5_test_", name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

#ifdef RPSR_TEST_HAVE_HDF5
// Writes a file in the modelnet40_ply_hdf5_2048 layout: data float32 [shapes, points, 3] with
// point p of shape s at (s, p, first_label), label uint8 [shapes, 1] = first_label + s. A
// `data_width` other than 3 or a missing label dataset make malformed files.
void WriteH5(const std::string& path, int shapes, int points, int first_label, int data_width = 3,
             bool with_label = true) {
  const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  std::vector<float> data(static_cast<size_t>(shapes) * points * data_width);
  for (int s = 0; s < shapes; ++s) {
    for (int p = 0; p < points; ++p) {
      for (int k = 0; k < data_width; ++k) {
        data[(static_cast<size_t>(s) * points + p) * data_width + k] =
            k == 0 ? s : (k == 1 ? p * 0.5f : first_label);
      }
    }
  }
  const hsize_t data_dims[3] = {static_cast<hsize_t>(shapes), static_cast<hsize_t>(points),
                                static_cast<hsize_t>(data_width)};
  const hid_t data_space = H5Screate_simple(3, data_dims, nullptr);
  const hid_t data_set =
      H5Dcreate2(file, "data", H5T_IEEE_F32LE, data_space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(H5Dwrite(data_set, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data()), 0);
  H5Dclose(data_set);
  H5Sclose(data_space);
  if (with_label) {
    std::vector<uint8_t> labels(shapes);
    for (int s = 0; s < shapes; ++s) labels[s] = static_cast<uint8_t>(first_label + s);
    const hsize_t label_dims[2] = {static_cast<hsize_t>(shapes), 1};
    const hid_t label_space = H5Screate_simple(2, label_dims, nullptr);
    const hid_t label_set =
        H5Dcreate2(file, "label", H5T_STD_U8LE, label_space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    ASSERT_GE(H5Dwrite(label_set, H5T_NATIVE_UINT8, H5S_ALL, H5S_ALL, H5P_DEFAULT, labels.data()),
              0);
    H5Dclose(label_set);
    H5Sclose(label_space);
  }
  H5Fclose(file);
}

TEST(ModelNet40H5Test, ReadsTheDcpLayout) {
  ASSERT_TRUE(ModelNet40H5Supported());
  const std::string dir = FreshDirectory("layout");
  WriteH5(dir + "/ply_data_train0.h5", 3, 16, 7);
  absl::StatusOr<ModelNet40Shapes> shapes = ReadModelNet40H5File(dir + "/ply_data_train0.h5");
  ASSERT_TRUE(shapes.ok()) << shapes.status();
  ASSERT_EQ(shapes->clouds.size(), 3u);
  EXPECT_EQ(shapes->labels, (std::vector<int>{7, 8, 9}));
  for (int s = 0; s < 3; ++s) {
    ASSERT_EQ(shapes->clouds[s].size(), 16u);
    EXPECT_TRUE(shapes->clouds[s].intensities.empty());
    EXPECT_EQ(shapes->clouds[s].points[5], Eigen::Vector3f(s, 2.5f, 7));
  }
}

TEST(ModelNet40H5Test, ConcatenatesSplitFilesInNumericOrder) {
  const std::string dir = FreshDirectory("split");
  WriteH5(dir + "/ply_data_train0.h5", 2, 4, 0);
  WriteH5(dir + "/ply_data_train1.h5", 1, 4, 10);
  WriteH5(dir + "/ply_data_train10.h5", 1, 4, 20);
  WriteH5(dir + "/ply_data_test0.h5", 5, 4, 30);
  ASSERT_TRUE(WriteFileBytes(dir + "/shape_names.txt", "airplane\nbathtub\n\n").ok());
  absl::StatusOr<ModelNet40Shapes> train = ReadModelNet40Split(dir, ModelNet40Split::kTrain);
  ASSERT_TRUE(train.ok()) << train.status();
  EXPECT_EQ(train->labels, (std::vector<int>{0, 1, 10, 20}));
  absl::StatusOr<ModelNet40Shapes> test = ReadModelNet40Split(dir, ModelNet40Split::kTest);
  ASSERT_TRUE(test.ok()) << test.status();
  EXPECT_EQ(test->clouds.size(), 5u);
  absl::StatusOr<std::vector<std::string>> names = ReadModelNet40ShapeNames(dir);
  ASSERT_TRUE(names.ok());
  EXPECT_EQ(*names, (std::vector<std::string>{"airplane", "bathtub"}));
}

TEST(ModelNet40H5Test, MalformedFilesGiveStatusesNamingFileAndDataset) {
  const std::string dir = FreshDirectory("malformed");
  WriteH5(dir + "/no_label.h5", 2, 4, 0, 3, /*with_label=*/false);
  absl::Status status = ReadModelNet40H5File(dir + "/no_label.h5").status();
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), AllOf(HasSubstr("no_label.h5"), HasSubstr("'label'")));
  WriteH5(dir + "/two_wide.h5", 2, 4, 0, 2);
  EXPECT_THAT(ReadModelNet40H5File(dir + "/two_wide.h5").status().message(),
              AllOf(HasSubstr("'data'"), HasSubstr("[2, 4, 2]")));
  ASSERT_TRUE(WriteFileBytes(dir + "/text.h5", "not hdf5").ok());
  EXPECT_THAT(ReadModelNet40H5File(dir + "/text.h5").status().message(),
              HasSubstr("not an HDF5 file"));
  EXPECT_EQ(ReadModelNet40H5File(dir + "/missing.h5").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(ReadModelNet40Split(dir, ModelNet40Split::kTrain).status().code(),
            absl::StatusCode::kNotFound);
}
#else
TEST(ModelNet40H5Test, ReadsTheDcpLayout) {
  GTEST_SKIP() << "HDF5 was not found at build time (install libhdf5-dev)";
}
#endif  // RPSR_TEST_HAVE_HDF5

TEST(ModelNet40H5Test, WithoutHdf5ReadersSayWhatToInstall) {
  if (ModelNet40H5Supported()) GTEST_SKIP() << "built with HDF5";
  absl::Status status = ReadModelNet40H5File("x.h5").status();
  EXPECT_EQ(status.code(), absl::StatusCode::kUnimplemented);
  EXPECT_THAT(status.message(), HasSubstr("libhdf5-dev"));
}

}  // namespace
}  // namespace rpsr::core
