// The confidence (issue 5): its text format, the fit, the reliability measures, the cap on
// degenerate geometry, and the shipped calibration on a fixed seeded set of both protocols.
#include <cmath>
#include <cstdio>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/refine/symmetry_starts.h"
#include "core/registrar/confidence_calibration.h"
#include "core/registrar/confidence_model.h"
#include "core/registrar/embedded_models.h"
#include "core/synth/seeded_random.h"
#include "core/synth/shape_families.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/registrar/registrar_test_util.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

std::vector<double> Features(double fitness, double rmse_cells) {
  std::vector<double> f(kNumConfidenceFeatures, 0.0);
  f[kFeatureFitness] = fitness;
  f[kFeatureInlierRmseCells] = rmse_cells;
  return f;
}

CalibrationSample Sample(std::vector<double> features, bool success, bool valid = true) {
  CalibrationSample s;
  s.features = std::move(features);
  s.valid = valid;
  s.rotation_error_deg = success ? 0.1 : 20.0;
  s.translation_error_rel = success ? 0.001 : 0.2;
  return s;
}

TEST(ConfidenceModelTest, TextRoundTrip) {
  ConfidenceModel model;
  model.bias = -0.5;
  model.features = {{kFeatureFitness, 0.8, 0.1, 2.0}, {kFeatureModeNet, 0.3, 0.4, -3.0}};
  model.isotonic_x = {0.1, 0.5, 0.9};
  model.isotonic_y = {0.0, 0.4, 0.95};
  model.degenerate_cap = 0.02;
  auto parsed = ConfidenceModel::Parse(model.ToText("a comment\nover two lines"));
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->bias, model.bias);
  ASSERT_EQ(parsed->features.size(), 2u);
  EXPECT_EQ(parsed->features[1].index, kFeatureModeNet);
  EXPECT_EQ(parsed->features[1].weight, -3.0);
  EXPECT_EQ(parsed->isotonic_y, model.isotonic_y);
  EXPECT_EQ(parsed->degenerate_cap, 0.02);
  const std::vector<double> x = Features(0.9, 0.1);
  EXPECT_DOUBLE_EQ(parsed->Probability(x), model.Probability(x));
  EXPECT_TRUE(parsed->calibrated);
  EXPECT_FALSE(ConfidenceModel::Uncalibrated().calibrated);
}

TEST(ConfidenceModelTest, ParseErrorsNameTheLine) {
  EXPECT_FALSE(ConfidenceModel::Parse("").ok());
  EXPECT_FALSE(ConfidenceModel::Parse("bias 1\n").ok());  // no header
  auto unknown = ConfidenceModel::Parse("rpsr_confidence 1\nfeature colour 0 1 1\n");
  ASSERT_FALSE(unknown.ok());
  EXPECT_THAT(unknown.status().message(), HasSubstr("line 2"));
  EXPECT_THAT(unknown.status().message(), HasSubstr("colour"));
  EXPECT_FALSE(ConfidenceModel::Parse("rpsr_confidence 1\nfeature fitness 0 0 1\n").ok());
  EXPECT_FALSE(ConfidenceModel::Parse("rpsr_confidence 1\nisotonic 0.5 0.9 0.4 0.95\n").ok());
  EXPECT_FALSE(ConfidenceModel::Parse("rpsr_confidence 1\nbias nan\n").ok());
  EXPECT_FALSE(ConfidenceModel::Parse("rpsr_confidence 2\n").ok());
}

TEST(ConfidenceModelTest, InvalidIsZeroAndDegenerateIsCapped) {
  ConfidenceModel model;
  model.bias = 10.0;  // would say 0.99995 to anything
  const std::vector<double> x = Features(1.0, 0.1);
  EXPECT_GT(model.Confidence(x, true, 0), 0.99);
  EXPECT_EQ(model.Confidence(x, false, 0), 0.0);
  EXPECT_LE(model.Confidence(x, true, 1), model.degenerate_cap);
  EXPECT_LE(model.Confidence(x, true, 3), 0.05);
}

