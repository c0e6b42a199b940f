#include "core/synth/assembled_families.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/synth/primitive_meshes.h"

namespace rpsr::core {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kDegree = kPi / 180.0f;

float RandomFloat(SeededRandom& random, double low, double high) {
  return static_cast<float>(random.Uniform(low, high));
}

void AddBox(const Eigen::Vector3f& centre, const Eigen::Vector3f& half_extents,
            TriangleMesh& mesh) {
  AppendMesh(TransformedMesh(BoxMesh(half_extents), PlacedAt(centre)), mesh);
}

void AddEllipsoid(const Eigen::Affine3f& pose, const Eigen::Vector3f& half_axes,
                  TriangleMesh& mesh) {
  AppendMesh(TransformedMesh(EllipsoidMesh(half_axes, 10, 16), pose), mesh);
}

// Mirror image through the plane y = 0 (winding is fixed by TransformedMesh).
TriangleMesh MirroredInY(const TriangleMesh& mesh) {
  return TransformedMesh(mesh, Eigen::Affine3f(Eigen::Scaling(1.0f, -1.0f, 1.0f)));
}

// A limb direction: straight down, swung about y by `swing` then spread sideways about x by
// `spread`.
Eigen::Vector3f LimbDirection(float swing, float spread) {
  return Eigen::AngleAxisf(spread, Eigen::Vector3f::UnitX()) *
         (Eigen::AngleAxisf(swing, Eigen::Vector3f::UnitY()) * Eigen::Vector3f(0, 0, -1));
}

}  // namespace

TriangleMesh GenerateChair(SeededRandom& random) {
  const float half_width = RandomFloat(random, 0.4, 0.6);
  const float half_depth = RandomFloat(random, 0.4, 0.6);
  const float half_thickness = RandomFloat(random, 0.03, 0.06);
  const float seat_height = RandomFloat(random, 0.8, 1.1);
  TriangleMesh mesh;
  AddBox({0, 0, seat_height}, {half_width, half_depth, half_thickness}, mesh);
  const float inset = RandomFloat(random, 0.03, 0.08);
  const float leg_radius = RandomFloat(random, 0.025, 0.05);
  const bool round_legs = random.Bernoulli(0.5);
  const float leg_top = seat_height - half_thickness;
  for (float sx : {-1.0f, 1.0f}) {
    for (float sy : {-1.0f, 1.0f}) {
      const float x = sx * (half_width - inset);
      const float y = sy * (half_depth - inset);
      if (round_legs) {
        AppendMesh(CylinderBetween({x, y, 0}, {x, y, leg_top}, leg_radius, 12), mesh);
      } else {
        AddBox({x, y, 0.5f * leg_top}, {leg_radius, leg_radius, 0.5f * leg_top}, mesh);
      }
    }
  }
  // Backrest along the -y edge, leaning back (towards -y) by up to 20 degrees.
  const float back_height = RandomFloat(random, 0.6, 1.0);
  Eigen::Affine3f back_pose =
      PlacedAt({0, -half_depth + 0.03f, seat_height + half_thickness}, Eigen::Vector3f::UnitX(),
               RandomFloat(random, 0, 20) * kDegree);
  back_pose.translate(Eigen::Vector3f(0, 0, 0.5f * back_height));
  AppendMesh(TransformedMesh(BoxMesh({half_width, 0.03f, 0.5f * back_height}), back_pose), mesh);
  if (random.Bernoulli(0.4)) {
    const float arm_height = seat_height + RandomFloat(random, 0.2, 0.3);
    for (float sx : {-1.0f, 1.0f}) {
      AddBox({sx * half_width, 0, arm_height}, {0.03f, 0.8f * half_depth, 0.03f}, mesh);
      const Eigen::Vector3f front(sx * half_width, 0.7f * half_depth, seat_height);
      AppendMesh(CylinderBetween(front, front + Eigen::Vector3f(0, 0, arm_height - seat_height),
                                 0.025f, 8),
                 mesh);
    }
  }
  return mesh;
}

