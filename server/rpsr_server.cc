#include "server/rpsr_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <exception>
#include <thread>
#include <utility>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "absl/synchronization/notification.h"
#include "core/io/file_bytes.h"
#include "core/net/blas_info.h"
#include "core/net/rulebook_kernel.h"
#include "grpcpp/ext/proto_server_reflection_plugin.h"
#include "grpcpp/grpcpp.h"
#include "grpcpp/health_check_service_interface.h"
#include "prometheus/exposer.h"
#include "server/registration_service.h"
#include "server/service_metrics.h"
#include "server/session_store.h"
#include "server/structured_log.h"
#include "server/thread_stack_floor.h"

namespace rpsr::server {

const char* ServerVersion() { return "0.1.0"; }

namespace {

constexpr char kServiceName[] = "rpsr.v1.RegistrationService";

absl::Status ValidateOptions(const ServerOptions& o) {
  auto invalid = [](auto&&... parts) {
    return absl::InvalidArgumentError(absl::StrCat("ServerOptions: ", parts...));
  };
  if (o.address.empty()) return invalid("address is empty");
  if (o.cache.memory_budget_bytes == 0) return invalid("cache.memory_budget_bytes is 0");
  if (o.cache.max_sessions == 0) return invalid("cache.max_sessions is 0");
  if (o.cache.max_clouds_per_session == 0) return invalid("cache.max_clouds_per_session is 0");
  if (o.cache.default_ttl <= absl::ZeroDuration() || o.cache.max_ttl < o.cache.default_ttl) {
    return invalid("need 0 < cache.default_ttl <= cache.max_ttl");
  }
  if (o.batching.max_batch < 1 || o.batching.max_queue < 1 || o.batching.workers < 1 ||
      o.batching.intra_op_threads < 1 || o.batching.max_queue_delay < absl::ZeroDuration()) {
    return invalid(
        "batching needs max_batch, max_queue, workers, intra_op_threads >= 1 and "
        "max_queue_delay >= 0");
  }
  if (o.batching.prepared_targets < 0) {
    return invalid("batching.prepared_targets must be >= 0, got ", o.batching.prepared_targets);
  }
  if (o.batching.prepared_target_bytes > (uint64_t{1} << 40)) {
    return invalid("batching.prepared_target_bytes must be at most 1 TiB, got ",
                   o.batching.prepared_target_bytes);
  }
  if (o.max_points_per_cloud == 0) return invalid("max_points_per_cloud is 0");
  if (o.max_open_streams == 0) return invalid("max_open_streams is 0");
  if (o.max_message_bytes < 1024 || o.max_message_bytes > (1u << 31) - 1) {
    return invalid("max_message_bytes must be in [1024, 2^31 - 1], got ", o.max_message_bytes);
  }
  if (o.min_tree_max_depth < 5 || o.min_tree_max_depth > o.default_tree_max_depth ||
      o.default_tree_max_depth > o.max_tree_max_depth || o.max_tree_max_depth > 21) {
    return invalid(
        "need 5 <= min_tree_max_depth <= default_tree_max_depth <= max_tree_max_depth <= 21 (the "
        "network reads depth 5)");
  }
  if (o.drain_notice < absl::ZeroDuration()) return invalid("drain_notice is negative");
  if (o.tls_cert_file.empty() != o.tls_key_file.empty()) {
    return invalid("give both tls_cert_file and tls_key_file, or neither");
  }
  for (const std::string& token : o.auth_tokens) {
    if (token.empty()) return invalid("an empty auth token");
  }
  return absl::OkStatus();
}

// "host:port" -> the host to dial locally (a wildcard becomes loopback).
std::string DialHost(const std::string& address) {
  const size_t colon = address.rfind(':');
  std::string host = colon == std::string::npos ? address : address.substr(0, colon);
  if (host.empty() || host == "0.0.0.0" || host == "[::]" || host == "::") return "127.0.0.1";
  return host;
}

// civetweb (under prometheus-cpp's Exposer) cannot bind port 0, so for "host:0" the kernel picks a
// free port on a socket we then close, and the exposer binds it. Another process could take it in
// between; StartServer retries a few times.
absl::StatusOr<std::string> ResolvePortZero(const std::string& address) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos || address.substr(colon + 1) != "0") return address;
  const std::string host = address.substr(0, colon);
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return absl::UnavailableError("socket() failed while picking a metrics port");
  sockaddr_in bound{};
  bound.sin_family = AF_INET;
  bound.sin_port = 0;
  const std::string ip = DialHost(address) == "127.0.0.1" && host != "127.0.0.1" ? "0.0.0.0" : host;
  if (inet_pton(AF_INET, ip.c_str(), &bound.sin_addr) != 1) {
    close(fd);
    return absl::InvalidArgumentError(
        absl::StrCat("metrics address ", address, ": port 0 needs an IPv4 host"));
  }
  socklen_t length = sizeof(bound);
  if (bind(fd, reinterpret_cast<sockaddr*>(&bound), sizeof(bound)) != 0 ||
      getsockname(fd, reinterpret_cast<sockaddr*>(&bound), &length) != 0) {
    close(fd);
    return absl::UnavailableError(absl::StrCat("could not find a free port on ", host));
  }
  close(fd);
  return absl::StrCat(host, ":", ntohs(bound.sin_port));
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeCredentials(const ServerOptions& o) {
  if (o.tls_cert_file.empty()) return grpc::InsecureServerCredentials();
  absl::StatusOr<std::string> cert = core::ReadFileBytes(o.tls_cert_file);
  if (!cert.ok()) return cert.status();
  absl::StatusOr<std::string> key = core::ReadFileBytes(o.tls_key_file);
  if (!key.ok()) return key.status();
  grpc::SslServerCredentialsOptions ssl;
  ssl.pem_key_cert_pairs.push_back({*key, *cert});
  return grpc::SslServerCredentials(ssl);
}

}  // namespace