TEST(ConfidenceModelTest, IsotonicMapInterpolatesAndRunsOnToTheCorners) {
  ConfidenceModel model;
  model.isotonic_x = {0.2, 0.8};
  model.isotonic_y = {0.1, 0.7};
  auto at = [&](double raw) {
    model.bias = std::log(raw / (1.0 - raw));  // the logistic output is `raw`
    return model.Probability(Features(0, 0));
  };
  EXPECT_NEAR(at(0.5), 0.4, 1e-12);
  EXPECT_NEAR(at(0.1), 0.05, 1e-12);  // on the line from (0, 0) to (0.2, 0.1)
  EXPECT_NEAR(at(0.9), 0.85, 1e-12);  // on the line from (0.8, 0.7) to (1, 1)
  EXPECT_LT(at(0.95), at(0.99));      // no flat ends
  EXPECT_GT(at(0.01), at(0.001));
}

TEST(ConfidenceFitTest, ThePureTopBlockIsNeverCertain) {
  std::vector<CalibrationSample> samples;
  for (int i = 0; i < 200; ++i) {
    const double fitness = i / 200.0;
    samples.push_back(Sample(Features(fitness, 0), fitness > 0.5));
  }
  auto model = FitConfidenceModel(samples);
  ASSERT_TRUE(model.ok()) << model.status();
  ASSERT_GE(model->isotonic_y.size(), 2u);
  EXPECT_LT(model->isotonic_y.back(), 1.0);
  for (size_t i = 1; i < model->isotonic_y.size(); ++i) {
    EXPECT_GT(model->isotonic_y[i], model->isotonic_y[i - 1]);
  }
}

TEST(ReliabilityTest, PerfectAndKnownCases) {
  std::vector<CalibrationSample> samples;
  std::vector<double> confidences;
  for (int i = 0; i < 10; ++i) {
    samples.push_back(Sample(Features(0, 0), i < 5));
    confidences.push_back(i < 5 ? 1.0 : 0.0);
  }
  ReliabilityReport r = MeasureReliability(samples, confidences);
  EXPECT_EQ(r.successes, 5);
  EXPECT_EQ(r.failures, 5);
  EXPECT_NEAR(r.ece, 0.0, 1e-12);
  EXPECT_NEAR(r.auroc, 1.0, 1e-12);
  EXPECT_NEAR(r.brier, 0.0, 1e-12);
  // Everyone at 0.5 with half successes: calibrated (ECE 0) but no ranking (AUROC 0.5).
  std::fill(confidences.begin(), confidences.end(), 0.5);
  r = MeasureReliability(samples, confidences);
  EXPECT_NEAR(r.ece, 0.0, 1e-12);
  EXPECT_NEAR(r.auroc, 0.5, 1e-12);
  // Everyone at 0.9 with half successes: ECE 0.4.
  std::fill(confidences.begin(), confidences.end(), 0.9);
  EXPECT_NEAR(MeasureReliability(samples, confidences).ece, 0.4, 1e-12);
  // Reversed ranking.
  for (int i = 0; i < 10; ++i) confidences[i] = i < 5 ? 0.2 : 0.8;
  EXPECT_NEAR(MeasureReliability(samples, confidences).auroc, 0.0, 1e-12);
}

