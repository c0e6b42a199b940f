// End to end (label e2e): the real `rpsrd` and `rpsr` binaries against each other on 127.0.0.1,
// as a user runs them: register, odometry on a short simulated sequence with KITTI's metrics
// under a threshold, bench for two seconds, demo, serve, the example program, and an application
// built against the installed client library through find_package(rpsr).
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

extern char** environ;

namespace rpsr::client {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

int FreePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address));
  socklen_t length = sizeof(address);
  getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length);
  close(fd);
  return ntohs(address.sin_port);
}

bool PortAccepts(int port) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = htons(static_cast<uint16_t>(port));
  const bool ok = connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
  close(fd);
  return ok;
}

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// The number after "key": in a JSON text (the first occurrence); NaN when absent.
double JsonNumber(const std::string& json, const std::string& key, size_t from = 0) {
  const std::string needle = absl::StrCat("\"", key, "\": ");
  const size_t at = json.find(needle, from);
  if (at == std::string::npos) return std::nan("");
  return std::strtod(json.c_str() + at + needle.size(), nullptr);
}

// A background process (rpsrd or `rpsr serve`) listening on a port.
class Daemon {
 public:
  Daemon(const std::vector<std::string>& argv, int port, const fs::path& log) : port_(port) {
    std::vector<char*> args;
    for (const std::string& arg : argv) args.push_back(const_cast<char*>(arg.c_str()));
    args.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
    if (posix_spawn(&pid_, args[0], &actions, nullptr, args.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&actions);
  }
  ~Daemon() {
    if (pid_ > 0) Stop();
  }
  bool WaitUntilListening(std::chrono::seconds timeout) const {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      if (PortAccepts(port_)) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
  }
  // SIGTERM, then the exit code (-1 if it did not exit normally).
  int Stop() {
    kill(pid_, SIGTERM);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  bool started() const { return pid_ > 0; }

 private:
  pid_t pid_ = -1;
  int port_;
};

class ServiceEndToEndTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() / absl::StrCat("rpsr_service_e2e_", getpid()));
    fs::remove_all(*dir_);
    fs::create_directories(*dir_);
    port_ = FreePort();
    rpsrd_ = new Daemon({RPSRD_BINARY, absl::StrCat("--address=127.0.0.1:", port_),
                         "--metrics_address=", "--log_requests=false"},
                        port_, *dir_ / "rpsrd.log");
    ASSERT_TRUE(rpsrd_->started());
    ASSERT_TRUE(rpsrd_->WaitUntilListening(std::chrono::seconds(60)))
        << ReadText(*dir_ / "rpsrd.log");
  }
  static void TearDownTestSuite() {
    // SIGTERM drains and exits 0.
    EXPECT_EQ(rpsrd_->Stop(), 0) << ReadText(*dir_ / "rpsrd.log");
    delete rpsrd_;
    fs::remove_all(*dir_);
    delete dir_;
  }

  // Runs a command line; stdout into out_, stderr into err_; returns the exit code.
  int Run(const std::string& command) {
    const fs::path out = *dir_ / "stdout.txt";
    const fs::path err = *dir_ / "stderr.txt";
    const int status = std::system(
        absl::StrCat("OMP_WAIT_POLICY=PASSIVE ", command, " >", out.string(), " 2>", err.string())
            .c_str());
    out_ = ReadText(out);
    err_ = ReadText(err);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  int Rpsr(const std::string& args) { return Run(absl::StrCat(RPSR_CLI_BINARY, " ", args)); }
  static std::string Server() { return absl::StrCat("127.0.0.1:", port_); }
  static std::string Data(const std::string& path) {
    return absl::StrCat(RPSR_SOURCE_DIR, "/client/examples/data/", path);
  }
  static std::string Truth(const std::string& sample) {
    const std::vector<std::string> lines =
        absl::StrSplit(ReadText(Data(sample + "/manifest.csv")), '\n', absl::SkipEmpty());
    return std::vector<std::string>(absl::StrSplit(lines[1], ','))[2];
  }

  static fs::path* dir_;
  static int port_;
  static Daemon* rpsrd_;
  std::string out_;
  std::string err_;
};

fs::path* ServiceEndToEndTest::dir_ = nullptr;
int ServiceEndToEndTest::port_ = 0;
Daemon* ServiceEndToEndTest::rpsrd_ = nullptr;