TriangleMesh GenerateTable(SeededRandom& random) {
  const float height = RandomFloat(random, 0.6, 1.0);
  const float half_thickness = RandomFloat(random, 0.02, 0.05);
  TriangleMesh mesh;
  if (random.Bernoulli(0.6)) {
    const Eigen::Vector3f half_top(RandomFloat(random, 0.6, 1.2), RandomFloat(random, 0.4, 0.8),
                                   half_thickness);
    AddBox({0, 0, height}, half_top, mesh);
    const float inset = RandomFloat(random, 0.04, 0.15);
    const float leg = RandomFloat(random, 0.03, 0.06);
    for (float sx : {-1.0f, 1.0f}) {
      for (float sy : {-1.0f, 1.0f}) {
        const float x = sx * (half_top.x() - inset);
        const float y = sy * (half_top.y() - inset);
        AddBox({x, y, 0.5f * (height - half_thickness)},
               {leg, leg, 0.5f * (height - half_thickness)}, mesh);
      }
    }
  } else {
    const float radius = RandomFloat(random, 0.5, 0.9);
    AppendMesh(TransformedMesh(FrustumMesh(radius, radius, 2 * half_thickness, 40),
                               PlacedAt({0, 0, height})),
               mesh);
    AppendMesh(CylinderBetween({0, 0, 0}, {0, 0, height}, RandomFloat(random, 0.05, 0.1), 16),
               mesh);
    const float base = radius * RandomFloat(random, 0.4, 0.7);
    AppendMesh(TransformedMesh(FrustumMesh(base, 0.3f * base, 0.06f, 32), PlacedAt({0, 0, 0.03f})),
               mesh);
  }
  return mesh;
}

TriangleMesh GenerateLamp(SeededRandom& random) {
  TriangleMesh mesh;
  const float base_radius = RandomFloat(random, 0.25, 0.4);
  AppendMesh(TransformedMesh(FrustumMesh(base_radius, 0.8f * base_radius, 0.06f, 32),
                             PlacedAt({0, 0, 0.03f})),
             mesh);
  // Both arm segments lie in the xz plane.
  const Eigen::Vector3f shoulder(0, 0, 0.06f);
  const float tilt = RandomFloat(random, -30, 30) * kDegree;
  const Eigen::Vector3f elbow =
      shoulder + RandomFloat(random, 0.5, 0.9) * Eigen::Vector3f(std::sin(tilt), 0, std::cos(tilt));
  const float reach = RandomFloat(random, 40, 110) * kDegree;
  const Eigen::Vector3f arm_direction(std::sin(reach), 0, std::cos(reach));
  const Eigen::Vector3f hand = elbow + RandomFloat(random, 0.3, 0.7) * arm_direction;
  AppendMesh(CylinderBetween(shoulder, elbow, 0.025f, 10), mesh);
  AppendMesh(CylinderBetween(elbow, hand, 0.025f, 10), mesh);
  AddEllipsoid(PlacedAt(elbow), Eigen::Vector3f::Constant(0.04f), mesh);
  // Shade: a frustum whose narrow end sits on the hand, opening downward and outward.
  const Eigen::Vector3f shade_axis =
      (arm_direction + Eigen::Vector3f(0, 0, -RandomFloat(random, 0.8, 1.5))).normalized();
  const float shade_length = RandomFloat(random, 0.2, 0.35);
  Eigen::Affine3f shade_pose = Eigen::Affine3f::Identity();
  shade_pose.translate(hand + 0.5f * shade_length * shade_axis);
  shade_pose.rotate(Eigen::Quaternionf::FromTwoVectors(Eigen::Vector3f::UnitZ(), -shade_axis));
  const float shade_radius = RandomFloat(random, 0.12, 0.25);
  AppendMesh(
      TransformedMesh(FrustumMesh(shade_radius, 0.3f * shade_radius, shade_length, 24), shade_pose),
      mesh);
  return mesh;
}

