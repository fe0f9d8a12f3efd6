// lwsccd — reading scene folders laid out like the Belgrod et al. CCD dataset
// (../shared/data/scenes/<scene>/): frames/, boxes/<step>{vf,ee}.json, mma_bool/<step>{vf,ee}_mma_bool.json.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "lwsccd/io/mesh_io.hpp"

namespace lwsccd {

/// Candidate feature pairs with an exact yes/no answer for each (does it touch in the step?).
/// Ids follow TriangleMesh's feature-id convention: vf = (vertex, V+E+face), ee = (V+e0, V+e1), e0 < e1.
struct GroundTruth {
  std::vector<std::pair<index_t, index_t>> vf, ee;
  std::vector<bool> vf_collides, ee_collides;
};

/// A two-frame scene: the step plus its ground truth, when the folder has one.
struct Scene {
  std::string name;      ///< folder name
  std::string step_id;   ///< e.g. "92" (the prefix of the boxes files)
  Step step;
  bool has_ground_truth = false;
  GroundTruth truth;
};

/// Loads a scene folder: frames/ with exactly two mesh files (t0, t1 in name order) and, when
/// present, boxes/ and mma_bool/ JSON ground truth. Throws InputError naming the file and problem.
Scene load_scene(const std::string& folder);

/// Parses a JSON array of [a, b] integer pairs (the boxes files).
std::vector<std::pair<index_t, index_t>> load_json_pairs(const std::string& path);
/// Parses a JSON array of booleans (the mma_bool files).
std::vector<bool> load_json_bools(const std::string& path);

}  // namespace lwsccd

#include "lwsccd/io/detail/dataset_impl.hpp"
