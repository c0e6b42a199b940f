#include "tests/server/service_test_client.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <future>
#include <sstream>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "grpcpp/generic/generic_stub.h"
#include "gtest/gtest.h"
#include "server/cloud_assembler.h"
#include "server/proto_convert.h"

namespace rpsr::server::testing {

ServiceTestClient::ServiceTestClient(const std::string& target, std::string token,
                                     std::shared_ptr<grpc::ChannelCredentials> credentials,
                                     const grpc::ChannelArguments& arguments)
    : token_(std::move(token)) {
  if (credentials == nullptr) credentials = grpc::InsecureChannelCredentials();
  channel_ = grpc::CreateCustomChannel(target, credentials, arguments);
  stub_ = v1::RegistrationService::NewStub(channel_);
}

void ServiceTestClient::Prepare(grpc::ClientContext* context, double timeout_seconds) const {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<int64_t>(timeout_seconds * 1000)));
  if (!token_.empty()) context->AddMetadata("authorization", "Bearer " + token_);
}

grpc::Status ServiceTestClient::CreateSession(std::string* session_id,
                                              const v1::SessionOptions& options) {
  grpc::ClientContext context;
  Prepare(&context);
  v1::CreateSessionRequest request;
  *request.mutable_options() = options;
  v1::CreateSessionResponse response;
  grpc::Status status = stub_->CreateSession(&context, request, &response);
  *session_id = response.session_id();
  return status;
}

std::vector<v1::UploadCloudRequest> UploadMessagesFor(const std::string& session_id,
                                                      const std::vector<Eigen::Vector3f>& points,
                                                      size_t chunk_points) {
  const std::string bytes = EncodeXyz(points);
  const size_t chunk_bytes = chunk_points * kBytesPerPoint;
  std::vector<v1::UploadCloudRequest> messages;
  size_t begin = 0;
  do {
    v1::UploadCloudRequest message;
    if (messages.empty()) {
      message.set_session_id(session_id);
      message.set_point_count(points.size());
    }
    message.set_sequence(static_cast<uint32_t>(messages.size()));
    message.set_xyz(bytes.substr(begin, chunk_bytes));
    messages.push_back(std::move(message));
    begin += chunk_bytes;
  } while (begin < bytes.size());
  return messages;
}

std::vector<v1::TrackRequest> TrackFrameRequests(uint64_t frame,
                                                 const std::vector<Eigen::Vector3f>& points,
                                                 size_t chunk_points) {
  std::vector<v1::TrackRequest> requests;
  for (const v1::UploadCloudRequest& message : UploadMessagesFor("", points, chunk_points)) {
    v1::FrameChunk* chunk = requests.emplace_back().mutable_chunk();
    chunk->set_frame_index(frame);
    chunk->set_sequence(message.sequence());
    chunk->set_point_count(message.point_count());
    chunk->set_xyz(message.xyz());
  }
  return requests;
}

grpc::Status ServiceTestClient::Upload(const std::string& session_id,
                                       const std::vector<Eigen::Vector3f>& points,
                                       v1::UploadCloudResponse* response, size_t chunk_points) {
  return UploadMessages(UploadMessagesFor(session_id, points, chunk_points), response);
}

grpc::Status ServiceTestClient::UploadMessages(const std::vector<v1::UploadCloudRequest>& messages,
                                               v1::UploadCloudResponse* response) {
  grpc::ClientContext context;
  Prepare(&context);
  std::unique_ptr<grpc::ClientWriter<v1::UploadCloudRequest>> writer =
      stub_->UploadCloud(&context, response);
  for (const v1::UploadCloudRequest& message : messages) {
    if (!writer->Write(message)) break;  // the server already answered
  }
  writer->WritesDone();
  return writer->Finish();
}

grpc::Status ServiceTestClient::Register(const v1::RegisterRequest& request,
                                         v1::RegisterResponse* response, double timeout_seconds) {
  grpc::ClientContext context;
  Prepare(&context, timeout_seconds);
  return stub_->Register(&context, request, response);
}

grpc::Status ServiceTestClient::RegisterIds(const std::string& session_id, uint64_t source,
                                            uint64_t target, const v1::RegisterOptions& options,
                                            v1::RegisterResponse* response) {
  v1::RegisterRequest request;
  request.set_session_id(session_id);
  request.set_source_cloud_id(source);
  request.set_target_cloud_id(target);
  *request.mutable_options() = options;
  return Register(request, response);
}

