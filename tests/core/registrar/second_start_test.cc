// net+refine's second start (RegistrationOptions::also_refine_from_initial): the answer is the
// refinement from the network's estimate or the one from the initial guess, the latter only when
// the first is not confident and the latter is clearly better; on consecutive simulated scans,
// where the shipped object network is off its training distribution, the answer is right.
#include <cmath>
#include <cstdio>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/data/training_pairs.h"
#include "core/data/transform_convention.h"
#include "core/refine/node_closeness.h"
#include "core/refine/symmetry_starts.h"
#include "core/refine/weak_direction_start.h"
#include "core/registrar/confidence_calibration.h"
#include "core/registrar/registrar.h"
#include "core/synth/lidar_sequence.h"
#include "core/synth/seeded_random.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/registrar/registrar_test_util.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using testing_util::AnswersWithAndWithout;
using testing_util::RegisterStudyPair;
using testing_util::SharedRegistrar;
using testing_util::TreeOf;

// Each test here isolates one start by comparing answers with and without it. The later network
// passes' start, which comes before all of them, is off: it would rescue some of the pairs these
// tests need wrong without their start (later_passes_test.cc covers it). So is the
// weak-direction start, which comes after the round-axis start and brought a mug that start
// turns back within 2.05 degrees without it (its own test below runs the defaults).
RegistrationOptions EveryPassFirst() {
  RegistrationOptions options;
  options.later_passes_only_when_unconfident = false;
  options.search_weak_direction_start = false;
  return options;
}

TEST(RegistrarSecondStartTest, KeepsTheBetterOfTheNetworksStartAndTheGuess) {
  LidarSequenceOptions sequence;
  sequence.frame_count = 40;
  sequence.seed = 7;
  sequence.thread_count = 1;
  auto simulator = LidarSequenceSimulator::Create(sequence);
  ASSERT_TRUE(simulator.ok()) << simulator.status();
  int from_guess = 0;
  for (int first : {0, 12, 24, 30}) {
    const Octree source = TreeOf(simulator->SimulateFrame(first).cloud, 9);
    const Octree target = TreeOf(simulator->SimulateFrame(first + 5).cloud, 9);
    const Eigen::Isometry3d truth =
        simulator->T_world_lidar()[first + 5].inverse() * simulator->T_world_lidar()[first];

    // Three network passes (net+refine's default is two, kNetRefinePasses): with them the
    // network's start goes astray on one of these frames, the case this test needs; with two
    // it does on none of the four.
    RegistrationOptions defaults = EveryPassFirst();
    defaults.passes = 3;
    defaults.search_scene_start = false;  // the third start has its own test below
    RegistrationOptions network_start = defaults;
    network_start.also_refine_from_initial = false;
    RegistrationOptions guess_start = EveryPassFirst();
    guess_start.mode = RegistrationMode::kRefine;
    auto a = SharedRegistrar().Register(source, target, network_start);
    auto b = SharedRegistrar().Register(source, target, guess_start);
    auto both = SharedRegistrar().Register(source, target, defaults);  // second start on
    ASSERT_TRUE(a.ok() && b.ok() && both.ok());

    const bool is_a = both->T_target_source.isApprox(a->T_target_source, 1e-9);
    const bool is_b = both->T_target_source.isApprox(b->T_target_source, 1e-9);
    ASSERT_TRUE(is_a || is_b) << "frame " << first << ": neither start's answer";
    // The result says which start it came from and how many ran.
    EXPECT_EQ(a->start, "network");
    EXPECT_EQ(a->starts, 1);
    EXPECT_EQ(b->start, "initial");
    EXPECT_EQ(b->starts, 1);
    EXPECT_EQ(both->start, is_a ? "network" : "initial") << "frame " << first;
    // A confident first answer is kept alone; the second start ran where the answer is its own.
    if (a->confidence >= 0.9) {
      EXPECT_EQ(both->starts, 1) << "frame " << first;
    }
    if (!is_a) {
      EXPECT_EQ(both->starts, 2) << "frame " << first;
    }
    if (!is_a) {
      ++from_guess;
      EXPECT_LT(a->confidence, 0.9) << "a confident first answer is kept, frame " << first;
      EXPECT_TRUE(b->valid);
      // Clearly better, or as good by fitness with its finest nodes closer to the target's.
      const int finest = 9;
      const double a_cells = MeanNodeDistanceCells(source, target, a->T_target_source, finest);
      const double b_cells = MeanNodeDistanceCells(source, target, b->T_target_source, finest);
      EXPECT_TRUE(!a->valid || b->fitness > a->fitness + 0.01 ||
                  (b->fitness >= a->fitness - 0.01 && b_cells < 0.99 * a_cells))
          << "frame " << first;
    }
    EXPECT_EQ(both->net_T_target_source.matrix(), a->net_T_target_source.matrix());
    const PairError e = ErrorOf(both->T_target_source, truth);
    EXPECT_LT(e.rotation_deg, 1.0) << "frame " << first;
    EXPECT_LT(e.translation, 0.3) << "frame " << first;
    EXPECT_TRUE(both->valid) << "frame " << first << ": " << both->failure_reason;
  }
  std::printf("answers from the initial guess's start: %d of 4\n", from_guess);
  // The object network is off its training distribution on scans: on these frames the second
  // start has to win at least once (1 of 4 when written), or this test no longer covers it.
  EXPECT_GE(from_guess, 1);
}