TEST(ConfidenceFitTest, LearnsAMonotoneRelationAndIsCalibratedInSample) {
  // Success probability rises with fitness: p = sigmoid(12 (fitness - 0.7)).
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<CalibrationSample> samples;
  for (int i = 0; i < 4000; ++i) {
    const double fitness = u(rng);
    const double p = 1.0 / (1.0 + std::exp(-12.0 * (fitness - 0.7)));
    samples.push_back(Sample(Features(fitness, u(rng)), u(rng) < p));
  }
  samples.push_back(Sample(Features(1.0, 0.0), true, /*valid=*/false));  // ignored by the fit
  auto model = FitConfidenceModel(samples);
  ASSERT_TRUE(model.ok()) << model.status();
  EXPECT_GT(model->Probability(Features(0.95, 0.5)), 0.9);
  EXPECT_LT(model->Probability(Features(0.3, 0.5)), 0.05);
  std::vector<double> confidences;
  for (const CalibrationSample& s : samples) {
    confidences.push_back(model->Confidence(s.features, s.valid, s.num_degenerate));
  }
  const ReliabilityReport r = MeasureReliability(samples, confidences);
  EXPECT_LT(r.ece, 0.03);
  // The fitness weight is positive; the noise feature's is small.
  for (const ConfidenceModel::Feature& f : model->features) {
    if (f.index == kFeatureFitness) {
      EXPECT_GT(f.weight, 1.0);
    }
    if (f.index == kFeatureInlierRmseCells) {
      EXPECT_LT(std::abs(f.weight), 0.3);
    }
  }
  // One outcome only: nothing to fit.
  std::vector<CalibrationSample> all_good = {Sample(Features(1, 0), true),
                                             Sample(Features(0.9, 0), true)};
  EXPECT_EQ(FitConfidenceModel(all_good).status().code(), absl::StatusCode::kInvalidArgument);
}

// The shipped calibration on a fixed seeded set of both protocols (unseen objects in all 21
// settings, and simulated LiDAR pairs), every mode: loosely calibrated and ranking successes
// above failures. The held-out figures at full size are in tests/bench/results/.
TEST(ShippedCalibrationTest, ReliableOnASmallSeededSetOfBothProtocols) {
  auto embedded = FindEmbeddedModel("objects");
  ASSERT_TRUE(embedded.ok());
  ASSERT_TRUE(embedded->confidence.has_value())
      << "core/models/objects/confidence.txt is not shipped (rpsr calibrate writes it)";
  CalibrationSetOptions options;
  options.seed = 2024;  // neither the fit's seeds nor the held-out report's
  options.object_splits = {ObjectSplit::kM2Unseen};
  options.object_pairs_per_setting = 2;
  options.lidar_pairs_per_offset = 2;
  options.lidar_frame_offsets = {5};
  options.lidar_tree_depth = 8;
  options.threads = 2;
  auto samples = CollectCalibrationSamples(testing_util::SharedRegistrar(), options);
  ASSERT_TRUE(samples.ok()) << samples.status();
  ASSERT_EQ(samples->size(), (21u * 2u + 2u) * 3u);
  std::vector<double> confidences;
  double success_sum = 0.0, failure_sum = 0.0;
  int successes = 0, failures = 0;
  for (const CalibrationSample& s : *samples) {
    confidences.push_back(s.confidence);
    EXPECT_GE(s.confidence, 0.0);
    EXPECT_LE(s.confidence, 1.0);
    if (!s.valid) {
      EXPECT_EQ(s.confidence, 0.0);
    }
    if (s.num_degenerate > 0) {
      EXPECT_LE(s.confidence, 0.05);
    }
    if (s.success()) {
      success_sum += s.confidence;
      ++successes;
    }
    if (s.failure()) {
      failure_sum += s.confidence;
      ++failures;
    }
  }
  ASSERT_GT(successes, 10);
  ASSERT_GT(failures, 10);
  const ReliabilityReport r = MeasureReliability(*samples, confidences);
  std::printf(
      "%zu samples: ECE %.3f, AUROC %.3f, mean confidence of successes %.3f, failures %.3f\n",
      samples->size(), r.ece, r.auroc, success_sum / successes, failure_sum / failures);
  EXPECT_LT(r.ece, 0.12);
  EXPECT_GT(r.auroc, 0.9);
  EXPECT_GT(success_sum / successes, failure_sum / failures + 0.4);
}