// Everything a running server owns, in construction order (destroyed in reverse).
class ServerState {
 public:
  explicit ServerState(const ServerOptions& options) : options_(options) {}
  ~ServerState() {
    Shutdown(absl::Seconds(30));
    Wait();
  }

  absl::Status Start() {
    metrics_ = std::make_unique<ServiceMetrics>();
    store_ = std::make_unique<SessionStore>(options_.cache, metrics_->CacheHooks());
    service_ = std::make_unique<RegistrationService>(options_, metrics_.get(), store_.get());

    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials =
        MakeCredentials(options_);
    if (!credentials.ok()) return credentials.status();
    grpc::EnableDefaultHealthCheckService(true);
    if (options_.enable_reflection) grpc::reflection::InitProtoReflectionServerBuilderPlugin();
    grpc::ServerBuilder builder;
    builder.AddListeningPort(options_.address, *credentials, &port_);
    builder.SetMaxReceiveMessageSize(static_cast<int>(options_.max_message_bytes));
    builder.RegisterService(service_.get());
    server_ = builder.BuildAndStart();
    if (server_ == nullptr || port_ == 0) {
      return absl::UnavailableError(
          absl::StrCat("could not listen on ", options_.address, " (address in use or invalid)"));
    }
    SetServing(false);  // until the model is loaded

    if (!options_.metrics_address.empty()) {
      std::string last_error;
      for (int attempt = 0; attempt < 5 && exposer_ == nullptr; ++attempt) {
        absl::StatusOr<std::string> address = ResolvePortZero(options_.metrics_address);
        if (!address.ok()) return address.status();
        try {
          exposer_ = std::make_unique<prometheus::Exposer>(*address);
        } catch (const std::exception& error) {
          last_error = error.what();
          if (*address == options_.metrics_address) break;  // a fixed port: no retry
        }
      }
      if (exposer_ == nullptr) {
        return absl::UnavailableError(absl::StrCat("could not serve metrics on ",
                                                   options_.metrics_address, ": ", last_error));
      }
      exposer_->RegisterCollectable(metrics_->registry());
      const std::vector<int> ports = exposer_->GetListeningPorts();
      metrics_port_ = ports.empty() ? 0 : ports.front();
    }

    janitor_ = std::thread([this] {
      // Expired sessions free their trees even when no call comes to notice them.
      while (!stop_janitor_.WaitForNotificationWithTimeout(absl::Seconds(1))) {
        store_->ExpireIdleSessions();
      }
    });

    if (options_.wait_for_model) {
      absl::Status loaded = LoadModel();
      if (!loaded.ok()) return loaded;
    } else {
      loader_ = std::thread([this] { LoadModel().IgnoreError(); });
    }
    if (!options_.auth_tokens.empty() && options_.tls_cert_file.empty()) {
      // Bearer tokens over plaintext can be read by anyone on the path: say so once.
      LogEvent(
          "warn", "auth_without_tls",
          {{"detail", "bearer tokens travel in plaintext; enable TLS or terminate it in front"}});
    }
    if (options_.log_lifecycle) {
      LogEvent("info", "listening",
               {{"address", options_.address},
                {"port", absl::StrCat(port_)},
                {"metrics_port", absl::StrCat(metrics_port_)},
                {"workers", absl::StrCat(options_.batching.workers)},
                {"tls", options_.tls_cert_file.empty() ? "off" : "on"},
                {"auth", options_.auth_tokens.empty() ? "off" : "bearer"},
                {"raised_thread_stacks", absl::StrCat(RaisedThreadStackRequests())}});
    }
    return absl::OkStatus();
  }

