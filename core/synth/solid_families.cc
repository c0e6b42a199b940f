#include "core/synth/solid_families.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/synth/primitive_meshes.h"

namespace rpsr::core {
namespace {

constexpr float kPi = 3.14159265358979f;

float RandomFloat(SeededRandom& random, double low, double high) {
  return static_cast<float>(random.Uniform(low, high));
}

Eigen::Vector3f RandomUnitVector(SeededRandom& random) { return random.UnitVector().cast<float>(); }

// Catmull-Rom interpolation of `controls` at `samples` evenly spaced parameters (ends clamped):
// a smooth curve through every control value.
std::vector<float> SmoothCurve(const std::vector<float>& controls, int samples) {
  std::vector<float> out;
  const int last = static_cast<int>(controls.size()) - 1;
  for (int s = 0; s < samples; ++s) {
    const float u = static_cast<float>(s) * last / (samples - 1);
    const int i = std::min(static_cast<int>(u), last - 1);
    const float t = u - i;
    const float p0 = controls[std::max(i - 1, 0)];
    const float p1 = controls[i];
    const float p2 = controls[i + 1];
    const float p3 = controls[std::min(i + 2, last)];
    out.push_back(0.5f * (2 * p1 + (-p0 + p2) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t * t +
                          (-p0 + 3 * p1 - 3 * p2 + p3) * t * t * t));
  }
  return out;
}

// Drops path points closer than `min_step` to their predecessor, so tube frames stay defined.
std::vector<Eigen::Vector3f> WithoutRepeats(const std::vector<Eigen::Vector3f>& path,
                                            float min_step) {
  std::vector<Eigen::Vector3f> out;
  for (const Eigen::Vector3f& p : path) {
    if (out.empty() || (p - out.back()).norm() > min_step) out.push_back(p);
  }
  return out;
}

}  // namespace

TriangleMesh GenerateBentSuperquadric(SeededRandom& random) {
  const Eigen::Vector3f half_axes(RandomFloat(random, 0.4, 1.0), RandomFloat(random, 0.4, 1.0),
                                  RandomFloat(random, 0.4, 1.0));
  const float epsilon1 = RandomFloat(random, 0.25, 1.6);
  const float epsilon2 = RandomFloat(random, 0.25, 1.6);
  TriangleMesh mesh = SuperquadricMesh(half_axes, epsilon1, epsilon2, 16, 24);
  // Taper (breaks z -> -z) and bend (breaks x -> -x); at least a noticeable bend so no object is
  // nearly symmetric.
  const float taper = RandomFloat(random, -0.5, 0.5);
  const float bend = (random.Bernoulli(0.5) ? 1.0f : -1.0f) * RandomFloat(random, 0.25, 0.6);
  for (Eigen::Vector3f& v : mesh.vertices) {
    const float t = v.z() / half_axes.z();
    v.x() *= 1.0f + taper * t;
    v.y() *= 1.0f + taper * t;
    v.x() += bend * half_axes.x() * t * t;
  }
  return mesh;
}

TriangleMesh GenerateLumpyRing(SeededRandom& random) {
  const float tube = RandomFloat(random, 0.15, 0.35);
  const float first_harmonic = RandomFloat(random, 0.25, 0.5);
  const float second_harmonic = RandomFloat(random, 0.1, 0.3);
  const float first_phase = RandomFloat(random, 0, 2 * kPi);
  const float second_phase = RandomFloat(random, 0, 2 * kPi);
  constexpr int kMajorSegments = 48;
  std::vector<float> tube_radii;
  for (int c = 0; c < kMajorSegments; ++c) {
    const float angle = 2 * kPi * c / kMajorSegments;
    const float factor = 1.0f + first_harmonic * std::cos(angle - first_phase) +
                         second_harmonic * std::cos(2 * angle - second_phase);
    tube_radii.push_back(tube * std::max(factor, 0.3f));
  }
  const float squash = RandomFloat(random, 0.6, 1.2);
  return TransformedMesh(
      TorusMesh(1.0f, tube_radii, 16),
      Eigen::Affine3f(Eigen::Scaling(1.0f, RandomFloat(random, 0.7, 1.0), squash)));
}

TriangleMesh GenerateVase(SeededRandom& random) {
  const int num_controls = random.UniformInt(4, 7);
  std::vector<float> radii;
  for (int i = 0; i < num_controls; ++i) radii.push_back(RandomFloat(random, 0.2, 0.8));
  const float height = RandomFloat(random, 1.2, 2.4);
  constexpr int kRows = 20;
  const std::vector<float> smooth = SmoothCurve(radii, kRows);
  std::vector<Eigen::Vector2f> profile;
  for (int r = 0; r < kRows; ++r) {
    profile.emplace_back(std::max(smooth[r], 0.08f), height * r / (kRows - 1));
  }
  return RevolutionMesh(profile, 32);
}

TriangleMesh GenerateTwistedPrism(SeededRandom& random) {
  const int corners = random.UniformInt(5, 9);
  std::vector<Eigen::Vector2f> polygon;
  for (int i = 0; i < corners; ++i) {
    // Jittered angles stay increasing, so the polygon is star-shaped about the origin.
    const float angle = 2 * kPi * (i + RandomFloat(random, -0.3, 0.3)) / corners;
    const float radius = RandomFloat(random, 0.45, 1.0);
    polygon.emplace_back(radius * std::cos(angle), radius * std::sin(angle));
  }
  const float height = RandomFloat(random, 0.6, 2.0);
  const float twist = (random.Bernoulli(0.5) ? 1.0f : -1.0f) * RandomFloat(random, 0.25, 1.6);
  const float top_scale = RandomFloat(random, 0.4, 1.0);
  constexpr int kSections = 8;
  std::vector<std::vector<Eigen::Vector2f>> sections;
  std::vector<float> heights;
  for (int k = 0; k < kSections; ++k) {
    const float t = static_cast<float>(k) / (kSections - 1);
    const Eigen::Rotation2Df turn(twist * t);
    const float scale = 1.0f + (top_scale - 1.0f) * t;
    std::vector<Eigen::Vector2f> section;
    for (const Eigen::Vector2f& p : polygon) section.push_back(scale * (turn * p));
    sections.push_back(std::move(section));
    heights.push_back(height * t);
  }
  Eigen::Affine3f shear = Eigen::Affine3f::Identity();
  shear.linear()(0, 2) = RandomFloat(random, -0.4, 0.4);
  shear.linear()(1, 2) = RandomFloat(random, -0.4, 0.4);
  return TransformedMesh(LoftMesh(sections, heights), shear);
}

TriangleMesh GenerateBlob(SeededRandom& random) {
  TriangleMesh mesh = EllipsoidMesh(Eigen::Vector3f::Ones(), 16, 24);
  const int num_waves = random.UniformInt(3, 5);
  std::vector<Eigen::Vector3f> directions;
  std::vector<float> amplitudes, frequencies, phases;
  for (int k = 0; k < num_waves; ++k) {
    directions.push_back(RandomUnitVector(random));
    amplitudes.push_back(RandomFloat(random, 0.06, 0.2));
    frequencies.push_back(RandomFloat(random, 1.0, 3.0));
    phases.push_back(RandomFloat(random, 0, 2 * kPi));
  }
  for (Eigen::Vector3f& v : mesh.vertices) {
    float radius = 1.0f;
    for (int k = 0; k < num_waves; ++k) {
      radius += amplitudes[k] * std::sin(frequencies[k] * directions[k].dot(v) + phases[k]);
    }
    v *= radius;
  }
  const Eigen::Vector3f scale(RandomFloat(random, 0.6, 1.0), RandomFloat(random, 0.6, 1.0),
                              RandomFloat(random, 0.6, 1.0));
  return TransformedMesh(mesh, Eigen::Affine3f(Eigen::Scaling(scale)));
}

TriangleMesh GenerateCurvedTube(SeededRandom& random) {
  Eigen::Vector3f drift = RandomUnitVector(random) * RandomFloat(random, 0.5, 1.5);
  Eigen::Vector3f amplitudes[3];
  float phases[3];
  for (int k = 0; k < 3; ++k) {
    amplitudes[k] = Eigen::Vector3f(RandomFloat(random, -1, 1), RandomFloat(random, -1, 1),
                                    RandomFloat(random, -1, 1)) /
                    static_cast<float>(k + 1);
    phases[k] = RandomFloat(random, 0, 2 * kPi);
  }
  constexpr int kSamples = 48;
  std::vector<Eigen::Vector3f> path;
  for (int s = 0; s < kSamples; ++s) {
    const float t = static_cast<float>(s) / (kSamples - 1);
    Eigen::Vector3f p = t * drift;
    for (int k = 0; k < 3; ++k) p += amplitudes[k] * std::sin(kPi * (k + 1) * t + phases[k]);
    path.push_back(p);
  }
  path = WithoutRepeats(path, 1e-3f);
  if (path.size() < 2) path = {Eigen::Vector3f::Zero(), drift};
  return TubeMesh(path, RandomFloat(random, 0.06, 0.14), 12);
}

TriangleMesh GenerateGear(SeededRandom& random) {
  const int teeth = random.UniformInt(8, 16);
  const float root = RandomFloat(random, 0.6, 0.8);
  const float thickness = RandomFloat(random, 0.15, 0.4);
  std::vector<Eigen::Vector2f> outline;
  for (int i = 0; i < teeth; ++i) {
    const float pitch = 2 * kPi / teeth;
    const float base = pitch * i;
    // Root, flank up, tip, flank down: four corners per tooth.
    const float fractions[4] = {0.0f, 0.2f, 0.45f, 0.65f};
    const float radii[4] = {root, 1.0f, 1.0f, root};
    for (int k = 0; k < 4; ++k) {
      const float angle = base + fractions[k] * pitch;
      outline.emplace_back(radii[k] * std::cos(angle), radii[k] * std::sin(angle));
    }
  }
  TriangleMesh mesh = LoftMesh({outline, outline}, {-0.5f * thickness, 0.5f * thickness});
  const float hub_radius = RandomFloat(random, 0.2, 0.35);
  AppendMesh(FrustumMesh(hub_radius, hub_radius, thickness * RandomFloat(random, 1.6, 2.6), 24),
             mesh);
  const float pin_angle = RandomFloat(random, 0, 2 * kPi);
  const float pin_distance = RandomFloat(random, hub_radius + 0.1, root - 0.1);
  const Eigen::Vector3f pin_base(pin_distance * std::cos(pin_angle),
                                 pin_distance * std::sin(pin_angle), 0.5f * thickness);
  AppendMesh(
      CylinderBetween(pin_base, pin_base + Eigen::Vector3f(0, 0, RandomFloat(random, 0.2, 0.4)),
                      0.06f, 12),
      mesh);
  return mesh;
}

TriangleMesh GenerateHelixSpring(SeededRandom& random) {
  const float turns = RandomFloat(random, 2.0, 5.0);
  const float pitch = RandomFloat(random, 0.3, 0.6);
  const float wire = RandomFloat(random, 0.06, 0.12);
  std::vector<Eigen::Vector3f> path;
  // Radial leg pointing into the coil at the start.
  const float leg_in = RandomFloat(random, 0.4, 0.9);
  path.emplace_back(1.0f - leg_in, 0.0f, 0.0f);
  const int samples = static_cast<int>(turns * 24);
  for (int s = 0; s <= samples; ++s) {
    const float angle = 2 * kPi * turns * s / samples;
    path.emplace_back(std::cos(angle), std::sin(angle), pitch * angle / (2 * kPi));
  }
  // Axial leg at the end.
  path.push_back(path.back() + Eigen::Vector3f(0, 0, RandomFloat(random, 0.3, 0.7)));
  return TubeMesh(WithoutRepeats(path, 1e-3f), wire, 10);
}

TriangleMesh GenerateMolecule(SeededRandom& random) {
  const int num_atoms = random.UniformInt(4, 8);
  std::vector<Eigen::Vector3f> centres = {Eigen::Vector3f::Zero()};
  std::vector<float> radii = {RandomFloat(random, 0.2, 0.4)};
  TriangleMesh mesh;
  for (int a = 1; a < num_atoms; ++a) {
    const int parent = static_cast<int>(random.UniformIndex(centres.size()));
    const Eigen::Vector3f centre =
        centres[parent] + RandomUnitVector(random) * RandomFloat(random, 0.6, 1.0);
    AppendMesh(CylinderBetween(centres[parent], centre, 0.07f, 10), mesh);
    centres.push_back(centre);
    radii.push_back(RandomFloat(random, 0.2, 0.4));
  }
  for (size_t a = 0; a < centres.size(); ++a) {
    AppendMesh(TransformedMesh(EllipsoidMesh(Eigen::Vector3f::Constant(radii[a]), 8, 12),
                               PlacedAt(centres[a])),
               mesh);
  }
  return mesh;
}

TriangleMesh GenerateBlockAssembly(SeededRandom& random) {
  struct Block {
    Eigen::Vector3f centre;
    Eigen::Vector3f half;
  };
  std::vector<Block> blocks = {
      {Eigen::Vector3f::Zero(),
       Eigen::Vector3f(RandomFloat(random, 0.2, 0.6), RandomFloat(random, 0.2, 0.6),
                       RandomFloat(random, 0.2, 0.6))}};
  const int num_blocks = random.UniformInt(3, 6);
  for (int b = 1; b < num_blocks; ++b) {
    const Block& base = blocks[random.UniformIndex(blocks.size())];
    const int axis = static_cast<int>(random.UniformIndex(3));
    const float side = random.Bernoulli(0.5) ? 1.0f : -1.0f;
    Block block;
    block.half = Eigen::Vector3f(RandomFloat(random, 0.12, 0.5), RandomFloat(random, 0.12, 0.5),
                                 RandomFloat(random, 0.12, 0.5));
    block.centre = base.centre;
    // Glued to the chosen face, sliding anywhere within it.
    block.centre[axis] += side * (base.half[axis] + block.half[axis]);
    for (int other = 0; other < 3; ++other) {
      if (other != axis) block.centre[other] += RandomFloat(random, -1, 1) * base.half[other];
    }
    blocks.push_back(block);
  }
  TriangleMesh mesh;
  for (const Block& block : blocks) {
    AppendMesh(TransformedMesh(BoxMesh(block.half), PlacedAt(block.centre)), mesh);
  }
  if (random.Bernoulli(0.6)) {
    const Block& base = blocks[random.UniformIndex(blocks.size())];
    const int axis = static_cast<int>(random.UniformIndex(3));
    const float side = random.Bernoulli(0.5) ? 1.0f : -1.0f;
    Eigen::Vector3f from = base.centre;
    from[axis] += side * base.half[axis];
    Eigen::Vector3f to = from;
    to[axis] += side * RandomFloat(random, 0.15, 0.5);
    const float radius = 0.8f * std::min({base.half[(axis + 1) % 3], base.half[(axis + 2) % 3]});
    AppendMesh(CylinderBetween(from, to, radius, 20), mesh);
  }
  return mesh;
}

TriangleMesh GenerateStairs(SeededRandom& random) {
  const int steps = random.UniformInt(3, 7);
  const float width = RandomFloat(random, 0.6, 1.2);
  const float depth = RandomFloat(random, 0.2, 0.35);
  const float rise = RandomFloat(random, 0.12, 0.25);
  TriangleMesh mesh;
  for (int s = 0; s < steps; ++s) {
    // Step s is a solid block from the floor up to its tread.
    const float top = rise * (s + 1);
    AppendMesh(TransformedMesh(BoxMesh({0.5f * depth, 0.5f * width, 0.5f * top}),
                               PlacedAt({depth * (s + 0.5f), 0.0f, 0.5f * top})),
               mesh);
  }
  // Handrail on the +y side: a post per step and a rail along the slope.
  const float rail_height = RandomFloat(random, 0.5, 0.9);
  const float y = 0.5f * width - 0.03f;
  std::vector<Eigen::Vector3f> rail;
  for (int s = 0; s < steps; ++s) {
    const Eigen::Vector3f foot(depth * (s + 0.5f), y, rise * (s + 1));
    const Eigen::Vector3f head = foot + Eigen::Vector3f(0, 0, rail_height);
    AppendMesh(CylinderBetween(foot, head, 0.02f, 8), mesh);
    rail.push_back(head);
  }
  if (rail.size() >= 2) AppendMesh(TubeMesh(rail, 0.03f, 8), mesh);
  return mesh;
}

}  // namespace rpsr::core
