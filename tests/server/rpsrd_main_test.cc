// The rpsrd binary end to end: it starts with flags, logs key=value lines, serves, and drains and
// exits 0 on SIGTERM.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/service_test_client.h"

namespace rpsr::server {
namespace {

using ::testing::HasSubstr;

// The value of `key=` in a log line ("" if absent).
std::string Field(const std::string& line, const std::string& key) {
  const size_t at = line.find(" " + key + "=");
  if (at == std::string::npos) return "";
  const size_t begin = at + key.size() + 2;
  return line.substr(begin, line.find(' ', begin) - begin);
}

// rpsrd started with `flags`, its stderr read as it comes. Never hangs a test: reads wait at most
// 60 s in all, and a process still running when the helper goes is killed and reaped.
class RpsrdProcess {
 public:
  explicit RpsrdProcess(std::vector<std::string> flags) {
    int out[2];
    if (pipe2(out, O_CLOEXEC) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      dup2(out[1], STDERR_FILENO);  // dup2 clears close-on-exec on the copy
      std::vector<char*> argv = {const_cast<char*>(RPSRD_PATH)};
      for (std::string& flag : flags) argv.push_back(flag.data());
      argv.push_back(nullptr);
      execv(RPSRD_PATH, argv.data());
      _exit(127);
    }
    close(out[1]);
    if (pid_ < 0) {
      close(out[0]);
      return;
    }
    fd_ = out[0];
  }
  ~RpsrdProcess() {
    if (pid_ > 0 && !reaped_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    if (fd_ >= 0) close(fd_);
  }

  bool started() const { return pid_ > 0 && fd_ >= 0; }
  const std::string& log() const { return log_; }

  // The first line with `event=<event>`, reading until it comes, the output ends, or 60 s pass.
  std::string ReadUntil(const std::string& event) {
    char buffer[4096];
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (fd_ >= 0 && log_.find("event=" + event) == std::string::npos) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          give_up - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      pollfd readable = {fd_, POLLIN, 0};
      if (poll(&readable, 1, static_cast<int>(left.count())) <= 0) break;
      const ssize_t n = read(fd_, buffer, sizeof(buffer));
      if (n <= 0) break;
      log_.append(buffer, n);
    }
    const size_t at = log_.find("event=" + event);
    if (at == std::string::npos) return std::string();
    const size_t begin = log_.rfind('\n', at) == std::string::npos ? 0 : log_.rfind('\n', at) + 1;
    return log_.substr(begin, log_.find('\n', at) - begin);
  }

