// Between the wire types of proto/rpsr/v1 and core's plain types, with the validation of what a
// client may send (a rigid initial guess, a known mode, sane pass counts).
#ifndef RPSR_SERVER_PROTO_CONVERT_H_
#define RPSR_SERVER_PROTO_CONVERT_H_

#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/registrar/registrar.h"
#include "core/tree/bh_tree.h"
#include "grpcpp/support/status.h"
#include "rpsr/v1/registration.pb.h"

namespace rpsr::server {

// Most network passes a request may ask for (each pass is one forward pass).
inline constexpr int kMaxPasses = 16;

// A rigid transform from `rotation` (9, row-major, orthonormal with det +1 within 1e-3) or, when
// empty, `quaternion` (any non-zero norm), and `translation` (3 or none). InvalidArgument naming
// `what` otherwise.
absl::StatusOr<Eigen::Isometry3d> TransformFromProto(const v1::RigidTransform& proto,
                                                     absl::string_view what);
void TransformToProto(const Eigen::Isometry3d& T, v1::RigidTransform* proto);

// Mode ("" = net+refine), passes in [0, kMaxPasses], the initial guess when present.
absl::StatusOr<core::RegistrationOptions> OptionsFromProto(const v1::RegisterOptions& proto);

void ResultToProto(const core::RegistrationResult& result, v1::RegistrationResult* proto);

void TreeStatsToProto(const core::Octree& tree, double build_seconds, v1::TreeStats* proto);

// absl and gRPC share the canonical codes; the message is kept.
grpc::Status ToGrpcStatus(const absl::Status& status);

}  // namespace rpsr::server

#endif  // RPSR_SERVER_PROTO_CONVERT_H_
