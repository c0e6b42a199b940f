#include "core/synth/shape_families.h"

#include "absl/strings/str_cat.h"
#include "core/synth/assembled_families.h"
#include "core/synth/solid_families.h"

namespace rpsr::core {

const std::vector<ShapeFamily>& ShapeFamilies() {
  using enum FamilySplit;
  using enum RotationalSymmetry;
  static const std::vector<ShapeFamily>* const kFamilies = new std::vector<ShapeFamily>{
      {"bent_superquadric", kSeen, kNone, &GenerateBentSuperquadric},
      {"lumpy_ring", kSeen, kNone, &GenerateLumpyRing},
      {"vase", kSeen, kContinuous, &GenerateVase},
      {"twisted_prism", kSeen, kNone, &GenerateTwistedPrism},
      {"chair", kSeen, kNone, &GenerateChair},
      {"table", kSeen, kContinuous, &GenerateTable},
      {"lamp", kSeen, kNone, &GenerateLamp},
      {"bookshelf", kSeen, kNone, &GenerateBookshelf},
      {"airplane", kSeen, kNone, &GenerateAirplane},
      {"mug", kSeen, kNone, &GenerateMug},
      {"block_assembly", kSeen, kNone, &GenerateBlockAssembly},
      {"curved_tube", kSeen, kNone, &GenerateCurvedTube},
      {"blob", kUnseen, kNone, &GenerateBlob},
      {"gear", kUnseen, kNone, &GenerateGear},
      {"helix_spring", kUnseen, kNone, &GenerateHelixSpring},
      {"molecule", kUnseen, kNone, &GenerateMolecule},
      {"stairs", kUnseen, kNone, &GenerateStairs},
      {"sofa", kUnseen, kNone, &GenerateSofa},
      {"car", kUnseen, kNone, &GenerateCar},
      {"guitar", kUnseen, kNone, &GenerateGuitar},
      {"figure", kUnseen, kNone, &GenerateFigure},
      {"laptop", kUnseen, kNone, &GenerateLaptop},
      {"potted_plant", kUnseen, kNone, &GeneratePottedPlant},
      {"house", kUnseen, kNone, &GenerateHouse},
  };
  return *kFamilies;
}

std::vector<size_t> FamilyIndicesIn(FamilySplit split) {
  std::vector<size_t> indices;
  const std::vector<ShapeFamily>& families = ShapeFamilies();
  for (size_t i = 0; i < families.size(); ++i) {
    if (families[i].split == split) indices.push_back(i);
  }
  return indices;
}

absl::StatusOr<TriangleMesh> GenerateObject(size_t family_index, uint64_t seed) {
  const std::vector<ShapeFamily>& families = ShapeFamilies();
  if (family_index >= families.size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "shape family index ", family_index, " out of range (", families.size(), " families)"));
  }
  // Mix in the family so that one seed gives unrelated draws in different families.
  SeededRandom random(DeriveSeed(seed, family_index));
  return families[family_index].generate(random);
}

}  // namespace rpsr::core