// Two starts that fit equally well by fitness: a helix spring of the unseen object study (`rpsr
// eval --protocol objects --split unseen --count 100`, clean, pair 16), whose network start
// settles in a twin turned along the screw (11.6 degrees off, fitness 1.000 like the truth's).
// The refinement from the identity finds the pose; fitness cannot tell the two apart, the finest
// nodes' distance to the target's can (MeanNodeDistanceCells), and the answer is the closer one.
TEST(RegistrarSecondStartTest, OfTwoEquallyFittingAnswersTheCloserOneIsKept) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  auto pair = MakeObjectPair(options, DeriveSeed(1, 16));
  ASSERT_TRUE(pair.ok()) << pair.status();
  const Octree source = TreeOf(pair->source);
  const Octree target = TreeOf(pair->target);
  // The weak-direction chamfer would move the network start's twin 3.7 degrees from the pose
  // (registrar_test's RegistrarWeakDirectionChamferTest covers it), the round-axis start's screw
  // turns bring it back to 0.5 (RegistrarScrewTurnsTest) and the far-count valley to 2.5
  // (RegistrarFarValleyTest); all off in every arm, so that this test keeps covering the choice
  // between the two starts.
  RegistrationOptions every_pass = EveryPassFirst();
  every_pass.search_weak_direction_chamfer = false;
  every_pass.round_axis_screw_turns = false;
  every_pass.search_far_valley = false;
  RegistrationOptions network_start = every_pass;
  network_start.also_refine_from_initial = false;
  RegistrationOptions guess_start = every_pass;
  guess_start.mode = RegistrationMode::kRefine;
  auto a = SharedRegistrar().Register(source, target, network_start);
  auto b = SharedRegistrar().Register(source, target, guess_start);
  auto both = SharedRegistrar().Register(source, target, every_pass);
  ASSERT_TRUE(a.ok() && b.ok() && both.ok());
  const PairError twin = ErrorOf(a->T_target_source, pair->T_target_source);
  const PairError found = ErrorOf(b->T_target_source, pair->T_target_source);
  std::printf("network start %.2f deg (fitness %.3f), identity start %.2f deg (fitness %.3f)\n",
              twin.rotation_deg, a->fitness, found.rotation_deg, b->fitness);
  // The case this test needs: the network's start in the twin, the identity's at the pose, and
  // neither clearly better by fitness.
  ASSERT_GT(twin.rotation_deg, 5.0);
  ASSERT_LT(found.rotation_deg, 2.0);
  ASSERT_TRUE(a->valid && b->valid);
  ASSERT_NEAR(a->fitness, b->fitness, 0.01);
  EXPECT_LT(MeanNodeDistanceCells(source, target, b->T_target_source, 6),
            0.99 * MeanNodeDistanceCells(source, target, a->T_target_source, 6));
  EXPECT_EQ(both->start, "initial");
  EXPECT_EQ(both->starts, 2);
  EXPECT_TRUE(both->T_target_source.isApprox(b->T_target_source, 1e-9));
  EXPECT_LT(ErrorOf(both->T_target_source, pair->T_target_source).rotation_deg, 2.0);
}

