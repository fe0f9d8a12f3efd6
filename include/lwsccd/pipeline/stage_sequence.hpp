// lwsccd — the stages of a CCD step, in the order they run, written once for both backends and
// for both ways of running a step: whole, or in parts.
//
// cpu::CcdPipeline and gpu::CcdPipeline each supply the stages (a backend: member functions
// named below); run_stage_sequence runs them in order and marks the end of each, so a new stage
// is added here, once, and each backend then has to supply it (a backend that does not fails to
// compile at the call). A step in parts (PipelineParams::part_pairs, or a GPU memory budget) is
// the same sequence with more than one part: the backend hands out traversal parts and, for each,
// narrow-phase parts (feature pairs and narrow phase together); a whole step is one of each.
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

/// The feature pairs and the narrow phase of every narrow-phase part the backend hands out now.
template <class Backend, class StepState>
void run_narrow_parts(Backend& backend, StepState& step) {
  while (backend.next_narrow_part(step)) {
    backend.stage_feature_pairs(step);
    backend.stage_done(PipelineStage::feature_pairs, step);
    backend.stage_narrow_phase(step);
    backend.stage_done(PipelineStage::narrow_phase, step);
  }
}

/// Runs one step's stages in order. `Backend` supplies, each taking the step's state `step`:
///   stage_refit, stage_traversal, stage_feature_pairs, stage_narrow_phase (a stage may only
///   enqueue its work, as the GPU's do in a whole step), stage_done(PipelineStage, step) after
///   each (where the backend marks or adds up the time), then complete_step(step) (the GPU reads
///   its counts there and runs again what outgrew its room; a step in parts sorts its hits);
///   next_traversal_part(step): whether another traversal part follows (a whole step: one);
///   next_narrow_part(step): whether another part of the current candidates follows (a whole
///   step: one, every candidate and the orphans). After the traversal parts the backend may hand
///   out narrow-phase parts of candidates no traversal part held (a step in parts: the orphans,
///   and on the GPU the pairs met by the cut below the root, tested once the parts' lists hold
///   their room).
template <class Backend, class StepState>
void run_stage_sequence(Backend& backend, StepState& step) {
  backend.stage_refit(step);
  backend.stage_done(PipelineStage::refit, step);
  while (backend.next_traversal_part(step)) {
    backend.stage_traversal(step);
    backend.stage_done(PipelineStage::traversal, step);
    run_narrow_parts(backend, step);
  }
  run_narrow_parts(backend, step);
  backend.complete_step(step);
}

}  // namespace lwsccd::detail