TriangleMesh GenerateBookshelf(SeededRandom& random) {
  const float width = RandomFloat(random, 0.6, 1.2);
  const float depth = RandomFloat(random, 0.25, 0.4);
  const float height = RandomFloat(random, 1.0, 2.0);
  const float t = 0.025f;
  TriangleMesh mesh;
  for (float sx : {-1.0f, 1.0f}) {
    AddBox({sx * 0.5f * (width - t), 0, 0.5f * height}, {0.5f * t, 0.5f * depth, 0.5f * height},
           mesh);
  }
  AddBox({0, -0.5f * (depth - t), 0.5f * height}, {0.5f * width, 0.5f * t, 0.5f * height}, mesh);
  const int shelves = random.UniformInt(2, 5);
  std::vector<float> levels;
  for (int k = 0; k <= shelves + 1; ++k) levels.push_back(height * k / (shelves + 1));
  for (float z : levels) {
    AddBox({0, 0, std::clamp(z, 0.5f * t, height - 0.5f * t)},
           {0.5f * width, 0.5f * depth, 0.5f * t}, mesh);
  }
  // Books stand on each board from the left, each compartment filled to a random extent.
  for (size_t k = 0; k + 1 < levels.size(); ++k) {
    const float floor = levels[k] + 0.5f * t;
    const float gap = levels[k + 1] - levels[k] - t;
    float cursor = -0.5f * width + t;
    while (random.Bernoulli(0.88)) {
      const float book = RandomFloat(random, 0.02, 0.06);
      if (cursor + book > 0.5f * width - t) break;
      const float book_height = gap * RandomFloat(random, 0.5, 0.9);
      const float book_depth = depth * RandomFloat(random, 0.6, 0.9);
      AddBox(
          {cursor + 0.5f * book, -0.5f * depth + t + 0.5f * book_depth, floor + 0.5f * book_height},
          {0.5f * book, 0.5f * book_depth, 0.5f * book_height}, mesh);
      cursor += book + (random.Bernoulli(0.2) ? RandomFloat(random, 0.02, 0.1) : 0.0f);
    }
  }
  return mesh;
}

TriangleMesh GenerateAirplane(SeededRandom& random) {
  TriangleMesh mesh;
  // Nose towards +x.
  const float half_length = RandomFloat(random, 0.8, 1.1);
  const float fuselage_radius = RandomFloat(random, 0.07, 0.12);
  AddEllipsoid(Eigen::Affine3f::Identity(), {half_length, fuselage_radius, fuselage_radius}, mesh);
  const float sweep = RandomFloat(random, 0.0, 0.6);
  // One swept wing on +y, then its mirror image.
  auto add_wing_pair = [&](float chord, float span, const Eigen::Vector3f& root) {
    Eigen::Affine3f pose = Eigen::Affine3f::Identity();
    pose.translate(root);
    Eigen::Matrix3f shear = Eigen::Matrix3f::Identity();
    shear(0, 1) = -sweep;
    pose.linear() = shear;
    const TriangleMesh wing =
        TransformedMesh(TransformedMesh(BoxMesh({0.5f * chord, 0.5f * span, 0.012f}),
                                        PlacedAt({0, 0.5f * span, 0})),
                        pose);
    AppendMesh(wing, mesh);
    AppendMesh(MirroredInY(wing), mesh);
  };
  const float chord = RandomFloat(random, 0.18, 0.35);
  const float span = RandomFloat(random, 0.7, 1.2);
  const float wing_x = RandomFloat(random, -0.2, 0.2);
  const float wing_z = -RandomFloat(random, 0.0, 0.5) * fuselage_radius;
  add_wing_pair(chord, span, {wing_x, 0, wing_z});
  const float tail_x = -0.85f * half_length;
  add_wing_pair(0.5f * chord, RandomFloat(random, 0.2, 0.4) * span, {tail_x, 0, 0});
  const float fin_height = RandomFloat(random, 0.15, 0.35);
  Eigen::Affine3f fin_pose = Eigen::Affine3f::Identity();
  fin_pose.translate(Eigen::Vector3f(tail_x, 0, 0.5f * fuselage_radius));
  Eigen::Matrix3f fin_shear = Eigen::Matrix3f::Identity();
  fin_shear(0, 2) = -sweep;
  fin_pose.linear() = fin_shear;
  AppendMesh(TransformedMesh(TransformedMesh(BoxMesh({0.3f * chord, 0.012f, 0.5f * fin_height}),
                                             PlacedAt({0, 0, 0.5f * fin_height})),
                             fin_pose),
             mesh);
  if (random.Bernoulli(0.5)) {
    for (float sy : {-1.0f, 1.0f}) {
      const float y = sy * 0.4f * span;
      const Eigen::Vector3f front(wing_x + 0.5f * chord - sweep * 0.4f * span, y, wing_z - 0.08f);
      AppendMesh(CylinderBetween(front, front - Eigen::Vector3f(0.25f, 0, 0), 0.05f, 12), mesh);
    }
  }
  return mesh;
}