// Partial views join the calibration set after the paper's 21 settings, whose pairs (seeded by
// their index) stay the same, so held-out figures with and without them compare.
TEST(CalibrationSetTest, PartialViewsAreAppendedWithoutChangingTheOtherPairs) {
  CalibrationSetOptions options;
  options.seed = 2025;
  options.object_splits = {ObjectSplit::kM2Unseen};
  options.object_pairs_per_setting = 1;
  options.lidar_pairs_per_offset = 0;
  options.modes = {RegistrationMode::kNet};
  options.threads = 2;
  auto paper = CollectCalibrationSamples(testing_util::SharedRegistrar(), options);
  options.partial_views = true;
  auto with_partial = CollectCalibrationSamples(testing_util::SharedRegistrar(), options);
  ASSERT_TRUE(paper.ok()) << paper.status();
  ASSERT_TRUE(with_partial.ok()) << with_partial.status();
  ASSERT_EQ(paper->size(), 21u);
  ASSERT_EQ(with_partial->size(), 26u);
  for (size_t i = 0; i < paper->size(); ++i) {
    EXPECT_EQ((*with_partial)[i].setting, (*paper)[i].setting);
    EXPECT_EQ((*with_partial)[i].rotation_error_deg, (*paper)[i].rotation_error_deg) << i;
    EXPECT_EQ((*with_partial)[i].translation_error_rel, (*paper)[i].translation_error_rel) << i;
  }
  std::set<std::string> partial_settings;
  for (size_t i = paper->size(); i < with_partial->size(); ++i) {
    EXPECT_THAT((*with_partial)[i].setting, HasSubstr("partial_views@"));
    partial_settings.insert((*with_partial)[i].setting);
  }
  EXPECT_EQ(partial_settings.size(), 5u);  // one per level
}

// A gear refined from a start a tooth off ends a tooth off, fitting as well as at the truth; the
// twin margin (how many more of the target's pin nodes the answer's pin meets than its best twin's
// does) says so, and the shipped confidence reads it. An object without a symmetry reads 1.
TEST(ShippedCalibrationTest, AGearATurnOffReadsANegativeTwinMargin) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  int gears = 0;
  bool sofa_seen = false;
  for (uint64_t i = 0; i < 200 && (gears < 2 || !sofa_seen); ++i) {
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(2, i));
    ASSERT_TRUE(pair.ok()) << pair.status();
    const std::string& family = ShapeFamilies()[pair->family_index].name;
    if ((family != "gear" || gears == 2) && (family != "sofa" || sofa_seen)) continue;
    const Octree source = testing_util::TreeOf(pair->source);
    const Octree target = testing_util::TreeOf(pair->target);
    RegistrationOptions refine;
    refine.mode = RegistrationMode::kRefine;
    refine.initial_T_target_source = pair->T_target_source;
    auto at_truth = testing_util::SharedRegistrar().Register(source, target, refine);
    ASSERT_TRUE(at_truth.ok()) << at_truth.status();
    const double truth_margin = at_truth->confidence_features[kFeatureSymmetricTwinMargin];
    if (family == "sofa") {
      EXPECT_EQ(truth_margin, 1.0);  // no twin
      sofa_seen = true;
      continue;
    }
    ++gears;
    const std::vector<SelfSymmetry> teeth = FindSelfSymmetries(target);
    ASSERT_FALSE(teeth.empty());
    refine.initial_T_target_source = teeth.front().S * pair->T_target_source;
    auto off = testing_util::SharedRegistrar().Register(source, target, refine);
    ASSERT_TRUE(off.ok()) << off.status();
    SCOPED_TRACE(testing::Message() << "pair " << i);
    ASSERT_GT(ErrorOf(off->T_target_source, pair->T_target_source).rotation_deg, 5.0);
    // The pins meet at the truth (about 1 more than any twin) and not a tooth off (about -1).
    EXPECT_GE(truth_margin, 0.5);
    EXPECT_LE(off->confidence_features[kFeatureSymmetricTwinMargin], -0.5);
  }
  EXPECT_EQ(gears, 2);
  EXPECT_TRUE(sofa_seen);
  // The shipped calibration reads it, a higher margin raising the confidence.
  auto embedded = FindEmbeddedModel("objects");
  ASSERT_TRUE(embedded.ok() && embedded->confidence.has_value());
  auto model = ConfidenceModel::Parse(*embedded->confidence);
  ASSERT_TRUE(model.ok()) << model.status();
  bool read = false;
  for (const ConfidenceModel::Feature& f : model->features) {
    if (f.index != kFeatureSymmetricTwinMargin) continue;
    read = true;
    EXPECT_GT(f.weight, 0.0);
  }
  EXPECT_TRUE(read);
}

