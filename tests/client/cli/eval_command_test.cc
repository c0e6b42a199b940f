// End to end: `rpsr data pairs` writes a manifest, `rpsr eval` registers it with the shipped model
// and writes per-pair rows and summaries whose numbers agree with each other; `rpsr register` picks
// an object's tree depth whatever its units; `rpsr calibrate` refuses flags it would ignore.
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::client {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

class EvalCommandTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const testing::TestInfo* info = testing::UnitTest::GetInstance()->current_test_info();
    dir_ =
        fs::temp_directory_path() / absl::StrCat("rpsr_eval_command_", info->name(), "_", getpid());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Runs the CLI with `args`; its stdout goes to `stdout_path` (discarded when empty).
  int Run(const std::string& args, const std::string& stdout_path = "") {
    const fs::path log = dir_ / "stderr.txt";
    const std::string command =
        absl::StrCat("OMP_WAIT_POLICY=PASSIVE ", RPSR_CLI_BINARY, " ", args, " 2>", log.string(),
                     " >", stdout_path.empty() ? "/dev/null" : stdout_path);
    const int status = std::system(command.c_str());
    stderr_ = Read(log.string());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  static std::string Read(const std::string& path) {
    std::ifstream in(path);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
  std::string stderr_;
};

TEST_F(EvalCommandTest, ManifestRowsAndSummaryAgree) {
  ASSERT_EQ(Run(absl::StrCat("data pairs --protocol objects --count 6 --split unseen --seed 5 "
                             "--output ",
                             Path("pairs"))),
            0)
      << stderr_;
  ASSERT_EQ(Run(absl::StrCat("eval --manifest ", Path("pairs/manifest.csv"), " --batch_size 4 ",
                             "--output ", Path("out/eval.csv"))),
            0)
      << stderr_;
  // Per-pair rows: 16 numbers, finite errors.
  std::vector<std::string> lines =
      absl::StrSplit(Read(Path("out/eval.csv")), '\n', absl::SkipEmpty());
  ASSERT_EQ(lines.size(), 7u);
  double sum_sq = 0.0;
  for (size_t i = 1; i < lines.size(); ++i) {
    std::vector<std::string> fields = absl::StrSplit(lines[i], ',');
    ASSERT_EQ(fields.size(), 10u) << lines[i];
    EXPECT_EQ(std::vector<std::string>(absl::StrSplit(fields[3], ' ')).size(), 16u);
    double rotation = 0.0;
    ASSERT_TRUE(absl::SimpleAtod(fields[6], &rotation)) << fields[6];
    EXPECT_GE(rotation, 0.0);
    EXPECT_LE(rotation, 180.0);
    sum_sq += rotation * rotation;
  }
  // The summary's RMSE is the rows' RMSE.
  std::vector<std::string> summary =
      absl::StrSplit(Read(Path("out/eval.csv.summary.csv")), '\n', absl::SkipEmpty());
  ASSERT_EQ(summary.size(), 2u);
  std::vector<std::string> fields = absl::StrSplit(summary[1], ',');
  // Every column name is one CSV field (a name with a comma once broke the header).
  EXPECT_EQ(std::vector<std::string>(absl::StrSplit(summary[0], ',')).size(), fields.size());
  double rmse = 0.0;
  ASSERT_TRUE(absl::SimpleAtod(fields[2], &rmse));
  EXPECT_NEAR(rmse, std::sqrt(sum_sq / 6.0), 1e-3 * (1 + rmse));
  EXPECT_EQ(fields[1], "6");
  EXPECT_THAT(Read(Path("out/eval.csv.summary.json")), HasSubstr("\"rotation_rmse_deg\""));
}

TEST_F(EvalCommandTest, StudyHasTheTwentyOneSettings) {
  ASSERT_EQ(Run(absl::StrCat("eval --protocol objects --study --count 1 --num_points 256 ",
                             "--output ", Path("study.csv"))),
            0)
      << stderr_;
  std::vector<std::string> summary =
      absl::StrSplit(Read(Path("study.csv.summary.csv")), '\n', absl::SkipEmpty());
  EXPECT_EQ(summary.size(), 1u + 21u);
}

// An object given in millimetres (a bounding box diagonal of ~3,000) is still an object: the CLI
// used to read any cloud over 10 units across as a LiDAR scene, built depth-9 trees whose cells
// hold single samples, and the registration ended "no overlap".
TEST_F(EvalCommandTest, RegisterTakesAnObjectInMillimetresForAnObject) {
  ASSERT_EQ(Run(absl::StrCat("data pairs --protocol objects --count 1 --split unseen --seed 5 ",
                             "--format xyz --output ", Path("pairs"))),
            0)
      << stderr_;
  std::vector<std::string> rows =
      absl::StrSplit(Read(Path("pairs/manifest.csv")), '\n', absl::SkipEmpty());
  ASSERT_EQ(rows.size(), 2u);
  const std::vector<std::string> row = absl::StrSplit(rows[1], ',');
  ASSERT_EQ(row.size(), 3u);
  constexpr double kMillimetres = 1000.0;
  for (const int i : {0, 1}) {  // source and target, every coordinate times 1,000
    std::ifstream in(Path("pairs/" + row[i]));
    std::ofstream out(Path(absl::StrCat("mm", i, ".xyz")));
    double x = 0, y = 0, z = 0;
    while (in >> x >> y >> z)
      out << x * kMillimetres << ' ' << y * kMillimetres << ' ' << z * kMillimetres << '\n';
  }
  std::vector<std::string> truth = absl::StrSplit(row[2], ' ', absl::SkipEmpty());
  ASSERT_EQ(truth.size(), 16u);
  for (const int k : {3, 7, 11}) {  // the translation scales with the clouds
    double t = 0;
    ASSERT_TRUE(absl::SimpleAtod(truth[k], &t));
    truth[k] = absl::StrCat(t * kMillimetres);
  }
  ASSERT_EQ(Run(absl::StrCat("register --local --json --truth \"", absl::StrJoin(truth, " "), "\" ",
                             Path("mm0.xyz"), " ", Path("mm1.xyz")),
                Path("result.json")),
            0)
      << stderr_;
  const std::string json = Read(Path("result.json"));
  EXPECT_THAT(json, HasSubstr("\"tree_depth\": 6")) << json;
  EXPECT_THAT(json, HasSubstr("\"valid\": true")) << json;
  const size_t at = json.find("\"rotation_error_deg\": ");
  ASSERT_NE(at, std::string::npos) << json;
  double rotation_error = 0;
  ASSERT_TRUE(absl::SimpleAtod(json.substr(at + 22, json.find_first_of(",}", at + 22) - (at + 22)),
                               &rotation_error));
  EXPECT_LT(rotation_error, 1.0) << json;
}

TEST_F(EvalCommandTest, BadInputSaysWhatToFix) {
  EXPECT_EQ(Run("eval --count 1"), 2);
  EXPECT_THAT(stderr_, HasSubstr("--output"));
  EXPECT_EQ(Run(absl::StrCat("eval --mode icp --output ", Path("x.csv"))), 2);
  EXPECT_THAT(stderr_, HasSubstr("net, net+refine or refine"));
  EXPECT_EQ(Run(absl::StrCat("eval --model ", Path("missing.rpsrw"), " --output ", Path("x.csv"))),
            1);
  EXPECT_THAT(stderr_, HasSubstr("missing.rpsrw"));
  EXPECT_EQ(Run(absl::StrCat("eval --manifest ", Path("none.csv"), " --output ", Path("x.csv"))),
            1);
  EXPECT_THAT(stderr_, HasSubstr("none.csv"));
}

// calibrate measures the shipped pipeline on its own pairs: a flag that would change either is
// refused, named, with the flags that do choose the pairs; nothing is written.
TEST_F(EvalCommandTest, CalibrateRefusesFlagsItWouldIgnore) {
  const std::string out = Path("calibration.txt");
  EXPECT_EQ(Run(absl::StrCat("calibrate --passes 1 --seed 5 --output ", out)), 2);
  EXPECT_THAT(stderr_, HasSubstr("does not take --passes, --seed"));
  EXPECT_THAT(stderr_, HasSubstr("--pair_seed"));
  EXPECT_EQ(Run(absl::StrCat("calibrate --evaluate --noise_polish=false --output ", out)), 2);
  EXPECT_THAT(stderr_, HasSubstr("--noise_polish"));
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace rpsr::client
