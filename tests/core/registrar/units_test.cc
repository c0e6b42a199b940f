// The answer must not depend on the clouds' units or on where they lie from their frame's origin:
// the same pair in millimetres, in kilometres or a hundred units away is the same registration.
// (Found by scaling the unseen object pairs: the refinement's damping, relative to a mean over
// rotation and translation entries of different units, froze the rotation of clouds scaled by
// 1/1024 (refine from the identity: median error 0.11 -> 0.86 degree); pose differences taken as
// translation differences made the confidence read 0 or 1 for clouds 1,000 units away.)
#include <cmath>
#include <vector>

#include "core/cloud/point_cloud.h"
#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/registrar/registrar.h"
#include "gtest/gtest.h"
#include "tests/core/registrar/registrar_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::AsymmetricObjectPair;
using testing_util::SharedRegistrar;
using testing_util::TreeOf;

// p -> scale * p + offset for every point.
PointCloud Placed(const PointCloud& cloud, float scale, const Eigen::Vector3f& offset) {
  PointCloud out = cloud;
  for (Eigen::Vector3f& p : out.points) p = scale * p + offset;
  return out;
}

// The truth of a pair whose clouds were both placed so.
Eigen::Isometry3d PlacedTruth(const Eigen::Isometry3d& T, double scale,
                              const Eigen::Vector3d& offset) {
  Eigen::Isometry3d out = T;
  out.translation() = scale * T.translation() + offset - T.linear() * offset;
  return out;
}

struct Answer {
  PairError error;  // against the truth, translation divided by the scale
  // How far from where the truth puts it the answer puts the source's centre of mass, divided by
  // the scale (unlike the translation error, it does not grow with the distance from the origin).
  double centre_error = 0.0;
  double confidence = 0.0;
  bool valid = false;
};

Answer RegisterPlaced(const ObjectPair& pair, float scale, const Eigen::Vector3f& offset,
                      RegistrationMode mode) {
  const Octree source = TreeOf(Placed(pair.source, scale, offset));
  const Octree target = TreeOf(Placed(pair.target, scale, offset));
  RegistrationOptions options;
  options.mode = mode;
  auto result = SharedRegistrar().Register(source, target, options);
  EXPECT_TRUE(result.ok()) << result.status();
  Answer a;
  if (!result.ok()) return a;
  const Eigen::Isometry3d truth = PlacedTruth(pair.T_target_source, scale, offset.cast<double>());
  a.error = ErrorOf(result->T_target_source, truth);
  a.error.translation /= scale;
  const Eigen::Vector3d centre = source.level(0).center_of_mass[0].cast<double>();
  a.centre_error = (result->T_target_source * centre - truth * centre).norm() / scale;
  a.confidence = result->confidence;
  a.valid = result->valid;
  return a;
}

// Scaling by powers of two is exact in floating point: every stage must then give the same
// answer, scaled, to rounding.
TEST(RegistrarUnitsTest, AnswersDoNotDependOnTheCloudsScale) {
  for (uint64_t seed : {20, 40}) {
    const ObjectPair pair = AsymmetricObjectPair(seed, /*max_angle_deg=*/45.0);
    for (RegistrationMode mode : {RegistrationMode::kNetRefine, RegistrationMode::kRefine}) {
      const Answer unit = RegisterPlaced(pair, 1.0f, Eigen::Vector3f::Zero(), mode);
      for (float scale : {1.0f / 1024.0f, 1024.0f}) {
        const Answer scaled = RegisterPlaced(pair, scale, Eigen::Vector3f::Zero(), mode);
        SCOPED_TRACE(testing::Message() << "seed " << seed << ", mode "
                                        << RegistrationModeName(mode) << ", scale " << scale);
        EXPECT_NEAR(scaled.error.rotation_deg, unit.error.rotation_deg, 1e-3);
        EXPECT_NEAR(scaled.error.translation, unit.error.translation, 1e-5);
        EXPECT_NEAR(scaled.confidence, unit.confidence, 1e-3);
        EXPECT_EQ(scaled.valid, unit.valid);
      }
    }
  }
}

// Moved away from the origin, the clouds' coordinates lose a little precision (float), so the
// answers may differ in the last digits, not in substance; the confidence reads the same.
TEST(RegistrarUnitsTest, AnswersDoNotDependOnWhereTheCloudsLie) {
  int confident = 0;
  for (uint64_t seed : {20, 40, 60}) {
    const ObjectPair pair = AsymmetricObjectPair(seed, /*max_angle_deg=*/45.0);
    const Answer home =
        RegisterPlaced(pair, 1.0f, Eigen::Vector3f::Zero(), RegistrationMode::kNetRefine);
    const Answer away = RegisterPlaced(pair, 1.0f, Eigen::Vector3f(300.0f, -200.0f, 100.0f),
                                       RegistrationMode::kNetRefine);
    SCOPED_TRACE(testing::Message() << "seed " << seed);
    EXPECT_NEAR(away.error.rotation_deg, home.error.rotation_deg, 0.05);
    EXPECT_NEAR(away.centre_error, home.centre_error, 1e-3);
    EXPECT_NEAR(away.confidence, home.confidence, 0.05);
    EXPECT_EQ(away.valid, home.valid);
    if (home.confidence > 0.5) ++confident;
  }
  EXPECT_GE(confident, 2);  // the comparison is between confident answers, not two failures
}

}  // namespace
}  // namespace rpsr::core