TriangleMesh GenerateMug(SeededRandom& random) {
  const float radius = RandomFloat(random, 0.35, 0.5);
  const float height = RandomFloat(random, 0.7, 1.1);
  TriangleMesh mesh = RevolutionMesh({{radius, 0.0f},
                                      {radius * RandomFloat(random, 0.95, 1.2), height},
                                      {radius * 0.9f, height},
                                      {radius * 0.9f, height * 0.92f}},
                                     32);
  // C-shaped handle in the xz plane on the +x side.
  const float handle_radius = height * RandomFloat(random, 0.25, 0.4);
  const float reach = RandomFloat(random, 0.7, 1.3);
  const float centre_z = height * RandomFloat(random, 0.45, 0.55);
  std::vector<Eigen::Vector3f> handle;
  for (int s = 0; s <= 16; ++s) {
    const float angle = -0.5f * kPi + kPi * s / 16;
    handle.emplace_back(radius * 0.95f + reach * handle_radius * std::cos(angle), 0.0f,
                        centre_z + handle_radius * std::sin(angle));
  }
  AppendMesh(TubeMesh(handle, RandomFloat(random, 0.035, 0.06), 10), mesh);
  return mesh;
}

TriangleMesh GenerateSofa(SeededRandom& random) {
  const float width = RandomFloat(random, 1.2, 2.0);
  const float depth = RandomFloat(random, 0.6, 0.9);
  const float base_height = RandomFloat(random, 0.25, 0.4);
  const float back_thickness = RandomFloat(random, 0.15, 0.2);
  const float back_height = RandomFloat(random, 0.35, 0.6);
  const float arm_width = RandomFloat(random, 0.1, 0.2);
  const float arm_height = RandomFloat(random, 0.15, 0.3);
  TriangleMesh mesh;
  AddBox({0, 0, 0.5f * base_height}, {0.5f * width, 0.5f * depth, 0.5f * base_height}, mesh);
  AddBox({0, -0.5f * (depth - back_thickness), base_height + 0.5f * back_height},
         {0.5f * width, 0.5f * back_thickness, 0.5f * back_height}, mesh);
  for (float sx : {-1.0f, 1.0f}) {
    const float top = base_height + arm_height;
    AddBox({sx * (0.5f * width + 0.5f * arm_width), 0, 0.5f * top},
           {0.5f * arm_width, 0.5f * depth, 0.5f * top}, mesh);
  }
  const int cushions = random.UniformInt(2, 3);
  const float cushion_width = width / cushions;
  for (int c = 0; c < cushions; ++c) {
    AddBox({-0.5f * width + cushion_width * (c + 0.5f), 0.5f * back_thickness, base_height + 0.05f},
           {0.48f * cushion_width, 0.5f * (depth - back_thickness), 0.05f}, mesh);
  }
  if (random.Bernoulli(0.5)) {
    // Chaise: the seat extends forward on the +x side only.
    const float chaise_width = width * RandomFloat(random, 0.3, 0.45);
    const float chaise_length = RandomFloat(random, 0.4, 0.7);
    AddBox({0.5f * width - 0.5f * chaise_width, 0.5f * depth + 0.5f * chaise_length,
            0.5f * base_height},
           {0.5f * chaise_width, 0.5f * chaise_length, 0.5f * base_height}, mesh);
  }
  return mesh;
}

