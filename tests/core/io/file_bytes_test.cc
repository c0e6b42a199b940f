#include "core/io/file_bytes.h"

#include <filesystem>
#include <string>
#include <thread>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/io/status_expectations.h"

namespace rpsr::core {
namespace {

TEST(FileBytesTest, WritesAndReadsBackBinaryBytes) {
  const std::string path = testing::TempDir() + "/bytes.dat";
  const std::string bytes("a\0b\xff\n", 5);
  ASSERT_TRUE(WriteFileBytes(path, bytes).ok());
  absl::StatusOr<std::string> read = ReadFileBytes(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, bytes);
}

TEST(FileBytesTest, OverwriteReplacesAndLeavesNoTemporary) {
  const std::filesystem::path dir = std::filesystem::path(testing::TempDir()) / "overwrite_dir";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "overwrite.dat").string();
  ASSERT_TRUE(WriteFileBytes(path, "first, longer content").ok());
  ASSERT_TRUE(WriteFileBytes(path, "second").ok());
  EXPECT_EQ(*ReadFileBytes(path), "second");
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    ++files;
    EXPECT_EQ(entry.path().filename(), "overwrite.dat");
  }
  EXPECT_EQ(files, 1) << "no temporary file is left behind";
}

TEST(FileBytesTest, ConcurrentWritersOfOnePathNeverMixContents) {
  const std::string path = testing::TempDir() + "/concurrent.dat";
  const std::string a(100000, 'a');
  const std::string b(100000, 'b');
  std::thread writer_a([&] {
    for (int i = 0; i < 20; ++i) EXPECT_TRUE(WriteFileBytes(path, a).ok());
  });
  std::thread writer_b([&] {
    for (int i = 0; i < 20; ++i) EXPECT_TRUE(WriteFileBytes(path, b).ok());
  });
  writer_a.join();
  writer_b.join();
  const std::string read = *ReadFileBytes(path);
  EXPECT_TRUE(read == a || read == b) << "a whole write wins";
}

TEST(FileBytesTest, MissingFileIsNotFoundNamingThePath) {
  ExpectError(ReadFileBytes(testing::TempDir() + "/missing.dat"), absl::StatusCode::kNotFound,
              {"missing.dat", "no such file"});
}

TEST(FileBytesTest, DirectoryIsInvalidArgument) {
  ExpectError(ReadFileBytes(testing::TempDir()), absl::StatusCode::kInvalidArgument,
              {"not a regular file"});
}

TEST(FileBytesTest, SizeLimitIsResourceExhausted) {
  const std::string path = testing::TempDir() + "/limit.dat";
  ASSERT_TRUE(WriteFileBytes(path, std::string(100, 'x')).ok());
  ExpectError(ReadFileBytes(path, 99), absl::StatusCode::kResourceExhausted,
              {"limit.dat", "100 bytes", "limit of 99"});
  EXPECT_TRUE(ReadFileBytes(path, 100).ok());
}

TEST(FileBytesTest, WriteIntoMissingFolderFailsNamingThePath) {
  const std::string path = testing::TempDir() + "/no/such/folder/out.dat";
  absl::Status status = WriteFileBytes(path, "x");
  EXPECT_FALSE(status.ok());
  EXPECT_THAT(std::string(status.message()), ::testing::HasSubstr(path));
}

}  // namespace
}  // namespace rpsr::core
