// Flags read by more than one subcommand (see shared_flags.h).
#include "client/cli/shared_flags.h"

#include "absl/flags/flag.h"

ABSL_FLAG(std::string, output, "",
          "the folder written: train: model.rpsrw, last.rpsrw, the state and the log; data: the "
          "clouds, manifest.csv and the simulated sequences");
ABSL_FLAG(std::string, protocol, "objects",
          "objects: the paper's ModelNet-style protocol on procedural objects (train: the M2 seen "
          "classes; data: --split); lidar: pairs of frames i and i+5 (train: simulated HDL-64E "
          "streets, half without ground; data pairs: "
          "read from --kitti)");
ABSL_FLAG(uint64_t, seed, 1,
          "seed of everything drawn at random (train: weights and pair streams; data: objects, "
          "poses, disturbances, simulated streets and the choice of --max_pairs)");
ABSL_FLAG(int, num_points, 1024, "objects: points sampled per cloud");
