#include "core/synth/mesh_folder.h"

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/data/object_pairs.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

namespace fs = std::filesystem;

// A scratch folder per test, removed afterwards.
class MeshFolderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    folder_ = fs::path(::testing::TempDir()) /
              ("mesh_folder_test_" +
               std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(folder_);
    fs::create_directories(folder_ / "chair" / "train");
  }
  void TearDown() override { fs::remove_all(folder_); }

  void Write(const fs::path& relative, const std::string& text) {
    std::ofstream(folder_ / relative) << text;
  }

  // A tetrahedron with one corner at (4, 6, 8): its normalised copy spans [-1, 1] along z.
  static std::string TetrahedronOff() {
    return "OFF\n4 4 0\n0 0 0\n2 0 0\n0 3 0\n4 6 8\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 2 0 3\n";
  }

  fs::path folder_;
};

TEST_F(MeshFolderTest, ListsOffAndPlySortedAndOnlyThose) {
  Write("b.off", TetrahedronOff());
  Write("a.PLY", "not read by the listing");
  Write("c.txt", "ignored");
  Write("chair/train/d.off", TetrahedronOff());
  fs::create_directories(folder_ / "folder.off");  // a directory named like a mesh is skipped

  absl::StatusOr<std::vector<std::string>> flat = ListMeshFiles(folder_.string());
  ASSERT_TRUE(flat.ok()) << flat.status();
  EXPECT_EQ(*flat,
            (std::vector<std::string>{(folder_ / "a.PLY").string(), (folder_ / "b.off").string()}));

  absl::StatusOr<std::vector<std::string>> deep = ListMeshFiles(folder_.string(), true);
  ASSERT_TRUE(deep.ok()) << deep.status();
  EXPECT_EQ(*deep,
            (std::vector<std::string>{(folder_ / "a.PLY").string(), (folder_ / "b.off").string(),
                                      (folder_ / "chair/train/d.off").string()}));
}

TEST_F(MeshFolderTest, MissingFolderIsNotFound) {
  EXPECT_EQ(ListMeshFiles((folder_ / "nope").string()).status().code(),
            absl::StatusCode::kNotFound);
}

TEST_F(MeshFolderTest, ReadsNormalisedMeshAndMakesPairs) {
  Write("tetra.off", TetrahedronOff());
  absl::StatusOr<TriangleMesh> mesh = ReadNormalizedMesh((folder_ / "tetra.off").string());
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  ASSERT_EQ(mesh->vertices.size(), 4u);
  const Eigen::AlignedBox3f bounds = BoundsOf(mesh->vertices);
  EXPECT_NEAR(bounds.min().z(), -1.0f, 1e-6f);
  EXPECT_NEAR(bounds.max().z(), 1.0f, 1e-6f);

  absl::StatusOr<ObjectPair> pair = MakeObjectPairFromMesh(*mesh, PairOptions{}, 5);
  ASSERT_TRUE(pair.ok()) << pair.status();
  EXPECT_EQ(pair->source.size(), 1024u);
  EXPECT_EQ(pair->family_index, -1);
}

TEST_F(MeshFolderTest, ReadErrorsPassThrough) {
  Write("broken.off", "OFF\n4 4 0\n0 0 0\n");
  EXPECT_FALSE(ReadNormalizedMesh((folder_ / "broken.off").string()).ok());
}

}  // namespace
}  // namespace rpsr::core
