// lwsccd — the stages of a CCD step, in the order they run, written once for both backends.
//
// cpu::CcdPipeline and gpu::CcdPipeline each supply the stages (a backend: member functions
// named below); run_stage_sequence runs them in order and marks the end of each, so a new stage
// is added here, once, and each backend then has to supply it (a backend that does not fails to
// compile at the call). A step run whole goes through this sequence; a step in parts
// (PipelineParams::part_pairs, or a GPU memory budget) interleaves the last three stages a part at
// a time in each backend's own loop (step_in_parts, run_streamed_stages).
#pragma once

namespace lwsccd::detail {

/// The stages of a step, in the order they run (docs/DESIGN.md draws them).
enum class PipelineStage : int {
  refit = 0,          ///< the BVH built, refit or rebuilt for the step's motion
  traversal = 1,      ///< BVTT self-collision traversal (broad phase): candidate triangle pairs
  feature_pairs = 2,  ///< vertex-face and edge-edge pairs, each produced once, culled by their boxes
  narrow_phase = 3,   ///< the CCD method on every feature pair: hits and times of impact
};
inline constexpr int kPipelineStages = 4;

/// Runs one step's stages in order. `Backend` supplies, each taking the step's state `step`:
///   stage_refit, stage_traversal, stage_feature_pairs, stage_narrow_phase (a stage may only
///   enqueue its work, as the GPU's do), stage_done(PipelineStage, step) after each (where the
///   backend marks the time), then complete_step(step) (the GPU reads its counts there and runs
///   again what outgrew its room).
template <class Backend, class StepState>
void run_stage_sequence(Backend& backend, StepState& step) {
  backend.stage_refit(step);
  backend.stage_done(PipelineStage::refit, step);
  backend.stage_traversal(step);
  backend.stage_done(PipelineStage::traversal, step);
  backend.stage_feature_pairs(step);
  backend.stage_done(PipelineStage::feature_pairs, step);
  backend.stage_narrow_phase(step);
  backend.stage_done(PipelineStage::narrow_phase, step);
  backend.complete_step(step);
}

}  // namespace lwsccd::detail