  void Shutdown(absl::Duration grace) {
    // Only a server that has said SERVING has load balancers to warn with the drain notice.
    const bool was_serving = ready();
    {
      absl::MutexLock lock(&mu_);
      if (shutting_down_) return;
      shutting_down_ = true;
    }
    if (options_.log_lifecycle) {
      LogEvent("info", "draining", {{"grace_seconds", absl::StrCat(absl::ToDoubleSeconds(grace))}});
    }
    if (service_ != nullptr) service_->StartDraining();
    if (server_ != nullptr) {
      SetServing(false);
      if (was_serving && options_.drain_notice > absl::ZeroDuration()) {
        absl::SleepFor(options_.drain_notice);
      }
      // Waits for calls in flight (their registrations still run on the batcher) up to the grace,
      // then cancels the rest.
      server_->Shutdown(absl::ToChronoTime(absl::Now() + grace));
    }
    if (loader_.joinable()) loader_.join();
    if (service_ != nullptr) service_->StopBatcher();
    stop_janitor_.Notify();
    if (janitor_.joinable()) janitor_.join();
    exposer_.reset();
    if (server_ != nullptr) server_->Wait();
    if (options_.log_lifecycle) LogEvent("info", "stopped", {});
    shutdown_done_.Notify();
  }

  void Wait() { shutdown_done_.WaitForNotification(); }

  int port() const { return port_; }
  int metrics_port() const { return metrics_port_; }
  std::string target() const { return absl::StrCat(DialHost(options_.address), ":", port_); }
  bool ready() const { return service_ != nullptr && service_->ready() && !draining(); }

  bool draining() const {
    absl::MutexLock lock(&mu_);
    return shutting_down_;
  }

  void SetServing(bool serving) {
    grpc::HealthCheckServiceInterface* health = server_->GetHealthCheckService();
    if (health == nullptr) return;
    health->SetServingStatus(serving);
    health->SetServingStatus(kServiceName, serving);
  }

  absl::Status WaitForModel() {
    model_done_.WaitForNotification();
    absl::MutexLock lock(&mu_);
    return model_status_;
  }

 private:
  absl::Status LoadModel() {
    absl::Status status = LoadModelOnce();
    {
      absl::MutexLock lock(&mu_);
      model_status_ = status;
    }
    model_done_.Notify();
    return status;
  }

  absl::Status LoadModelOnce() {
    const absl::Time start = absl::Now();
    std::shared_ptr<const core::Registrar> registrar = options_.registrar;
    if (registrar == nullptr) {
      absl::StatusOr<std::unique_ptr<core::Registrar>> created =
          core::Registrar::Create(options_.registrar_config);
      if (!created.ok()) {
        LogEvent("error", "model_load_failed",
                 {{"error", std::string(created.status().message())}});
        return created.status();
      }
      registrar = std::shared_ptr<const core::Registrar>(*std::move(created));
    }
    absl::StatusOr<std::unique_ptr<RegistrationBatcher>> batcher =
        MakeRegistrationBatcher(registrar, options_.batching, metrics_.get());
    if (!batcher.ok()) return batcher.status();
    const std::string description = registrar->model_description();
    service_->SetEngine(std::move(registrar), *std::move(batcher));
    metrics_->SetModelLoaded(true);
    if (!draining()) SetServing(true);
    if (options_.log_lifecycle) {
      LogEvent("info", "model_loaded",
               {{"model", description},
                {"blas", core::net::BlasDescription()},
                {"network_products", core::net::RulebookKernelDescription()},
                {"seconds", absl::StrCat(absl::ToDoubleSeconds(absl::Now() - start))}});
    }
    return absl::OkStatus();
  }

  const ServerOptions options_;
  std::unique_ptr<ServiceMetrics> metrics_;
  std::unique_ptr<SessionStore> store_;
  std::unique_ptr<RegistrationService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<prometheus::Exposer> exposer_;
  int port_ = 0;
  int metrics_port_ = 0;
  std::thread loader_;
  std::thread janitor_;
  absl::Notification stop_janitor_;
  absl::Notification shutdown_done_;
  absl::Notification model_done_;
  mutable absl::Mutex mu_;
  absl::Status model_status_ ABSL_GUARDED_BY(mu_) = absl::UnavailableError("model not loaded");
  bool shutting_down_ ABSL_GUARDED_BY(mu_) = false;
};

RunningServer::RunningServer(std::unique_ptr<ServerState> state) : state_(std::move(state)) {}
RunningServer::~RunningServer() = default;
int RunningServer::port() const { return state_->port(); }
int RunningServer::metrics_port() const { return state_->metrics_port(); }
std::string RunningServer::target() const { return state_->target(); }
void RunningServer::Shutdown(absl::Duration grace) { state_->Shutdown(grace); }
void RunningServer::Wait() { state_->Wait(); }
bool RunningServer::ready() const { return state_->ready(); }
absl::Status RunningServer::WaitForModel() { return state_->WaitForModel(); }

absl::StatusOr<std::unique_ptr<RunningServer>> StartServer(const ServerOptions& given) {
  ServerOptions options = given;
  if (options.batching.workers == 0) {
    options.batching.workers = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  }
  absl::Status valid = ValidateOptions(options);
  if (!valid.ok()) return valid;
  auto state = std::make_unique<ServerState>(options);
  absl::Status started = state->Start();
  if (!started.ok()) {
    state->Shutdown(absl::ZeroDuration());
    return started;
  }
  return std::unique_ptr<RunningServer>(new RunningServer(std::move(state)));
}

}  // namespace rpsr::server