TEST_F(ServiceEndToEndTest, RegisterOnTheServerMatchesLocal) {
  const std::string pair = absl::StrCat(Data("object/clouds/000000_source.ply"), " ",
                                        Data("object/clouds/000000_target.ply"));
  const fs::path aligned = *dir_ / "aligned.ply";
  ASSERT_EQ(Rpsr(absl::StrCat("register ", pair, " --server ", Server(), " --json --truth '",
                              Truth("object"), "' --output-aligned ", aligned.string())),
            0)
      << err_;
  EXPECT_THAT(out_, HasSubstr("\"valid\": true"));
  const double server_error = JsonNumber(out_, "rotation_error_deg");
  EXPECT_LT(server_error, 2.0) << out_;
  EXPECT_LT(JsonNumber(out_, "translation_error"), 0.02) << out_;
  EXPECT_GT(JsonNumber(out_, "confidence"), 0.5) << out_;
  EXPECT_TRUE(fs::exists(aligned));
  ASSERT_EQ(
      Rpsr(absl::StrCat("register ", pair, " --local --json --truth '", Truth("object"), "'")), 0)
      << err_;
  EXPECT_NEAR(JsonNumber(out_, "rotation_error_deg"), server_error, 1e-3) << out_;
  // Text output names R, t and the confidence.
  ASSERT_EQ(Rpsr(absl::StrCat("register ", pair, " --server ", Server())), 0) << err_;
  EXPECT_THAT(out_, HasSubstr("R =\n"));
  EXPECT_THAT(out_, HasSubstr("confidence"));
  // Both places at once is a flag error; a missing file a failure naming it.
  EXPECT_EQ(Rpsr(absl::StrCat("register ", pair, " --local --server ", Server())), 2);
  EXPECT_EQ(Rpsr(absl::StrCat("register /nonexistent.ply ", Data("object/clouds/000000_target.ply"),
                              " --server ", Server())),
            1);
  EXPECT_THAT(err_, HasSubstr("/nonexistent.ply"));
}

// --initial: a starting guess reaches the registrar in both places. From the truth, refine stays
// there; on a corridor (floor and two walls along x) from a guess 0.6 m along it, the degenerate
// answer keeps the guess's 0.6 m (--hold_degenerate_at_initial, on by default) and says so.
TEST_F(ServiceEndToEndTest, RegisterStartsFromTheInitialGuess) {
  const std::string pair = absl::StrCat(Data("object/clouds/000000_source.ply"), " ",
                                        Data("object/clouds/000000_target.ply"));
  for (const std::string& where : {std::string("--local"), absl::StrCat("--server ", Server())}) {
    ASSERT_EQ(Rpsr(absl::StrCat("register ", pair, " ", where, " --mode refine --json --initial '",
                                Truth("object"), "' --truth '", Truth("object"), "'")),
              0)
        << where << ": " << err_;
    EXPECT_LT(JsonNumber(out_, "rotation_error_deg"), 0.5) << where << ": " << out_;
    EXPECT_THAT(out_, HasSubstr("\"start\": \"initial\"")) << where;
    EXPECT_THAT(out_, HasSubstr("\"held_at_initial\": false")) << where;
  }
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> along(-10.0, 10.0), unit(0.0, 1.0);
  for (const std::string name : {"corridor_source.xyz", "corridor_target.xyz"}) {
    std::ofstream file(*dir_ / name);
    for (int i = 0; i < 8000; ++i) {
      const double x = along(rng);
      if (i % 3 == 0) file << x << " " << -1.5 + 3.0 * unit(rng) << " 0\n";
      if (i % 3 == 1) file << x << " -1.5 " << 2.5 * unit(rng) << "\n";
      if (i % 3 == 2) file << x << " 1.5 " << 2.5 * unit(rng) << "\n";
    }
  }
  const std::string corridor = absl::StrCat(
      (*dir_ / "corridor_source.xyz").string(), " ", (*dir_ / "corridor_target.xyz").string(),
      " --mode refine --json --initial '1 0 0 0.6  0 1 0 0.15  0 0 1 0  0 0 0 1'");
  for (const std::string& where : {std::string("--local"), absl::StrCat("--server ", Server())}) {
    EXPECT_EQ(Rpsr(absl::StrCat("register ", corridor, " ", where)), 3) << where << ": " << err_;
    EXPECT_THAT(out_, HasSubstr("\"held_at_initial\": true")) << where << ": " << out_;
    const size_t translation = out_.find("\"translation\": [");
    ASSERT_NE(translation, std::string::npos) << out_;
    EXPECT_NEAR(std::strtod(out_.c_str() + translation + 16, nullptr), 0.6, 1e-3)
        << where << ": " << out_;
    EXPECT_EQ(Rpsr(absl::StrCat("register ", corridor, " ", where,
                                " --hold_degenerate_at_initial=false")),
              3)
        << where << ": " << err_;
    EXPECT_THAT(out_, HasSubstr("\"held_at_initial\": false")) << where << ": " << out_;
  }
  EXPECT_EQ(Rpsr(absl::StrCat("register ", pair, " --local --initial '1 0 0'")), 2);
  EXPECT_THAT(err_, HasSubstr("--initial needs 16 numbers"));
  EXPECT_EQ(Rpsr(absl::StrCat("register ", pair,
                              " --local --initial '2 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1'")),
            2);
  EXPECT_THAT(err_, HasSubstr("--initial: transform's 3x3 block is not a rotation"));
}

