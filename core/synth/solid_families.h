// Shape families whose objects are one body (or a cluster of bodies) built from a single random
// parametric surface: deformed superquadrics, rings, vases, twisted prisms, blobs, tubes, gears,
// springs, molecules, block assemblies and stairs. Each generator draws all of its parameters from
// `random`, so the object is a pure function of the generator's seed. Objects come out in
// arbitrary units and position; callers normalise them (object_normalization.h). The registry
// (shape_families.h) records each family's rotational symmetry.
#ifndef RPSR_CORE_SYNTH_SOLID_FAMILIES_H_
#define RPSR_CORE_SYNTH_SOLID_FAMILIES_H_

#include "core/cloud/point_cloud.h"
#include "core/synth/seeded_random.h"

namespace rpsr::core {

// Superquadric (random half axes and exponents: from box-like to diamond-like) tapered along z and
// bent in x; one mirror plane (y -> -y), no rotational symmetry.
TriangleMesh GenerateBentSuperquadric(SeededRandom& random);

// Torus whose tube radius varies around the ring by two harmonics of random phase, squashed in z;
// only the z mirror plane in general.
TriangleMesh GenerateLumpyRing(SeededRandom& random);

// Vase / bottle: surface of revolution of a smooth random profile. Continuous symmetry about its
// axis: the rotation about that axis is unobservable.
TriangleMesh GenerateVase(SeededRandom& random);

// Random star-shaped polygon (5-9 corners) lofted upward with a twist, a taper and a shear.
// No symmetry.
TriangleMesh GenerateTwistedPrism(SeededRandom& random);

// Sphere displaced by a few random plane waves, scaled anisotropically (a pebble). No symmetry.
TriangleMesh GenerateBlob(SeededRandom& random);

// Tube swept along a random smooth space curve. No symmetry.
TriangleMesh GenerateCurvedTube(SeededRandom& random);

// Spur gear (8-16 teeth) with a hub and one off-centre pin on one face, which removes the n-fold
// symmetry. No symmetry.
TriangleMesh GenerateGear(SeededRandom& random);

// Helical spring of 2-5 turns with a radial leg at its start and an axial leg at its end.
// No symmetry.
TriangleMesh GenerateHelixSpring(SeededRandom& random);

// 4-8 spheres of random radii joined by cylinders into a random tree. No symmetry.
TriangleMesh GenerateMolecule(SeededRandom& random);

// 3-6 boxes, each glued to a random face of an earlier one, plus maybe a cylindrical boss (a CSG
// union of boxes and cylinders). No symmetry.
TriangleMesh GenerateBlockAssembly(SeededRandom& random);

// Solid staircase of 3-7 steps with a handrail on one side. No symmetry.
TriangleMesh GenerateStairs(SeededRandom& random);

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_SOLID_FAMILIES_H_