// net+refine's third start (RegistrationOptions::search_scene_start) on simulated scans ten
// frames apart whose motion (10 m and more) neither the network's start nor the identity's
// pulls in: with the searched start the answers reach (1 deg, 0.3 m) and are valid; without it
// they do not.
TEST(RegistrarSecondStartTest, SearchedStartRescuesMotionsOfTenMetres) {
  const RegistrationPairGenerator pairs = CalibrationLidarPairs(11, 10);
  for (int index : {25, 31}) {  // 15-16 m off without the search (28 and 56 were too before
                                // the coarse stages searched two cells)
    auto pair = pairs(index);
    ASSERT_TRUE(pair.ok()) << pair.status();
    const Octree source = TreeOf(pair->source, 9);
    const Octree target = TreeOf(pair->target, 9);
    RegistrationOptions without = EveryPassFirst();
    without.search_scene_start = false;
    without.check_sensor_aligned_answers = false;  // nor the other search
    auto a = SharedRegistrar().Register(source, target, without);
    auto b = SharedRegistrar().Register(source, target, EveryPassFirst());
    ASSERT_TRUE(a.ok() && b.ok());
    const PairError ea = ErrorOf(a->T_target_source, pair->T_target_source);
    const PairError eb = ErrorOf(b->T_target_source, pair->T_target_source);
    EXPECT_FALSE(ea.rotation_deg < 1.0 && ea.translation < 0.3)
        << "pair " << index << " no longer needs the search; pick another";
    EXPECT_LT(eb.rotation_deg, 1.0) << "pair " << index;
    EXPECT_LT(eb.translation, 0.3) << "pair " << index;
    EXPECT_TRUE(b->valid) << "pair " << index << ": " << b->failure_reason;
    EXPECT_GT(b->confidence, a->confidence) << "pair " << index;
    EXPECT_EQ(b->start, "searched") << "pair " << index;
    EXPECT_EQ(b->starts, a->starts + 1) << "pair " << index;
    EXPECT_NE(a->start, "searched") << "pair " << index;
  }
}

// Held-out scan pairs whose net+refine answer, without the sensor-aligned check, ends at the
// identity translation metres from the truth (the ground's rings line up there): two pairs of a
// parking lot 5 frames apart (pair seed 5003), 7.7 m off at confidence 0.99, and a street 10 frames
// apart (pair seed 1003), 14.8 m off and degenerate along it, so invalid. With the check the search
// over the structure off the ground finds the true motion.
TEST(RegistrarSecondStartTest, SensorAlignedCheckFindsTheMotionOfSlidScans) {
  struct Slide {
    uint64_t pair_seed;
    int frame_offset;
    int index;
    bool degenerate;
  };
  for (const Slide& slide :
       {Slide{5003, 5, 26, false}, Slide{5003, 5, 27, false}, Slide{1003, 10, 30, true}}) {
    SCOPED_TRACE(testing::Message() << "pair seed " << slide.pair_seed << ", " << slide.frame_offset
                                    << " frames apart, pair " << slide.index);
    auto pair = CalibrationLidarPairs(slide.pair_seed, slide.frame_offset)(slide.index);
    ASSERT_TRUE(pair.ok()) << pair.status();
    ASSERT_GT(pair->T_target_source.translation().norm(), 5.0) << "a motion of several metres";
    const Octree source = TreeOf(pair->source, 9);
    const Octree target = TreeOf(pair->target, 9);
    RegistrationOptions without = EveryPassFirst();
    without.check_sensor_aligned_answers = false;
    auto a = SharedRegistrar().Register(source, target, without);
    auto b = SharedRegistrar().Register(source, target, EveryPassFirst());
    ASSERT_TRUE(a.ok() && b.ok());
    const PairError ea = ErrorOf(a->T_target_source, pair->T_target_source);
    const PairError eb = ErrorOf(b->T_target_source, pair->T_target_source);
    EXPECT_GT(ea.translation, 5.0) << "no longer slides; pick another pair";
    if (slide.degenerate) {
      EXPECT_FALSE(a->valid) << "no longer degenerate; pick another pair";
      EXPECT_GT(a->num_degenerate, 0);
    } else {
      EXPECT_LT(a->T_target_source.translation().norm(), 1.0);
      EXPECT_GT(a->confidence, 0.9) << "a confident slide";
    }
    EXPECT_LT(eb.rotation_deg, 1.0);
    EXPECT_LT(eb.translation, 0.3);
    EXPECT_TRUE(b->valid) << b->failure_reason;
    EXPECT_EQ(b->start, "structure");
    EXPECT_EQ(b->starts, a->starts + 1);
    // A prepared target holds its plane: the same answer.
    auto prepared = SharedRegistrar().PrepareTarget(target);
    ASSERT_TRUE(prepared.ok()) << prepared.status();
    EXPECT_TRUE((*prepared)->has_dominant_plane());
    auto from_prepared = SharedRegistrar().Register(source, **prepared, EveryPassFirst());
    ASSERT_TRUE(from_prepared.ok());
    EXPECT_EQ(from_prepared->start, "structure");
    EXPECT_LT(ErrorOf(from_prepared->T_target_source, b->T_target_source).rotation_deg, 0.01);
    EXPECT_LT(ErrorOf(from_prepared->T_target_source, b->T_target_source).translation, 0.01);
    // Mode refine keeps its one answer, the start refined, and doubts the slide.
    RegistrationOptions refine = EveryPassFirst();
    refine.mode = RegistrationMode::kRefine;
    auto c = SharedRegistrar().Register(source, target, refine);
    refine.check_sensor_aligned_answers = false;
    auto d = SharedRegistrar().Register(source, target, refine);
    ASSERT_TRUE(c.ok() && d.ok());
    EXPECT_EQ(c->start, "initial");
    EXPECT_TRUE(c->T_target_source.isApprox(d->T_target_source, 1e-12));
    if (!slide.degenerate) {
      EXPECT_GT(ErrorOf(d->T_target_source, pair->T_target_source).translation, 5.0);
      EXPECT_GT(d->confidence, 0.9) << "a confident slide in mode refine too";
      EXPECT_TRUE(c->valid);
      EXPECT_LE(c->confidence, 0.05);
      EXPECT_THAT(c->failure_reason, HasSubstr("doubted"));
      // The pose the structure prefers is the motion itself.
      ASSERT_TRUE(c->structure_alternative_T_target_source.has_value());
      const PairError alternative =
          ErrorOf(*c->structure_alternative_T_target_source, pair->T_target_source);
      EXPECT_LT(alternative.rotation_deg, 1.0);
      EXPECT_LT(alternative.translation, 0.3);
    }
    EXPECT_FALSE(d->structure_alternative_T_target_source.has_value());
  }
}