TEST_F(ServiceEndToEndTest, OdometryOnASimulatedSequenceMeetsKittiThresholds) {
  const fs::path kitti = *dir_ / "kitti";
  ASSERT_EQ(Rpsr(absl::StrCat("data lidar --output ", kitti.string(),
                              " --frames 150 --style suburban --azimuth_steps 1000 --seed 11")),
            0)
      << err_;
  const fs::path poses = *dir_ / "odometry" / "poses.txt";
  ASSERT_EQ(Rpsr(absl::StrCat("odometry ", (kitti / "sequences" / "00").string(), " --server ",
                              Server(), " --output ", poses.string(), " --json")),
            0)
      << err_;
  EXPECT_EQ(JsonNumber(out_, "frames"), 150);
  EXPECT_EQ(JsonNumber(out_, "invalid_pairs"), 0) << out_;
  EXPECT_EQ(JsonNumber(out_, "held_pairs"), 0) << out_;  // no degenerate frame on this street
  // An HDL-64E's rings lie closer than a depth-9 cell: the line rule is chosen off
  // (tests/bench/notes/odometry-notes.md, *Sparser scanners drift more*).
  EXPECT_EQ(JsonNumber(out_, "line_normals_from_planes_pairs"), 0) << out_;
  ASSERT_GE(JsonNumber(out_, "segments"), 1) << out_;  // at least one 100 m segment
  // Thresholds with room: measured 0.56 % and 0.008 deg/m on this sequence.
  EXPECT_LT(JsonNumber(out_, "translation_error_percent"), 2.0) << out_;
  EXPECT_LT(JsonNumber(out_, "rotation_error_deg_per_m"), 0.03) << out_;
  const std::vector<std::string> lines = absl::StrSplit(ReadText(poses), '\n', absl::SkipEmpty());
  ASSERT_EQ(lines.size(), 150u);
  EXPECT_EQ(std::vector<std::string>(absl::StrSplit(lines[0], ' ', absl::SkipEmpty())).size(), 12u);
  const std::string png = ReadText(*dir_ / "odometry" / "poses.png");
  EXPECT_EQ(png.substr(1, 3), "PNG");
  // The same in this process, on the first 40 frames, with segments short enough for them.
  ASSERT_EQ(Rpsr(absl::StrCat("odometry ", (kitti / "sequences" / "00").string(),
                              " --local --max_frames 40 --segment_lengths 10,20 --plot none "
                              "--output ",
                              (*dir_ / "local_poses.txt").string(), " --json")),
            0)
      << err_;
  EXPECT_EQ(JsonNumber(out_, "frames"), 40);
  ASSERT_GE(JsonNumber(out_, "segments"), 1) << out_;
  EXPECT_LT(JsonNumber(out_, "translation_error_percent"), 2.0) << out_;
  // Given on the command line, the line rule runs in every pair.
  ASSERT_EQ(Rpsr(absl::StrCat("odometry ", (kitti / "sequences" / "00").string(),
                              " --local --max_frames 6 --line_normals_from_planes --plot none "
                              "--output ",
                              (*dir_ / "line_poses.txt").string(), " --json")),
            0)
      << err_;
  EXPECT_EQ(JsonNumber(out_, "line_normals_from_planes_pairs"), 5) << out_;
}

TEST_F(ServiceEndToEndTest, BenchReportsThroughputAndPercentiles) {
  ASSERT_EQ(Rpsr(absl::StrCat("bench --server ", Server(), " --clients 3 --duration 2 --json")), 0)
      << err_;
  EXPECT_GT(JsonNumber(out_, "requests_ok"), 5) << out_;
  EXPECT_EQ(JsonNumber(out_, "errors"), 0) << out_;
  EXPECT_GT(JsonNumber(out_, "throughput_per_s"), 0) << out_;
  EXPECT_LE(JsonNumber(out_, "p50"), JsonNumber(out_, "p99")) << out_;
  EXPECT_GE(JsonNumber(out_, "mean_batch_size"), 1.0) << out_;
}

TEST_F(ServiceEndToEndTest, ExampleProgramRegistersTheSamplePair) {
  ASSERT_EQ(Run(absl::StrCat(RPSR_EXAMPLE_BINARY, " ", Server(), " ",
                             Data("object/clouds/000000_source.ply"), " ",
                             Data("object/clouds/000000_target.ply"))),
            0)
      << err_ << out_;
  EXPECT_THAT(out_, HasSubstr("valid yes"));
}

