// The wire contract must not change under clients' feet: every field keeps its number and type,
// and every method its streaming shape. A deliberate addition updates the pinned list below (append
// only); a change or removal of a pinned line is a breaking change of rpsr.v1.
#include <algorithm>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "rpsr/v1/registration.pb.h"

namespace rpsr {
namespace {

std::vector<std::string> FieldsOf(const google::protobuf::FileDescriptor& file) {
  std::vector<std::string> lines;
  for (int m = 0; m < file.message_type_count(); ++m) {
    const google::protobuf::Descriptor& message = *file.message_type(m);
    for (int f = 0; f < message.field_count(); ++f) {
      const google::protobuf::FieldDescriptor& field = *message.field(f);
      lines.push_back(absl::StrCat(message.name(), ".", field.name(), "=", field.number(), ":",
                                   field.is_repeated() ? "repeated " : "", field.type_name()));
    }
  }
  return lines;
}

TEST(RegistrationProtoTest, FieldNumbersArePinned) {
  const std::vector<std::string> pinned = {
#include "tests/proto/pinned_fields.inc"
  };
  const std::vector<std::string> now = FieldsOf(*v1::ServerInfo::descriptor()->file());
  for (const std::string& line : pinned) {
    EXPECT_THAT(now, ::testing::Contains(line)) << "a pinned field changed or vanished: " << line;
  }
  EXPECT_EQ(now.size(), pinned.size()) << "fields now:\n" << absl::StrJoin(now, "\n");
}

TEST(RegistrationProtoTest, MethodsKeepTheirStreamingShape) {
  const google::protobuf::ServiceDescriptor* service =
      v1::ServerInfo::descriptor()->file()->FindServiceByName("RegistrationService");
  ASSERT_NE(service, nullptr);
  std::vector<std::string> methods;
  for (int i = 0; i < service->method_count(); ++i) {
    const auto* method = service->method(i);
    methods.push_back(absl::StrCat(method->name(),
                                   method->client_streaming() ? " client-stream" : "",
                                   method->server_streaming() ? " server-stream" : ""));
  }
  EXPECT_THAT(methods,
              ::testing::UnorderedElementsAre("GetServerInfo", "CreateSession", "CloseSession",
                                              "UploadCloud client-stream", "ReleaseCloud",
                                              "Register", "Track client-stream server-stream"));
  EXPECT_EQ(v1::ServerInfo::descriptor()->file()->package(), "rpsr.v1");
}

}  // namespace
}  // namespace rpsr
