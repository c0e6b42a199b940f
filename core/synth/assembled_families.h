// Shape families whose objects are assembled from parts (boxes, cylinders, ellipsoids, tubes), the
// way ModelNet's man-made categories are: chairs, tables, lamps, bookshelves, airplanes, mugs,
// sofas, cars, guitars, human figures, laptops, potted plants and houses. Each generator draws all
// of its part sizes and placements from `random`, so the object is a pure function of the
// generator's seed. Objects come out in arbitrary units and position; callers normalise them
// (object_normalization.h). Parts overlap rather than being boolean-merged. The registry
// (shape_families.h) records each family's rotational symmetry.
#ifndef RPSR_CORE_SYNTH_ASSEMBLED_FAMILIES_H_
#define RPSR_CORE_SYNTH_ASSEMBLED_FAMILIES_H_

#include "core/cloud/point_cloud.h"
#include "core/synth/seeded_random.h"

namespace rpsr::core {

// Seat, four legs (round or square), a tilted backrest, sometimes armrests. One mirror plane.
TriangleMesh GenerateChair(SeededRandom& random);

// Rectangular top on four legs, or a round top on a pedestal. Rectangular: 180 degree symmetry
// about the vertical; round: continuous symmetry about the vertical.
TriangleMesh GenerateTable(SeededRandom& random);

// Desk lamp: base disc, two-segment arm bent in one plane, conical shade. One mirror plane.
TriangleMesh GenerateLamp(SeededRandom& random);

// Open bookshelf (sides, top, bottom, back, 2-5 shelves) with random books. No symmetry.
TriangleMesh GenerateBookshelf(SeededRandom& random);

// Fuselage, swept wings, tailplane and fin, sometimes two engines. One mirror plane.
TriangleMesh GenerateAirplane(SeededRandom& random);

// Tapered cylindrical body with a C-shaped handle. One mirror plane.
TriangleMesh GenerateMug(SeededRandom& random);

// Base, back, two arms, 2-3 seat cushions, sometimes a chaise on one side. One mirror plane or
// none.
TriangleMesh GenerateSofa(SeededRandom& random);

// Body, cabin set back from the centre, four wheels. One mirror plane.
TriangleMesh GenerateCar(SeededRandom& random);

// Two-lobed body, neck, angled headstock, bridge. One mirror plane.
TriangleMesh GenerateGuitar(SeededRandom& random);

// Human figure (torso, head, jointed arms and legs) in a random pose. No symmetry.
TriangleMesh GenerateFigure(SeededRandom& random);

// Base with keyboard and a lid opened at a random angle. One mirror plane.
TriangleMesh GenerateLaptop(SeededRandom& random);

// Tapered pot with 3-6 curved stems each ending in a leaf. No symmetry.
TriangleMesh GeneratePottedPlant(SeededRandom& random);

// Walls, gabled roof, an off-centre chimney and a door on one wall. No symmetry.
TriangleMesh GenerateHouse(SeededRandom& random);

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_ASSEMBLED_FAMILIES_H_
