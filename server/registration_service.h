// The gRPC service of proto/rpsr/v1/registration.proto on gRPC's callback API: handlers never
// block on registration; they validate, resolve clouds from the session store and hand the pair
// to the dynamic batcher, whose worker answers the call.
//
// Threads: gRPC's callback threads run validation, chunk decoding and tree building (a few
// milliseconds for a 120k-point cloud); the batcher's workers run the registrar.
#ifndef RPSR_SERVER_REGISTRATION_SERVICE_H_
#define RPSR_SERVER_REGISTRATION_SERVICE_H_

#include <atomic>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "core/registrar/registrar.h"
#include "core/tree/bh_tree.h"
#include "grpcpp/grpcpp.h"
#include "rpsr/v1/registration.grpc.pb.h"
#include "server/dynamic_batcher.h"
#include "server/rpsr_server.h"
#include "server/service_metrics.h"
#include "server/session_store.h"

namespace rpsr::server {

// One pair for the batcher.
struct RegistrationJob {
  std::shared_ptr<const core::Octree> source;
  std::shared_ptr<const core::Octree> target;
  core::RegistrationOptions options;
  absl::Time enqueued;
  // The target is a cloud of the session store, likely registered against again: its prepared
  // target is kept (PreparedTargetCache). Inline clouds and Track frames are used once.
  bool target_from_store = false;
};

struct RegistrationOutcome {
  core::RegistrationResult result;
  double queue_seconds = 0.0;
  int batch_size = 0;
};

using RegistrationBatcher = DynamicBatcher<RegistrationJob, RegistrationOutcome>;

// The batcher over `registrar` with the options' batching settings, reporting to `metrics`.
absl::StatusOr<std::unique_ptr<RegistrationBatcher>> MakeRegistrationBatcher(
    std::shared_ptr<const core::Registrar> registrar, const BatchingOptions& options,
    ServiceMetrics* metrics);

class RegistrationService final : public v1::RegistrationService::CallbackService {
 public:
  // `metrics` and `store` outlive the service.
  RegistrationService(const ServerOptions& options, ServiceMetrics* metrics, SessionStore* store);
  ~RegistrationService() override;

  // The model is loaded: registrations are accepted from now on.
  void SetEngine(std::shared_ptr<const core::Registrar> registrar,
                 std::unique_ptr<RegistrationBatcher> batcher);
  bool ready() const;
  // New calls answer UNAVAILABLE; calls in flight go on.
  void StartDraining();
  // Finishes what the batcher holds (after gRPC's Shutdown has returned).
  void StopBatcher();

  grpc::ServerUnaryReactor* GetServerInfo(grpc::CallbackServerContext* context,
                                          const v1::GetServerInfoRequest* request,
                                          v1::ServerInfo* response) override;
  grpc::ServerUnaryReactor* CreateSession(grpc::CallbackServerContext* context,
                                          const v1::CreateSessionRequest* request,
                                          v1::CreateSessionResponse* response) override;
  grpc::ServerUnaryReactor* CloseSession(grpc::CallbackServerContext* context,
                                         const v1::CloseSessionRequest* request,
                                         v1::CloseSessionResponse* response) override;
  grpc::ServerReadReactor<v1::UploadCloudRequest>* UploadCloud(
      grpc::CallbackServerContext* context, v1::UploadCloudResponse* response) override;
  grpc::ServerUnaryReactor* ReleaseCloud(grpc::CallbackServerContext* context,
                                         const v1::ReleaseCloudRequest* request,
                                         v1::ReleaseCloudResponse* response) override;
  grpc::ServerUnaryReactor* Register(grpc::CallbackServerContext* context,
                                     const v1::RegisterRequest* request,
                                     v1::RegisterResponse* response) override;
  grpc::ServerBidiReactor<v1::TrackRequest, v1::TrackResponse>* Track(
      grpc::CallbackServerContext* context) override;

  // What the reactors (registration_service.cc) share; public for them only.
  struct Shared;

 private:
  std::unique_ptr<Shared> shared_;
};

}  // namespace rpsr::server

#endif  // RPSR_SERVER_REGISTRATION_SERVICE_H_