TEST_F(ServiceEndToEndTest, DemoRegistersBothSamplesAgainstTheirTruth) {
  const fs::path output = *dir_ / "demo";
  ASSERT_EQ(Rpsr(absl::StrCat("demo --json --output ", output.string())), 0) << err_;
  const size_t lidar = out_.find("LiDAR");
  ASSERT_NE(lidar, std::string::npos) << out_;
  EXPECT_LT(JsonNumber(out_, "rotation_error_deg"), 2.0) << out_;
  EXPECT_LT(JsonNumber(out_, "rotation_error_deg", lidar), 0.5) << out_;
  EXPECT_LT(JsonNumber(out_, "translation_error", lidar), 0.1) << out_;
  EXPECT_TRUE(fs::exists(output / "object_pair.png"));
  EXPECT_TRUE(fs::exists(output / "lidar_pair.png"));
  // The text form says what it did; --data reads the same pairs from the source tree instead of
  // the copy linked into rpsr.
  ASSERT_EQ(Rpsr(absl::StrCat("demo --output ", output.string(), " --data ", Data(""))), 0) << err_;
  EXPECT_THAT(out_, HasSubstr(Data("object/clouds/000000_source.ply")));
  EXPECT_THAT(out_, HasSubstr("in-process server"));
  EXPECT_THAT(out_, HasSubstr("error vs truth"));
}

TEST_F(ServiceEndToEndTest, ServeAcceptsRegistrationsAndStopsOnSigterm) {
  const int port = FreePort();
  Daemon serve({RPSR_CLI_BINARY, "serve", absl::StrCat("--address=127.0.0.1:", port)}, port,
               *dir_ / "serve.log");
  ASSERT_TRUE(serve.WaitUntilListening(std::chrono::seconds(60)));
  ASSERT_EQ(
      Rpsr(absl::StrCat("register ", Data("object/clouds/000000_source.ply"), " ",
                        Data("object/clouds/000000_target.ply"), " --server 127.0.0.1:", port)),
      0)
      << err_;
  EXPECT_EQ(serve.Stop(), 0);
}

TEST_F(ServiceEndToEndTest, EverySubcommandHasHelp) {
  for (const std::string name : {"register", "odometry", "bench", "demo", "serve"}) {
    Rpsr(absl::StrCat(name, " --help"));
    EXPECT_THAT(out_ + err_, HasSubstr("rpsr " + name)) << name;
  }
  Rpsr("register --help");
  EXPECT_THAT(out_ + err_, HasSubstr("--output_aligned"));
  EXPECT_THAT(out_ + err_, HasSubstr("--server"));
  EXPECT_THAT(out_ + err_, HasSubstr("--json"));
}

// The installed library is usable by an application through find_package(rpsr).
TEST_F(ServiceEndToEndTest, InstalledPackageBuildsAnApplication) {
  const fs::path prefix = *dir_ / "prefix";
  ASSERT_EQ(Run(absl::StrCat("cmake --install ", RPSR_BUILD_DIR, " --component client --prefix ",
                             prefix.string())),
            0)
      << err_;
  const fs::path app = *dir_ / "app";
  fs::create_directories(app);
  std::ofstream(app / "CMakeLists.txt")
      << "cmake_minimum_required(VERSION 3.25)\nproject(rpsr_app CXX)\n"
         "set(CMAKE_CXX_STANDARD 20)\nfind_package(rpsr 0.1 CONFIG REQUIRED)\n"
         "add_executable(app main.cc)\ntarget_link_libraries(app PRIVATE rpsr::client)\n";
  std::ofstream(app / "main.cc")
      << "#include <cstdio>\n#include \"client/rpsr_client.h\"\n"
         "int main(int argc, char** argv) {\n"
         "  auto client = rpsr::client::Client::Connect({.address = argv[1]});\n"
         "  auto info = (*client)->GetServerInfo();\n"
         "  if (!info.ok()) { std::printf(\"%s\\n\", info.status().ToString().c_str()); return 1; "
         "}\n"
         "  std::printf(\"model %s\\n\", info->model_name.c_str());\n"
         "  return 0;\n}\n";
  ASSERT_EQ(Run(absl::StrCat("cmake -S ", app.string(), " -B ", (app / "build").string(),
                             " -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=", prefix.string())),
            0)
      << err_ << out_;
  ASSERT_EQ(Run(absl::StrCat("cmake --build ", (app / "build").string())), 0) << err_ << out_;
  ASSERT_EQ(Run(absl::StrCat((app / "build" / "app").string(), " ", Server())), 0) << out_;
  EXPECT_THAT(out_, HasSubstr("model objects"));
}

}  // namespace
}  // namespace rpsr::client
