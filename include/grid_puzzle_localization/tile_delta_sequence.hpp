// Revision bookkeeping of incremental tile deltas (TileDelta.msg), so a lost delta is noticed and the
// whole window requested again instead of silently matching against a wrong map. No ROS.
#pragma once

#include <cstdint>

namespace grid_puzzle_localization {

class TileDeltaSequence {
 public:
  enum class Verdict {
    kApply,          ///< the next delta in order, or a reset: apply it
    kIgnore,         ///< a duplicate or an older delta, or one after a gap while a resend is pending
    kRequestResend,  ///< a gap (or no reset seen yet): ask the provider to resend the window, drop this delta
  };

  /// Judges the delta with `revision` and `reset` and advances the state.
  Verdict accept(std::uint32_t revision, bool reset);

  /// The resend request failed (service down): the next out-of-order delta asks again.
  void resendFailed() { awaiting_reset_ = false; }

  /// The delta last judged kApply could not be applied (its tile directory was missing): the map no longer
  /// follows the revisions, so the next delta asks for the whole window.
  void notApplied() { synced_ = awaiting_reset_ = false; }

  bool synchronised() const { return synced_; }

 private:
  bool synced_ = false;          // a reset delta has been applied and no gap seen since
  bool awaiting_reset_ = false;  // a resend was requested and its reset delta has not arrived
  std::uint32_t last_ = 0;
};

}  // namespace grid_puzzle_localization
