// A thin synchronous client of the rpsr.v1 service for the server's integration tests: generated
// stubs plus chunked uploads, raw message sequences for the bad-input cases, the health check and
// a /metrics scrape. (The product's client library is client/rpsr_client.h.)
#ifndef RPSR_TESTS_SERVER_SERVICE_TEST_CLIENT_H_
#define RPSR_TESTS_SERVER_SERVICE_TEST_CLIENT_H_

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "grpcpp/grpcpp.h"
#include "rpsr/v1/registration.grpc.pb.h"

namespace rpsr::server::testing {

class ServiceTestClient {
 public:
  // Plaintext unless `credentials` are given; `token` goes out as "authorization: Bearer ...".
  explicit ServiceTestClient(const std::string& target, std::string token = "",
                             std::shared_ptr<grpc::ChannelCredentials> credentials = nullptr,
                             const grpc::ChannelArguments& arguments = {});

  v1::RegistrationService::Stub& stub() { return *stub_; }
  // Deadline and token on a fresh context.
  void Prepare(grpc::ClientContext* context, double timeout_seconds = 60.0) const;

  grpc::Status CreateSession(std::string* session_id, const v1::SessionOptions& options = {});
  grpc::Status Upload(const std::string& session_id, const std::vector<Eigen::Vector3f>& points,
                      v1::UploadCloudResponse* response, size_t chunk_points = 4096);
  // Sends exactly these messages, then half-closes.
  grpc::Status UploadMessages(const std::vector<v1::UploadCloudRequest>& messages,
                              v1::UploadCloudResponse* response);
  grpc::Status Register(const v1::RegisterRequest& request, v1::RegisterResponse* response,
                        double timeout_seconds = 60.0);
  grpc::Status RegisterIds(const std::string& session_id, uint64_t source, uint64_t target,
                           const v1::RegisterOptions& options, v1::RegisterResponse* response);

  // grpc.health.v1.Health/Check of `service` ("" = the server): 1 SERVING, 2 NOT_SERVING, or the
  // call's error code negated.
  int HealthStatus(const std::string& service = "");
  // The services grpc.reflection.v1alpha lists, as the raw bytes of its first answer.
  std::string ReflectionListServices();

 private:
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::RegistrationService::Stub> stub_;
  std::string token_;
};

// Messages of an upload in chunks of `chunk_points` (sequence 0.., count in the first).
std::vector<v1::UploadCloudRequest> UploadMessagesFor(const std::string& session_id,
                                                      const std::vector<Eigen::Vector3f>& points,
                                                      size_t chunk_points);

// The chunks of frame `frame` of a Track stream, `chunk_points` points a message.
std::vector<v1::TrackRequest> TrackFrameRequests(uint64_t frame,
                                                 const std::vector<Eigen::Vector3f>& points,
                                                 size_t chunk_points);

// The /metrics text of a Prometheus exposer on 127.0.0.1:port (empty on failure).
std::string ScrapeMetrics(int port);
// The value of the first sample of `name` whose labels include every `labels` pair, or nullopt.
std::optional<double> MetricValue(
    const std::string& text, const std::string& name,
    const std::vector<std::pair<std::string, std::string>>& labels = {});

// The transform of a response; a missing or invalid rotation or translation fails the test.
Eigen::Isometry3d TransformOf(const v1::RigidTransform& proto);

}  // namespace rpsr::server::testing

#endif  // RPSR_TESTS_SERVER_SERVICE_TEST_CLIENT_H_