// The check runs on right answers too (pairs 2 frames apart, the sensors 1-2 m apart, where it
// always runs): mode refine does not doubt them.
TEST(RegistrarSecondStartTest, SensorAlignedCheckLeavesRightRefineAnswersAlone) {
  int checked = 0;
  for (int index = 0; index < 8; ++index) {
    auto pair = CalibrationLidarPairs(5003, 2)(index);
    ASSERT_TRUE(pair.ok()) << pair.status();
    ASSERT_LT(pair->T_target_source.translation().norm(), 3.5) << "the check would not run";
    const Octree source = TreeOf(pair->source, 9);
    const Octree target = TreeOf(pair->target, 9);
    RegistrationOptions refine = EveryPassFirst();
    refine.mode = RegistrationMode::kRefine;
    auto c = SharedRegistrar().Register(source, target, refine);
    ASSERT_TRUE(c.ok());
    const PairError e = ErrorOf(c->T_target_source, pair->T_target_source);
    if (e.rotation_deg > 1.0 || e.translation > 0.3) continue;
    SCOPED_TRACE(testing::Message() << "pair " << index);
    EXPECT_GT(c->confidence, 0.5);
    EXPECT_THAT(c->failure_reason, Not(HasSubstr("doubted")));
    EXPECT_FALSE(c->structure_alternative_T_target_source.has_value());
    ++checked;
  }
  EXPECT_GE(checked, 6) << "mode refine misses these pairs; pick others";
}

// Held-out pairs 10 frames apart where the vehicle turns 54-69 degrees at a junction: every start
// within +-20 degrees of the identity ends 50-75 degrees off at confidence 0; the search over
// every turn finds the turn.
TEST(RegistrarSecondStartTest, SearchOverEveryTurnFindsAJunctionTurn) {
  for (int index : {24, 58}) {
    SCOPED_TRACE(testing::Message() << "pair seed 7003, 10 frames apart, pair " << index);
    auto pair = CalibrationLidarPairs(7003, 10)(index);
    ASSERT_TRUE(pair.ok()) << pair.status();
    ASSERT_GT(ErrorOf(pair->T_target_source, Eigen::Isometry3d::Identity()).rotation_deg, 45.0);
    const Octree source = TreeOf(pair->source, 9);
    const Octree target = TreeOf(pair->target, 9);
    RegistrationOptions without = EveryPassFirst();
    without.search_scene_start = false;
    auto a = SharedRegistrar().Register(source, target, without);
    auto b = SharedRegistrar().Register(source, target, EveryPassFirst());
    ASSERT_TRUE(a.ok() && b.ok());
    EXPECT_GT(ErrorOf(a->T_target_source, pair->T_target_source).rotation_deg, 20.0)
        << "no longer missed without the search; pick another pair";
    EXPECT_LT(a->confidence, 0.1);
    const PairError e = ErrorOf(b->T_target_source, pair->T_target_source);
    EXPECT_LT(e.rotation_deg, 1.0);
    EXPECT_LT(e.translation, 0.3);
    EXPECT_EQ(b->start, "searched_turns");
    EXPECT_GT(b->confidence, 0.9);
  }
}