TriangleMesh GenerateCar(SeededRandom& random) {
  const float length = RandomFloat(random, 1.6, 2.2);
  const float width = RandomFloat(random, 0.8, 1.0);
  const float wheel_radius = RandomFloat(random, 0.16, 0.22);
  const float body_height = RandomFloat(random, 0.3, 0.45);
  const float floor = 0.6f * wheel_radius;
  TriangleMesh mesh;
  AddBox({0, 0, floor + 0.5f * body_height}, {0.5f * length, 0.5f * width, 0.5f * body_height},
         mesh);
  const float cabin_length = length * RandomFloat(random, 0.4, 0.6);
  const float cabin_height = RandomFloat(random, 0.25, 0.4);
  // Cabin set back from the centre (the nose is +x), narrower at the top.
  const float cabin_x = -length * RandomFloat(random, 0.05, 0.2);
  const float roof_scale = RandomFloat(random, 0.6, 0.9);
  const std::vector<Eigen::Vector2f> bottom = {{-0.5f * cabin_length, -0.45f * width},
                                               {0.5f * cabin_length, -0.45f * width},
                                               {0.5f * cabin_length, 0.45f * width},
                                               {-0.5f * cabin_length, 0.45f * width}};
  std::vector<Eigen::Vector2f> top;
  for (const Eigen::Vector2f& p : bottom) top.emplace_back(roof_scale * p.x(), 0.9f * p.y());
  AppendMesh(TransformedMesh(LoftMesh({bottom, top}, {0.0f, cabin_height}),
                             PlacedAt({cabin_x, 0, floor + body_height})),
             mesh);
  const float axle = length * RandomFloat(random, 0.28, 0.36);
  for (float sx : {-1.0f, 1.0f}) {
    for (float sy : {-1.0f, 1.0f}) {
      const Eigen::Vector3f inner(sx * axle, sy * (0.5f * width - 0.12f), wheel_radius);
      AppendMesh(
          CylinderBetween(inner, inner + Eigen::Vector3f(0, sy * 0.16f, 0), wheel_radius, 20),
          mesh);
    }
  }
  return mesh;
}

TriangleMesh GenerateGuitar(SeededRandom& random) {
  TriangleMesh mesh;
  const float thickness = RandomFloat(random, 0.06, 0.1);
  const Eigen::Vector3f lower(RandomFloat(random, 0.35, 0.45), RandomFloat(random, 0.3, 0.42),
                              thickness);
  const Eigen::Vector3f upper = lower.cwiseProduct(
      Eigen::Vector3f(RandomFloat(random, 0.65, 0.85), RandomFloat(random, 0.65, 0.85), 1.0f));
  AddEllipsoid(Eigen::Affine3f::Identity(), lower, mesh);
  const float upper_x = lower.x() + 0.5f * upper.x();
  AddEllipsoid(PlacedAt({upper_x, 0, 0}), upper, mesh);
  const float neck_length = RandomFloat(random, 0.9, 1.3);
  const float neck_start = upper_x + 0.5f * upper.x();
  AddBox({neck_start + 0.5f * neck_length, 0, 0.5f * thickness},
         {0.5f * neck_length, 0.04f, 0.025f}, mesh);
  Eigen::Affine3f head_pose =
      PlacedAt({neck_start + neck_length + 0.1f, 0, 0.5f * thickness}, Eigen::Vector3f::UnitY(),
               RandomFloat(random, 5, 15) * kDegree);
  AppendMesh(TransformedMesh(BoxMesh({0.12f, 0.06f, 0.015f}), head_pose), mesh);
  AddBox({-0.4f * lower.x(), 0, thickness}, {0.03f, 0.12f, 0.015f}, mesh);
  return mesh;
}