int ServiceTestClient::HealthStatus(const std::string& service) {
  // grpc.health.v1.HealthCheckRequest{service = 1} and HealthCheckResponse{status = 1}, encoded
  // by hand: the health proto is not installed by Debian's gRPC packages.
  std::string request_bytes;
  if (!service.empty()) {
    request_bytes.push_back('\x0a');
    request_bytes.push_back(static_cast<char>(service.size()));
    request_bytes += service;
  }
  grpc::Slice slice(request_bytes);
  grpc::ByteBuffer request(&slice, 1);
  grpc::ByteBuffer response;
  grpc::GenericStub generic(channel_);
  grpc::ClientContext context;
  Prepare(&context, 10.0);
  std::promise<grpc::Status> done;
  generic.UnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request,
                    &response, [&done](grpc::Status status) { done.set_value(status); });
  grpc::Status status = done.get_future().get();
  if (!status.ok()) return -static_cast<int>(status.error_code());
  std::vector<grpc::Slice> slices;
  if (!response.Dump(&slices).ok()) return 0;
  std::string bytes;
  for (const grpc::Slice& s : slices)
    bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  if (bytes.size() == 2 && bytes[0] == '\x08') return bytes[1];
  return 0;  // UNKNOWN (the default value is not serialized)
}

namespace {

// One request (list_services = "", field 7) and the first answer of the reflection stream.
class ReflectionCall : public grpc::ClientBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  ReflectionCall() {
    const std::string bytes("\x3a\x00", 2);
    grpc::Slice slice(bytes);
    request_ = grpc::ByteBuffer(&slice, 1);
  }
  void Start() {
    StartWrite(&request_);
    StartRead(&response_);
    StartCall();
  }
  void OnWriteDone(bool) override { StartWritesDone(); }
  void OnReadDone(bool ok) override {
    if (ok) {
      std::vector<grpc::Slice> slices;
      if (response_.Dump(&slices).ok()) {
        for (const grpc::Slice& s : slices) {
          text_.append(reinterpret_cast<const char*>(s.begin()), s.size());
        }
      }
      StartRead(&response_);
    }
  }
  void OnDone(const grpc::Status&) override { done_.set_value(text_); }
  std::future<std::string> result() { return done_.get_future(); }

 private:
  grpc::ByteBuffer request_;
  grpc::ByteBuffer response_;
  std::string text_;
  std::promise<std::string> done_;
};

}  // namespace

std::string ServiceTestClient::ReflectionListServices() {
  grpc::GenericStub generic(channel_);
  grpc::ClientContext context;
  Prepare(&context, 10.0);
  ReflectionCall call;
  std::future<std::string> result = call.result();
  generic.PrepareBidiStreamingCall(&context,
                                   "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
                                   grpc::StubOptions(), &call);
  call.Start();
  return result.get();
}

std::string ScrapeMetrics(int port) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return "";
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  inet_pton(AF_INET, "127.0.0.1", &address.sin_addr);
  std::string text;
  if (connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0) {
    const std::string request = "GET /metrics HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
    if (write(fd, request.data(), request.size()) == static_cast<ssize_t>(request.size())) {
      char buffer[65536];
      for (ssize_t n; (n = read(fd, buffer, sizeof(buffer))) > 0;) text.append(buffer, n);
    }
  }
  close(fd);
  const size_t body = text.find("\r\n\r\n");
  return body == std::string::npos ? "" : text.substr(body + 4);
}

std::optional<double> MetricValue(const std::string& text, const std::string& name,
                                  const std::vector<std::pair<std::string, std::string>>& labels) {
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    if (line.empty() || line.front() == '#') continue;
    const size_t name_end = line.find_first_of("{ ");
    if (name_end == absl::string_view::npos || line.substr(0, name_end) != name) continue;
    bool all = true;
    for (const auto& [key, value] : labels) {
      if (!absl::StrContains(line, absl::StrCat(key, "=\"", value, "\""))) all = false;
    }
    if (!all) continue;
    const size_t space = line.rfind(' ');
    double number = 0.0;
    if (absl::SimpleAtod(line.substr(space + 1), &number)) return number;
  }
  return std::nullopt;
}

Eigen::Isometry3d TransformOf(const v1::RigidTransform& proto) {
  // The server always sends both; an absent one must fail the test, not read as the identity.
  if (proto.rotation_size() != 9 || proto.translation_size() != 3) {
    ADD_FAILURE() << "transform without a full rotation and translation: "
                  << proto.ShortDebugString();
    return Eigen::Isometry3d::Identity();
  }
  absl::StatusOr<Eigen::Isometry3d> T = TransformFromProto(proto, "transform");
  if (!T.ok()) {
    ADD_FAILURE() << T.status();
    return Eigen::Isometry3d::Identity();
  }
  return *T;
}

}  // namespace rpsr::server::testing