// A mug whose handle is small (3% of its 1,024 points): a cylinder of radius 0.5 and height 1.6
// about z with a bottom, and a half ring of radius 0.12 outside its wall. Without the handle it
// would be round about z; the handle alone tells its turns about z apart.
PointCloud SmallHandledMug(uint64_t seed) {
  SeededRandom random(seed);
  PointCloud cloud;
  while (cloud.points.size() < 1024) {
    const double part = random.UniformUnit();
    const double theta = random.Uniform(0.0, 2.0 * M_PI);
    if (part < 0.77) {  // the wall
      cloud.points.emplace_back(0.5 * std::cos(theta), 0.5 * std::sin(theta),
                                random.Uniform(-0.8, 0.8));
    } else if (part < 0.97) {  // the bottom
      const double r = 0.5 * std::sqrt(random.UniformUnit());
      cloud.points.emplace_back(r * std::cos(theta), r * std::sin(theta), -0.8);
    } else {  // the handle: a tube of radius 0.03 along a half ring in the x-z plane
      const double along = random.Uniform(-0.5 * M_PI, 0.5 * M_PI);
      const double ring = 0.12 + 0.03 * std::cos(theta);
      cloud.points.emplace_back(0.5 + ring * std::cos(along), 0.03 * std::sin(theta),
                                ring * std::sin(along));
    }
  }
  return cloud;
}

TEST(SymmetryTurnsTest, TurnsAboutAMugsBodyAndNoneForAFlatBox) {
  const Octree mug = TreeOf(SmallHandledMug(1), 6);
  const std::vector<SelfSymmetry> turns = TurnsAboutRoundAxes(mug, 15.0);
  // 15, 30, ... 345 degrees about its one round principal axis, the body's (z). (A mug about as
  // tall as wide would be round about every axis: its three variances alike.)
  ASSERT_EQ(turns.size(), 23u);
  const Eigen::Vector3d centre = mug.level(0).center_of_mass[0].cast<double>();
  int about_z = 0;
  for (size_t k = 0; k < turns.size(); ++k) {
    EXPECT_NEAR(turns[k].angle_deg, 15.0 * static_cast<double>(k + 1), 1e-9);
    EXPECT_LT((turns[k].S * centre - centre).norm(), 1e-9);
    const Eigen::AngleAxisd turn(turns[k].S.linear());
    about_z += std::abs(turn.axis().z()) > 0.99 ? 1 : 0;
  }
  EXPECT_EQ(about_z, 23);
  // A box of three different sides has no round axis.
  PointCloud box;
  SeededRandom random(3);
  for (int i = 0; i < 1024; ++i) {
    box.points.emplace_back(random.Uniform(-1.0, 1.0), random.Uniform(-0.5, 0.5),
                            random.Uniform(-0.2, 0.2));
  }
  EXPECT_TRUE(TurnsAboutRoundAxes(TreeOf(box, 6), 15.0).empty());
}

// net+refine's round-axis start (RegistrationOptions::search_round_axis_start) on mugs with a
// small handle at the protocol's poses: where it settles, the answer is within 2 degrees and was
// beyond 5 without it; no answer within 1 degree without it is worse with it.
TEST(RegistrarSecondStartTest, RoundAxisStartTurnsAMugBackOntoItsHandle) {
  int settled = 0;
  for (uint64_t i = 0; i < 16; ++i) {
    SeededRandom random(DeriveSeed(26, i));
    Eigen::Vector3d angles;
    for (int a = 0; a < 3; ++a) angles[a] = random.Uniform(0.0, 45.0 * M_PI / 180.0);
    Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
    truth.linear() = RotationFromEulerXyz(angles);
    for (int a = 0; a < 3; ++a) truth.translation()[a] = random.Uniform(-0.5, 0.5);
    const PointCloud source_cloud = SmallHandledMug(DeriveSeed(27, 2 * i));
    PointCloud target_cloud = SmallHandledMug(DeriveSeed(27, 2 * i + 1));
    for (Eigen::Vector3f& p : target_cloud.points) p = (truth * p.cast<double>()).cast<float>();
    const Octree source = TreeOf(source_cloud, 6);
    const Octree target = TreeOf(target_cloud, 6);
    RegistrationOptions without = EveryPassFirst();
    without.search_round_axis_start = false;
    auto a = SharedRegistrar().Register(source, target, without);
    auto b = SharedRegistrar().Register(source, target, EveryPassFirst());
    ASSERT_TRUE(a.ok() && b.ok());
    const double error_without = ErrorOf(a->T_target_source, truth).rotation_deg;
    const double error_with = ErrorOf(b->T_target_source, truth).rotation_deg;
    if (error_without < 1.0) {
      EXPECT_LT(error_with, 1.0) << "pair " << i;
    }
    // A confident answer is not searched further: the same pose from the same starts.
    if (a->confidence >= 0.9) {
      EXPECT_TRUE(b->T_target_source.isApprox(a->T_target_source, 1e-12)) << "pair " << i;
      EXPECT_EQ(b->starts, a->starts) << "pair " << i;
    }
    // Mode refine is a local refinement from the caller's guess: never a turned start.
    RegistrationOptions refine = EveryPassFirst();
    refine.mode = RegistrationMode::kRefine;
    auto c = SharedRegistrar().Register(source, target, refine);
    ASSERT_TRUE(c.ok());
    EXPECT_EQ(c->start, "initial") << "pair " << i;
    EXPECT_EQ(c->starts, 1) << "pair " << i;
    if (b->start != "round_axis") continue;
    ++settled;
    EXPECT_LT(error_with, 2.0) << "pair " << i;
    EXPECT_GT(error_without, 5.0) << "pair " << i;
    EXPECT_EQ(b->starts, a->starts + 1) << "pair " << i;
  }
  std::printf("mugs turned back by the round-axis start: %d of 16\n", settled);
  EXPECT_GE(settled, 1);
}