// Pairs with nothing in common (two random volumes, two objects of different families, two scans
// of different streets): every answer counts as a failure, and the shipped confidence keeps them
// low on average (held-out, `rpsr calibrate --evaluate --object_pairs 0 --lidar_pairs 8
// --unrelated_pairs 32`: mean 0.014, tests/bench/results/confidence_heldout_unrelated.csv).
// Samples of scan pairs 5 frames apart (trees to depth 8) and of unrelated pairs of each kind, no
// object pairs, all three modes.
absl::StatusOr<std::vector<CalibrationSample>> ScanAndUnrelatedSamples(uint64_t seed,
                                                                       int lidar_pairs,
                                                                       int unrelated_per_kind) {
  CalibrationSetOptions options;
  options.seed = seed;
  options.object_pairs_per_setting = 0;
  options.lidar_pairs_per_offset = lidar_pairs;
  options.lidar_frame_offsets = {5};
  options.lidar_tree_depth = 8;
  options.unrelated_pairs_per_kind = unrelated_per_kind;
  options.threads = 2;
  return CollectCalibrationSamples(testing_util::SharedRegistrar(), options);
}

TEST(ShippedCalibrationTest, UnrelatedPairsAreFailuresAndReadLowConfidence) {
  auto samples =
      ScanAndUnrelatedSamples(/*seed=*/2024, /*lidar_pairs=*/1, /*unrelated_per_kind=*/2);
  ASSERT_TRUE(samples.ok()) << samples.status();
  ASSERT_EQ(samples->size(), (1u + 2u * 3u) * 3u);
  double sum = 0.0;
  int unrelated = 0;
  std::set<std::string> kinds;
  for (const CalibrationSample& s : *samples) {
    if (s.protocol != "unrelated") continue;
    ++unrelated;
    kinds.insert(s.setting);
    EXPECT_TRUE(s.failure()) << s.setting;
    EXPECT_FALSE(s.success()) << s.setting;
    sum += s.confidence;
  }
  ASSERT_EQ(unrelated, 18);
  EXPECT_EQ(kinds,
            (std::set<std::string>{"unrelated/objects", "unrelated/scans", "unrelated/volumes"}));
  std::printf("unrelated pairs: mean confidence %.3f over %d answers\n", sum / unrelated,
              unrelated);
  EXPECT_LT(sum / unrelated, 0.2);
}

