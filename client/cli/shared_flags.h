// Flags that more than one subcommand reads. Abseil flags are global to the binary, so a name can
// be defined only once: a flag that a second subcommand needs moves here, with a help text that
// covers every subcommand using it, and `rpsr <name> --help` lists these besides the
// subcommand's own.
#ifndef RPSR_CLIENT_CLI_SHARED_FLAGS_H_
#define RPSR_CLIENT_CLI_SHARED_FLAGS_H_

#include <cstdint>
#include <initializer_list>
#include <optional>
#include <string>
#include <vector>

#include "absl/flags/declare.h"
#include "core/data/disturbances.h"
#include "core/data/object_pairs.h"
#include "core/registrar/registrar.h"

ABSL_DECLARE_FLAG(std::string, output);
ABSL_DECLARE_FLAG(std::string, protocol);
ABSL_DECLARE_FLAG(uint64_t, seed);
ABSL_DECLARE_FLAG(int, num_points);
ABSL_DECLARE_FLAG(int, count);
ABSL_DECLARE_FLAG(std::string, split);
ABSL_DECLARE_FLAG(std::string, disturbance);
ABSL_DECLARE_FLAG(int, level);
ABSL_DECLARE_FLAG(int, batch_size);
ABSL_DECLARE_FLAG(int, passes);
ABSL_DECLARE_FLAG(bool, later_passes_when_unconfident);
ABSL_DECLARE_FLAG(bool, refine_from_initial);
ABSL_DECLARE_FLAG(bool, search_scene_start);
ABSL_DECLARE_FLAG(bool, symmetric_starts);
ABSL_DECLARE_FLAG(bool, round_axis_start);
ABSL_DECLARE_FLAG(bool, weak_direction_start);
ABSL_DECLARE_FLAG(bool, weak_direction_finest_round);
ABSL_DECLARE_FLAG(bool, centroid_start);
ABSL_DECLARE_FLAG(bool, principal_axes_start);
ABSL_DECLARE_FLAG(bool, extent_slide);
ABSL_DECLARE_FLAG(bool, weak_direction_chamfer);
ABSL_DECLARE_FLAG(bool, half_turn_start);
ABSL_DECLARE_FLAG(bool, screw_turns);
ABSL_DECLARE_FLAG(bool, far_valley);
ABSL_DECLARE_FLAG(bool, sensor_aligned_check);
ABSL_DECLARE_FLAG(bool, rebin_coarse_depths);
ABSL_DECLARE_FLAG(bool, joint_finest_stage);
ABSL_DECLARE_FLAG(bool, noise_polish);
ABSL_DECLARE_FLAG(bool, hold_degenerate_at_initial);
ABSL_DECLARE_FLAG(bool, coarse_wide_search);
ABSL_DECLARE_FLAG(bool, line_normals_from_planes);
ABSL_DECLARE_FLAG(int, threads);
ABSL_DECLARE_FLAG(std::string, model);
ABSL_DECLARE_FLAG(std::string, mode);
ABSL_DECLARE_FLAG(int, tree_depth);

namespace rpsr::client {

// The --disturbance names: none, noise, outliers, crop, jitter, partial; nullopt for anything else.
std::optional<core::DisturbanceKind> ParseDisturbanceFlag(const std::string& name);

// The --split names of the object protocol: m1, seen, unseen (any case); an empty name gives
// `empty_means`; nullopt for anything else.
std::optional<core::ObjectSplit> ParseObjectSplitFlag(const std::string& name,
                                                      core::ObjectSplit empty_means);

// The registration flags the subcommands share (--passes, --later_passes_when_unconfident,
// --refine_from_initial,
// --search_scene_start, --symmetric_starts, --round_axis_start, --weak_direction_start,
// --weak_direction_finest_round, --centroid_start, --principal_axes_start, --extent_slide,
// --weak_direction_chamfer, --half_turn_start, --screw_turns, --far_valley,
// --sensor_aligned_check,
// --rebin_coarse_depths, --joint_finest_stage, --noise_polish, --coarse_wide_search,
// --line_normals_from_planes, --hold_degenerate_at_initial) set on `options`; its mode and initial
// guess stay the caller's.
void ApplyRegistrationFlags(core::RegistrationOptions& options);

// Whether the flag `name` was given on the command line (a subcommand then uses it as given
// instead of choosing itself).
bool GivenOnCommandLine(const char* name);

// The flags of `names` given on the command line, as "--name", in the order of `names`: for a
// subcommand that refuses flags it would otherwise ignore (rpsr calibrate measures the shipped
// pipeline and its own pair sets).
std::vector<std::string> GivenAmong(std::initializer_list<const char*> names);

// --line_normals_from_planes when given on the command line; nullopt (the refinement chooses per
// pair) when not.
std::optional<bool> ExplicitLineNormalsFlag();

// --model: a weights file, or the name of an embedded model when no file of that name exists;
// empty: the default embedded model (the Registrar then loads its shipped calibration too).
core::RegistrarConfig RegistrarConfigFromModelFlag(const std::string& model);

}  // namespace rpsr::client

#endif  // RPSR_CLIENT_CLI_SHARED_FLAGS_H_