// net+refine's weak-direction start (RegistrationOptions::search_weak_direction_start) on the
// clean unseen pairs of pair seed 1 (the study's): the helix spring of pair 48, 7 degrees off
// along its screw without it, ends within 1.5 degrees from the start "weak_direction"; no answer
// within (1 deg, 0.01) without it is lost with it; where the start is not kept, the answer and
// its confidence are the very ones without it. The far-count valley, which runs later and brings
// that spring back without the start (to 0.77 degree; RegistrarFarValleyTest covers it), is off
// in both arms.
TEST(RegistrarSecondStartTest, WeakDirectionStartTurnsASpringBackAlongItsScrew) {
  RegistrationOptions with;
  with.search_far_valley = false;
  RegistrationOptions without = with;
  without.search_weak_direction_start = false;
  int kept = 0;
  std::vector<uint64_t> pairs = {48};
  for (uint64_t i = 0; i < 32; ++i) pairs.push_back(i);
  for (uint64_t i : pairs) {
    absl::StatusOr<AnswersWithAndWithout> answers = RegisterStudyPair(1, i, without, with);
    ASSERT_TRUE(answers.ok()) << answers.status();
    const RegistrationResult* a = &answers->without;
    const RegistrationResult* b = &answers->with;
    const PairError& error_without = answers->error_without;
    const PairError& error_with = answers->error_with;
    if (i == 48) {
      EXPECT_GT(error_without.rotation_deg, 5.0);
      EXPECT_LT(error_with.rotation_deg, 1.5);
      EXPECT_EQ(b->start, "weak_direction");
      EXPECT_EQ(b->starts, a->starts + 1);
    }
    if (error_without.rotation_deg <= 1.0 && error_without.translation <= 0.01) {
      EXPECT_LE(error_with.rotation_deg, 1.0) << "pair " << i;
      EXPECT_LE(error_with.translation, 0.01) << "pair " << i;
    }
    if (b->start == "weak_direction") {
      ++kept;
      continue;
    }
    EXPECT_TRUE(b->T_target_source.isApprox(a->T_target_source, 1e-12)) << "pair " << i;
    EXPECT_EQ(b->confidence, a->confidence) << "pair " << i;
    EXPECT_GE(b->starts, a->starts) << "pair " << i;
    EXPECT_LE(b->starts, a->starts + 1) << "pair " << i;
  }
  std::printf("answers from the weak-direction start: %d of %zu\n", kept, pairs.size());
  EXPECT_GE(kept, 1);
}