// Partial views on both sides (DisturbanceKind::kPartialViews) are not in the calibration set, yet
// the README says the confidence stays honest there on average: on the unseen study's first 60
// pairs (pair seed 1, as `rpsr eval --disturbance partial --level 2`), each cloud cropped by 20%,
// session 38 read a mean confidence of 0.738 against a success rate (1 deg, 1% of the extent) of
// 0.717, one answer at 0.9 or more beyond (5 deg, 5%) (a sofa slid along its length), successes at
// 0.84 and failures at 0.45 on average.
TEST(ShippedCalibrationTest, PartialViewsReadHonestlyOnAverage) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  options.disturbance = DisturbanceKind::kPartialViews;
  options.disturbance_level = 2;
  constexpr int kPairs = 60;
  double confidence_sum = 0.0, success_confidence = 0.0, failure_confidence = 0.0;
  int successes = 0, failures = 0, confident_failures = 0;
  for (int i = 0; i < kPairs; ++i) {
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(1, i));
    ASSERT_TRUE(pair.ok()) << pair.status();
    const Octree source = testing_util::TreeOf(pair->source, 6);
    const Octree target = testing_util::TreeOf(pair->target, 6);
    absl::StatusOr<RegistrationResult> r = testing_util::SharedRegistrar().Register(source, target);
    ASSERT_TRUE(r.ok()) << r.status();
    CalibrationSample s;
    const PairError e = ErrorOf(r->T_target_source, pair->T_target_source);
    s.rotation_error_deg = e.rotation_deg;
    s.translation_error_rel = e.translation / ConfidenceExtent(target);
    confidence_sum += r->confidence;
    if (s.success()) {
      ++successes;
      success_confidence += r->confidence;
    }
    if (s.failure()) {
      ++failures;
      failure_confidence += r->confidence;
      if (r->confidence >= 0.9) ++confident_failures;
    }
  }
  ASSERT_GT(successes, 20);
  ASSERT_GT(failures, 5);
  const double mean = confidence_sum / kPairs;
  const double rate = static_cast<double>(successes) / kPairs;
  std::printf(
      "partial views at 20%%: mean confidence %.3f, success rate %.3f, successes %.3f, failures "
      "%.3f, %d failures at 0.9 or more\n",
      mean, rate, success_confidence / successes, failure_confidence / failures,
      confident_failures);
  EXPECT_NEAR(mean, rate, 0.08);
  EXPECT_GT(success_confidence / successes, failure_confidence / failures + 0.25);
  EXPECT_LE(confident_failures, 2);
}

// The turn contrast (confidence_model.h) tells a fit that singles out its pose from one that any
// pose would give: right answers on scans lose most of their partners when turned by 45 degrees
// (held out: 0.64-0.88), two volumes of random points hardly any (-0.01-0.15), and the shipped
// calibration reads both (volumes' confidence up to 0.35 held out, 0.57 before the feature).
TEST(ShippedCalibrationTest, RandomVolumesReadALowTurnContrastAndRightScansAHighOne) {
  auto samples =
      ScanAndUnrelatedSamples(/*seed=*/2025, /*lidar_pairs=*/2, /*unrelated_per_kind=*/3);
  ASSERT_TRUE(samples.ok()) << samples.status();
  int volumes = 0, right_scans = 0;
  double volume_contrast = -1.0, volume_confidence = 0.0, scan_contrast = 1.0;
  for (const CalibrationSample& s : *samples) {
    if (s.mode == RegistrationMode::kNet) continue;  // the network's raw estimate is rarely right
    ASSERT_EQ(s.features.size(), static_cast<size_t>(kNumConfidenceFeatures));
    const double contrast = s.features[kFeatureTurnContrast];
    SCOPED_TRACE(testing::Message() << s.setting << " " << RegistrationModeName(s.mode));
    if (s.setting == "unrelated/volumes") {
      ++volumes;
      volume_contrast = std::max(volume_contrast, contrast);
      volume_confidence = std::max(volume_confidence, s.confidence);
      EXPECT_LT(contrast, 0.2);
      EXPECT_LT(s.confidence, 0.5);
    } else if (s.protocol == "lidar" && s.success()) {
      ++right_scans;
      scan_contrast = std::min(scan_contrast, contrast);
      EXPECT_GT(contrast, 0.4);
    }
  }
  std::printf(
      "random volumes: turn contrast and confidence at most %.3f and %.3f; right scans' "
      "contrast at least %.3f\n",
      volume_contrast, volume_confidence, scan_contrast);
  EXPECT_EQ(volumes, 6);  // three pairs, two modes
  EXPECT_GE(right_scans, 2);
}

}  // namespace
}  // namespace rpsr::core