  // SIGTERM; the exit status once it has stopped (-1 if it did not exit normally).
  int Terminate() {
    if (!started() || kill(pid_, SIGTERM) != 0) return -1;
    ReadUntil("stopped");
    int status = 0;
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (waitpid(pid_, &status, WNOHANG) != pid_) {
      if (std::chrono::steady_clock::now() > give_up) return -1;  // the destructor kills it
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    reaped_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

 private:
  pid_t pid_ = -1;
  int fd_ = -1;
  bool reaped_ = false;
  std::string log_;
};

TEST(RpsrdTest, ServesAndDrainsOnSigterm) {
  RpsrdProcess rpsrd({"--address=127.0.0.1:0", "--metrics_address=", "--max_batch=4",
                      "--max_points_per_cloud=5000", "--drain_notice=200ms"});
  ASSERT_TRUE(rpsrd.started());
  const std::string listening = rpsrd.ReadUntil("listening");
  int port = 0;
  ASSERT_TRUE(absl::SimpleAtoi(Field(listening, "port"), &port)) << rpsrd.log();
  // No --workers: one per hardware thread, said in the log and in ServerInfo.
  const uint32_t hardware_threads = std::max(1u, std::thread::hardware_concurrency());
  EXPECT_EQ(Field(listening, "workers"), absl::StrCat(hardware_threads)) << listening;
  const std::string loaded = rpsrd.ReadUntil("model_loaded");
  EXPECT_THAT(loaded, HasSubstr("RPSRNet"));
  // The BLAS kernels decide the network's speed: the log names them (DEPS.md installs OpenBLAS).
  EXPECT_THAT(loaded, HasSubstr("blas=\"OpenBLAS ")) << loaded;
  // And which does the network's products: rpsr's AVX2 kernel or the BLAS (rulebook_kernel.h).
  EXPECT_THAT(loaded, HasSubstr("network_products=\"")) << loaded;

  testing::ServiceTestClient client(absl::StrCat("127.0.0.1:", port));
  EXPECT_EQ(client.HealthStatus(""), 1);
  grpc::ClientContext context;
  client.Prepare(&context);
  v1::ServerInfo info;
  ASSERT_TRUE(client.stub().GetServerInfo(&context, {}, &info).ok());
  EXPECT_EQ(info.limits().max_batch(), 4u);
  EXPECT_EQ(info.limits().max_points_per_cloud(), 5000u);
  EXPECT_EQ(info.limits().workers(), hardware_threads);

  EXPECT_EQ(rpsrd.Terminate(), 0) << rpsrd.log();
  EXPECT_THAT(rpsrd.log(), HasSubstr("event=stopped"));
  EXPECT_THAT(rpsrd.log(), HasSubstr("event=signal signal=SIGTERM"));
  EXPECT_THAT(rpsrd.log(), HasSubstr("event=draining"));
  EXPECT_THAT(rpsrd.log(), HasSubstr("method=GetServerInfo code=OK"));
}

// --log_requests=false drops the per-call lines only: an operator still sees the server start,
// load its model, drain and stop.
TEST(RpsrdTest, WithoutRequestLogsItStillLogsItsLifecycle) {
  RpsrdProcess rpsrd({"--address=127.0.0.1:0", "--metrics_address=", "--log_requests=false"});
  ASSERT_TRUE(rpsrd.started());
  const std::string listening = rpsrd.ReadUntil("listening");
  int port = 0;
  ASSERT_TRUE(absl::SimpleAtoi(Field(listening, "port"), &port)) << rpsrd.log();
  EXPECT_THAT(rpsrd.ReadUntil("model_loaded"), HasSubstr("RPSRNet")) << rpsrd.log();
  testing::ServiceTestClient client(absl::StrCat("127.0.0.1:", port));
  grpc::ClientContext context;
  client.Prepare(&context);
  v1::ServerInfo info;
  ASSERT_TRUE(client.stub().GetServerInfo(&context, {}, &info).ok());
  EXPECT_EQ(rpsrd.Terminate(), 0) << rpsrd.log();
  EXPECT_THAT(rpsrd.log(), HasSubstr("event=draining"));
  EXPECT_THAT(rpsrd.log(), HasSubstr("event=stopped"));
  EXPECT_THAT(rpsrd.log(), ::testing::Not(HasSubstr("method=GetServerInfo")));
}

TEST(RpsrdTest, RefusesBadFlagsWithAReason) {
  int out[2];
  ASSERT_EQ(pipe(out), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    dup2(out[1], STDERR_FILENO);
    close(out[0]);
    execl(RPSRD_PATH, RPSRD_PATH, "--address=127.0.0.1:0", "--metrics_address=", "--max_batch=0",
          static_cast<char*>(nullptr));
    _exit(127);
  }
  close(out[1]);
  std::string log;
  char buffer[4096];
  for (ssize_t n; (n = read(out[0], buffer, sizeof(buffer))) > 0;) log.append(buffer, n);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_EQ(WEXITSTATUS(status), 1);
  EXPECT_THAT(log, HasSubstr("event=start_failed"));
  EXPECT_THAT(log, HasSubstr("max_batch"));
  close(out[0]);
}

}  // namespace
}  // namespace rpsr::server