// The weak-direction start's finest round (RegistrationOptions::weak_direction_finest_round, off
// by default) on the same clean unseen pairs: the blob of pair 1, 4 degrees off with the first
// round alone, ends within 1 degree from the start "weak_direction"; no answer within (1 deg, 0.01)
// without the round is lost with it; where it is not kept, the answer and its confidence are the
// very ones without it, after one more refined start at most for an answer inside its gate (clean
// and whole: WeakDirectionOptions::finest_max_scatter_cells, finest_min_fitness) and none for one
// outside.
TEST(RegistrarSecondStartTest, WeakDirectionFinestRoundTurnsABlobBack) {
  RegistrationOptions finest;
  finest.weak_direction_finest_round = true;
  const WeakDirectionOptions weak;
  int kept = 0;
  int gated = 0;
  for (uint64_t i = 0; i < 32; ++i) {
    absl::StatusOr<AnswersWithAndWithout> answers =
        RegisterStudyPair(1, i, RegistrationOptions{}, finest);
    ASSERT_TRUE(answers.ok()) << answers.status();
    const RegistrationResult* a = &answers->without;
    const RegistrationResult* b = &answers->with;
    const PairError& error_without = answers->error_without;
    const PairError& error_with = answers->error_with;
    if (i == 1) {
      EXPECT_GT(error_without.rotation_deg, 3.0);
      EXPECT_LT(error_with.rotation_deg, 1.0);
      EXPECT_EQ(b->start, "weak_direction");
    }
    if (error_without.rotation_deg <= 1.0 && error_without.translation <= 0.01) {
      EXPECT_LE(error_with.rotation_deg, 1.0) << "pair " << i;
      EXPECT_LE(error_with.translation, 0.01) << "pair " << i;
    }
    // The gate reads the answer the first round left, which is a's where b's round kept nothing.
    const bool inside = weak.FinestRoundAdmits(a->surface_scatter_cells, a->fitness);
    gated += inside;
    if (b->starts > a->starts) {
      EXPECT_TRUE(inside) << "pair " << i;
      EXPECT_NE(a->start, "weak_direction") << "pair " << i;
    }
    EXPECT_LE(b->starts, a->starts + 1) << "pair " << i;
    if (!b->T_target_source.isApprox(a->T_target_source, 1e-12)) {
      EXPECT_EQ(b->start, "weak_direction") << "pair " << i;
      EXPECT_EQ(b->starts, a->starts + 1) << "pair " << i;
      ++kept;
      continue;
    }
    EXPECT_EQ(b->confidence, a->confidence) << "pair " << i;
  }
  std::printf("answers from the finest round: %d of 32; inside its gate: %d\n", kept, gated);
  EXPECT_GE(kept, 1);
  EXPECT_GT(gated, kept);
}

// net+refine's centroid-aligned start (RegistrationOptions::search_centroid_start) on the clean
// unseen pairs of pair seed 3 (the study's `--seed 3`): the gear of pair 95, 8.9 degrees and 0.14
// off without it (turned about a point of its rim), ends within (1 deg, 0.01) from the start
// "centroid"; no answer within (1 deg, 0.01) without it is lost with it; an answer whose start did
// not run is the very one without it, and a confident one's runs only where it overlaps below
// 0.97.
TEST(RegistrarSecondStartTest, CentroidStartBringsATurnedGearBack) {
  // The extent slide, which runs after it whatever the confidence, is off in both: it would move
  // an answer the centroid start left alone (pair 6, a laptop, reads 0.95 once slid).
  RegistrationOptions with;
  with.search_extent_slide = false;
  RegistrationOptions without = with;
  without.search_centroid_start = false;
  int ran = 0;
  std::vector<uint64_t> pairs = {95};
  for (uint64_t i = 0; i < 32; ++i) pairs.push_back(i);
  for (uint64_t i : pairs) {
    absl::StatusOr<AnswersWithAndWithout> answers = RegisterStudyPair(3, i, without, with);
    ASSERT_TRUE(answers.ok()) << answers.status();
    const RegistrationResult& a = answers->without;
    const RegistrationResult& b = answers->with;
    if (i == 95) {
      EXPECT_GT(answers->error_without.rotation_deg, 5.0);
      EXPECT_GT(answers->error_without.translation, 0.05);
      EXPECT_LE(answers->error_with.rotation_deg, 1.0);
      EXPECT_LE(answers->error_with.translation, 0.01);
      EXPECT_EQ(b.start, "centroid");
    }
    if (answers->error_without.rotation_deg <= 1.0 && answers->error_without.translation <= 0.01) {
      EXPECT_LE(answers->error_with.rotation_deg, 1.0) << "pair " << i;
      EXPECT_LE(answers->error_with.translation, 0.01) << "pair " << i;
    }
    if (b.starts == a.starts) {
      EXPECT_TRUE(b.T_target_source.isApprox(a.T_target_source, 1e-12)) << "pair " << i;
      EXPECT_EQ(b.confidence, a.confidence) << "pair " << i;
      continue;
    }
    ++ran;
    if (a.confidence >= 0.9) {
      EXPECT_LT(a.fitness, 0.97) << "pair " << i;
    }
  }
  std::printf("answers whose centroid-aligned start ran: %d of %zu\n", ran, pairs.size());
  EXPECT_GE(ran, 1);
}