TriangleMesh GenerateFigure(SeededRandom& random) {
  TriangleMesh mesh;
  const Eigen::Vector3f torso(RandomFloat(random, 0.18, 0.25), RandomFloat(random, 0.1, 0.14),
                              RandomFloat(random, 0.3, 0.4));
  const float waist = 1.2f;
  AddEllipsoid(PlacedAt({0, 0, waist + 0.6f * torso.z()}), torso, mesh);
  const float head = RandomFloat(random, 0.1, 0.14);
  AddEllipsoid(PlacedAt({0, 0, waist + 1.6f * torso.z() + 0.9f * head}),
               Eigen::Vector3f::Constant(head), mesh);
  // Each limb: two segments with a random swing, sideways spread and joint bend.
  auto add_limb = [&](const Eigen::Vector3f& root, float swing, float spread, float bend,
                      float segment, float radius) {
    const Eigen::Vector3f upper = LimbDirection(swing, spread);
    const Eigen::Vector3f lower = Eigen::AngleAxisf(bend, Eigen::Vector3f::UnitY()) * upper;
    const Eigen::Vector3f joint = root + segment * upper;
    AppendMesh(TubeMesh({root, joint, joint + segment * lower}, radius, 10), mesh);
  };
  for (float side : {-1.0f, 1.0f}) {
    add_limb({0, side * 0.6f * torso.y() + side * 0.05f, waist},
             RandomFloat(random, -40, 40) * kDegree, side * RandomFloat(random, 0, 15) * kDegree,
             RandomFloat(random, 0, 60) * kDegree, 0.45f, 0.06f);
    add_limb({0, side * (torso.x() * 0.9f), waist + 1.2f * torso.z()},
             RandomFloat(random, -60, 60) * kDegree, side * RandomFloat(random, 10, 80) * kDegree,
             -RandomFloat(random, 0, 90) * kDegree, 0.3f, 0.04f);
  }
  return mesh;
}

TriangleMesh GenerateLaptop(SeededRandom& random) {
  const float width = RandomFloat(random, 0.9, 1.3);
  const float depth = RandomFloat(random, 0.6, 0.9);
  const float thickness = RandomFloat(random, 0.03, 0.05);
  TriangleMesh mesh;
  AddBox({0, 0, 0.5f * thickness}, {0.5f * width, 0.5f * depth, 0.5f * thickness}, mesh);
  // Keyboard towards the hinge (+y), touchpad towards the user (-y).
  AddBox({0, 0.12f * depth, thickness + 0.004f}, {0.4f * width, 0.22f * depth, 0.005f}, mesh);
  AddBox({0, -0.3f * depth, thickness + 0.003f}, {0.12f * width, 0.1f * depth, 0.004f}, mesh);
  const float lid_depth = depth * RandomFloat(random, 0.9, 1.0);
  const float lid_thickness = 0.6f * thickness;
  // Closed, the lid would lie on the base extending to -y from the hinge; open it by `angle`.
  const float angle = RandomFloat(random, 80, 130) * kDegree;
  Eigen::Affine3f lid_pose =
      PlacedAt({0, 0.5f * depth, thickness}, Eigen::Vector3f::UnitX(), -angle);
  lid_pose.translate(Eigen::Vector3f(0, -0.5f * lid_depth, 0.5f * lid_thickness));
  AppendMesh(
      TransformedMesh(BoxMesh({0.5f * width, 0.5f * lid_depth, 0.5f * lid_thickness}), lid_pose),
      mesh);
  return mesh;
}

