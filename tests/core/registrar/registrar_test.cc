// The Registrar (issue 5): the embedded model, each mode, initial guesses, batches, input errors.
#include "core/registrar/registrar.h"

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/registrar/embedded_models.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

using ::testing::Contains;
using ::testing::HasSubstr;

Octree TreeOf(const PointCloud& cloud, int max_depth = 6) {
  BarnesHutTreeOptions options;
  options.max_depth = max_depth;
  auto tree = BuildOctree(cloud, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return *std::move(tree);
}

const Registrar& SharedRegistrar() {
  static const Registrar* registrar = [] {
    auto r = Registrar::Create();
    EXPECT_TRUE(r.ok()) << r.status();
    return r->release();
  }();
  return *registrar;
}

TEST(EmbeddedModelsTest, ObjectsModelIsEmbedded) {
  EXPECT_THAT(EmbeddedModelNames(), Contains("objects"));
  auto model = FindEmbeddedModel("objects");
  ASSERT_TRUE(model.ok()) << model.status();
  EXPECT_GT(model->weights.size(), 1000000u);
  auto missing = FindEmbeddedModel("no-such-model");
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("objects"));
}

TEST(RegistrarTest, DefaultCreateLoadsTheEmbeddedObjectsModel) {
  EXPECT_THAT(SharedRegistrar().model_description(), HasSubstr("objects (embedded)"));
}

TEST(RegistrarTest, EachModeRegistersAnObjectPair) {
  PairOptions options;
  options.num_points = 2048;
  options.max_angle_deg = 10;
  options.max_translation = 0.1;
  auto pair = MakeObjectPair(options, 3);
  ASSERT_TRUE(pair.ok()) << pair.status();
  const Octree source = TreeOf(pair->source);
  const Octree target = TreeOf(pair->target);
  for (RegistrationMode mode :
       {RegistrationMode::kNet, RegistrationMode::kNetRefine, RegistrationMode::kRefine}) {
    RegistrationOptions o;
    o.mode = mode;
    auto result = SharedRegistrar().Register(source, target, o);
    ASSERT_TRUE(result.ok()) << result.status();
    const PairError e = ErrorOf(result->T_target_source, pair->T_target_source);
    std::printf("%s: rot %.3f deg, t %.4f, valid %d (%s), conf %.3f fit %.3f rmse %.4f it %d\n",
                std::string(RegistrationModeName(mode)).c_str(), e.rotation_deg, e.translation,
                result->valid, result->failure_reason.c_str(), result->confidence, result->fitness,
                result->inlier_rmse, result->iterations);
    EXPECT_EQ(result->mode, mode);
  }
}

}  // namespace
}  // namespace rpsr::core