// A confident answer that overlaps less than wholly and leaves the centres of mass apart gets the
// centroid-aligned start too: pair 258 of `rpsr eval --protocol objects --split unseen --count
// 2000 --seed 1` (clean), a sofa slid by 0.217 along its length at 0.989 confidence (fitness 0.946;
// 0.979 at the truth), comes back within (1 deg, 0.01).
TEST(RegistrarSecondStartTest, CentroidStartBringsAConfidentSlidSofaBack) {
  RegistrationOptions without;
  without.search_centroid_start = false;
  const RegistrationOptions with;
  absl::StatusOr<AnswersWithAndWithout> answers = RegisterStudyPair(1, 258, without, with);
  ASSERT_TRUE(answers.ok()) << answers.status();
  std::printf("sofa: %.3f off at %.3f (fitness %.3f) -> %.4f off at %.3f (fitness %.3f)\n",
              answers->error_without.translation, answers->without.confidence,
              answers->without.fitness, answers->error_with.translation, answers->with.confidence,
              answers->with.fitness);
  EXPECT_GT(answers->error_without.translation, 0.1);
  EXPECT_GE(answers->without.confidence, 0.9);
  EXPECT_LE(answers->error_with.rotation_deg, 1.0);
  EXPECT_LE(answers->error_with.translation, 0.01);
  EXPECT_EQ(answers->with.start, "centroid");
  EXPECT_GE(answers->with.fitness, 0.97);
}

// Where the target has near-symmetries (a gear's teeth), the twin margin and the twin rule speak
// for its turns: the round-axis start does not run, so answers and starts are those without it.
TEST(RegistrarSecondStartTest, RoundAxisStartStaysOffForNearSymmetricTargets) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  int gears = 0;
  for (uint64_t i = 0; i < 400 && gears < 3; ++i) {
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(2, i));
    ASSERT_TRUE(pair.ok()) << pair.status();
    const Octree target = TreeOf(pair->target, 6);
    if (FindSelfSymmetries(target).empty()) continue;
    ++gears;
    const Octree source = TreeOf(pair->source, 6);
    RegistrationOptions without = EveryPassFirst();
    without.search_round_axis_start = false;
    auto a = SharedRegistrar().Register(source, target, without);
    auto b = SharedRegistrar().Register(source, target, EveryPassFirst());
    ASSERT_TRUE(a.ok() && b.ok());
    EXPECT_TRUE(b->T_target_source.isApprox(a->T_target_source, 1e-12)) << "pair " << i;
    EXPECT_EQ(b->starts, a->starts) << "pair " << i;
    EXPECT_NE(b->start, "round_axis") << "pair " << i;
  }
  EXPECT_EQ(gears, 3);
}

// net+refine's symmetric start (RegistrationOptions::try_symmetric_starts) on the unseen gears of
// pair seed 2 (the study's clean pairs): the four whose answer ends a whole tooth off without it
// end within 1 degree with it, from the start "symmetric"; the gears answered right without it
// keep the very same answer.
TEST(RegistrarSecondStartTest, SymmetricStartTurnsAGearBackOntoItsPin) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  int brought_back = 0;
  int left_alone = 0;
  for (uint64_t i : {0, 3, 7, 34, 38, 40, 62, 71}) {
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(2, i));
    ASSERT_TRUE(pair.ok()) << pair.status();
    const Octree source = TreeOf(pair->source, 6);
    const Octree target = TreeOf(pair->target, 6);
    ASSERT_FALSE(FindSelfSymmetries(target).empty()) << "pair " << i;
    RegistrationOptions without = EveryPassFirst();
    without.try_symmetric_starts = false;
    auto a = SharedRegistrar().Register(source, target, without);
    auto b = SharedRegistrar().Register(source, target, EveryPassFirst());
    ASSERT_TRUE(a.ok() && b.ok());
    const double error_without = ErrorOf(a->T_target_source, pair->T_target_source).rotation_deg;
    const double error_with = ErrorOf(b->T_target_source, pair->T_target_source).rotation_deg;
    if (error_without < 1.0) {
      ++left_alone;
      EXPECT_TRUE(b->T_target_source.isApprox(a->T_target_source, 1e-12)) << "pair " << i;
      EXPECT_NE(b->start, "symmetric") << "pair " << i;
      continue;
    }
    // A whole tooth off: 360 / n for 8-16 teeth.
    EXPECT_GT(error_without, 20.0) << "pair " << i;
    EXPECT_LT(error_with, 1.0) << "pair " << i;
    EXPECT_EQ(b->start, "symmetric") << "pair " << i;
    EXPECT_EQ(b->starts, a->starts + 1) << "pair " << i;
    EXPECT_TRUE(b->valid) << "pair " << i;
    ++brought_back;
  }
  EXPECT_EQ(brought_back, 4);
  EXPECT_EQ(left_alone, 4);
}

}  // namespace
}  // namespace rpsr::core