TriangleMesh GeneratePottedPlant(SeededRandom& random) {
  const float bottom_radius = RandomFloat(random, 0.2, 0.3);
  const float top_radius = bottom_radius * RandomFloat(random, 1.2, 1.5);
  const float pot_height = RandomFloat(random, 0.3, 0.5);
  TriangleMesh mesh = TransformedMesh(FrustumMesh(bottom_radius, top_radius, pot_height, 28),
                                      PlacedAt({0, 0, 0.5f * pot_height}));
  const int stems = random.UniformInt(3, 6);
  for (int s = 0; s < stems; ++s) {
    const float azimuth = RandomFloat(random, 0, 2 * kPi);
    const float start_radius = RandomFloat(random, 0, 0.5) * top_radius;
    const Eigen::Vector3f start(start_radius * std::cos(azimuth), start_radius * std::sin(azimuth),
                                pot_height);
    const float tilt = RandomFloat(random, 10, 55) * kDegree;
    const float heading = RandomFloat(random, 0, 2 * kPi);
    const Eigen::Vector3f direction(std::sin(tilt) * std::cos(heading),
                                    std::sin(tilt) * std::sin(heading), std::cos(tilt));
    const float length = RandomFloat(random, 0.4, 0.9);
    // Quadratic Bezier: leaves the soil upward, bends towards `direction`.
    const Eigen::Vector3f control = start + Eigen::Vector3f(0, 0, 0.5f * length);
    const Eigen::Vector3f end = start + length * direction;
    std::vector<Eigen::Vector3f> stem;
    for (int k = 0; k <= 8; ++k) {
      const float t = k / 8.0f;
      stem.push_back((1 - t) * (1 - t) * start + 2 * (1 - t) * t * control + t * t * end);
    }
    AppendMesh(TubeMesh(stem, 0.02f, 8), mesh);
    const Eigen::Vector3f tangent = (end - control).normalized();
    const Eigen::Vector3f leaf_half(RandomFloat(random, 0.12, 0.2), RandomFloat(random, 0.05, 0.08),
                                    0.015f);
    Eigen::Affine3f leaf_pose = Eigen::Affine3f::Identity();
    leaf_pose.translate(end + 0.8f * leaf_half.x() * tangent);
    leaf_pose.rotate(Eigen::Quaternionf::FromTwoVectors(Eigen::Vector3f::UnitX(), tangent));
    AddEllipsoid(leaf_pose, leaf_half, mesh);
  }
  return mesh;
}

TriangleMesh GenerateHouse(SeededRandom& random) {
  const float width = RandomFloat(random, 1.0, 1.6);
  const float depth = RandomFloat(random, 0.8, 1.2);
  const float wall_height = RandomFloat(random, 0.6, 1.0);
  const float roof_height = RandomFloat(random, 0.3, 0.7);
  const float overhang = RandomFloat(random, 0.05, 0.15);
  TriangleMesh mesh;
  AddBox({0, 0, 0.5f * wall_height}, {0.5f * width, 0.5f * depth, 0.5f * wall_height}, mesh);
  // Gable roof: a triangle (centred on its centroid so the loft's caps fan correctly) extruded
  // along the local z axis, which the pose turns onto x.
  const float centroid = roof_height / 3.0f;
  const std::vector<Eigen::Vector2f> gable = {{-0.5f * depth - overhang, -centroid},
                                              {0.5f * depth + overhang, -centroid},
                                              {0.0f, roof_height - centroid}};
  Eigen::Affine3f roof_pose = Eigen::Affine3f::Identity();
  roof_pose.translate(Eigen::Vector3f(0, 0, wall_height + centroid));
  Eigen::Matrix3f axes;
  axes << 0, 0, 1, 1, 0, 0, 0, 1, 0;  // local (u, v, w) -> world (y, z, x); a proper rotation.
  roof_pose.linear() = axes;
  AppendMesh(
      TransformedMesh(LoftMesh({gable, gable}, {-0.5f * width - overhang, 0.5f * width + overhang}),
                      roof_pose),
      mesh);
  const float chimney_x = RandomFloat(random, -0.35, 0.35) * width;
  const float chimney_y =
      (random.Bernoulli(0.5) ? 1.0f : -1.0f) * RandomFloat(random, 0.1, 0.3) * depth;
  const float chimney_top = wall_height + roof_height + RandomFloat(random, 0.05, 0.25);
  const float chimney_half = RandomFloat(random, 0.06, 0.1);
  AddBox({chimney_x, chimney_y, 0.5f * (wall_height + chimney_top)},
         {chimney_half, chimney_half, 0.5f * (chimney_top - wall_height)}, mesh);
  const float door_height = wall_height * RandomFloat(random, 0.5, 0.75);
  AddBox({RandomFloat(random, -0.3, 0.3) * width, -0.5f * depth - 0.015f, 0.5f * door_height},
         {RandomFloat(random, 0.08, 0.14), 0.02f, 0.5f * door_height}, mesh);
  return mesh;
}

}  // namespace rpsr::core
