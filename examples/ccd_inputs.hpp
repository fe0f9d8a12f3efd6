// lwsccd-ccd — where the main program's steps come from: the built-in scene, two frames, a scene
// folder (with its ground truth) or a folder of frames, opened as one StepSource.
#pragma once

#include <algorithm>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "ccd_app.hpp"
#include "ccd_options.hpp"
#include "lwsccd/simulation/simulation.hpp"

namespace ccd_app {

/// Where the steps come from: one topology (and body layout), then steps until there are none.
struct StepSource {
  std::string description;
  std::shared_ptr<const lwsccd::TriangleMesh> mesh;
  lwsccd::BodyLayout layout;
  std::size_t num_steps = 0;
  std::function<lwsccd::Step(std::size_t)> step;  ///< step i, in order
  const lwsccd::GroundTruth* truth = nullptr;     ///< for a scene folder with ground truth
};

struct Inputs {
  std::unique_ptr<lwsccd::ClothBallSimulation> simulation;
  std::unique_ptr<lwsccd::Scene> scene;
  std::unique_ptr<lwsccd::Sequence> sequence;
  std::unique_ptr<lwsccd::Step> two_frames;
};

inline StepSource open_source(const Options& o, Inputs& in) {
  namespace fs = std::filesystem;
  StepSource src;
  if (o.inputs.empty()) {
    in.simulation = std::make_unique<lwsccd::ClothBallSimulation>(o.triangles);
    in.simulation->advance(o.first_frame);
    src.mesh = in.simulation->mesh();
    src.layout = in.simulation->layout();
    src.num_steps = o.steps ? o.steps : 3;
    src.description = "built-in scene: a folded cloth (" + std::to_string(in.simulation->cloth_triangles()) +
                      " triangles, self-colliding) dropped on a rigid ball (" +
                      std::to_string(src.mesh->num_faces() - in.simulation->cloth_triangles()) + " triangles), frames " +
                      std::to_string(o.first_frame) + " to " + std::to_string(o.first_frame + src.num_steps);
    src.step = [&in](std::size_t) { return in.simulation->next_step(); };
  } else if (o.inputs.size() == 2) {
    in.two_frames = std::make_unique<lwsccd::Step>(lwsccd::load_step(o.inputs[0], o.inputs[1]));
    src.mesh = in.two_frames->mesh;
    src.num_steps = o.steps ? o.steps : 1;  // K > 1: the same step again (a steady state)
    src.description = "two frames: " + o.inputs[0] + " -> " + o.inputs[1];
    src.step = [&in](std::size_t) { return *in.two_frames; };
  } else if (fs::is_directory(fs::path(o.inputs[0]) / "frames")) {
    in.scene = std::make_unique<lwsccd::Scene>(lwsccd::load_scene(o.inputs[0]));
    src.mesh = in.scene->step.mesh;
    src.num_steps = o.steps ? o.steps : 1;  // K > 1: the same step again (a steady state)
    src.truth = in.scene->has_ground_truth ? &in.scene->truth : nullptr;
    src.description = "scene " + in.scene->name + " (" + in.scene->step.name + ")" +
                      (src.truth ? ", with ground truth" : ", no ground truth");
    src.step = [&in](std::size_t) { return in.scene->step; };
  } else if (fs::is_directory(o.inputs[0])) {
    in.sequence = std::make_unique<lwsccd::Sequence>(lwsccd::load_sequence(o.inputs[0]));
    src.mesh = in.sequence->mesh();
    src.num_steps = o.steps ? std::min(o.steps, in.sequence->num_steps()) : in.sequence->num_steps();
    src.description = "sequence " + o.inputs[0] + ": " + std::to_string(in.sequence->num_frames()) + " frames";
    src.step = [&in](std::size_t i) { return in.sequence->step(i); };
  } else {
    throw lwsccd::InputError(o.inputs[0], "", "is neither a scene folder, a folder of frames, nor one of two frame files");
  }
  return src;
}

}  // namespace ccd_app
